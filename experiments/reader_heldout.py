"""Does the stride-start reader hold on walking its guards and evidence were not chosen on?

The reader as first shipped (fit gate 1; experiments/stride_reader.py) was tuned on SYN-NEW
(wearers 0-4), LG_2_Ramp and Multispeed with the bundled able-bodied kernels, and its false stair
switches were counted on those same two recordings. This script checks it, and each variant of its
constants (``--variants``, as in stride_reader.py: JOINS/GATE/SWITCH_FIT/REPORT_FROM), against the
reader off, where none of that tuning looked:

* **Unseen wearers** (``--wearers``, default 20): synthetic new wearers 200, 201, ... (test/synthetic.py
  ``new_wearer``; SYN-NEW uses 0-4, the 15-wearer check 0-14) walking bench_common.ROUTE: accuracy,
  accuracy with Slow/Med/Fast as one class, phase error.
* **Stops, no stairs**: the same wearers on a stair-free route (level speeds and ramps) that slows
  down over five strides (each up to 1.4x longer, outside the cadence band) into a stop, stands 3-6 s
  (test/synthetic.py ``with_stops``: a 0.6 s fade to a standing pose, sway and noise), and sets off
  again, four times; and an abrupt stop: ten Med strides, 4 s standing, four more. Time (episodes)
  reported as a stair mode; accuracy of the walking rows.
* **A library it was not tuned with**: the bundled prosthesis-side kernels on LG_2_Ramp (raw
  stamps) and Multispeed, whole recordings, neither has stairs: time reported as a stair mode.
* **The fit gate recording by recording**: false stair time on LG_2_Ramp and on Multispeed
  separately (bundled able-bodied kernels) for fit gates off, 2, 1.5, 1.25 and 1.

The reader as first shipped reported stairs in those stops. READER_SWITCH_FIT and REPORT_FROM were
then chosen on wearers 100-119 (experiments/results/reader_heldout_dev, ``--first-wearer 100`` and
the variants named there); the default run, wearers 200-219, checks them on wearers that played no
part in choosing them. Deterministic; about 3 min.

    python experiments/reader_heldout.py [--wearers 20] [--first-wearer 200] [--variants V ...] [--evidence 40] [--jobs 2]
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np
from bench_common import (
    MS_CSV,
    REPO,
    ROUTE,
    Dataset,
    Part,
    column_hs,
    machine_text,
    md_table,
    part_stats,
    pct,
    run_script_jobs,
    write_report,
)
from cross_session import SPEEDS, lg2_raw_part
from stride_reader import current_constants, format_variant, parse_variant, reader_constants
from synthetic import generate, new_wearer, with_stops

from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.core.kernels import KernelLibrary
from gait_estimator.core.stride_reader import SUGGESTED_EVIDENCE_DEG2S
from gait_estimator.io.library_io import load_library
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording

FIRST_WEARER = 200
STAIRS = ("SA", "SD")
STOP_ROUTE = [
    ("Med", 8), ("Med", 5), ("Slow", 6), ("Med", 6), ("Fast", 6), ("Fast", 5), ("RA", 6), ("Med", 4),
    ("RD", 6), ("RD", 5), ("Med", 6), ("Slow", 6), ("Slow", 5), ("Med", 6),
]
"""Stair-free route (80 strides); the walk slows down into a stop over each segment of STOP_AFTER."""
STOP_AFTER = (1, 5, 9, 12)
SLOWDOWN = (1.08, 1.16, 1.24, 1.32, 1.4)
"""Extra duration factor of the five strides before a stop."""
GATES = (math.inf, 2.0, 1.5, 1.25, 1.0)
RECORDINGS = ("LG_2_Ramp", "Multispeed")


def standing(lib: KernelLibrary, wearer: int) -> np.ndarray:
    """The wearer's standing pose: the Med kernel's mean at their sensor offsets, degrees."""
    return lib.mode("Med").samples.mean(axis=0) + np.asarray(new_wearer(wearer).channel_offset_deg)


def abrupt_stop(lib: KernelLibrary, wearer: int) -> Recording:
    """Wearer ``wearer``: ten Med strides, a stop of 4 s without slowing down first, four more."""
    syn = generate(lib, [("Med", 10), ("Med", 4)], new_wearer(wearer), seed=6000 + wearer, source=f"wearer {wearer}")
    return with_stops(syn.recording, {10: 4.0}, standing(lib, wearer), seed=7000 + wearer)


def stop_walk(lib: KernelLibrary, wearer: int) -> Recording:
    """Wearer ``wearer`` on STOP_ROUTE with four slowdowns into stops of 3-6 s."""
    cfg = new_wearer(wearer)
    starts = np.cumsum([0] + [n for _, n in STOP_ROUTE])
    slow = {int(starts[j]) + s: f for j in STOP_AFTER for s, f in enumerate(SLOWDOWN)}
    syn = generate(lib, STOP_ROUTE, cfg, seed=3000 + wearer, duration_scale=slow, source=f"wearer {wearer}")
    rng = np.random.default_rng([4000, wearer])
    stops = {int(starts[j + 1]): float(rng.uniform(3.0, 6.0)) for j in STOP_AFTER}
    return with_stops(syn.recording, stops, standing(lib, wearer), seed=5000 + wearer)


def stair_time(rec: Recording, modes: np.ndarray) -> tuple[float, int]:
    """Seconds and episodes reported as a stair mode."""
    dt = np.diff(rec.time_s, append=rec.time_s[-1])
    on = np.isin(modes, STAIRS)
    return float(dt[on].sum()), int((on & ~np.r_[False, on[:-1]]).sum())


def trace_modes(lib: KernelLibrary, rec: Recording, cfg: EstimatorConfig) -> tuple[Any, np.ndarray]:
    est = Estimator(lib, cfg, stamped=True)
    trace = run_estimator(est, rec.time_s, rec.angles_deg)
    return trace, np.asarray(lib.mode_names, dtype=object)[trace.mode_index]


def scores(lib: KernelLibrary, rec: Recording, trace: Any, one_level: bool = False) -> dict[str, Any]:
    part = Part(rec.source, rec, rec, column_hs(rec), {m: SPEEDS for m in SPEEDS} if one_level else {})
    s = part_stats(Dataset("", "", lib, [part]), part, trace)
    return {"correct": s["correct"], "evaluated": s["evaluated"], "ph_sum": s["ph_sum"], "ph_n": s["ph_n"],
            "switches": s["switches"], "duration_s": s["duration_s"]}


def run_wearer(job: tuple[int, float, tuple[str, ...]]) -> dict[str, Any]:
    """Reader off, and at ``evidence`` in each variant (stride_reader.py): the wearer on ROUTE, on
    STOP_ROUTE and on an abrupt stop."""
    wearer, evidence, variants = job
    ab = load_library("able_bodied")
    route = generate(ab, ROUTE, new_wearer(wearer), seed=2000 + wearer, source=f"wearer {wearer}").recording
    stops = stop_walk(ab, wearer)
    abrupt = abrupt_stop(ab, wearer)
    out: dict[str, Any] = {"wearer": wearer}
    for name, e in (("off", 0.0), *((v, evidence) for v in variants)):
        with nullcontext() if name == "off" else reader_constants(parse_variant(name)):
            cfg = EstimatorConfig(switch_evidence_deg2s=e)
            trace, _ = trace_modes(ab, route, cfg)
            st, modes = trace_modes(ab, stops, cfg)
            _, abrupt_modes = trace_modes(ab, abrupt, cfg)
        out[name] = {"route": scores(ab, route, trace), "route_l": scores(ab, route, trace, one_level=True),
                     "stops": scores(ab, stops, st, one_level=True), "stops_stairs": stair_time(stops, modes),
                     "stops_s": float(stops.time_s[-1] - stops.time_s[0]),
                     "abrupt_stairs": stair_time(abrupt, abrupt_modes)}
    return out


def recordings() -> dict[str, Recording]:
    return dict(zip(RECORDINGS, (lg2_raw_part(REPO).feed, read_recording(REPO / MS_CSV)), strict=True))


def run_recording(job: tuple[str, str, float, str]) -> dict[str, Any]:
    """False stair time of one stair-free recording with one library, evidence and variant."""
    rec_name, lib_name, evidence, variant = job
    lib = load_library(lib_name)
    rec = recordings()[rec_name]
    with reader_constants(parse_variant(variant)):
        _, modes = trace_modes(lib, rec, EstimatorConfig(switch_evidence_deg2s=evidence))
    s, n = stair_time(rec, modes)
    return {"recording": rec_name, "library": lib_name, "evidence": evidence, "variant": variant, "stairs_s": s,
            "episodes": n, "duration_s": float(rec.time_s[-1] - rec.time_s[0])}


def run_job(job: tuple) -> dict[str, Any]:
    return run_wearer(job) if len(job) == 3 else run_recording(job)


def with_gate(variant: str, gate: float) -> str:
    j, _, fit, start, agree = parse_variant(variant)
    return format_variant((j, gate, fit, start, agree))


def pooled(rows: Sequence[dict[str, Any]], key: str) -> tuple[str, str]:
    c = sum(r[key]["correct"] for r in rows)
    e = sum(r[key]["evaluated"] for r in rows)
    ph = sum(r[key]["ph_sum"] for r in rows) / max(1, sum(r[key]["ph_n"] for r in rows))
    return pct(c / e), pct(ph, 2)


FIRST_SHIPPED = "0.25+0.65/1/off/0"
"""The reader as first shipped: the fit gate only (stride_reader.py variants: JOINS/GATE/SWITCH_FIT/REPORT_FROM)."""


def variant_name(variant: str) -> str:
    _, gate, fit, start = variant.split("/")
    return f"gate {gate}, switch fit {fit}, from {start}"


def main(argv: Sequence[str] | None = None) -> int:
    now = format_variant(current_constants())
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wearers", type=int, default=20, help="unseen synthetic wearers")
    ap.add_argument("--first-wearer", type=int, default=FIRST_WEARER, help="the first of them")
    ap.add_argument("--evidence", type=float, default=SUGGESTED_EVIDENCE_DEG2S, help="switch_evidence_deg2s of the reader")
    ap.add_argument("--variants", nargs="+", default=[FIRST_SHIPPED, now],
                    help="reader constants as in stride_reader.py; the first and last are also run on the recordings")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", type=Path, default=REPO / "experiments/results/reader_heldout", help="output directory")
    args = ap.parse_args(argv)
    variants = tuple(args.variants)
    ends = tuple(dict.fromkeys((variants[0], variants[-1])))
    e = args.evidence
    jobs: list[Any] = [(args.first_wearer + w, e, variants) for w in range(args.wearers)]
    jobs += [(r, "prosthesis", x, v) for r in RECORDINGS for x, v in ((0.0, variants[-1]), *((e, v) for v in ends))]
    jobs += [(r, "able_bodied", e, with_gate(v, g)) for v in ends for r in RECORDINGS for g in GATES]

    results, command, seconds = run_script_jobs("reader_heldout.py", argv, run_job, jobs, args.jobs)
    wearers = [r for r in results if "wearer" in r]
    recs = [r for r in results if "recording" in r]

    syn_rows = []
    for name in ("off", *variants):
        ws = [w[name] for w in wearers]
        acc, ph = pooled(ws, "route")
        acc_l, _ = pooled(ws, "route_l")
        sacc, _ = pooled(ws, "stops")
        stairs = sum(w["stops_stairs"][0] for w in ws)
        episodes = sum(w["stops_stairs"][1] for w in ws)
        worst = max(w["stops_stairs"][0] for w in ws)
        abrupt = sum(w["abrupt_stairs"][0] for w in ws)
        abrupt_wearers = sum(w["abrupt_stairs"][1] > 0 for w in ws)
        minutes = sum(w["stops_s"] for w in ws) / 60
        per_min = sum(w["stops"]["switches"] for w in ws) / minutes
        label = "off" if name == "off" else f"{e:g}, {variant_name(name)}"
        syn_rows.append([label, acc, acc_l, ph, sacc, f"{stairs:.2f} s ({episodes})", f"{worst:.2f} s",
                         f"{per_min:.0f}", f"{abrupt:.2f} s ({abrupt_wearers})"])
    lib_rows = [[r["recording"], "off" if r["evidence"] == 0 else f"{r['evidence']:g}, {variant_name(r['variant'])}",
                 f"{r['stairs_s']:.2f} s ({r['episodes']})", f"{r['duration_s']:.0f} s"]
                for r in recs if r["library"] == "prosthesis"]
    cells = {(r["recording"], r["variant"]): r for r in recs if r["library"] == "able_bodied"}
    gate_rows = [["off" if math.isinf(g) else f"{g:g}"]
                 + [f"{c['stairs_s']:.2f} s ({c['episodes']})" for v in ends for n in RECORDINGS
                    for c in [cells[n, with_gate(v, g)]]] for g in GATES]
    n = len(wearers)
    stop_minutes = sum(w["off"]["stops_s"] for w in wearers) / 60
    first = args.first_wearer
    text = (
        "### The stride-start reader where it was not tuned\n\n"
        f"Measured by `{command}` in {seconds:.0f} s ({machine_text()}; deterministic). Every other option the "
        "default. Reader: evidence (deg² s), READER_FIT_GATE, READER_SWITCH_FIT and REPORT_FROM "
        f"(experiments/stride_reader.py); {variant_name(FIRST_SHIPPED)} is the reader as first shipped.\n\n"
        f"**Synthetic wearers {first}-{first + n - 1}** ({n}; SYN-NEW is 0-4): bench_common.ROUTE (78 strides, "
        "all 7 modes, 12 changes) and a stair-free route with four slowdowns (five strides up to 1.4x longer) into "
        f"stops of 3-6 s ({stop_minutes:.1f} min in all). One class: Slow, Med and Fast scored as one. False stairs: "
        "time (episodes) the stair-free walks are reported as SA or SD, all wearers; worst: the worst wearer. "
        "Abrupt stops: ten Med strides, a 4 s stop without slowing down first, four more; time reported as SA or "
        "SD, all wearers (how many wearers had any).\n\n"
        + md_table(["reader", "route accuracy", "route, one level class", "route phase error",
                    "stair-free walking rows, one level class", "false stairs", "worst wearer",
                    "changes /min (stair-free)", "false stairs, abrupt stops (wearers)"], syn_rows)
        + "\n\n**A library the reader was not tuned with**: the bundled prosthesis-side kernels on the two "
        "stair-free recordings, whole recordings (standing up, turns, stops, a treadmill speeding up and slowing "
        "down). False stairs: time (episodes) reported as SA or SD.\n\n"
        + md_table(["recording", "reader", "false stairs", "length"], lib_rows)
        + f"\n\n**The fit gate recording by recording** (able-bodied kernels, evidence {e:g}): false stair time "
        "(episodes), LG_2_Ramp (34 s) and Multispeed (62 s).\n\n"
        + md_table(["fit gate"] + [f"{n}, {variant_name(v).split(', ', 1)[1]}" for v in ends for n in RECORDINGS],
                   gate_rows)
        + "\n"
    )
    write_report(args.out, text, {"wearers": wearers, "recordings": recs})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
