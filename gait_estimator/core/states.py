"""What the estimate says beside the library mode: not ready, walking, standing, or unknown.

The stage after the supervisor (``Estimator._step``, and in bulk ``batch.py``). Per matcher
sample, from the angles it matched and the supervisor's estimate:

* ``not_ready``: the matcher's window is not full: no mode (``""``) and no phase (NaN);
* ``stand``: the segments have been still for ``stand_after_s``: every matched channel's angle
  within ``still_speed_dps * still_tau_s`` of its exponential average (time constant
  ``still_tau_s``), i.e. a smoothed angular speed below ``still_speed_dps``. Ends at the first
  sample that moves faster;
* ``unknown``: the reported mode's fit (``fit_rms_deg``) has been beyond that mode's fit limit for
  ``unknown_after_s``: a library taught or trained here stores the limit per mode
  (``fit_limit_deg``, in the mode's ``info``); others get ``default_fit_limit_deg``;
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
from typing import TYPE_CHECKING

import numpy as np

from . import compiled
from .kernels import KernelLibrary

if TYPE_CHECKING:
    from .supervisor import Estimate

STAND = "stand"
UNKNOWN = "unknown"
NOT_READY_MODE = ""
FIT_LIMIT_KEY = "fit_limit_deg"
"""Key of a mode's fit limit (degrees) in its ``info``, written by ``fit_limit_deg``'s callers."""


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
        still_tau_s: Time constant (s) of the angle average the speed is read against.
        stand_after_s: Seconds of stillness before ``stand``.
        fit_limit_scale: Factor on a mode's stored fit limit.
        default_fit_limit_deg: Fit limit (deg RMS) of a mode with none stored.
        unknown_after_s: Seconds beyond the fit limit before ``unknown``.
    """

    enabled: bool = True
    still_speed_dps: float = 10.0
    still_tau_s: float = 0.1
    stand_after_s: float = 0.3
    fit_limit_scale: float = 1.5
    default_fit_limit_deg: float = 8.0
    unknown_after_s: float = 0.1

    def limits(self, library: KernelLibrary) -> np.ndarray:
        """Each mode's fit limit, degrees RMS, (M,)."""
        out = []
        for m in library.modes:
            stored = m.info.get(FIT_LIMIT_KEY)
            ok = isinstance(stored, (int, float)) and math.isfinite(stored) and stored > 0
            out.append(self.fit_limit_scale * float(stored) if ok else self.default_fit_limit_deg)
        return np.asarray(out, dtype=np.float64)


def fit_limit_deg(strides: np.ndarray, kernel: np.ndarray) -> float:
    """The fit limit of a mode trained or taught from ``strides`` (S, N, 4), degrees, each resampled
    to the ``kernel``'s (N, 4) length: the largest RMS (over samples and channels) of a stride
    from the kernel, degrees."""
    rms = np.sqrt(np.mean((np.asarray(strides) - np.asarray(kernel)[None]) ** 2, axis=(1, 2)))
    return float(rms.max())


MEMORY = 8
"""state_step's memory: known, last time, the four angle averages, still since, over limit since."""


def state_step(mem, time_s: float, x0: float, x1: float, x2: float, x3: float, active, ready: bool,
               fit: float, limit: float, still_dps: float, tau: float, stand_after: float,
               unknown_after: float) -> int:
    """The state of one matcher sample at ``time_s`` (seconds), angles ``x0..x3`` (degrees),
    ``active`` (4,) 1.0 for matched channels; ``mem`` (MEMORY,) updated in place; ``fit`` and
    ``limit``: the reported mode's fit and its limit, degrees."""
    if mem[0] == 0.0:
        mem[0], mem[2], mem[3], mem[4], mem[5], mem[6], mem[7] = 1.0, x0, x1, x2, x3, time_s, math.nan
    else:
        k = 1.0 - math.exp(-(time_s - mem[1]) / tau)
        mem[2] += k * (x0 - mem[2])
        mem[3] += k * (x1 - mem[3])
        mem[4] += k * (x2 - mem[4])
        mem[5] += k * (x3 - mem[5])
    mem[1] = time_s
    d = max(active[0] * abs(x0 - mem[2]), active[1] * abs(x1 - mem[3]), active[2] * abs(x2 - mem[4]),
            active[3] * abs(x3 - mem[5]))
    if d >= still_dps * tau:
        mem[6] = time_s
    if not ready:
        mem[7] = math.nan
        return 0
    if time_s - mem[6] >= stand_after - 1e-9:
        mem[7] = math.nan
        return 2
    if fit > limit:
        if math.isnan(mem[7]):
            mem[7] = time_s
        return 3 if time_s - mem[7] >= unknown_after - 1e-9 else 1
    mem[7] = math.nan
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
        self._active = (np.asarray(channel_weights, dtype=np.float64) > 0).astype(np.float64)
        self._active_list: list[float] = self._active.tolist()
        self.names = reported_names(library.mode_names)
        self.reset()

    def reset(self) -> None:
        """Forget the stillness and fit history (a window restart)."""
        self._mem: list[float] = [0.0] * MEMORY

    def step(self, time_s: float, x: tuple[float, float, float, float] | list[float], est: Estimate) -> Estimate:
        """``est`` (the supervisor's, for the sample ``x``, degrees) in its state."""
        if not self.enabled:
            return est if est.ready else est.in_state(NOT_READY, est.mode, est.phase)
        p = self.params
        state = state_step(self._mem, time_s, x[0], x[1], x[2], x[3], self._active_list, est.ready,
                           est.fit_rms_deg, self._limit_list[est.mode_index], p.still_speed_dps, p.still_tau_s,
                           p.stand_after_s, p.unknown_after_s)
        if state == WALKING:
            return est
        return est.in_state(state, self.names[int(name_index(state, est.mode_index, len(self.names)))], math.nan)

    def decide_many(self, time_s: np.ndarray, x: np.ndarray, columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """The bulk form of ``step`` over the supervisor's ``columns`` for samples ``x`` (G, 4) at
        ``time_s`` (G,): the ``state`` column and the phase as ``step`` leaves them."""
        if not self.enabled:
            names = np.asarray(self.names, dtype=object)[columns["mode_index"]]
            return {**columns, "state": np.where(columns["ready"], WALKING, NOT_READY), "mode": names}
        p = self.params
        n = time_s.shape[0]
        state = np.empty(n, dtype=np.int64)
        mem = np.asarray(self._mem, dtype=np.float64)
        limit = self.limits[columns["mode_index"]] if n else np.zeros(0)
        _state_rows(mem, time_s, np.ascontiguousarray(x, dtype=np.float64), self._active, columns["ready"],
                    columns["fit_rms_deg"], limit, p.still_speed_dps, p.still_tau_s, p.stand_after_s,
                    p.unknown_after_s, state)
        self._mem = mem.tolist()
        phase = np.where(state == WALKING, columns["phase"], math.nan)
        index = name_index(state, columns["mode_index"], len(self.names))
        return {**columns, "state": state, "phase": phase, "mode": np.asarray(self.names, dtype=object)[index]}


def reported_names(mode_names: list[str]) -> list[str]:
    """The library's mode names, then the ``mode`` of each state but walking (``name_index``)."""
    return [*mode_names, NOT_READY_MODE, "", STAND, UNKNOWN]


def name_index(state: int | np.ndarray, mode_index: int | np.ndarray, names: int) -> np.ndarray:
    """Index in ``reported_names`` (``names`` long) of the ``mode`` reported in ``state`` with the
    library mode ``mode_index`` (scalars or arrays)."""
    return np.where(np.asarray(state) == WALKING, mode_index, names - 4 + np.asarray(state))


_state_step = compiled.njit(cache=True, nogil=True)(state_step)


@compiled.njit(cache=True, nogil=True)
def _state_rows(mem, time_s, x, active, ready, fit, limit, still_dps, tau, stand_after, unknown_after,
                state):  # pragma: no cover - compiled
    for g in range(time_s.shape[0]):
        state[g] = _state_step(mem, time_s[g], x[g, 0], x[g, 1], x[g, 2], x[g, 3], active, ready[g], fit[g],
                               limit[g], still_dps, tau, stand_after, unknown_after)

