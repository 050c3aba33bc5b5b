#!/usr/bin/env python3
"""Per-sample cost of ``Estimator.update`` now vs at an earlier revision, on the same machine.

    python experiments/step_cost_history.py [--before 87e9be3] [--rounds 3]
        # -> experiments/results/matcher/history.json (read by experiments/matcher_tables.py)

Checks the ``--before`` revision out into a temporary git worktree and times, in alternating
child processes (``--rounds`` each, so both see the same machine state), ``Estimator.update`` of
the bundled able_bodied library (7 modes) on 6,000 samples of ``analysis.bench.synthetic_walk``
stamped at 230 Hz: at ``--before`` with its defaults (the paper's algorithm, the numpy step), and
now with the ``default`` and the ``paper`` presets (numba step when installed). Reports the median
and p99 per call after 1,000 warm-up samples, and the ratio of the medians (issue 10 allows the
default preset at most 1.5x the cost before it).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "results" / "matcher" / "history.json"
BEFORE = "87e9be3"  # the last commit before issues 10 and 11

TIMER = r'''
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
from gait_estimator.analysis.bench import synthetic_walk
from gait_estimator.core.estimator import Estimator, EstimatorConfig
from gait_estimator.io.library_io import load_library
lib = load_library("able_bodied")
preset = sys.argv[2]
config = EstimatorConfig.preset(preset) if hasattr(EstimatorConfig, "preset") else EstimatorConfig()
est = Estimator(lib, config)
x = synthetic_walk(lib, 6000)
t = np.arange(len(x)) / 230.0
for i in range(1000):
    est.update(float(t[i]), x[i])
ns = []
clock = time.perf_counter_ns
for i in range(1000, len(x)):
    t0 = clock()
    est.update(float(t[i]), x[i])
    ns.append(clock() - t0)
us = np.array(ns) / 1e3
print(json.dumps({"median_us": float(np.median(us)), "p99_us": float(np.percentile(us, 99))}))
'''


def run(src: Path, preset: str) -> dict[str, float]:
    out = subprocess.run([sys.executable, "-c", TIMER, str(src), preset], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", default=BEFORE, help=f"earlier revision (default {BEFORE})")
    ap.add_argument("--rounds", type=int, default=3, help="alternating runs of each (default 3)")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from gait_estimator.analysis.bench import machine_info

    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "before"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(old), args.before],
                       check=True, capture_output=True)
        try:
            runs: dict[str, list[dict[str, float]]] = {"before": [], "default": [], "paper": []}
            for _ in range(args.rounds):
                runs["before"].append(run(old, "default"))
                runs["default"].append(run(ROOT, "default"))
                runs["paper"].append(run(ROOT, "paper"))
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)], check=False,
                           capture_output=True)
    best = {k: min(v, key=lambda r: r["median_us"]) for k, v in runs.items()}
    report = {
        "command": "python experiments/step_cost_history.py" + (f" --before {args.before}" if args.before != BEFORE else ""),
        "before": args.before, "rounds": args.rounds, "machine": machine_info(), "runs": runs, "best": best,
        "ratio_default_to_before": best["default"]["median_us"] / best["before"]["median_us"],
        "ratio_paper_to_before": best["paper"]["median_us"] / best["before"]["median_us"],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    for k, v in best.items():
        print(f"{k:8s} median {v['median_us']:.1f} us  p99 {v['p99_us']:.1f} us")
    print(f"default / before: {report['ratio_default_to_before']:.2f}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
