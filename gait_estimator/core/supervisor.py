"""Supervision of the matcher's raw choice: confidence, holding, dwell, allowed transitions,
phase rate.

The matcher picks argmin_m SSE every sample. The supervisor turns that into the reported
estimate:

1. allowed transitions: from the current mode only the modes its table row lists (and itself)
   are candidates (the paper's suggested state-machine supervision);
2. confidence: margin = (SSE of the best other mode - SSE of the candidate) / SSE of the
   candidate; fit quality = RMS error per sample and channel, degrees;
3. hold: below ``min_confidence`` the last confident mode stays reported, flagged ``held``;
4. switch-back margin (hysteresis against flicker between close modes): a return to the mode
   reported before the current one needs its error below (1 - ``switch_back_margin``) x the
   current mode's (``switch_candidate``);
5. dwell: a new mode is reported only after it has been the candidate for ``min_dwell_s`` seconds;
6. phase rate: exponentially smoothed d(phase)/dt of the reported mode, strides per second.

``Supervisor.decide`` is the one place where the reported mode and phase are decided;
``Supervisor.decide_many`` is its bulk form (offline, ``batch.py``), and both compute confidence,
fit and phase rate with the same functions (``relative_margin``, ``fit_rms``,
``phase_rate_step``; compiled for the bulk form). Every option off (the defaults) reports the
matcher's choice unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from . import compiled
from .errors import GaitEstimatorError
from .matcher import StepBlock, StepResult
from .options import EstimatorConfig


@dataclass(frozen=True)
class Estimate:
    """What the estimator reports for one (matcher) sample.

    Attributes:
        time_s: Time of the sample, seconds (the input stamp, or the resampling grid time).
        mode_index: The supervisor's library mode (index into the library's modes), whatever
            the state.
        mode: Reported mode: the library mode's name while walking, else ``stand``, ``unknown``
            or ``""`` (not ready) (states.py).
        phase: Gait phase of the reported mode, [0, 1), 0 = right heel strike; NaN in every state
            but walking (states on).
        ready: The matcher's windows are full.
        sse: Per-mode minimum SSE, deg^2 (weighted by channel weights), shape (M,).
        phases: Per-mode phase at the best shift, shape (M,).
        raw_mode_index: The matcher's own argmin (before supervision).
        confidence: Margin of the candidate over the best other mode, relative to its SSE (>= 0
            when the candidate is the argmin; inf with a single mode).
        fit_rms_deg: RMS error per sample and channel of the reported mode, degrees.
        held: True while the reported mode is held (low confidence or dwell pending).
        phase_rate: Smoothed phase velocity, strides per second; nan until known.
        cadence_ratio: Wearer cadence / kernel cadence of the reported mode: 1 / the time scale
            of its best kernel variant; nan when the matcher has one scale.
        state: ``EstimateState`` value (states.py): 0 not ready, 1 walking, 2 stand, 3 unknown.
    """

    time_s: float
    mode_index: int
    mode: str
    phase: float
    ready: bool
    sse: np.ndarray
    phases: np.ndarray
    raw_mode_index: int
    confidence: float
    fit_rms_deg: float
    held: bool
    phase_rate: float
    cadence_ratio: float = math.nan
    state: int = 1

    def at(self, time_s: float) -> Estimate:
        """This estimate carried forward to a later ``time_s`` (seconds): the phase advanced by the
        phase rate over the time since (within one resampling interval), wrapped to [0, 1)."""
        dt = time_s - self.time_s
        if dt <= 0.0:
            return self
        phase = self.phase
        if self.ready and math.isfinite(self.phase_rate):
            phase = advanced_phase(phase, self.phase_rate, dt)
        return self.restamped(time_s, phase)

    def restamped(self, time_s: float, phase: float) -> Estimate:
        """This estimate at another time with another reported phase (dataclasses.replace is
        several times slower, and this runs for every input sample between grid points)."""
        return Estimate(time_s, self.mode_index, self.mode, phase, self.ready, self.sse, self.phases,
                        self.raw_mode_index, self.confidence, self.fit_rms_deg, self.held, self.phase_rate,
                        self.cadence_ratio, self.state)

    def in_state(self, state: int, mode: str, phase: float) -> Estimate:
        """This estimate in ``state`` (states.py) reporting ``mode`` and ``phase``."""
        return Estimate(self.time_s, self.mode_index, mode, phase, self.ready, self.sse, self.phases,
                        self.raw_mode_index, self.confidence, self.fit_rms_deg, self.held, self.phase_rate,
                        self.cadence_ratio, state)

    @classmethod
    def from_columns(cls, columns: Mapping[str, np.ndarray], g: int, mode_names: Sequence[str]) -> Estimate:
        """Row ``g`` of the columns ``Supervisor.decide_many`` gives, or of those the state stage
        leaves (with ``state`` and ``mode``)."""
        c, m = columns, int(columns["mode_index"][g])
        state = int(c["state"][g]) if "state" in c else 1
        mode = str(c["mode"][g]) if "mode" in c else mode_names[m]
        return cls(float(c["time_s"][g]), m, mode, float(c["phase"][g]), bool(c["ready"][g]), c["sse"][g],
                   c["phases"][g], int(c["raw_mode_index"][g]), float(c["confidence"][g]), float(c["fit_rms_deg"][g]),
                   bool(c["held"][g]), float(c["phase_rate"][g]), float(c["cadence_ratio"][g]), state)


def carry_forward(columns: Mapping[str, np.ndarray], time_s: np.ndarray) -> dict[str, np.ndarray]:
    """The bulk form of ``Estimate.at``: row i of the decided ``columns`` carried forward to
    ``time_s[i]``, seconds."""
    out = dict(columns)
    out["phase"] = columns["phase"].copy()
    _carried_rows(columns["time_s"], time_s, columns["ready"], columns["phase_rate"], out["phase"])
    out["time_s"] = np.where(time_s - columns["time_s"] > 0.0, time_s, columns["time_s"])
    return out


def load_transitions(path: str | Path, mode_names: Sequence[str]) -> np.ndarray:
    """Read an allowed-transitions YAML into an (M, M) bool matrix, allowed[from, to].

    Format: ``allowed_transitions: {FROM: [TO, ...], ...}``. Staying in a mode is always allowed;
    a mode without an entry may change to any mode.
    """
    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise GaitEstimatorError(f"{p}: cannot read transitions file ({exc})") from None
    except yaml.YAMLError:
        raise GaitEstimatorError(f"{p}: invalid YAML") from None
    table = doc.get("allowed_transitions") if isinstance(doc, dict) else None
    if not isinstance(table, dict):
        raise GaitEstimatorError(f"{p}: expected a mapping 'allowed_transitions: {{MODE: [MODE, ...]}}'")
    return transitions_matrix(table, mode_names, str(p))


def transitions_matrix(table: Mapping[str, Sequence[str]], mode_names: Sequence[str], where: str = "transitions") -> np.ndarray:
    """(M, M) allowed[from, to] from a {from: [to, ...]} table; see load_transitions."""
    index = {m: i for i, m in enumerate(mode_names)}
    allowed = np.ones((len(mode_names), len(mode_names)), dtype=bool)
    for src, targets in table.items():
        if src not in index:
            raise GaitEstimatorError(f"{where}: unknown mode {src!r} (library modes: {', '.join(mode_names)})")
        if not isinstance(targets, (list, tuple)):
            raise GaitEstimatorError(f"{where}: entry for {src!r} must be a list of modes")
        row = np.zeros(len(mode_names), dtype=bool)
        for t in targets:
            if t not in index:
                raise GaitEstimatorError(f"{where}: unknown mode {t!r} in the entry for {src!r}")
            row[index[t]] = True
        row[index[src]] = True
        allowed[index[src]] = row
    return allowed


@dataclass(frozen=True)
class SupervisorParams:
    """Supervision settings (the options of the same names).

    Attributes:
        min_confidence: Hold the last confident mode below this margin; 0 = off.
        min_dwell_s: Seconds a new mode must win before it is reported; 0 = off.
        switch_back_margin: Relative error margin by which the mode reported before the current
            one must beat it to be reported again, [0, 1); 0 = off.
        transitions: YAML file of allowed transitions; '' = any.
        phase_rate_tau_s: Time constant of the phase-rate smoothing, seconds.
    """

    min_confidence: float = EstimatorConfig.min_confidence
    min_dwell_s: float = EstimatorConfig.min_dwell_s
    switch_back_margin: float = EstimatorConfig.switch_back_margin
    transitions: str = EstimatorConfig.transitions
    phase_rate_tau_s: float = EstimatorConfig.phase_rate_tau_s


class Supervisor:
    """Turns matcher results into reported estimates (see the module docstring).

    Args:
        mode_names: The library's mode names.
        params: Confidence, dwell, transitions and phase-rate settings.
        allowed: (M, M) allowed[from, to] matrix; None = read ``params.transitions`` (if set).
        active_channels: Channels with non-zero weight (for the RMS fit quality).
        normalized: The matcher's errors are per window sample (not SSE).
        time_scales: The matcher's time scales (for the cadence ratio).
    """

    def __init__(
        self,
        mode_names: Sequence[str],
        params: SupervisorParams = SupervisorParams(),
        allowed: np.ndarray | None = None,
        active_channels: int = 4,
        normalized: bool = False,
        time_scales: Sequence[float] | np.ndarray = (1.0,),
    ) -> None:
        self.mode_names = list(mode_names)
        self.params = params
        if allowed is None and params.transitions:
            allowed = load_transitions(params.transitions, self.mode_names)
        self.allowed = allowed
        self.active_channels = active_channels
        self.min_confidence = float(params.min_confidence)
        self.min_dwell_s = float(params.min_dwell_s)
        self.switch_back_margin = float(params.switch_back_margin)
        self.phase_rate_tau_s = float(params.phase_rate_tau_s)
        self.normalized = bool(normalized)
        self._inverse_scales: list[float] = (1.0 / np.asarray(time_scales, dtype=np.float64)).tolist()
        self.reset()

    @property
    def passes_through(self) -> bool:
        """Every option off: the reported mode is the matcher's choice (``decide_many`` needs it)."""
        return self.min_confidence == 0 and self.min_dwell_s == 0 and self.switch_back_margin == 0 and self.allowed is None

    def reset(self) -> None:
        self._current: int | None = None
        self._previous: int | None = None  # the mode reported before _current
        self._pending: int | None = None
        self._pending_since = 0.0
        self._last: tuple[float, int, float] | None = None  # time, mode, phase
        self._rate = math.nan

    def decide(self, time_s: float, result: StepResult) -> Estimate:
        """The reported mode and phase for one matcher result at ``time_s`` (seconds): the
        allowed candidate, held while unconfident or dwelling, with that mode's phase."""
        sse = result.sse
        values = sse.tolist()  # Python floats from here on: per-sample numpy calls are costly when cold
        candidate = result.mode_index
        if self._current is not None and self.allowed is not None:
            masked = np.where(self.allowed[self._current], sse, np.inf)
            candidate = int(masked.argmin())
        kept = False
        if self._current is not None and self.switch_back_margin > 0 and result.ready:
            chosen = switch_candidate(values, self._current, self._previous, candidate, self.switch_back_margin)
            candidate, kept = chosen, chosen != candidate
        confidence = _margin(values, sse, candidate, result.mode_index)
        held = False
        if not result.ready:
            reported = candidate
        else:
            reported, held = self._choose(time_s, candidate, confidence)
            held = held or kept
        fit = fit_rms(values[reported], int(result.window[reported]), self.normalized, self.active_channels)
        phase = result.phase if reported == result.mode_index else float(result.phases[reported])
        rate = self._phase_rate(time_s, reported, phase) if result.ready else math.nan
        return Estimate(
            time_s=time_s,
            mode_index=reported,
            mode=self.mode_names[reported],
            phase=phase,
            ready=result.ready,
            sse=sse,
            phases=result.phases,
            raw_mode_index=result.mode_index,
            confidence=confidence,
            fit_rms_deg=fit,
            held=held,
            phase_rate=rate,
            cadence_ratio=math.nan if result.variant is None else self._inverse_scales[int(result.variant[reported])],
        )

    def decide_many(self, time_s: np.ndarray, steps: StepBlock) -> dict[str, np.ndarray]:
        """The bulk form of ``decide`` for a run of matcher steps at ``time_s`` (G,), seconds: the
        fields of their estimates as columns (G,) or (G, M), the values ``decide`` gives, the state
        left as it leaves it. Only while the supervisor passes the matcher's choice through."""
        if not self.passes_through:
            raise ValueError("decide_many needs min_confidence 0, min_dwell_s 0, switch_back_margin 0 and no transitions")
        n, (best, ready) = time_s.shape[0], (steps.best, steps.ready)
        rows = np.arange(n)
        phase, err = steps.phases[rows, best], steps.sse[rows, best]
        other = np.partition(steps.sse, 1, axis=1)[:, 1] if steps.sse.shape[1] > 1 else np.full(n, math.inf)
        state = np.array([0.0, 0.0, 0.0, 0.0, self._rate])  # _last (known, time, mode, phase), _rate
        if self._last is not None:
            state[:4] = 1.0, *self._last
        ready_t = time_s[ready]
        alpha = np.zeros(n)
        alpha[ready] = self._smoothing_weights(ready_t - np.concatenate([state[1:2], ready_t[:-1]]))
        confidence, fit, rate = np.empty((3, n))
        _decided_rows(time_s, err, best, phase, steps.window, ready, other, alpha, state, self.normalized,
                      self.active_channels, confidence, fit, rate)
        if state[0] > 0:
            self._last = (float(state[1]), int(state[2]), float(state[3]))
        self._rate = float(state[4])
        if ready.any():  # what _choose leaves with every option off
            self._current, self._pending = int(best[ready][-1]), None
        cadence = np.asarray(self._inverse_scales)[steps.variant] if steps.n_scales > 1 else np.full(n, math.nan)
        return {
            "time_s": time_s, "mode_index": best, "phase": phase, "ready": ready, "sse": steps.sse,
            "phases": steps.phases, "raw_mode_index": best.copy(), "confidence": confidence, "fit_rms_deg": fit,
            "held": np.zeros(n, dtype=bool), "phase_rate": rate, "cadence_ratio": cadence,
        }

    def _smoothing_weights(self, dt: np.ndarray) -> np.ndarray:
        """``smoothing_weight`` of each of ``dt`` (math.exp, as ``decide``), once per distinct dt."""
        values, inverse = np.unique(dt, return_inverse=True)
        alpha = np.array([smoothing_weight(v, self.phase_rate_tau_s) for v in values.tolist()])
        return alpha[inverse.reshape(-1)] if values.size else np.zeros(0)

    def _choose(self, time_s: float, candidate: int, confidence: float) -> tuple[int, bool]:
        low = self.min_confidence > 0 and confidence < self.min_confidence
        if self._current is None:
            self._current = candidate
            return candidate, low
        if low:
            self._pending = None
            return self._current, True
        if candidate == self._current:
            self._pending = None
            return candidate, False
        if candidate != self._pending:
            self._pending, self._pending_since = candidate, time_s
        if time_s - self._pending_since >= self.min_dwell_s - 1e-9:
            self._previous, self._current, self._pending = self._current, candidate, None
            return candidate, False
        return self._current, True

    def _phase_rate(self, time_s: float, mode: int, phase: float) -> float:
        last = self._last
        self._last = (time_s, mode, phase)
        if last is not None:
            alpha = smoothing_weight(time_s - last[0], self.phase_rate_tau_s)
            self._rate = phase_rate_step(self._rate, last[0], last[1], last[2], time_s, mode, phase, alpha)
        return self._rate


def _margin(values: list[float], sse: np.ndarray, candidate: int, argmin: int) -> float:
    """(SSE of the best mode other than ``candidate`` - SSE of ``candidate``) / SSE of
    ``candidate``; ``values`` = ``sse`` as a list."""
    if len(values) < 2:
        return math.inf
    if candidate == argmin:  # the second smallest; a sort of a short list beats np.partition here
        best_other = sorted(values)[1] if len(values) <= 64 else float(np.partition(sse, 1)[1])
    else:
        best_other = values[argmin]
    return relative_margin(values[candidate], best_other)


# The formulas of the decision, one each for decide (Python floats) and decide_many (compiled).


def switch_candidate(errors: Sequence[float], current: int, previous: int | None, candidate: int, margin: float) -> int:
    """The mode to follow: ``candidate``, unless it is the ``previous`` mode (reported before
    ``current``) and its error is not below (1 - ``margin``) x the current mode's (``errors`` per
    mode): two close modes then do not take turns on noise, and a change to a third is not delayed."""
    if candidate != previous or errors[candidate] < (1.0 - margin) * errors[current]:
        return candidate
    return current


def relative_margin(own: float, best_other: float) -> float:
    """The confidence margin (best_other - own) / own of an error ``own`` over the best other
    ``best_other`` (inf when own is 0 and the other is not, 0 when both are)."""
    if own <= 0.0:
        return math.inf if best_other > 0 else 0.0
    return (best_other - own) / own


def fit_rms(error: float, window: int, normalized: bool, channels: int) -> float:
    """RMS error per sample and channel, degrees, of a mode whose matcher error is ``error`` over
    a window of ``window`` samples (``normalized``: per window sample already) and ``channels``
    channels."""
    per_sample = (0.0 if error < 0.0 else error) / (1 if normalized else max(window, 1))
    return math.sqrt(per_sample / channels)


def smoothing_weight(dt: float, tau: float) -> float:
    """Weight 1 - exp(-dt / tau) of a phase-rate reading ``dt`` s after the previous one."""
    return 1.0 - math.exp(-dt / tau) if tau > 0 else 1.0


def phase_rate_step(rate: float, last_time: float, last_mode: int, last_phase: float, time_s: float, mode: int,
                    phase: float, alpha: float) -> float:
    """The smoothed phase rate (strides/s) after a ready step: ``rate`` moved by ``alpha``
    (``smoothing_weight``) towards the phase change over the time since the previous ready step
    if both report the same mode (the first such reading sets it); else unchanged."""
    if last_mode != mode or time_s <= last_time:
        return rate
    inst = ((phase - last_phase + 0.5) % 1.0 - 0.5) / (time_s - last_time)
    return inst if math.isnan(rate) else rate + alpha * (inst - rate)


def advanced_phase(phase: float, rate: float, dt: float) -> float:
    """``phase`` advanced at ``rate`` (strides/s) over ``dt`` seconds, wrapped to [0, 1)."""
    phase = (phase + rate * dt) % 1.0
    return 0.0 if phase >= 1.0 else phase


_compile = compiled.njit(cache=True, nogil=True)
_relative_margin, _fit_rms, _phase_rate_step, _advanced_phase = (
    _compile(f) for f in (relative_margin, fit_rms, phase_rate_step, advanced_phase))


@_compile
def _decided_rows(time_s, err, best, phase, window, ready, other, alpha, state, normalized, channels,
                  confidence, fit, rate):  # pragma: no cover - compiled
    """decide's confidence, fit and phase rate for the reported mode ``best`` of each step (its
    error ``err``, the best other error ``other``); ``state`` = the phase-rate state (known, last
    time, mode, phase, rate), in place; ``alpha`` per step the smoothing weight."""
    for g in range(time_s.shape[0]):
        confidence[g] = _relative_margin(err[g], other[g])
        fit[g] = _fit_rms(err[g], window[g], normalized, channels)
        if not ready[g]:
            rate[g] = np.nan
            continue
        if state[0] > 0.0:
            state[4] = _phase_rate_step(state[4], state[1], int(state[2]), state[3], time_s[g], best[g], phase[g],
                                        alpha[g])
        state[0], state[1], state[2], state[3] = 1.0, time_s[g], best[g], phase[g]
        rate[g] = state[4]


@_compile
def _carried_rows(est_time, time_s, ready, rate, phase):  # pragma: no cover - compiled
    """``Estimate.at`` of each row: ``phase`` advanced in place."""
    for i in range(phase.shape[0]):
        dt = time_s[i] - est_time[i]
        if dt > 0.0 and ready[i] and math.isfinite(rate[i]):
            phase[i] = _advanced_phase(phase[i], rate[i], dt)
