"""What the estimate says beside the library mode: not ready, walking, standing, or unknown.

The stage after the supervisor (``Estimator._step``, and in bulk ``batch.py``). Per matcher
sample, from the angles it matched and the supervisor's estimate:

* ``not_ready``: the matcher's window is not full: no mode (``""``) and no phase (NaN);
* ``stand``: the segments have been still for ``stand_after_s``: every matched channel's smoothed
  angular speed (``state_step``) below ``still_speed_dps``. Ends at the first sample that moves
  faster;
* ``unknown``: the reported mode's fit (``fit_rms_deg``) has been beyond that mode's fit limit
  (judged from ``start_strides`` after ``stand``), the stride rate (``phase_rate``) above
  ``max_cadence_ratio`` times its kernel's with the knees flexing faster than ``knee_speed_ratio``
  times its kernel's (``knee_speed_dps``), or every segment slower than ``slow_speed_dps``, for
  ``unknown_after_s`` (and stays until it has been within it as long): a library taught or
  trained here stores each mode's limit (``fit_limit_deg`` in its ``info``: its worst stride's
  RMS from the kernel, ``training.train_mode``) times ``fit_limit_scale``; others get ``default_fit_limit_deg``;
* ``walking``: otherwise: a library mode, with its phase.

``mode`` reads ``stand`` or ``unknown`` in those states, and the phase is NaN in every state but
walking. With ``enabled`` False (``states: false``, the paper preset) the state is only
``not_ready`` or ``walking`` and the mode and phase are the supervisor's, as in the paper.

``state_step`` is the rule, on Python floats for ``StateTracker.step`` and compiled for
``StateTracker.decide_many``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING, Any

import numpy as np

from . import compiled
from .kernels import STAND, UNKNOWN, KernelLibrary

if TYPE_CHECKING:
    from .supervisor import Estimate

NOT_READY_MODE = ""
FIT_LIMIT_KEY = "fit_limit_deg"
"""Key of a mode's fit limit (degrees) in its ``info``, written by ``training.train_mode``."""


class EstimateState(IntEnum):
    """The estimate's state (the ``state`` value of the ``estimate`` message and CSV column)."""

    not_ready = 0
    walking = 1
    stand = 2
    unknown = 3


NOT_READY, WALKING, STANDING, UNKNOWN_STATE = (int(s) for s in EstimateState)


@dataclass(frozen=True)
class StateParams:
    """Thresholds of the state decision (module docstring); defaults measured by
    benchmarks/contract.py.

    Attributes:
        enabled: Report ``stand`` and ``unknown`` and blank mode/phase while not ready.
        still_speed_dps: Smoothed angular speed (deg/s) below which a segment is still.
        fast_tau_s: Time constant (s) of the fast angle average (noise smoothing).
        slow_tau_s: Time constant (s) of the slow angle average the fast one is read against.
        stand_after_s: Seconds of stillness before ``stand``.
        fit_limit_scale: Factor on a mode's stored fit limit.
        default_fit_limit_deg: Fit limit (deg RMS) of a mode with none stored.
        max_cadence_ratio: Stride rate (``phase_rate``) over the reported mode's kernel's above
            which no kernel variant fits either (running-like strides; slower strides are walking:
            turns and first steps), when the knees also flex faster than ``knee_speed_ratio``.
        knee_speed_ratio: Knee flexion speed (``knee_speed_dps``, each matched knee, averaged over
            ``knee_tau_s``) over the reported mode's kernel's above which a fast stride is running-
            like (a short last stride before a stop flexes the knee as a walking one does). With no
            knee matched (thigh and shank of one side), cadence alone decides.
        knee_tau_s: Time constant (s) of the knee speed average (about a stride).
        unknown_after_s: Seconds beyond the fit limit before ``unknown``, and within it before
            walking again.
        start_strides: Strides (the reported mode's kernel's) after ``stand`` during which the
            fit is not judged: the window still holds the standing samples.
        slow_speed_dps: Smoothed angular speed (deg/s) below which every matched segment moving
            counts as beyond a limit (slowing to a stop, shuffling; walking swings faster).
    """

    enabled: bool = True
    still_speed_dps: float = 10.0
    fast_tau_s: float = 0.05
    slow_tau_s: float = 0.15
    stand_after_s: float = 0.2
    fit_limit_scale: float = 3.0
    default_fit_limit_deg: float = 12.0
    max_cadence_ratio: float = 1.25
    knee_speed_ratio: float = 1.2
    knee_tau_s: float = 1.0
    unknown_after_s: float = 0.2
    start_strides: float = 1.0
    slow_speed_dps: float = 40.0

    def limits(self, library: KernelLibrary) -> np.ndarray:
        """Each mode's fit limit, degrees RMS, (M,)."""
        out = []
        for m in library.modes:
            stored = m.info.get(FIT_LIMIT_KEY)
            ok = isinstance(stored, (int, float)) and math.isfinite(stored) and stored > 0
            out.append(self.fit_limit_scale * float(stored) if ok else self.default_fit_limit_deg)
        return np.asarray(out, dtype=np.float64)

    def knee_limits(self, library: KernelLibrary) -> np.ndarray:
        """Each mode's ``knee_speed_ratio`` x its kernel's knee speed, as ``state_step`` reads it:
        a fast minus slow average difference, degrees, (M,)."""
        span = self.slow_tau_s - self.fast_tau_s
        speeds = [knee_speed_dps(m.samples, m.sample_rate_hz, self.fast_tau_s, self.slow_tau_s) for m in library.modes]
        return self.knee_speed_ratio * span * np.asarray(speeds, dtype=np.float64)


def knee_speed_dps(samples: np.ndarray, rate_hz: float, fast_tau: float, slow_tau: float) -> float:
    """The knee flexion speed of a kernel (N, 4) at ``rate_hz`` repeated, deg/s, as ``state_step``
    smooths it: each knee's (thigh - shank) fast minus slow exponential average (time constants
    ``fast_tau``, ``slow_tau``, s) over slow_tau - fast_tau, its magnitude averaged over the stride
    and the two knees (the filters' periodic steady state)."""
    x = np.asarray(samples, dtype=np.float64)
    knee = x[:, :2] - x[:, 2:]
    n = knee.shape[0]
    z = np.exp(-2j * np.pi * np.arange(n // 2 + 1) / n)
    af, a_s = 1.0 - math.exp(-1.0 / (rate_hz * fast_tau)), 1.0 - math.exp(-1.0 / (rate_hz * slow_tau))
    band = af / (1.0 - (1.0 - af) * z) - a_s / (1.0 - (1.0 - a_s) * z)
    speed = np.fft.irfft(np.fft.rfft(knee, axis=0) * band[:, None], n=n, axis=0)
    return float(np.mean(np.abs(speed)) / (slow_tau - fast_tau))


NAN = math.nan
MEMORY = 21
"""state_step's memory: known, last time, fast (4) and slow (4) angle averages, still since, over
the limit since, unknown (1.0) or not, within the limit since; the last interval and its two
smoothing weights (resampled input repeats one interval); the last ``stand`` sample's time; the
right and left knee speed averages; the last interval's knee smoothing weight."""


def state_step(mem: np.ndarray, time_s: float, x0: float, x1: float, x2: float, x3: float, active: np.ndarray, ready: bool,
               fit: float, limit: float, cadence: float, start: float, knee_limit: float, max_cadence: float,
               still_deg: float, slow_deg: float, fast_tau: float, slow_tau: float, knee_tau: float,
               stand_after: float, unknown_after: float) -> int:
    """The state of one matcher sample at ``time_s`` (seconds), angles ``x0..x3`` (degrees),
    ``active`` (4,) 1.0 for matched channels; ``mem`` (MEMORY,) updated in place; ``fit`` and
    ``limit``: the reported mode's fit and its limit, degrees; ``cadence``: the wearer's stride
    rate over the reported mode's kernel's (nan unknown), ``max_cadence`` its upper limit, judged
    only while the knees flex faster than ``knee_limit`` (``StateParams.knee_limits``);
    ``start``: seconds after ``stand`` during which the fit is not judged.

    Stillness: each angle's fast and slow exponential averages (time constants ``fast_tau`` <
    ``slow_tau``, s) differ by speed x (slow_tau - fast_tau) for an angle moving at a steady speed,
    and by little for sensor noise; ``still_deg`` (``slow_deg``) = still_speed_dps (slow_speed_dps)
    x (slow_tau - fast_tau). Knee speed: each knee's (thigh - shank) fast minus slow average
    difference, its magnitude averaged over ``knee_tau`` s; the slower matched knee counts."""
    slow = False
    if mem[0] == 0.0:
        mem[2], mem[3], mem[4], mem[5], mem[6], mem[7], mem[8], mem[9] = x0, x1, x2, x3, x0, x1, x2, x3
        mem[0], mem[10], mem[11], mem[12], mem[13], mem[14], mem[17] = 1.0, time_s, NAN, 0.0, NAN, NAN, NAN
        mem[18], mem[19] = 0.0, 0.0
    else:
        dt = time_s - mem[1]
        if dt != mem[14]:
            mem[14], mem[15], mem[16] = dt, 1.0 - math.exp(-dt / fast_tau), 1.0 - math.exp(-dt / slow_tau)
            mem[20] = 1.0 - math.exp(-dt / knee_tau)
        kf, ks = mem[15], mem[16]
        f0, f1, f2, f3 = mem[2] + kf * (x0 - mem[2]), mem[3] + kf * (x1 - mem[3]), mem[4] + kf * (x2 - mem[4]), \
            mem[5] + kf * (x3 - mem[5])
        s0, s1, s2, s3 = mem[6] + ks * (x0 - mem[6]), mem[7] + ks * (x1 - mem[7]), mem[8] + ks * (x2 - mem[8]), \
            mem[9] + ks * (x3 - mem[9])
        mem[2], mem[3], mem[4], mem[5], mem[6], mem[7], mem[8], mem[9] = f0, f1, f2, f3, s0, s1, s2, s3
        if (active[0] * abs(f0 - s0) >= still_deg or active[1] * abs(f1 - s1) >= still_deg
                or active[2] * abs(f2 - s2) >= still_deg or active[3] * abs(f3 - s3) >= still_deg):
            mem[10] = time_s
        mem[18] += mem[20] * (abs(f0 - f2 - s0 + s2) - mem[18])
        mem[19] += mem[20] * (abs(f1 - f3 - s1 + s3) - mem[19])
        slow = (active[0] * abs(f0 - s0) < slow_deg and active[1] * abs(f1 - s1) < slow_deg
                and active[2] * abs(f2 - s2) < slow_deg and active[3] * abs(f3 - s3) < slow_deg)
    mem[1] = time_s
    if not ready or time_s - mem[10] >= stand_after - 1e-9:
        mem[11], mem[12], mem[13] = NAN, 0.0, NAN
        if not ready:
            return 0
        mem[17] = time_s
        return 2
    # unknown after unknown_after s beyond a limit, walking again after as long within them
    # fast strides: the slower matched knee's speed against the limit
    if ((fit > limit and not time_s - mem[17] < start) or slow
            or (cadence > max_cadence and min(mem[18] if active[0] * active[2] > 0.0 else math.inf,
                                              mem[19] if active[1] * active[3] > 0.0 else math.inf) > knee_limit)):
        mem[13] = NAN
        if math.isnan(mem[11]):
            mem[11] = time_s
        if mem[12] > 0.0 or time_s - mem[11] >= unknown_after - 1e-9:
            mem[12] = 1.0
            return 3
        return 1
    if mem[12] > 0.0:
        if math.isnan(mem[13]):
            mem[13] = time_s
        if time_s - mem[13] < unknown_after - 1e-9:
            return 3
        mem[12], mem[13] = 0.0, NAN
    mem[11] = NAN
    return 1


class StateTracker:
    """The state stage of one estimator (module docstring).

    Args:
        library: The kernels (their fit limits).
        params: Thresholds.
        channel_weights: (4,) weights of the matched channels (0 = not matched).
    """

    def __init__(self, library: KernelLibrary, params: StateParams, channel_weights: np.ndarray) -> None:
        self.params = params
        self.enabled = bool(params.enabled)
        self.limits = params.limits(library)
        self._limit_list: list[float] = self.limits.tolist()
        self.durations = np.array([m.stride_duration_s for m in library.modes])
        self._duration_list: list[float] = self.durations.tolist()
        self._start_list: list[float] = (params.start_strides * self.durations).tolist()
        self.knee_limits = params.knee_limits(library)
        self._knee_list: list[float] = self.knee_limits.tolist()
        self._active = (np.asarray(channel_weights, dtype=np.float64) > 0).astype(np.float64)
        self._active_list: list[float] = self._active.tolist()
        self.names = reported_names(library.mode_names)
        self._thresholds = (params.max_cadence_ratio, params.still_speed_dps * (params.slow_tau_s - params.fast_tau_s),
                            params.slow_speed_dps * (params.slow_tau_s - params.fast_tau_s),
                            params.fast_tau_s, params.slow_tau_s, params.knee_tau_s, params.stand_after_s,
                            params.unknown_after_s)
        self.reset()

    def reset(self) -> None:
        """Forget the stillness and fit history (a window restart)."""
        self._mem: list[float] = [0.0] * MEMORY

    def step(self, time_s: float, x: tuple[float, float, float, float] | list[float], est: Estimate) -> Estimate:
        """``est`` (the supervisor's, for the sample ``x``, degrees) in its state."""
        if not self.enabled:
            return est if est.ready else est.in_state(NOT_READY, est.mode, est.phase)
        m = est.mode_index
        state = state_step(self._mem, time_s, x[0], x[1], x[2], x[3], self._active_list, est.ready, est.fit_rms_deg,
                           self._limit_list[m], est.phase_rate * self._duration_list[m], self._start_list[m],
                           self._knee_list[m], *self._thresholds)
        if state == WALKING:
            return est
        return est.in_state(state, self.names[name_index(state, est.mode_index, len(self.names))], math.nan)

    def decide_many(self, time_s: np.ndarray, x: np.ndarray, columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The bulk form of ``step`` over the supervisor's ``columns`` for samples ``x`` (G, 4) at
        ``time_s`` (G,): the ``state`` column and the phase as ``step`` leaves them."""
        if not self.enabled:
            names = np.asarray(self.names, dtype=object)[columns["mode_index"]]
            return {**columns, "state": np.where(columns["ready"], WALKING, NOT_READY), "mode": names}
        n = time_s.shape[0]
        state = np.empty(n, dtype=np.int64)
        mem = np.asarray(self._mem, dtype=np.float64)
        limit = self.limits[columns["mode_index"]] if n else np.zeros(0)
        duration = self.durations[columns["mode_index"]] if n else np.zeros(0)
        knee = self.knee_limits[columns["mode_index"]] if n else np.zeros(0)
        _state_rows(mem, time_s, np.ascontiguousarray(x, dtype=np.float64), self._active, columns["ready"],
                    columns["fit_rms_deg"], limit, columns["phase_rate"] * duration,
                    self.params.start_strides * duration, knee, *self._thresholds, state)
        self._mem = mem.tolist()
        phase = np.where(state == WALKING, columns["phase"], math.nan)
        index = name_index(state, columns["mode_index"], len(self.names))
        return {**columns, "state": state, "phase": phase, "mode": np.asarray(self.names, dtype=object)[index]}


def reported_names(mode_names: list[str]) -> list[str]:
    """The library's mode names, then the ``mode`` of each state but walking (``name_index``)."""
    return [*mode_names, NOT_READY_MODE, "", STAND, UNKNOWN]


def name_index(state: Any, mode_index: Any, names: int) -> Any:
    """Index in ``reported_names`` (``names`` long) of the ``mode`` reported in ``state`` with the
    library mode ``mode_index`` (ints, or integer arrays)."""
    walking = state == WALKING
    return mode_index * walking + (names - 4 + state) * (1 - walking)


_state_step = compiled.njit(cache=True, nogil=True)(state_step)


@compiled.njit(cache=True, nogil=True)
def _state_rows(mem, time_s, x, active, ready, fit, limit, cadence, start, knee, max_cadence, still_deg, slow_deg,
                fast_tau, slow_tau, knee_tau, stand_after, unknown_after, state):  # pragma: no cover - compiled
    for g in range(time_s.shape[0]):
        state[g] = _state_step(mem, time_s[g], x[g, 0], x[g, 1], x[g, 2], x[g, 3], active, ready[g], fit[g],
                               limit[g], cadence[g], start[g], knee[g], max_cadence, still_deg, slow_deg, fast_tau,
                               slow_tau, knee_tau, stand_after, unknown_after)

