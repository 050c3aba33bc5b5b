"""Benchmark of the matcher: per-step time, offline throughput, state memory, long-run drift."""

from __future__ import annotations

import os
import platform
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..core.kernels import KernelLibrary
from ..core.matcher import IncrementalMatcher, NaiveMatcher
from ..io.library_io import load_library, save_library


def synthetic_walk(library: KernelLibrary, steps: int, seed: int = 0) -> np.ndarray:
    """Input for benchmarks: strides of the library's kernels in turn (10 strides each), with
    0.5 deg Gaussian noise; (steps, 4), degrees."""
    rng = np.random.default_rng(seed)
    strides = []
    total = 0
    k = 0
    while total < steps:
        mode = library.modes[(k // 10) % len(library)]
        strides.append(mode.samples)
        total += mode.length
        k += 1
    x = np.concatenate(strides)[:steps]
    return x + rng.normal(0.0, 0.5, size=x.shape)


def machine_info() -> dict[str, Any]:
    """What the numbers were measured on."""
    info: dict[str, Any] = {
        "platform": platform.platform(),
        "machine": platform.machine(),
        "processor": _cpu_model(),
        "cpus": os.cpu_count(),
        "python": sys.version.split()[0],
        "numpy": np.__version__,
    }
    for var in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "OMP_NUM_THREADS"):
        if var in os.environ:
            info[var] = os.environ[var]
    return info


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def time_steps(matcher: IncrementalMatcher | NaiveMatcher, samples: np.ndarray, warmup: int) -> dict[str, float]:
    """Stream ``samples`` one step at a time; per-step wall time after ``warmup`` steps (us)."""
    for i in range(min(warmup, len(samples))):
        matcher.step(samples[i])
    timed = samples[warmup:]
    ns = np.empty(len(timed))
    clock = time.perf_counter_ns
    step = matcher.step
    for i in range(len(timed)):
        t0 = clock()
        step(timed[i])
        ns[i] = clock() - t0
    us = ns / 1e3
    return {
        "step_us_median": float(np.median(us)),
        "step_us_p99": float(np.percentile(us, 99)),
        "step_us_mean": float(us.mean()),
        "step_us_max": float(us.max()),
        "steps_timed": len(us),
    }


def bench(
    library: KernelLibrary,
    modes: list[int],
    steps: int = 5000,
    naive_max_modes: int = 7,
    naive_steps: int = 100,
) -> dict[str, Any]:
    """Measure incremental (and naive, for M <= naive_max_modes) matchers at each M in ``modes``."""
    results = []
    for m in modes:
        lib = library.replicated(m)
        warmup = int(lib.lengths.max())
        inc = IncrementalMatcher(lib)
        x = synthetic_walk(lib, warmup + steps)
        row: dict[str, Any] = {"modes": m, "impl": "incremental", **time_steps(inc, x, warmup)}
        fresh = IncrementalMatcher(lib)
        t0 = time.perf_counter()
        fresh.run(x)
        row["offline_samples_per_s"] = float(len(x) / (time.perf_counter() - t0))
        row["state_bytes"] = inc.state_bytes()
        results.append(row)
        if m <= naive_max_modes:
            naive = NaiveMatcher(lib)
            xn = x[: warmup + naive_steps]
            results.append({"modes": m, "impl": "naive", **time_steps(naive, xn, warmup), "state_bytes": naive.state_bytes()})
    by_key = {(r["modes"], r["impl"]): r for r in results}
    for (m, impl), r in by_key.items():
        if impl == "naive" and (m, "incremental") in by_key:
            r["median_ratio_to_incremental"] = r["step_us_median"] / by_key[(m, "incremental")]["step_us_median"]
    return {"machine": machine_info(), "results": results}


def drift(library: KernelLibrary, steps: int, seed: int = 1) -> dict[str, Any]:
    """Run ``steps`` steps, then compare the running SSE with a from-scratch recomputation."""
    matcher = IncrementalMatcher(library)
    chunk = synthetic_walk(library, 100_000, seed=seed)
    t0 = time.perf_counter()
    done = 0
    while done < steps:
        n = min(len(chunk), steps - done)
        for i in range(n):
            matcher.step(chunk[i])
        done += n
    elapsed = time.perf_counter() - t0
    running = matcher.running_sse()
    exact = matcher.full_sse()
    valid = np.isfinite(exact)
    rel = np.abs(running[valid] - exact[valid]) / np.maximum(np.abs(exact[valid]), 1e-300)
    return {
        "steps": steps,
        "modes": len(library),
        "max_relative_error": float(rel.max()),
        "max_absolute_error_deg2": float(np.abs(running[valid] - exact[valid]).max()),
        "seconds": elapsed,
    }


def load_times(library: KernelLibrary, modes: int, repeats: int = 3) -> list[dict[str, Any]]:
    """Seconds to load a ``modes``-mode library from project YAML and NPZ (best of ``repeats``)."""
    big = library.replicated(modes)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for suffix in (".yaml", ".npz"):
            path = save_library(big, Path(tmp) / f"lib{suffix}")
            best = min(_timed_load(path) for _ in range(repeats))
            out.append({"modes": modes, "format": suffix[1:], "load_s": best, "file_bytes": path.stat().st_size})
    return out


def _timed_load(path: Path) -> float:
    t0 = time.perf_counter()
    load_library(path)
    return time.perf_counter() - t0
