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
from ..core.batch import batch_supported
from ..core.estimator import Estimator, EstimatorConfig, run_estimator
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


def _summary(us: np.ndarray) -> dict[str, float]:
    """Median, p99, mean and max of per-step times ``us`` (microseconds), and their number."""
    return {"step_us_median": float(np.median(us)), "step_us_p99": float(np.percentile(us, 99)),
            "step_us_mean": float(us.mean()), "step_us_max": float(us.max()), "steps_timed": len(us)}


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
    return _summary(ns / 1e3)


def matcher_options(preset: str) -> dict[str, Any]:
    """IncrementalMatcher keyword arguments of an estimator preset (its matching options)."""
    c = EstimatorConfig.preset(preset)
    return {"channel_weights": c.effective_weights(), "time_scales": c.time_scales,
            "offset_tolerance_deg": c.offset_tolerance_deg, "normalize": c.normalize_error,
            "recency_half_life": c.recency_half_life}


def time_updates(estimator: Estimator, samples: np.ndarray, rate_hz: float, warmup: int) -> dict[str, float]:
    """Like ``time_steps`` for ``Estimator.update`` with stamps at ``rate_hz``: resampling,
    matcher, supervisor, calibration, everything a node runs per input sample."""
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
    return _summary(ns / 1e3)


def calibrated_after(library: KernelLibrary, samples: np.ndarray, backend: str = "auto") -> int:
    """Input samples a fresh default-preset estimator needs before its walking calibrations have
    read the strides after which they narrow the scale band (and recency weighting starts), or
    the matcher's window if that is longer; len(samples) if they never do."""
    est = Estimator(library, EstimatorConfig.preset("default"), backend=backend)
    t = np.arange(len(samples)) / library.sample_rate_hz
    for i in range(len(samples)):
        est.update(float(t[i]), samples[i])
        cal = est.calibration
        if cal.strides >= max(cal.params.cadence_min_strides, cal.params.recency_after_strides):
            return max(i + 1, est.matcher.max_window)
    return len(samples)


PRESET_RATIO_TARGET = 2.0
"""The default preset's ``Estimator.update`` may take this many times the paper preset's (median and p99)."""


def preset_target_met(row: dict[str, Any]) -> bool:
    """Whether a default-preset row of ``bench`` is within PRESET_RATIO_TARGET of its paper row,
    median and p99."""
    return max(row["median_ratio_to_paper"], row["p99_ratio_to_paper"]) <= PRESET_RATIO_TARGET


def time_presets(library: KernelLibrary, m: int, steps: int, backend: str) -> list[dict[str, Any]]:
    """``Estimator.update`` of the default and the paper preset at M = m on one synthetic walk,
    fed to both sample by sample in turn (so that both see the same machine load), each timed:
    while the default preset calibrates (from a full window until its walking calibrations have
    acted) and on the next ``steps`` samples (its steady state). Rows per preset and stretch, with
    the matcher's state memory."""
    walk = synthetic_walk(library, 4000 + steps)
    start = calibrated_after(library, walk, backend)
    x = walk[: start + steps]
    t = np.arange(len(x)) / library.sample_rate_hz
    presets = ("paper", "default")
    estimators = [Estimator(library, EstimatorConfig.preset(p), backend=backend) for p in presets]
    first = estimators[1].matcher.max_window
    ns = np.empty((len(presets), len(x)))
    clock = time.perf_counter_ns
    for i in range(len(x)):
        ti, xi = float(t[i]), x[i]
        for k, est in enumerate(estimators):
            t0 = clock()
            est.update(ti, xi)
            ns[k, i] = clock() - t0
    rows = []
    for k, preset in enumerate(presets):
        state = {"state_bytes": estimators[k].matcher.state_bytes()}
        rows.append({"modes": m, "impl": f"estimator ({backend})", "preset": preset, "timed_from_sample": start,
                     **_summary(ns[k, start:] / 1e3), **state})
        if start > first + 10:
            rows.append({"modes": m, "impl": f"estimator ({backend}), calibrating", "preset": preset,
                         "timed_from_sample": first, **_summary(ns[k, first:start] / 1e3), **state})
    return rows


def process_throughput(library: KernelLibrary, m: int, samples: int) -> list[dict[str, Any]]:
    """Offline ``process`` throughput (``run_estimator``, the code behind it, from a fresh
    estimator over a synthetic walk of ``samples`` samples stamped at the library rate, walking
    calibrations included) in bulk and, for comparison, sample by sample (``Estimator.update``),
    for both presets; checks that the two give the same modes and phases."""
    x = synthetic_walk(library, samples)
    t = np.arange(len(x)) / library.sample_rate_hz
    rows = []
    for preset in ("paper", "default"):
        cfg = EstimatorConfig.preset(preset)
        bulk = Estimator(library, cfg)
        t0 = time.perf_counter()
        trace = run_estimator(bulk, t, x)
        bulk_s = time.perf_counter() - t0
        one = Estimator(library, cfg)
        t0 = time.perf_counter()
        ests = [one.update(float(t[i]), x[i]) for i in range(len(x))]
        stream_s = time.perf_counter() - t0
        same = bool(np.array_equal(trace.mode_index, [e.mode_index for e in ests])
                    and np.array_equal(trace.state, [e.state for e in ests])
                    and np.array_equal(trace.phase, [e.phase for e in ests], equal_nan=True))
        rows.append({"modes": m, "impl": "process", "preset": preset, "samples": len(x),
                     "bulk": batch_supported(bulk), "samples_per_s": len(x) / bulk_s,
                     "streaming_samples_per_s": len(x) / stream_s, "speedup": stream_s / bulk_s, "same_estimates": same})
    return rows


def bench(
    library: KernelLibrary,
    modes: list[int],
    steps: int = 5000,
    naive_max_modes: int = 7,
    naive_steps: int = 100,
    backends: list[str] | None = None,
    preset_max_modes: int = 70,
    process_max_modes: int = 70,
) -> dict[str, Any]:
    """Per-step time at each M in ``modes``, all in one run: the paper's incremental matcher with
    each backend (``numba``, ``numpy``; numba only if installed), the naive matcher (M <=
    naive_max_modes); the whole ``Estimator.update`` of the default preset next to the paper
    preset's at every M (``time_presets``); for M <= preset_max_modes the default preset's bare
    matcher (all its time-scaled rows, every step) and at the smallest M the default preset's
    update with the other backends; for M <= process_max_modes the offline ``process``
    throughput of both presets (``process_throughput``)."""
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
        backend = backends[0]
        if m <= preset_max_modes:
            inc = IncrementalMatcher(lib, backend=backend, **matcher_options("default"))
            xd = synthetic_walk(lib, inc.max_window + steps)
            results.append({"modes": m, "impl": f"incremental ({backend})", "preset": "default", "rows": inc.n_rows,
                            **time_steps(inc, xd, inc.max_window), "state_bytes": inc.state_bytes()})
        results.extend(time_presets(lib, m, steps, backend))
        if m == min(modes):  # the default preset without numba (the fallback), too, timed as time_presets does
            for other in backends[1:]:
                walk = synthetic_walk(lib, 4000 + steps)
                start = calibrated_after(lib, walk, other)
                est = Estimator(lib, EstimatorConfig.preset("default"), backend=other)
                results.append({"modes": m, "impl": f"estimator ({other})", "preset": "default",
                                "timed_from_sample": start,
                                **time_updates(est, walk[: start + steps], lib.sample_rate_hz, start)})
        if m <= process_max_modes and compiled.AVAILABLE:
            results.extend(process_throughput(lib, m, calibrated_after(lib, synthetic_walk(lib, 4000)) + steps))
    by_key = {(r["modes"], r["impl"], r["preset"]): r for r in results}
    for (m, impl, preset), r in by_key.items():
        paper = by_key.get((m, impl, "paper"))
        if preset == "default" and paper is not None and "step_us_median" in r:
            r["median_ratio_to_paper"] = r["step_us_median"] / paper["step_us_median"]
            r["p99_ratio_to_paper"] = r["step_us_p99"] / paper["step_us_p99"]
            if "state_bytes" in r and "state_bytes" in paper:
                r["state_ratio_to_paper"] = r["state_bytes"] / paper["state_bytes"]
        if preset == "default" and paper is not None and "samples_per_s" in r:
            r["throughput_ratio_to_paper"] = r["samples_per_s"] / paper["samples_per_s"]
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
