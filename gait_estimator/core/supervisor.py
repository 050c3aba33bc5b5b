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

``supervise_step`` is the decision, on Python floats for ``Supervisor.decide`` (one matcher
result) and compiled for ``Supervisor.decide_many`` (a run of them, offline: ``batch.py``) and
inside the compiled matcher steps (``Supervisor.step_hook``); the hold and dwell rule is
``choose_mode``. Every option off (the defaults) reports the matcher's
choice unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

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
        held: True while the reported mode is held (low confidence, dwell pending, switch-back margin).
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
        self._settings = (self.min_confidence, self.min_dwell_s, self.phase_rate_tau_s, self.normalized,
                          int(active_channels), self.switch_back_margin)
        self.reset()

    @property
    def passes_through(self) -> bool:
        """Every option off: the reported mode is the matcher's choice."""
        return self.min_confidence == 0 and self.min_dwell_s == 0 and self.switch_back_margin == 0 and self.allowed is None

    def reset(self) -> None:
        self._mem: list[float] = list(INITIAL_MEMORY)

    def decide(self, time_s: float, result: StepResult) -> Estimate:
        """The reported mode and phase for one matcher result at ``time_s`` (seconds): the
        allowed candidate, held while unconfident or dwelling, with that mode's phase."""
        sse = result.sse
        values = sse.tolist()  # Python floats from here on: per-sample numpy calls are costly when cold
        m = len(values)  # the second smallest error: a sort of a short list beats np.partition here
        second = math.inf if m < 2 else sorted(values)[1] if m <= 64 else float(np.partition(sse, 1)[1])
        reported, held, confidence, fit, phase, rate = supervise_step(
            self._mem, time_s, values, sse, result.mode_index, second, result.phase, result.phases, result.window,
            result.ready, self.allowed, self._settings)
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
        """``decide`` for a run of matcher steps at ``time_s`` (G,), seconds, in one compiled loop:
        the fields of their estimates as columns (G,) or (G, M), the state left as ``decide``
        leaves it."""
        hook = self.step_hook(time_s)
        _supervised_rows(hook.args, steps.sse, steps.best, steps.phases, steps.window, steps.ready)
        return self.columns(hook, 0, time_s.shape[0], steps)

    def step_hook(self, time_s: np.ndarray) -> compiled.StepHook:
        """``decide`` inside compiled matcher steps at ``time_s`` (G,), seconds
        (``IncrementalMatcher.run_steps``), from the supervisor's state on; ``columns`` reads
        the results."""
        n = time_s.shape[0]
        confidence, fit, phase, rate = np.empty((4, n))
        rows = SupervisedRows(np.asarray(self._mem, dtype=np.float64), time_s, self.allowed, self._settings,
                              np.empty(n, dtype=np.int64), np.empty(n, dtype=bool), confidence, fit, phase, rate)
        return compiled.StepHook(SUPERVISED_STEPS, rows)

    def columns(self, hook: compiled.StepHook, start: int, stop: int, steps: StepBlock) -> dict[str, np.ndarray]:
        """``decide_many``'s columns of the steps ``start`` .. ``stop`` - 1 decided in ``hook``
        (``step_hook``), ``steps`` their matcher results; the state left as ``decide`` leaves it
        after the last step decided."""
        rows: SupervisedRows = hook.args
        self._mem = rows.mem.tolist()
        s = slice(start, stop)
        reported = rows.reported[s]
        variant = np.take_along_axis(steps.variant, reported[:, None], axis=1)[:, 0]
        cadence = np.asarray(self._inverse_scales)[variant] if steps.n_scales > 1 else np.full(stop - start, math.nan)
        return {
            "time_s": rows.time_s[s], "mode_index": reported, "phase": rows.phase[s], "ready": steps.ready,
            "sse": steps.sse, "phases": steps.phases, "raw_mode_index": steps.best, "confidence": rows.confidence[s],
            "fit_rms_deg": rows.fit[s], "held": rows.held[s], "phase_rate": rows.rate[s], "cadence_ratio": cadence,
        }


class SupervisedRows(NamedTuple):
    """``supervise_step`` run inside the compiled matcher steps (``Supervisor.step_hook``): its
    memory (laid out as INITIAL_MEMORY), the steps' times (s), its options, and per step its results."""

    mem: np.ndarray
    time_s: np.ndarray
    allowed: np.ndarray | None
    settings: tuple[float, float, float, bool, int, float]
    reported: np.ndarray
    held: np.ndarray
    confidence: np.ndarray
    fit: np.ndarray
    phase: np.ndarray
    rate: np.ndarray


INITIAL_MEMORY = (-1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, math.nan, math.nan, 0.0, -1.0)
"""supervise_step's memory, as it starts: the current mode (-1: none yet), the pending mode (-1: none) and since
when; the last ready step (known, time, mode, phase); the phase rate; the last interval between
ready steps and its smoothing weight; the mode reported before the current one (-1: none)."""


def supervise_step(mem: Any, time_s: float, values: Any, sse: np.ndarray, argmin: int, second: float, best_phase: float,
                   phases: np.ndarray, window: np.ndarray, ready: bool, allowed: np.ndarray | None,
                   settings: tuple[float, float, float, bool, int, float]) -> tuple[int, bool, float, float, float, float]:
    """The supervisor's decision on one matcher step at ``time_s`` (s): errors ``sse`` (M,)
    (``values``: the same as a list, or the array), their ``argmin`` and ``second`` smallest
    (inf with one mode), the argmin's phase ``best_phase``, every mode's ``phases`` and
    ``window``; ``allowed`` (M, M) the transitions (None: any); ``settings`` = (min_confidence,
    min_dwell_s, phase_rate_tau_s, normalized, active channels, switch_back_margin); ``mem`` (laid
    out as INITIAL_MEMORY) updated in place. Returns the reported mode, held, confidence, fit (deg
    RMS), phase and phase rate: moved by 1 - exp(-dt / tau) towards the phase change over the dt
    since the last ready step if that reported the same mode (the first such reading sets it),
    else unchanged."""
    min_confidence, min_dwell_s, tau, normalized, channels, margin = settings
    candidate = argmin
    if allowed is not None and mem[0] >= 0.0:
        candidate = int(np.argmin(np.where(allowed[int(mem[0])], sse, math.inf)))
    kept = False
    if ready and margin > 0.0 and mem[0] >= 0.0:
        chosen = switch_candidate(values, int(mem[0]), int(mem[10]), candidate, margin)
        candidate, kept = chosen, chosen != candidate
    confidence = relative_margin(values[candidate], second if candidate == argmin else values[argmin])
    reported, held = candidate, False
    if ready:
        reported, held = choose_mode(mem, time_s, candidate, confidence, min_confidence, min_dwell_s)
        held = held or kept
    error = values[reported]  # the RMS error per sample and channel:
    fit = math.sqrt((0.0 if error < 0.0 else error) / (1 if normalized else max(int(window[reported]), 1)) / channels)
    phase = best_phase if reported == argmin else float(phases[reported])
    if not ready:
        return reported, held, confidence, fit, phase, math.nan
    if mem[3] > 0.0 and int(mem[5]) == reported and time_s > mem[4]:  # the phase change since the last ready step
        dt = time_s - mem[4]
        if dt != mem[8]:  # resampled input repeats one interval
            mem[8], mem[9] = dt, 1.0 - math.exp(-dt / tau) if tau > 0 else 1.0
        inst = ((phase - mem[6] + 0.5) % 1.0 - 0.5) / dt
        mem[7] = inst if math.isnan(mem[7]) else mem[7] + mem[9] * (inst - mem[7])
    mem[3], mem[4], mem[5], mem[6] = 1.0, time_s, reported, phase
    return reported, held, confidence, fit, phase, mem[7]


def choose_mode(mem: Any, time_s: float, candidate: int, confidence: float, min_confidence: float,
                min_dwell_s: float) -> tuple[int, bool]:
    """The reported mode of a ready step and whether it is held: the current one (``mem[0]``)
    while the ``candidate``'s ``confidence`` is below ``min_confidence``, or until the candidate
    has been pending (``mem[1]``, since ``mem[2]``) for ``min_dwell_s`` seconds."""
    low = min_confidence > 0 and confidence < min_confidence
    current = int(mem[0])
    if current < 0:
        mem[0] = candidate
        return candidate, low
    if low:
        mem[1] = -1.0
        return current, True
    if candidate == current:
        mem[1] = -1.0
        return candidate, False
    if candidate != int(mem[1]):
        mem[1], mem[2] = candidate, time_s
    if time_s - mem[2] >= min_dwell_s - 1e-9:
        mem[10], mem[0], mem[1] = current, candidate, -1.0
        return candidate, False
    return current, True


def switch_candidate(errors: Any, current: int, previous: int, candidate: int, margin: float) -> int:
    """The mode to follow: ``candidate``, unless it is the ``previous`` mode (reported before
    ``current``; -1: none) and its error is not below (1 - ``margin``) x the current mode's
    (``errors`` per mode): two close modes then do not take turns on noise, and a change to a
    third is not delayed."""
    if candidate != previous or errors[candidate] < (1.0 - margin) * errors[current]:
        return candidate
    return current


def relative_margin(own: float, best_other: float) -> float:
    """The confidence margin (best_other - own) / own of an error ``own`` over the best other
    ``best_other`` (inf when own is 0 and the other is not, 0 when both are)."""
    if own <= 0.0:
        return math.inf if best_other > 0 else 0.0
    return (best_other - own) / own


def second_smallest(values: np.ndarray) -> float:
    """The second smallest of ``values`` as ``np.partition(values, 1)[1]`` finds it (nan sorts
    last), inf with fewer than two."""
    lo = hi = math.inf
    known = 0
    for v in values:
        if v < lo:
            lo, hi = v, lo
        elif v < hi:
            hi = v
        known += 0 if math.isnan(v) else 1
    return hi if known >= 2 or values.shape[0] < 2 else math.nan


def advanced_phase(phase: float, rate: float, dt: float) -> float:
    """``phase`` advanced at ``rate`` (strides/s) over ``dt`` seconds, wrapped to [0, 1)."""
    phase = (phase + rate * dt) % 1.0
    return 0.0 if phase >= 1.0 else phase


_compile = compiled.njit(cache=True, nogil=True)
_advanced_phase = _compile(advanced_phase)
_second_smallest = _compile(second_smallest)
_choose_mode = compiled.compiled_copy(choose_mode, "_choose_mode")
_supervise_step = compiled.compiled_copy(supervise_step, "_supervise_step", choose_mode=_choose_mode,
                                         relative_margin=_compile(relative_margin),
                                         switch_candidate=_compile(switch_candidate))


@compiled.njit(cache=True, nogil=True, inline="always")
def _report_supervised(hook, g, best, sse, phases, window, ready):  # pragma: no cover - compiled
    """``supervise_step`` on matcher step ``g`` (``compiled.report_step``'s arguments), its results
    into row g of the outputs in ``hook`` (``Supervisor.step_hook``); the reported mode and phase."""
    m, hook.held[g], hook.confidence[g], hook.fit[g], p, hook.rate[g] = _supervise_step(
        hook.mem, hook.time_s[g], sse, sse, best, _second_smallest(sse), phases[best], phases, window, ready, hook.allowed,
        hook.settings)
    hook.reported[g], hook.phase[g] = m, p
    return m, p


SUPERVISED_STEPS = compiled.step_loops(_report_supervised, "run_supervised_steps")
"""The compiled matcher steps with the supervisor's decision at each step (``Supervisor.step_hook``)."""


@_compile
def _supervised_rows(hook, sse, best, phases, window, ready):  # pragma: no cover - compiled
    """``supervise_step`` of each step g (``Supervisor.step_hook``'s outputs) of the matcher results (G, M)."""
    for g in range(sse.shape[0]):
        _report_supervised(hook, g, best[g], sse[g], phases[g], window[g], ready[g])


@_compile
def _carried_rows(est_time, time_s, ready, rate, phase):  # pragma: no cover - compiled
    """``Estimate.at`` of each row: ``phase`` advanced in place."""
    for i in range(phase.shape[0]):
        dt = time_s[i] - est_time[i]
        if dt > 0.0 and ready[i] and math.isfinite(rate[i]):
            phase[i] = _advanced_phase(phase[i], rate[i], dt)
