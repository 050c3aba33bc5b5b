"""Sensors re-donned while the stream stopped: what the walking calibrations do after the gap
(docs/new_wearer.md, re-donned sensors).

SYN-NEW's synthetic new wearers (as in cross_session.py) walk the route, the stream stops for
``--gap`` seconds, and they walk it again (another random draw of the same wearer). Either the
sensors were re-donned meanwhile (new sensor offsets: those of wearer N + 10) or not. One
estimator reads both walks, with the defaults (a gap longer than ``calibration_reset_gap_s``, 5 s,
forgets the learnt offsets and cadence) and with ``calibration_reset_gap_s`` 0 (keeps them); a
fresh estimator reads the second walk alone. Scored on the second walk. Deterministic.

    python experiments/redon.py [--wearers 5] [--gap 60] [--jobs 2] [--out experiments/results/redon]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from bench_common import ROUTE, machine_text, md_table, pct, pool, recording_stats, run_script_jobs, sec, write_report
from synthetic import generate, new_wearer

from gait_estimator.core.estimator import Estimator, EstimatorConfig, trace_from_estimates
from gait_estimator.io.library_io import load_library
from gait_estimator.io.recording import Recording

REPO = Path(__file__).resolve().parent.parent
EARLY_S = 20.0
"""The learnt offsets are compared with the true ones this long into the second walk."""
SENSORS = ("re-donned", "same sensors")
READERS = {
    "forgets after the gap (default)": EstimatorConfig(),
    "keeps across the gap (calibration_reset_gap_s 0)": EstimatorConfig(calibration_reset_gap_s=0.0),
    "fresh estimator, second walk only": EstimatorConfig(),
}


def shifted(rec: Recording, seconds: float) -> Recording:
    return replace(rec, time_s=rec.time_s + seconds)


def run(job: tuple[str, str, int, float]) -> dict[str, Any]:
    sensors, reader, seed, gap = job
    ab = load_library("able_bodied")
    wearer = new_wearer(seed)
    first = generate(ab, ROUTE, wearer, seed=1000 + seed).recording
    again = wearer if sensors == "same sensors" else replace(
        wearer, channel_offset_deg=new_wearer(seed + 10).channel_offset_deg)
    second = shifted(generate(ab, ROUTE, again, seed=2000 + seed).recording, float(first.time_s[-1]) + gap)
    est = Estimator(ab, READERS[reader], stamped=True)
    if not reader.startswith("fresh"):
        for t, x in zip(first.time_s, first.angles_deg, strict=True):
            est.update(float(t), x)
    rows, early = [], None
    for i in range(len(second)):
        rows.append((int(second.index[i]), est.update(float(second.time_s[i]), second.angles_deg[i])))
        if early is None and second.time_s[i] - second.time_s[0] >= EARLY_S:
            early = est.sensor_offset_deg.copy()
    trace = trace_from_estimates(ab.mode_names, rows)
    stats = recording_stats(ab, second, trace)
    return {
        "sensors": sensors, "reader": reader, "seed": seed, "stats": stats,
        "offset_error_deg": float(np.sqrt(np.mean((early - np.asarray(again.channel_offset_deg)) ** 2))),
        "calibration_resets": est.calibration_resets,
    }


def summarise(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for sensors in SENSORS:
        for reader in READERS:
            rs = [r for r in results if r["sensors"] == sensors and r["reader"] == reader]
            m = pool([r["stats"] for r in rs])
            out.append({
                "sensors": sensors, "reader": reader, "accuracy": m["accuracy"], "steady_accuracy": m["steady_accuracy"],
                "phase_error_mean": m["phase_error_mean"], "mean_delay_s": m["mean_delay_s"],
                "per_wearer_accuracy": [pool([r["stats"]])["accuracy"] for r in rs],
                "offset_error_deg": float(np.mean([r["offset_error_deg"] for r in rs])),
            })
    return out


def tables(summary: list[dict[str, Any]], wearers: int, gap: float, command: str, seconds: float) -> str:
    rows = [[s["sensors"], s["reader"], pct(s["accuracy"]), pct(s["steady_accuracy"]), pct(s["phase_error_mean"], 2),
             sec(s["mean_delay_s"]), ", ".join(pct(a) for a in s["per_wearer_accuracy"]), f"{s['offset_error_deg']:.2f}°"]
            for s in summary]
    header = ["second walk", "estimator", "accuracy", "steady", "phase error", "transition delay",
              "accuracy per wearer", f"offset error {EARLY_S:g} s into it (RMS)"]
    return (
        "### Re-donned sensors: the second of two walks with a stop between\n\n"
        f"Measured by `{command}` in {seconds:.0f} s ({machine_text()}; deterministic). {wearers} synthetic new "
        "wearers (cross_session.py's "
        f"SYN-NEW) walk the route twice with a {gap:g} s stop between; re-donned = the second walk with other sensor "
        "offsets (those of wearer N + 10). Scored on the second walk. Offset error: RMS over the four channels of "
        f"learnt minus true sensor offset {EARLY_S:g} s into the second walk, mean over wearers.\n\n"
        + md_table(header, rows) + "\n"
    )


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wearers", type=int, default=5, help="synthetic new wearers (seeds 0..N-1)")
    ap.add_argument("--gap", type=float, default=60.0, help="stop between the two walks, seconds")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", type=Path, default=REPO / "experiments/results/redon", help="output directory")
    args = ap.parse_args(argv)
    jobs = [(sensors, reader, s, args.gap) for sensors in SENSORS for reader in READERS for s in range(args.wearers)]
    results, command, seconds = run_script_jobs("redon.py", argv, run, jobs, args.jobs)
    summary = summarise(results)
    write_report(args.out, tables(summary, args.wearers, args.gap, command, seconds), summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
