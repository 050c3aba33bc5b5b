"""Offline processing in bulk: a whole recording through an ``Estimator`` with the results of
``Estimator.update`` sample by sample, bit for bit, without a Python step per sample.

The streaming path hands every sample through Python (gap check, resampler, matcher step,
supervisor, calibrations, an ``Estimate`` object). Here each stage runs its bulk form, in the
order of ``update``: ``GapCheck.admit_many`` and ``UniformResampler.push_many`` for the whole
recording, ``IncrementalMatcher.run_steps`` for many steps per compiled call, ``decide``'s step
compiled (``Supervisor.decide_many`` after those steps, or inside them with a supervisor option
on: ``Supervisor.step_hook``, so that the walking calibrations' stride tracker follows the
reported mode) and ``StateTracker.decide_many`` (``step``'s rule, compiled) for the states. A
run of steps ends where the streaming path would do more than that: at a heel strike that ends
a whole stride (``WalkingCalibration.observe`` reads it), at the matcher's resynchronisation
steps, and at gaps (``Estimator.on_gap``). Used by ``run_estimator`` when the options allow it
(``batch_supported``); the streaming ``Estimator.update`` stays the reference
(test/test_batch.py compares every field).
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from . import compiled
from .gaps import GapVerdict
from .matcher import StepBlock
from .supervisor import Estimate, carry_forward

Estimator = Any  # an estimator.Estimator (not imported: estimator.run_estimator imports this module)

CHUNK_VALUES = 1 << 21
"""Matcher steps per compiled call, at most this many values of the per-mode outputs (M per step)."""
SHARED = ("sse", "phases")
"""Columns of the (G, M) matcher outputs: the supervisor's columns are views of them."""


def batch_supported(estimator: Estimator) -> bool:
    """True when ``estimator``'s options allow bulk processing: the compiled matcher and no
    personalisation."""
    return compiled.AVAILABLE and estimator.matcher.backend == "numba" and estimator.personaliser is None


def run_batch(estimator: Estimator, time_s: np.ndarray, angles_deg: np.ndarray) -> dict[str, np.ndarray] | None:
    """The columns of the trace ``run_estimator`` gives (``EstimateTrace`` fields but mode_names
    and sample), computed in bulk; None (nothing done) when the options or the input need the
    streaming path (a bad sample or stamp: it raises where it occurs)."""
    t = np.asarray(time_s, dtype=np.float64).reshape(-1)
    x = np.asarray(angles_deg, dtype=np.float64)
    if not batch_supported(estimator) or x.shape != (t.size, 4) or t.size == 0:
        return None
    if not (np.isfinite(x).all() and np.isfinite(t).all() and np.all(np.diff(t) > 0)):
        return None
    if np.abs(x).max() > 1e150:  # the matcher refuses a sample whose squared norm overflows
        return None
    if estimator.last_time is not None and not t[0] > estimator.last_time:
        return None
    restart, forget = estimator.gaps.admit_many(t)
    forget &= estimator.calibration.active
    bounds = [0, *[int(s) for s in np.flatnonzero(restart | forget) if s > 0], t.size]
    parts = []
    for a, b in itertools.pairwise(bounds):
        if restart[a] or forget[a]:
            estimator.on_gap(GapVerdict(bool(restart[a]), bool(forget[a])))
        parts.append(_run_segment(estimator, t[a:b], x[a:b]))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _run_segment(estimator: Estimator, t: np.ndarray, x: np.ndarray) -> dict[str, np.ndarray]:
    """One gap-free stretch of input through the estimator; the trace's columns."""
    if estimator.resampler is None:
        return _match(estimator, t, x)
    had = estimator.grid_estimate
    grid_t, grid_x, emitted = estimator.resampler.push_many(t, x)
    steps = _match(estimator, grid_t, grid_x)
    # Every input sample: the latest grid estimate carried forward to it (Estimate.at).
    if had is not None:
        steps = {k: np.concatenate([_column_of(had, k, v), v]) for k, v in steps.items()}
        g = emitted
    else:
        g = emitted - 1
    if steps["time_s"].size:
        estimator.grid_estimate = Estimate.from_columns(steps, int(steps["time_s"].size) - 1, estimator.mode_names)
    return carry_forward({k: v[g] for k, v in steps.items()}, t)


def _column_of(est: Estimate, name: str, like: np.ndarray) -> np.ndarray:
    return np.asarray([getattr(est, name)], dtype=like.dtype).reshape((1, *like.shape[1:]))


def _match(estimator: Estimator, grid_t: np.ndarray, grid_x: np.ndarray) -> dict[str, np.ndarray]:
    """Matcher and supervisor over the grid samples, the walking calibrations at the ends of
    whole strides; the decided columns. The supervisor decides inside the compiled steps unless it
    passes the matcher's choice through (then after them)."""
    mt, cal, sup = estimator.matcher, estimator.calibration, estimator.supervisor
    d, sq = mt.weighted_samples(grid_x)
    steps = StepBlock.empty(estimator.mode_names, mt.n_scales, grid_t.size)
    if grid_t.size == 0:
        return estimator.states.decide_many(grid_t, grid_x, sup.decide_many(grid_t, steps))
    hook = compiled.MATCHER_REPORTS if sup.passes_through else sup.step_hook(grid_t)
    chunk = max(1, CHUNK_VALUES // max(mt.n_modes, 1))
    parts = []
    g = 0
    while g < grid_t.size:
        track = cal.stride_state() if cal.active else None
        done, ended = mt.run_steps(d, sq, g, min(grid_t.size, g + chunk), steps, track, cal.near_copies,
                                   cal.params.mid_stride, hook)
        if track is not None:  # the tracker's state after the last step (before it, when that one ended a stride)
            cal.set_stride_state(track)
        rows = steps.rows(g, done)
        parts.append(sup.decide_many(grid_t[g:done], rows) if sup.passes_through else sup.columns(hook, g, done, rows))
        if ended:
            est = Estimate.from_columns(parts[-1], -1, estimator.mode_names)
            cal.observe(est, steps.result(done - 1, est.mode_index))
        g = done
    columns = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k not in SHARED}
    return estimator.states.decide_many(grid_t, grid_x, {**columns, "sse": steps.sse, "phases": steps.phases})
