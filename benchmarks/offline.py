"""Offline throughput of ``run_estimator`` (behind ``process``) against an older checkout in the
same run, and how far the matcher's arithmetic lets it go (issue 30). Run by
``python benchmarks/performance.py --offline TREE`` (TREE: a checkout of the older code, e.g.
``git worktree add /tmp/old 5b851d2``); writes benchmarks/results/performance/offline.json.

* Throughput: the bundled Multispeed recording (14,170 samples at 230 Hz, every sample a grid
  sample) through a fresh ``Estimator`` with the ``default`` and ``paper`` presets, the library
  replicated to M modes; samples/s, best of ``repeat``; each code tree in its own process, the
  trees taking turns.
* Ceiling: the same default-preset run with the time inside ``IncrementalMatcher.run_steps`` and
  the kernel columns it updated (rows in the scale band x their lengths, per step), and the cost
  per column of the running-sum update alone (the age-weighted recurrence of ``compiled.py``
  compiled here: no offset read-out, no best-shift search) over rows of the final band's lengths.
  The ceiling is the throughput if the matcher step cost only that update, on one thread and split
  perfectly over two; the rest of the run (resampling, supervisor, calibrations) as measured.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from gait_estimator import load_library  # noqa: E402
from gait_estimator.analysis.bench import machine_info  # noqa: E402
from gait_estimator.core.estimator import Estimator, run_estimator  # noqa: E402
from gait_estimator.core.matcher import PARALLEL_MIN_ROWS, IncrementalMatcher  # noqa: E402
from gait_estimator.io.readers import read_recording  # noqa: E402

RECORDING = REPO / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv"

TIMER = """
import sys, time, numpy as np
from gait_estimator import load_library
from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.io.readers import read_recording
rec = read_recording(sys.argv[1])
t, x = np.asarray(rec.time_s), np.asarray(rec.angles_deg)
m, preset, repeat = int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
lib = load_library("able_bodied")
lib = lib if m == len(lib.modes) else lib.replicated(m)
run_estimator(Estimator(lib, EstimatorConfig.preset(preset)), t[:400], x[:400])  # compile / load the cache
best = float("inf")
for _ in range(repeat):
    est = Estimator(lib, EstimatorConfig.preset(preset))
    t0 = time.perf_counter()
    run_estimator(est, t, x)
    best = min(best, time.perf_counter() - t0)
print(len(t) / best)
"""


def throughput(tree: Path, modes: int, preset: str, repeat: int) -> float:
    """Samples/s of run_estimator with the code in ``tree``."""
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    out = subprocess.run([sys.executable, "-c", TIMER, str(RECORDING), str(modes), preset, str(repeat)],
                         env=env, check=True, capture_output=True, text=True, cwd=tree)
    return float(out.stdout.split()[-1])


def _compiled_update():  # type: ignore[no-untyped-def]
    """The age-weighted running-sum update of every row, ``steps`` times (compiled.py's recurrence)."""
    from numba import njit  # only for measuring: the tables are written without numba

    @njit(cache=False)
    def update_only(e, kern, ksq, lens, lam, steps):  # pragma: no cover - compiled
        for _ in range(steps):
            for r in range(e.shape[0]):
                er, n, a = e[r], lens[r], lam[r]
                k0, k1, k2, k3, kq = kern[r, 0], kern[r, 1], kern[r, 2], kern[r, 3], ksq[r]
                last = er[n - 1]
                for j in range(n - 1, 0, -1):
                    er[j] = a * er[j - 1] + 0.5 + 0.25 * kq[j] - 0.5 * k0[j] + 0.25 * k1[j] - 0.125 * k2[j] + 0.5 * k3[j]
                er[0] = a * last + 0.5 + 0.25 * kq[0] - 0.5 * k0[0] + 0.25 * k1[0] - 0.125 * k2[0] + 0.5 * k3[0]

    return update_only


def update_ns_per_column(lengths: np.ndarray, float32: bool, steps: int = 2000) -> float:
    """ns per kernel column of the running-sum update alone, rows of ``lengths``, one thread."""
    update_only = _compiled_update()
    rows, n = lengths.size, int(lengths.max())
    rng = np.random.default_rng(0)
    kern = rng.normal(0.0, 20.0, (rows, 4, n)).astype(np.float32 if float32 else np.float64)
    ksq, e = (kern.astype(np.float64) ** 2).sum(axis=1), np.zeros((rows, n))
    lam = np.full(rows, 0.995)
    update_only(e, kern, ksq, lengths, lam, 2)
    t0 = time.perf_counter()
    update_only(e, kern, ksq, lengths, lam, steps)
    return (time.perf_counter() - t0) / (float(lengths.sum()) * steps) * 1e9


def ceiling(modes: int) -> dict[str, float]:
    """The default preset's run split into matcher step and the rest, and the throughput if the
    step cost only the running-sum update."""
    rec = read_recording(RECORDING)
    t, x = np.asarray(rec.time_s), np.asarray(rec.angles_deg)
    lib = load_library("able_bodied")
    lib = lib if modes == len(lib.modes) else lib.replicated(modes)
    run_estimator(Estimator(lib), t[:400], x[:400])
    spent = {"time": 0.0, "columns": 0.0}
    inner = IncrementalMatcher.run_steps

    def band_lengths(mt: IncrementalMatcher) -> np.ndarray:
        return mt.lengths.reshape(mt.n_modes, -1)[:, mt.scale_band].ravel()

    def timed(self, samples, squares, start, stop, out, *args, **kwargs):  # type: ignore[no-untyped-def]
        t0 = time.perf_counter()
        done, ended = inner(self, samples, squares, start, stop, out, *args, **kwargs)
        spent["time"] += time.perf_counter() - t0
        spent["columns"] += (done - start) * float(band_lengths(self).sum())
        return done, ended

    est = Estimator(lib)
    IncrementalMatcher.run_steps = timed
    try:
        t0 = time.perf_counter()
        run_estimator(est, t, x)
        total = time.perf_counter() - t0
    finally:
        IncrementalMatcher.run_steps = inner
    mt = est.matcher
    update_ns = update_ns_per_column(band_lengths(mt), mt.n_modes * mt.n_scales >= PARALLEL_MIN_ROWS)
    rest, update_s = total - spent["time"], spent["columns"] * update_ns * 1e-9
    return {
        "samples": float(t.size), "total_s": total, "step_s": spent["time"], "columns": spent["columns"],
        "run_ns_per_column": spent["time"] / spent["columns"] * 1e9, "update_ns_per_column": update_ns,
        "ceiling_one_thread": t.size / (rest + update_s), "ceiling_two_threads": t.size / (rest + update_s / 2),
    }


def section(report: dict[str, Any]) -> str:
    """The ``Offline throughput`` section of performance's tables.md."""
    m = report["machine"]
    lines = ["## Offline throughput", "",
             f"`python benchmarks/performance.py --offline TREE` (TREE: {report['baseline']}), {report['date']}, "
             f"{m['processor']}, {m['cpus_allowed']} CPUs, Python {m['python']}, numba {m['numba']}; 1-min load "
             f"average {m['load_average'][0]:.2f} at the start.", "",
             "| preset | M | before (samples/s) | now (samples/s) | ratio |", "|---|---|---|---|---|"]
    for row in report["throughput"]:
        lines.append(f"| {row['preset']} | {row['modes']} | {row['before']:,.0f} | {row['now']:,.0f} | "
                     f"{row['now'] / row['before']:.1f}× |")
    lines += ["", "| default, M | matcher step's share of the run | ns/column: in the run, update alone | "
              "ceiling, samples/s: 1 thread, 2 | ceiling ÷ before |", "|---|---|---|---|---|"]
    before = {r["modes"]: r["before"] for r in report["throughput"] if r["preset"] == "default"}
    for row in report["ceiling"]:
        b = before[row["modes"]]
        lines.append(f"| {row['modes']} | {row['step_s'] / row['total_s']:.0%} | {row['run_ns_per_column']:.2f}, "
                     f"{row['update_ns_per_column']:.2f} | {row['ceiling_one_thread']:,.0f}, "
                     f"{row['ceiling_two_threads']:,.0f} | {row['ceiling_one_thread'] / b:.1f}×, "
                     f"{row['ceiling_two_threads'] / b:.1f}× |")
    return "\n".join(lines) + "\n"


def run(baseline: Path, path: Path, modes: tuple[int, ...] = (7, 70), repeat: int = 3) -> None:
    """Measure and write the report to ``path``."""
    info = machine_info()
    rows = []
    for m in modes:
        for preset in ("default", "paper"):
            before, now = throughput(baseline, m, preset, repeat), throughput(REPO, m, preset, repeat)
            rows.append({"preset": preset, "modes": m, "before": before, "now": now})
            print(rows[-1], flush=True)
    head = subprocess.run(["git", "-C", str(baseline), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    report = {"date": datetime.now(timezone.utc).strftime("%Y-%m-%d"), "baseline": head or str(baseline),
              "machine": info, "throughput": rows, "ceiling": [{"modes": m, **ceiling(m)} for m in modes]}
    path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
