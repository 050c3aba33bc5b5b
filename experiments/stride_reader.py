"""How the stride-start reader's joins, guards and evidence were measured (docs/new_wearer.md, "The stride-start reader").

The reader (gait_estimator/core/stride_reader.py; opt-in, ``switch_evidence_deg2s``) assumes that a
new mode's stride joins its own course from the pose at the heel strike within one of
JOIN_FRACTIONS of the stride (each mode read with the one that fits it best), and reports another
mode once its error since the heel strike is ``switch_evidence_deg2s`` below every other's. It
starts a reading only at heel strikes after a stride the reported mode fitted within
READER_FIT_GATE of how the wearer's confident strides usually fit (core/estimator.py; "off" here:
at every heel strike once a confident stride has shown that fit), and reports a mode only while it
fits the stride since the heel strike within READER_SWITCH_FIT of that usual fit and only from
REPORT_FROM of its stride on (core/estimator.py, core/stride_reader.py; both chosen in
experiments/reader_heldout.py). This runs cross_session.py's SYN-NEW (synthetic: their generator
fades over 0.25 of the stride), LG2-AB (LG_2_Ramp's real mode changes) and MS-LG2 (no mode change:
every switch is a false one) for each variant of those constants (VARIANTS) and evidence, all
other options the defaults, and tabulates accuracy, LG_2_Ramp's level accuracy and phase error,
MS-LG2's phase error and the reported mode changes per minute. The accuracy scores only labelled
rows; the false switches in the unlabelled parts (standing up, turns,
stops, a treadmill slowing down) are counted apart: the time LG_2_Ramp (raw stamps) and Multispeed
(230 Hz) are reported as a stair mode, with the bundled kernels (neither has stairs), and the time
Multispeed (level walking only) is reported as a ramp. Deterministic; about 1 min per variant with
two workers.

    python experiments/stride_reader.py [--variants 0.25+0.65/1/1.25/0.25 ...] [--evidence 10,20,40] [--jobs 2]
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cross_session
import numpy as np
from bench_common import data_root, machine_text, md_table, pct, write_report

from gait_estimator.core import estimator, stride_reader
from gait_estimator.core.estimator import Estimator, EstimatorConfig
from gait_estimator.io.library_io import load_library
from gait_estimator.io.readers import read_recording

REPO = Path(__file__).resolve().parent.parent
DATASETS = ("SYN-NEW", "LG2-AB", "MS-LG2")
OFF = "no reader"
MULTISPEED = "data/swge/recordings/Multispeed_Walk_AB.csv"


def false_switches(evidence: Sequence[float]) -> dict[str, dict[str, float]]:
    """Seconds (and episodes) the stair-free recordings are reported as a stair mode, and
    Multispeed as a ramp, with the bundled kernels, the reader off and at each evidence."""
    ab = load_library("able_bodied")
    recordings = {"LG_2_Ramp": cross_session.lg2_raw_part(data_root()).feed,
                  "Multispeed": read_recording(REPO / MULTISPEED)}
    out = {}
    for e in [0.0, *evidence]:
        stairs, episodes, ramps = 0.0, 0, 0.0
        for name, rec in recordings.items():
            est = Estimator(ab, EstimatorConfig(switch_evidence_deg2s=e), stamped=True)
            modes = np.array([est.update(float(t), x).mode for t, x in zip(rec.time_s, rec.angles_deg, strict=True)])
            dt = np.diff(rec.time_s, append=rec.time_s[-1])
            on = np.isin(modes, ["SA", "SD"])
            stairs += float(dt[on].sum())
            episodes += int((on & ~np.r_[False, on[:-1]]).sum())
            if name == "Multispeed":
                ramps += float(dt[np.isin(modes, ["RA", "RD"])].sum())
        out[OFF if e == 0.0 else f"{e:g}"] = {"stairs_s": stairs, "stair_episodes": episodes, "multispeed_ramps_s": ramps}
    return out


def run_joins(evidence: Sequence[float], jobs: int, out: Path) -> dict[str, Any]:
    """cross_session.py's results and the false switches for the reader off and at each evidence,
    with the module constants as set by the caller."""
    adds = [a for e in evidence for a in ("--add", f"{e:g}={json.dumps({'switch_evidence_deg2s': e})}")]
    names = [OFF] + [f"{e:g}" for e in evidence]
    cross_session.main(["--out", str(out), "--datasets", ",".join(DATASETS), "--jobs", str(jobs),
                        "--add", f"{OFF}={json.dumps({'switch_evidence_deg2s': 0.0})}", *adds,
                        "--settings", ",".join(names)])
    res = json.loads((out / "summary.json").read_text(encoding="utf-8"))["results"]
    false = false_switches(evidence)
    return {name: {**{key: res[key][name] for key in (*DATASETS, "SYN-NEW-L")}, "false": false[name]} for name in names}


Constants = tuple[tuple[float, ...], float, float, float, float]
"""JOIN_FRACTIONS, READER_FIT_GATE, READER_SWITCH_FIT, REPORT_FROM, READER_PHASE_AGREEMENT."""
PHASE_AGREEMENT = estimator.READER_PHASE_AGREEMENT
"""The estimator's own value: the phase agreement of a variant that does not give one."""


def parse_variant(text: str) -> Constants:
    j, gate, fit, start, *agree = text.split("/")
    return (tuple(float(v) for v in j.split("+")), math.inf if gate == "off" else float(gate),
            math.inf if fit == "off" else float(fit), float(start), float(agree[0]) if agree else PHASE_AGREEMENT)


def format_variant(c: Constants) -> str:
    """The text ``parse_variant`` reads (the phase agreement only where it is not the estimator's)."""
    j, gate, fit, start, agree = c
    return "/".join(("+".join(f"{v:g}" for v in j), *("off" if math.isinf(v) else f"{v:g}" for v in (gate, fit)),
                     f"{start:g}", *([] if agree == PHASE_AGREEMENT else [f"{agree:g}"])))


def current_constants() -> Constants:
    return (stride_reader.JOIN_FRACTIONS, estimator.READER_FIT_GATE, estimator.READER_SWITCH_FIT,
            stride_reader.REPORT_FROM, estimator.READER_PHASE_AGREEMENT)


@contextmanager
def reader_constants(c: Constants) -> Iterator[None]:
    """The reader's constants as ``c`` for estimators built inside (and workers forked inside)."""
    default = current_constants()
    (stride_reader.JOIN_FRACTIONS, estimator.READER_FIT_GATE, estimator.READER_SWITCH_FIT, stride_reader.REPORT_FROM,
     estimator.READER_PHASE_AGREEMENT) = c
    try:
        yield
    finally:
        (stride_reader.JOIN_FRACTIONS, estimator.READER_FIT_GATE, estimator.READER_SWITCH_FIT,
         stride_reader.REPORT_FROM, estimator.READER_PHASE_AGREEMENT) = default


def phase_cell(r: dict[str, Any]) -> str:
    """Mean phase error (max) over the rows with the right mode, % of a stride."""
    return f"{pct(r['phase_error_mean'], 2)} ({pct(r['phase_error_max'], 0)})"


def row(name: str, r: dict[str, Any]) -> list[str]:
    lg2, f = r["LG2-AB"], r["false"]
    return [name, pct(r["SYN-NEW"]["accuracy"]), phase_cell(r["SYN-NEW"]), pct(r["SYN-NEW-L"]["accuracy"]),
            pct(lg2["accuracy"]), pct(lg2["per_mode_accuracy"].get("level")), phase_cell(lg2),
            f"{lg2['switches_per_min']:.0f}", pct(r["MS-LG2"]["accuracy"]), phase_cell(r["MS-LG2"]),
            f"{f['stairs_s']:.2f} s ({f['stair_episodes']})", f"{f['multispeed_ramps_s']:.2f} s"]


VARIANTS = ("0.25+0.65/off/off/0", "0.25+0.65/off/off/0/0", "0.25+0.65/1/off/0", "0.25+0.65/1/1.25/0",
            "0.5/1/1.25/0.25", "0.25+0.65/1/1.25/0.25/0", "0.25+0.65/1/1.25/0.25")
"""JOIN_FRACTIONS / READER_FIT_GATE / READER_SWITCH_FIT / REPORT_FROM [/ READER_PHASE_AGREEMENT]: the
reader without guards, with the fit gate (as first shipped), with the switch fit, with one join, and
as now; without guards and as now also with the reader's own phase wherever it reports (agreement 0)."""


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS),
                    help="JOINS/GATE/SWITCH_FIT/REPORT_FROM[/PHASE_AGREEMENT], join fractions joined by +, off = no "
                         "gate or switch fit; PHASE_AGREEMENT defaults to the estimator's")
    ap.add_argument("--evidence", default="10,20,40", help="comma-separated switch_evidence_deg2s values")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", type=Path, default=REPO / "experiments/results/stride_reader", help="output directory")
    args = ap.parse_args(argv)
    evidence = [float(v) for v in args.evidence.split(",")]
    default = current_constants()
    t0 = time.perf_counter()
    summary: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for variant in args.variants:
            with reader_constants(parse_variant(variant)):
                summary[variant] = run_joins(evidence, args.jobs, Path(tmp) / variant.replace("/", "_"))
    seconds = time.perf_counter() - t0
    rows = [["–", "–", "–", "–", "–", *row("off", next(iter(summary.values()))[OFF])]]
    for variant, by in summary.items():
        j, gate, fit, start, agree = parse_variant(variant)
        for name, r in by.items():
            if name != OFF:
                now = parse_variant(variant) == default and float(name) == stride_reader.SUGGESTED_EVIDENCE_DEG2S
                rows.append([" + ".join(f"{v:g}" for v in j), *("off" if math.isinf(v) else f"{v:g}" for v in (gate, fit)),
                             f"{start:g}", f"{agree:g}", *row(name + (" (suggested)" if now else ""), r)])
    command = shlex.join(["python", "experiments/stride_reader.py", *(sys.argv[1:] if argv is None else argv)])
    text = (
        "### The stride-start reader: join fractions, fit gate and evidence\n\n"
        f"Measured by `{command}` in {seconds:.0f} s ({machine_text()}; deterministic). cross_session.py's data "
        "sets, every other option the default. SYN-NEW-L: SYN-NEW with Slow, Med and Fast one class. "
        "MS-LG2 has no mode change: every reported change there is a false one. Mode changes per minute: "
        "reported on LG_2_Ramp (its truth changes 7.1 times a minute, the speed classes counted as one). "
        "False stairs: time (episodes) LG_2_Ramp and Multispeed, which have no stairs, are reported as SA or SD "
        "with the bundled kernels, over the whole recordings (34 s and 62 s, most of it outside the labelled "
        "rows); false ramps: Multispeed (level walking only) reported as RA or RD. Fit gate: a reading starts only at "
        "heel strikes after a stride the reported mode fitted within this factor (RMS) of the wearer's usual fit; off: "
        "at every heel strike once a confident stride has shown that fit. Switch fit: the reader's mode is reported only "
        "while it fits the stride since the heel strike within this factor (RMS) of that usual fit; off: always. Report "
        "from: the reader's mode is reported only from this part of its stride on. Phase agreement: where the reader "
        "reports another mode, the supervised phase is kept if it is within this of the reader's own (time since the "
        "heel strike over the new mode's stride at its best scale); 0: the reader's own always. Phase error: mean "
        "(max) over the rows with the right mode, % of a stride.\n\n"
        + md_table(["join fractions", "fit gate", "switch fit", "report from", "phase agreement", "evidence (deg² s)",
                    "SYN-NEW", "SYN-NEW phase error", "SYN-NEW-L", "LG2-AB", "LG2-AB level", "LG2-AB phase error",
                    "LG2-AB changes /min", "MS-LG2", "MS-LG2 phase error", "false stairs", "false ramps (Multispeed)"],
                   rows)
        + "\n"
    )
    write_report(args.out, text, summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
