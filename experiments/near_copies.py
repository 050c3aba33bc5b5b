"""Walking calibration with a library that holds near copies of its modes (docs/new_wearer.md).

SYN-NEW's synthetic new wearers (as in cross_session.py) read with the default options and three
libraries: able_bodied; able_bodied with every mode twice (``KernelLibrary.replicated``, the
copies 0.001 deg apart, as the benchmarks build large libraries); and five near copies of every
mode (``synthetic.near_copies``: a fraction of a degree and of a percent apart, as one kernel per
ramp angle or speed step would be). Each with near copies counted as one mode by the walking
calibrations (the default, ``CalibrationParams.near_copy_rms_deg`` 1.0) and counted apart (0). A reported copy
counts as its mode. Deterministic apart from the per-update times (two workers on two cores).

    python experiments/near_copies.py [--wearers 5] [--jobs 2] [--out experiments/results/near_copies]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from bench_common import ROUTE, machine_text, md_table, pct, pool, recording_stats, run_script_jobs, sec, write_report
from synthetic import generate, near_copies, new_wearer

from gait_estimator.core.calibration import CalibrationParams
from gait_estimator.core.estimator import Estimator, EstimatorConfig, trace_from_estimates
from gait_estimator.core.kernels import KernelLibrary
from gait_estimator.core.pipeline import PipelineParams
from gait_estimator.io.library_io import load_library

REPO = Path(__file__).resolve().parent.parent
COPIES = 5
RULES = {"as one mode (default)": CalibrationParams().near_copy_rms_deg, "apart": 0.0}


def libraries() -> dict[str, KernelLibrary]:
    ab = load_library("able_bodied")
    return {
        "able_bodied (7 modes)": ab,
        "every mode twice (14)": ab.replicated(2 * len(ab)),
        f"{COPIES} near copies of every mode ({COPIES * len(ab)})": near_copies(ab, COPIES),
    }


def base_name(name: str, modes: Sequence[str]) -> str:
    """The mode a copy stands for: MODE_v (near_copies) or MODE_r (replicated) -> MODE."""
    head, _, tail = name.rpartition("_")
    return head if tail.isdigit() and head in modes else name


def run(job: tuple[str, str, int]) -> dict[str, Any]:
    lib_name, rule, seed = job
    ab = load_library("able_bodied")
    lib = libraries()[lib_name]
    wearer = new_wearer(seed)
    syn = generate(ab, ROUTE, wearer, seed=1000 + seed, source=f"wearer {seed}")
    rec = syn.recording
    params = PipelineParams.from_config(EstimatorConfig(), calibration={"near_copy_rms_deg": RULES[rule]})
    est = Estimator(lib, EstimatorConfig(), stamped=True, params=params)
    rows, times = [], []
    for i in range(len(rec)):
        t0 = time.perf_counter()
        e = est.update(float(rec.time_s[i]), rec.angles_deg[i])
        times.append(time.perf_counter() - t0)
        rows.append((int(rec.index[i]), e))
    names = [base_name(n, ab.mode_names) for n in lib.mode_names]
    trace = trace_from_estimates(names, rows)
    stats = recording_stats(lib, rec, trace)
    truth_offset = np.asarray(wearer.channel_offset_deg)
    return {
        "library": lib_name, "rule": rule, "seed": seed, "stats": stats,
        "calibration_strides": est.calibration.strides,
        "offset_error_deg": float(np.sqrt(np.mean((est.sensor_offset_deg - truth_offset) ** 2))),
        "cadence_error": abs(est.cadence_scale * wearer.cadence - 1.0) if est.calibration.cadence_strides else None,
        "recency_started": est.matcher.recency_half_life > 0,
        "update_us_median": float(np.median(times[len(times) // 2:]) * 1e6),
    }


def summarise(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for lib_name in dict.fromkeys(r["library"] for r in results):
        for rule in RULES:
            rs = [r for r in results if r["library"] == lib_name and r["rule"] == rule]
            metrics = pool([r["stats"] for r in rs])
            cadence = [r["cadence_error"] for r in rs]
            learnt = [c for c in cadence if c is not None]
            out.append({
                "library": lib_name, "rule": rule, "accuracy": metrics["accuracy"],
                "steady_accuracy": metrics["steady_accuracy"], "phase_error_mean": metrics["phase_error_mean"],
                "mean_delay_s": metrics["mean_delay_s"],
                "calibration_strides": [r["calibration_strides"] for r in rs],
                "offset_error_deg": float(np.mean([r["offset_error_deg"] for r in rs])),
                "cadence_unlearnt": sum(c is None for c in cadence),
                "cadence_error": float(np.mean(learnt)) if learnt else None,
                "recency_started": sum(r["recency_started"] for r in rs),
                "update_us_median": float(np.median([r["update_us_median"] for r in rs])),
            })
    return out


def tables(summary: list[dict[str, Any]], wearers: int, command: str, seconds: float) -> str:
    rows = []
    for s in summary:
        cad = "–" if s["cadence_error"] is None else f"{100 * s['cadence_error']:.1f} %"
        if s["cadence_unlearnt"]:
            cad += f" ({s['cadence_unlearnt']} unlearnt)"
        rows.append([
            s["library"], s["rule"], pct(s["accuracy"]), pct(s["steady_accuracy"]), pct(s["phase_error_mean"], 2),
            sec(s["mean_delay_s"]), ", ".join(str(n) for n in s["calibration_strides"]),
            f"{s['offset_error_deg']:.2f}°", cad, f"{s['recency_started']} of {wearers}", f"{s['update_us_median']:.0f}",
        ])
    header = ["library", "near copies", "accuracy", "steady", "phase error", "transition delay",
              "calibration strides per wearer", "offset error (RMS)", "cadence error", "recency weighting started",
              "µs per update (median)"]
    return (
        "### Near copies: SYN-NEW wearers read with libraries holding near copies of their modes\n\n"
        f"Measured by `{command}` in {seconds:.0f} s ({machine_text()}; per-update times from two workers sharing two "
        f"cores). {wearers} synthetic new wearers (cross_session.py's SYN-NEW), default options; a reported copy "
        "counts as its mode. Offset error: RMS over the four channels of learnt minus true sensor offset, mean "
        "over wearers (0 learnt = the true offset's RMS). Cadence error: learnt time scale against the wearer's, "
        "mean over wearers that learnt one.\n\n" + md_table(header, rows) + "\n"
    )


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wearers", type=int, default=5, help="synthetic new wearers (seeds 0..N-1)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes")
    ap.add_argument("--out", type=Path, default=REPO / "experiments/results/near_copies", help="output directory")
    args = ap.parse_args(argv)
    jobs = [(lib, rule, s) for lib in libraries() for rule in RULES for s in range(args.wearers)]
    results, command, seconds = run_script_jobs("near_copies.py", argv, run, jobs, args.jobs)
    summary = summarise(results)
    write_report(args.out, tables(summary, args.wearers, command, seconds), summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
