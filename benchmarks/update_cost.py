#!/usr/bin/env python3
"""Per-sample cost of ``Estimator.update`` (default preset, able_bodied, Multispeed stamped at
230 Hz) in this checkout and in another one, interleaved, one process per round:

    git worktree add /tmp/old 1d47482
    taskset -c 0 python benchmarks/update_cost.py --other /tmp/old --rounds 6

Prints the median and p99 (microseconds) of each side over all rounds and their ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ROUND = r"""
import json, sys, time
import numpy as np
from gait_estimator import Estimator, load_library
from gait_estimator.io.readers import read_recording
lib = load_library("able_bodied")
rec = read_recording(sys.argv[1])
t = np.arange(len(rec)) / 230.0
rows = [tuple(r) for r in rec.angles_deg.tolist()]
est = Estimator(lib)
for i in range(2000):
    est.update(float(t[i]), rows[i])
est = Estimator(lib)
out = []
clock = time.perf_counter_ns
for i in range(len(rows)):
    a = clock()
    est.update(float(t[i]), rows[i])
    out.append(clock() - a)
print(json.dumps(out))
"""


def one_round(src: Path) -> np.ndarray:
    env = {**os.environ, "PYTHONPATH": str(src)}
    rec = REPO / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv"
    run = subprocess.run([sys.executable, "-c", ROUND, str(rec)], env=env, cwd=src, capture_output=True, text=True,
                         check=True)
    return np.asarray(json.loads(run.stdout), dtype=np.float64) / 1e3


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--other", type=Path, required=True, help="another checkout (e.g. a git worktree of main)")
    ap.add_argument("--rounds", type=int, default=6)
    args = ap.parse_args(argv)
    times: dict[str, list[np.ndarray]] = {"this": [], "other": []}
    for _ in range(args.rounds):
        for name, src in (("other", args.other.resolve()), ("this", REPO)):
            times[name].append(one_round(src))
    stats = {k: (float(np.median(np.concatenate(v))), float(np.percentile(np.concatenate(v), 99))) for k, v in times.items()}
    for k, (med, p99) in stats.items():
        print(f"{k:<6} median {med:7.2f} us  p99 {p99:7.2f} us")
    print(f"this / other: median x{stats['this'][0] / stats['other'][0]:.3f}, p99 x{stats['this'][1] / stats['other'][1]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
