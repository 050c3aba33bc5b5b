"""Benchmark of the matcher and the estimator: per-step time, offline throughput, state memory,
long-run drift, and optionally a reference binary timed as a black box."""

from __future__ import annotations

import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..core import compiled
from ..core.estimator import Estimator, EstimatorConfig
from ..core.kernels import KernelLibrary
from ..core.matcher import IncrementalMatcher, NaiveMatcher
from ..core.stride_reader import SUGGESTED_EVIDENCE_DEG2S
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
        "cpus_allowed": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None,
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "numba": _numba_version(),
        "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    for var in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "OMP_NUM_THREADS"):
        if var in os.environ:
            info[var] = os.environ[var]
    return info


def _numba_version() -> str | None:
    if not compiled.AVAILABLE:
        return None
    import numba

    return str(numba.__version__)


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


def matcher_options(preset: str) -> dict[str, Any]:
    """IncrementalMatcher keyword arguments of an estimator preset (its matching options)."""
    c = EstimatorConfig.preset(preset)
    return {"channel_weights": c.effective_weights(), "time_scales": c.time_scales,
            "offset_tolerance_deg": c.offset_tolerance_deg, "normalize": c.normalize_error,
            "recency_half_life": c.effective_recency_half_life}


def time_updates(estimator: Estimator, samples: np.ndarray, rate_hz: float, warmup: int) -> dict[str, float]:
    """Like ``time_steps`` for ``Estimator.update`` with stamps at ``rate_hz``: resampling,
    matcher, supervisor, calibration, everything a node or ``process`` runs per input sample."""
    t = np.arange(len(samples)) / rate_hz
    for i in range(min(warmup, len(samples))):
        estimator.update(float(t[i]), samples[i])
    ns = np.empty(len(samples) - warmup)
    clock = time.perf_counter_ns
    update = estimator.update
    for k, i in enumerate(range(warmup, len(samples))):
        t0 = clock()
        update(float(t[i]), samples[i])
        ns[k] = clock() - t0
    us = ns / 1e3
    return {"step_us_median": float(np.median(us)), "step_us_p99": float(np.percentile(us, 99)),
            "step_us_mean": float(us.mean()), "step_us_max": float(us.max()), "steps_timed": len(us)}


def bench(
    library: KernelLibrary,
    modes: list[int],
    steps: int = 5000,
    naive_max_modes: int = 7,
    naive_steps: int = 100,
    backends: list[str] | None = None,
    preset_max_modes: int = 70,
) -> dict[str, Any]:
    """Per-step time at each M in ``modes``: the paper's incremental matcher with each backend
    (``numba``, ``numpy``; numba only if installed), the naive matcher (M <= naive_max_modes), and
    for M <= preset_max_modes the default preset's matcher (all its time-scaled rows) and the whole
    default-preset ``Estimator.update`` (and the paper preset's, for the ratio; at the smallest M
    also the default preset's with the stride-start reader at SUGGESTED_EVIDENCE_DEG2S and with the
    other backends), all in one run."""
    backends = backends or ["numba", "numpy"]
    backends = [b for b in backends if b != "numba" or compiled.AVAILABLE]
    if not backends:
        raise ValueError("no backend to time: numba is not installed (or GAIT_ESTIMATOR_NO_NUMBA is set); add numpy")
    results = []
    for m in modes:
        lib = library.replicated(m)
        x = None
        for backend in backends:
            inc = IncrementalMatcher(lib, backend=backend)
            warmup = inc.max_window
            x = synthetic_walk(lib, warmup + steps) if x is None else x
            row: dict[str, Any] = {"modes": m, "impl": f"incremental ({backend})", "preset": "paper",
                                   **time_steps(inc, x, warmup)}
            fresh = IncrementalMatcher(lib, backend=backend)
            t0 = time.perf_counter()
            fresh.run(x)
            row["offline_samples_per_s"] = float(len(x) / (time.perf_counter() - t0))
            row["state_bytes"] = inc.state_bytes()
            results.append(row)
        assert x is not None
        if m <= naive_max_modes:
            naive = NaiveMatcher(lib)
            warmup = naive.max_window
            xn = x[: warmup + naive_steps]
            results.append({"modes": m, "impl": "naive", "preset": "paper", **time_steps(naive, xn, warmup),
                            "state_bytes": naive.state_bytes()})
        if m <= preset_max_modes:
            backend = backends[0]
            inc = IncrementalMatcher(lib, backend=backend, **matcher_options("default"))
            xd = synthetic_walk(lib, inc.max_window + steps)
            results.append({"modes": m, "impl": f"incremental ({backend})", "preset": "default", "rows": inc.n_rows,
                            **time_steps(inc, xd, inc.max_window), "state_bytes": inc.state_bytes()})
            for preset in ("paper", "default"):
                est = Estimator(lib, EstimatorConfig.preset(preset), backend=backend)
                warmup = est.matcher.max_window
                results.append({"modes": m, "impl": f"estimator ({backend})", "preset": preset,
                                **time_updates(est, xd, lib.sample_rate_hz, warmup)})
            if m == min(modes):  # the default preset with the opt-in reader, and without numba (the fallback), too
                cfg = EstimatorConfig.preset("default", switch_evidence_deg2s=SUGGESTED_EVIDENCE_DEG2S)
                est = Estimator(lib, cfg, backend=backend)
                results.append({"modes": m, "impl": f"estimator ({backend}) + stride-start reader", "preset": "default",
                                **time_updates(est, xd, lib.sample_rate_hz, est.matcher.max_window)})
                for other in backends[1:]:
                    est = Estimator(lib, EstimatorConfig.preset("default"), backend=other)
                    results.append({"modes": m, "impl": f"estimator ({other})", "preset": "default",
                                    **time_updates(est, xd, lib.sample_rate_hz, est.matcher.max_window)})
    by_key = {(r["modes"], r["impl"], r["preset"]): r for r in results}
    for (m, impl, preset), r in by_key.items():
        paper = by_key.get((m, impl, "paper"))
        if preset == "default" and paper is not None:
            r["median_ratio_to_paper"] = r["step_us_median"] / paper["step_us_median"]
        first = by_key.get((m, f"incremental ({backends[0]})", "paper"))
        if impl in ("naive", "incremental (numpy)") and first is not None and r is not first:
            r[f"median_ratio_to_{backends[0]}"] = r["step_us_median"] / first["step_us_median"]
    return {"machine": machine_info(), "results": results}


def time_reference(command: str, samples: int, repeats: int = 3, timeout_s: float = 600.0) -> dict[str, Any]:
    """Wall time of a user-built reference binary, run as ``command`` (a shell-style command line)
    that processes ``samples`` samples: best and median of ``repeats`` runs, per sample. Process
    start-up and file reading are included (a black-box upper bound on its per-sample cost)."""
    argv = shlex.split(command)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        done = subprocess.run(argv, capture_output=True, timeout=timeout_s, check=False)
        times.append(time.perf_counter() - t0)
        if done.returncode != 0:
            raise RuntimeError(f"reference command exited with {done.returncode}: {done.stderr.decode(errors='replace')[-300:]}")
    best, med = min(times), float(np.median(times))
    return {"command": command, "samples": samples, "runs": repeats, "wall_s_best": best, "wall_s_median": med,
            "us_per_sample_best": 1e6 * best / samples, "us_per_sample_median": 1e6 * med / samples}


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
