"""Offline processing in bulk: a whole recording through an ``Estimator`` with the results of
``Estimator.update`` sample by sample, bit for bit, without a Python step per sample.

The streaming path hands every sample through Python (gap check, resampler, matcher step,
supervisor, calibrations, an ``Estimate`` object). Here the stamps are checked and the input is
resampled for the whole recording at once (numpy, the same float operations), the matcher runs
many steps per compiled call (``compiled.run_steps``), and the supervisor's outputs are computed
as arrays. Control returns to Python only where the streaming path would do more than that: at a
heel strike that ends a whole stride (the walking calibrations may act there:
``WalkingCalibration.observe`` does it, from the stride tracker's state before that sample), at
the matcher's resynchronisation steps, and at gaps (the estimator's reset methods). Used by
``run_estimator`` when the options allow it (``batch_supported``); the streaming
``Estimator.update`` stays the reference (test/test_batch.py compares every field).
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from . import compiled
from .calibration import _StrideTrack
from .matcher import StepResult
from .supervisor import Estimate

Estimator = Any  # an estimator.Estimator (not imported: estimator.run_estimator imports this module)

CHUNK_VALUES = 1 << 21
"""Matcher steps per compiled call, at most this many values of the per-mode outputs (M per step)."""


def batch_supported(estimator: Estimator) -> bool:
    """True when ``estimator``'s options allow bulk processing: the compiled matcher, no
    supervisor holds, dwell or transitions, no personalisation."""
    sup = estimator.supervisor
    return (
        compiled.AVAILABLE
        and estimator.matcher.backend == "numba"
        and sup.min_confidence == 0
        and sup.min_dwell_s == 0
        and sup.allowed is None
        and estimator.personaliser is None
    )


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
    segments, restart, forget = _segments(estimator, t)
    parts = []
    for a, b in segments:  # the resets of Estimator.update, in its order
        if restart[a]:
            estimator._restart_window()
            estimator.resets += 1
        if forget[a]:
            estimator.calibration.reset()
            estimator.calibration_resets += 1
        parts.append(_run_segment(estimator, t[a:b], x[a:b]))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _segments(estimator: Estimator, t: np.ndarray) -> tuple[list[tuple[int, int]], np.ndarray, np.ndarray]:
    """Where ``Estimator.update`` would restart the window (``restart``) or forget the
    calibrations (``forget``): at a sample after a long gap. The stretches between, as (start,
    stop) pairs, and the two flags per sample."""
    c = estimator.gaps.params
    prev = np.concatenate([[np.nan if estimator.last_time is None else estimator.last_time], t[:-1]])
    gap = t - prev
    restart = (0 < c.max_gap_s) & (gap > c.max_gap_s)
    forget = estimator.calibration.active & (0 < c.calibration_reset_gap_s) & (gap > c.calibration_reset_gap_s)
    bounds = [0, *[int(s) for s in np.flatnonzero(restart | forget) if s > 0], t.size]
    return list(itertools.pairwise(bounds)), restart, forget


def _grid(estimator: Estimator, t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The matcher's input for the samples (t, x): grid times (G,), values (G, 4) and, per input
    sample, how many grid points it and the samples before it emitted (T,); the resampler's state
    is advanced as ``UniformResampler.push`` would. Without resampling: the samples themselves."""
    rs = estimator.resampler
    if rs is None:
        return t, x, np.arange(1, t.size + 1)
    first_t: list[float] = []
    first_x: list[np.ndarray] = []
    if rs._t0 is None:  # the first sample starts the grid
        rs._t0, rs._k, rs._prev_t, rs._prev_x = float(t[0]), 1, float(t[0]), tuple(x[0].tolist())
        first_t, first_x = [float(t[0])], [x[0]]
        t_in, x_in, lead = t[1:], x[1:], 1
    else:
        t_in, x_in, lead = t, x, 0
    snap = rs.snap / rs.rate_hz
    upper = t_in + snap
    if t_in.size:
        count = max(0, math.floor((float(upper[-1]) - rs._t0) * rs.rate_hz) - rs._k + 3)
        k = rs._k + np.arange(count)
        tk = rs._t0 + k / rs.rate_hz
        tk = tk[tk <= upper[-1]]
    else:
        tk = np.zeros(0)
    src = np.searchsorted(upper, tk, side="left")  # the first sample with t + snap >= t_k emits it
    prev_t = np.concatenate([[rs._prev_t], t_in[:-1]])
    prev_x = np.concatenate([np.asarray(rs._prev_x, dtype=np.float64)[None, :], x_in[:-1]])
    snapped = tk >= t_in[src] - snap if tk.size else np.zeros(0, dtype=bool)
    a = (tk - prev_t[src]) / (t_in[src] - prev_t[src])
    p, v = prev_x[src], x_in[src]
    gx = np.where(snapped[:, None], v, p + a[:, None] * (v - p))
    gt = np.where(snapped, t_in[src], tk)
    emitted = np.searchsorted(src, np.arange(t_in.size), side="right")
    if t_in.size:
        rs._k += tk.size
        rs._prev_t, rs._prev_x = float(t_in[-1]), tuple(x_in[-1].tolist())
    grid_t = np.concatenate([first_t, gt])
    grid_x = np.concatenate([np.reshape(first_x, (-1, 4)), gx]) if first_x else gx
    return grid_t, grid_x, np.concatenate([[lead] if lead else [], emitted + lead]).astype(np.int64)


def _run_segment(estimator: Estimator, t: np.ndarray, x: np.ndarray) -> dict[str, np.ndarray]:
    """One gap-free stretch of input through the estimator; the trace's columns."""
    had_last = estimator._last
    estimator.gaps.last_time = float(t[-1])
    grid_t, grid_x, emitted = _grid(estimator, t, x)
    steps = _match(estimator, grid_t, grid_x)
    if estimator.resampler is None:
        return {**steps, "time_s": t}
    # Every input sample: the latest grid estimate carried forward to it (Estimate.at).
    if had_last is not None:
        steps = {k: np.concatenate([_column_of(had_last, k, v), v]) for k, v in steps.items()}
        g = emitted
    else:
        g = emitted - 1
    if steps["time_s"].size:
        estimator._last = _estimate_at(estimator, steps, int(steps["time_s"].size) - 1)
    out = {k: v[g] for k, v in steps.items()}
    dt = t - out["time_s"]
    later = dt > 0.0  # else the grid estimate as it is (its stamp is the sample's)
    move = later & out["ready"] & np.isfinite(out["phase_rate"])
    ahead = (out["phase"] + out["phase_rate"] * dt) % 1.0
    ahead[ahead >= 1.0] = 0.0
    out["phase"] = np.where(move, ahead, out["phase"])
    out["time_s"] = np.where(later, t, out["time_s"])
    return out


def _column_of(est: Estimate, name: str, like: np.ndarray) -> np.ndarray:
    return np.asarray([getattr(est, name)], dtype=like.dtype).reshape((1, *like.shape[1:]))


def _estimate_at(estimator: Estimator, cols: dict[str, np.ndarray], g: int) -> Estimate:
    m = int(cols["mode_index"][g])
    return Estimate(
        time_s=float(cols["time_s"][g]), mode_index=m, mode=estimator.mode_names[m], phase=float(cols["phase"][g]),
        ready=bool(cols["ready"][g]), sse=cols["sse"][g], phases=cols["phases"][g],
        raw_mode_index=int(cols["raw_mode_index"][g]), confidence=float(cols["confidence"][g]),
        fit_rms_deg=float(cols["fit_rms_deg"][g]), held=False, phase_rate=float(cols["phase_rate"][g]),
        cadence_ratio=float(cols["cadence_ratio"][g]),
    )


def _weighted(matcher: Any, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The samples as the matcher steps them (``_weighted_values``): times sqrt(channel weight),
    and their squared norms summed in the same order."""
    d = x * np.asarray(matcher._scale_values) if matcher._weighted else x
    d = np.ascontiguousarray(d)
    return d, d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2] + d[:, 3] * d[:, 3]


def _match(estimator: Estimator, grid_t: np.ndarray, grid_x: np.ndarray) -> dict[str, np.ndarray]:
    """Matcher and supervisor over the grid samples; calibrations where they may act."""
    mt = estimator.matcher
    g_total, n_modes = grid_t.size, mt.n_modes
    d, sq = _weighted(mt, grid_x)
    sse, phases = np.empty((g_total, n_modes)), np.empty((g_total, n_modes))
    best, variant, column, window = np.empty((4, g_total), dtype=np.int64)
    ready = np.empty(g_total, dtype=bool)
    scratch_v, scratch_c, scratch_w = np.empty((3, n_modes), dtype=np.int64)
    cal = estimator.calibration
    tracking = cal.active
    near = cal.near_copies if cal.near_copies is not None else np.zeros((n_modes, n_modes), dtype=bool)
    chunk = max(1, CHUNK_VALUES // max(n_modes, 1))
    g = 0
    mid_lo, mid_hi = cal.params.mid_stride
    run = compiled.run_steps  # one thread: the rows' results do not depend on it; run recordings side by side instead
    while g < g_total:
        track = _track_state(estimator) if tracking else np.zeros(0)
        stop = min(g_total, g + chunk)
        if mt._resync_every:
            stop = min(stop, g + mt._resync_every - mt._count % mt._resync_every)
        count = mt._count
        done, ended = run(
            mt._e, mt._kernels, mt._ksq, mt.lengths, mt._ring, mt._ring_sq,
            mt._psum_ring, mt._psum, count, d, sq, g, stop,
            mt._decay, mt._lam, mt._lam_w, mt._wsum, mt._wsums,
            mt._offset, mt._mu, mt._mu_seg, mt._tau, mt._scratch, mt.normalize, mt.n_scales,
            mt._scale_allowed,
            mt._active, mt._out_col, mt._out_score,
            sse, phases, best, variant, column, window, scratch_v, scratch_c, scratch_w,
            track, near, mid_lo, mid_hi, mt.max_window,
        )
        mt._count = count + done - g
        ready[g:done] = count + 1 + np.arange(done - g) >= mt.max_window
        if mt._resync_every and mt._count % mt._resync_every == 0:
            mt._resync()
        if tracking:  # the tracker's state after the last step (before it, when that one ended a stride)
            _store_track(estimator, track)
        if ended:
            _observe(estimator, grid_t, sse, phases, best, variant, column, window, ready, done - 1)
        g = done
    return _supervised(estimator, grid_t, sse, phases, best, variant, window, ready)


def _track_state(estimator: Estimator) -> np.ndarray:
    last = estimator.calibration._last
    if last is None:
        return np.zeros(5)
    return np.array([1.0, last.mode, last.phase, float(last.passed_mid), float(last.began_in_mode)])


def _store_track(estimator: Estimator, track: np.ndarray) -> None:
    estimator.calibration._last = (
        _StrideTrack(int(track[1]), float(track[2]), bool(track[3] > 0), bool(track[4] > 0)) if track[0] > 0 else None
    )


def _confidence(sse: np.ndarray, best: np.ndarray) -> np.ndarray:
    """Supervisor._margin with the candidate the argmin: over the second smallest error."""
    rows = np.arange(sse.shape[0])
    own = sse[rows, best]
    if sse.shape[1] < 2:
        return np.full(own.shape, math.inf)
    other = np.partition(sse, 1, axis=1)[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        margin = (other - own) / own
    return np.where(own <= 0.0, np.where(other > 0, math.inf, 0.0), margin)


def _fit_rms(estimator: Estimator, err: np.ndarray, window: np.ndarray) -> np.ndarray:
    sup = estimator.supervisor
    per_sample = np.maximum(err, 0.0) / (1 if sup.normalized else np.maximum(window, 1))
    return np.sqrt(per_sample / sup.active_channels)


def _observe(
    estimator: Estimator, grid_t: np.ndarray, sse: np.ndarray, phases: np.ndarray, best: np.ndarray,
    variant: np.ndarray, column: np.ndarray, window: np.ndarray, ready: np.ndarray, g: int,
) -> None:
    """At a heel strike ending a whole stride (step g, the matcher's latest): the walking
    calibrations' own ``observe`` with that step's estimate (it tests the stride's confidence)."""
    b = int(best[g])
    conf = float(_confidence(sse[g : g + 1], best[g : g + 1])[0])
    fit = float(_fit_rms(estimator, sse[g : g + 1, b], window[g : g + 1])[0])
    mt = estimator.matcher
    var = np.zeros(mt.n_modes, dtype=np.int64)
    var[b] = variant[g]
    col = np.zeros(mt.n_modes, dtype=np.int64)
    col[b] = column[g]
    win = np.zeros(mt.n_modes, dtype=np.int64)
    win[b] = window[g]
    name = estimator.mode_names[b]
    result = StepResult(b, name, float(phases[g, b]), sse[g], phases[g], bool(ready[g]), win,
                        var if mt.n_scales > 1 else None, col)
    est = Estimate(float(grid_t[g]), b, name, float(phases[g, b]), bool(ready[g]), sse[g], phases[g], b, conf, fit,
                   False, math.nan)
    estimator.calibration.observe(est, result)


def _supervised(
    estimator: Estimator, grid_t: np.ndarray, sse: np.ndarray, phases: np.ndarray, best: np.ndarray,
    variant: np.ndarray, window: np.ndarray, ready: np.ndarray,
) -> dict[str, np.ndarray]:
    """Supervisor.update over the steps (no holds, dwell or transitions: the matcher's choice),
    its state left as the streaming path leaves it."""
    sup = estimator.supervisor
    n = grid_t.size
    rows = np.arange(n)
    phase = phases[rows, best]
    err = sse[rows, best]
    rate = np.full(n, math.nan)
    if n:
        state = np.array([0.0, 0.0, 0.0, 0.0, sup._rate])
        if sup._last is not None:
            state[:4] = 1.0, sup._last[0], sup._last[1], sup._last[2]
        ready_t = grid_t[ready]
        prev = np.concatenate([[state[1]], ready_t[:-1]])
        alpha = np.zeros(n)
        alpha[ready] = _alphas(ready_t - prev, sup.phase_rate_tau_s)
        compiled.phase_rates(grid_t, best, phase, ready, alpha, state, rate)
        if state[0] > 0:
            sup._last = (float(state[1]), int(state[2]), float(state[3]))
        sup._rate = float(state[4])
        if ready.any():
            sup._current, sup._pending = int(best[ready][-1]), None
    inverse = np.asarray(sup._inverse_scales)
    cadence = inverse[variant] if estimator.matcher.n_scales > 1 else np.full(n, math.nan)
    return {
        "time_s": grid_t, "mode_index": best, "phase": phase, "ready": ready, "sse": sse, "phases": phases,
        "raw_mode_index": best.copy(), "confidence": _confidence(sse, best), "fit_rms_deg": _fit_rms(estimator, err, window),
        "held": np.zeros(n, dtype=bool), "phase_rate": rate, "cadence_ratio": cadence,
    }


def _alphas(dt: np.ndarray, tau: float) -> np.ndarray:
    """1 - exp(-dt / tau) by math.exp (the supervisor's function), once per distinct dt."""
    values, inverse = np.unique(dt, return_inverse=True)
    alpha = np.array([1.0 - math.exp(-v / tau) for v in values.tolist()])
    return alpha[inverse.reshape(-1)] if values.size else np.zeros(0)
