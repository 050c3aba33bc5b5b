"""Walking self-calibration: what the estimator learns about the wearer's sensors and cadence
from the strides it reports confidently.

At a heel strike that ends a confidently reported stride (``WalkingCalibration.observe``):

* sensor offsets: the window-vs-kernel mean difference of the reported mode moves the learnt
  per-channel offsets (clipped steps); the matcher measures mean differences from them;
* cadence: the reported mode's best time scale (read between the matcher's scales) moves the
  learnt (log) scale; from ``cadence_min_strides`` strides on every mode is read only at scales
  near it, so speed classes are told apart at the wearer's own cadence (before, at the scale
  nearest 1, and the ``scale_search_modes`` best-fitting modes at every scale);
* typical fit: a running mean of the squared RMS fit of those strides;
* recency weighting (the matcher's ``recency_half_life``) starts after ``recency_after_strides``
  strides: before the offsets and cadence are learnt its shorter memory cannot tell the speed
  classes apart well enough to be confident.

Modes whose kernels are near copies (``near_copy_rms_deg``, ``near_copy_length_ratio``: half the
default offset band and the cadence band) count as one mode here: reading a stride against either
copy moves the offsets and scale by less than the matcher already lets pass, and a library of near
copies (e.g. one kernel per ramp angle) would otherwise never give a confident stride.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .channels import N_CHANNELS
from .kernels import KernelLibrary, near_duplicates
from .matcher import IncrementalMatcher, StepResult
from .options import EstimatorConfig
from .stride_track import stride_step
from .supervisor import Estimate, relative_margin


@dataclass(frozen=True)
class CalibrationParams:
    """Walking calibration settings: the first three are options, the rest tuning.

    Attributes:
        offset_rate: Weight of one confident stride in the sensor offsets, [0, 1]; 0 = off.
        cadence_rate: Weight of one confident stride's time scale, [0, 1]; 0 = off.
        cadence_tolerance: Relative band around the learnt time scale in which modes are read.
        confidence: Lowest confidence margin of a stride the calibrations read.
        step_deg: Largest offset step (deg) one stride can suggest, before weighting.
        max_offset_deg: Largest learnt offset (deg).
        mid_stride: A heel strike ends a stride only if the phase was in this range since the
            previous one.
        near_copy_rms_deg: Shape RMS (deg) within which kernels are near copies.
        near_copy_length_ratio: |ln| of the stride-length ratio within which kernels are near copies.
        cadence_min_strides: Strides read before the time scales are narrowed.
        spread_factor: The band is at least this many running RMS deviations of the strides'
            log time scale wide on each side.
        typical_fit_rate: Smallest weight of one stride in the typical fit.
        recency_after_strides: Strides read before recency weighting starts; 0 = from the start.
        scale_search_modes: Until the cadence is learnt, the modes matched at every time scale
            (those that fit best at the scale nearest 1; the others at that scale only).
    """

    offset_rate: float = EstimatorConfig.offset_calibration_rate
    cadence_rate: float = EstimatorConfig.cadence_calibration_rate
    cadence_tolerance: float = EstimatorConfig.cadence_tolerance
    confidence: float = 0.1
    step_deg: float = 5.0
    max_offset_deg: float = 15.0
    mid_stride: tuple[float, float] = (0.25, 0.75)
    near_copy_rms_deg: float = 1.0
    near_copy_length_ratio: float = 0.02
    cadence_min_strides: int = 3
    spread_factor: float = 2.0
    typical_fit_rate: float = 0.1
    recency_after_strides: int = 3
    scale_search_modes: int = 3


class _StrideTrack(NamedTuple):
    """What the calibrations know of the stride in progress, after the last sample."""

    mode: int  # reported mode
    phase: float  # its phase
    passed_mid: bool  # the phase was mid-stride since the stride began
    began_in_mode: bool  # the stride began at a heel strike of this mode (not at a mode change)


def _margin_over(sse: np.ndarray, mode: int, rivals: np.ndarray) -> float:
    """The supervisor's confidence margin of ``mode`` against the ``rivals`` (bool mask) only
    (inf without rivals)."""
    return relative_margin(float(sse[mode]), float(sse[rivals].min()) if rivals.any() else math.inf)


class WalkingCalibration:
    """Learns sensor offsets, cadence and typical fit from confident strides (module docstring)
    and sets them on ``matcher``.

    Args:
        library: The kernel library (for its near copies).
        matcher: The matcher to calibrate.
        params: Rates and tuning.
        channel_weights: The matcher's channel weights (CHANNELS order).
    """

    def __init__(self, library: KernelLibrary, matcher: IncrementalMatcher, params: CalibrationParams,
                 channel_weights: np.ndarray) -> None:
        self.matcher = matcher
        self.params = params
        self.learns_offsets = params.offset_rate > 0
        self.learns_cadence = params.cadence_rate > 0 and matcher.n_scales > 1
        self.active = self.learns_offsets or self.learns_cadence
        self.near_copies: np.ndarray | None = None  # (M, M) bool, when the library holds near copies
        if self.active:
            near = near_duplicates(library, params.near_copy_rms_deg, params.near_copy_length_ratio, channel_weights)
            self.near_copies = near if near.sum() > len(library) else None
        self.half_life = matcher.recency_half_life
        self.recency_waits = self.half_life > 0 and self.active and params.recency_after_strides > 0
        self.reset()

    def reset(self) -> None:
        """Forget the learnt sensor offsets, cadence and typical fit (e.g. after the sensors were
        re-donned, or for another wearer); recency weighting waits again."""
        self.strides = 0
        """Strides read since the calibrations (re)started."""
        self.fit_strides = 0
        self.typical_fit2 = math.nan
        """Mean squared RMS fit (deg^2) of the confident strides read so far (``fit_strides``)."""
        self.sensor_offset_deg = np.zeros(N_CHANNELS)
        self.matcher.set_sensor_offset(self.sensor_offset_deg)
        self.cadence_scale = math.nan
        """The wearer's learnt stride-duration scale (their strides last this times the kernels');
        nan until a confident stride was read. 1 / cadence_scale is their cadence ratio."""
        self.cadence_strides = 0
        self.cadence_spread = 0.0
        """Running RMS deviation of the strides' log time scale from the learnt one."""
        self.matcher.set_scale_band(*self._start_band())
        self._last: _StrideTrack | None = None
        if self.recency_waits:
            self.matcher.start_uniform()  # until the switch, which rebuilds the weighted sums from the window

    def adopt(self, other: WalkingCalibration) -> None:
        """Start from what ``other`` has learnt (same sensors and wearer, new options)."""
        if self.learns_offsets and np.any(other.sensor_offset_deg != 0):
            self.sensor_offset_deg = other.sensor_offset_deg.copy()
            self.matcher.set_sensor_offset(self.sensor_offset_deg)
        if self.learns_cadence and other.cadence_strides:
            self.cadence_scale, self.cadence_strides = other.cadence_scale, other.cadence_strides
            self.cadence_spread = other.cadence_spread
            if self.cadence_strides >= self.params.cadence_min_strides:
                self._narrow_scales()
        if self.active:
            self.strides = other.strides
        self.fit_strides, self.typical_fit2 = other.fit_strides, other.typical_fit2
        if self.recency_waits and self.strides >= self.params.recency_after_strides:
            self.matcher.set_recency_half_life(self.half_life)

    def observe(self, est: Estimate, result: StepResult) -> None:
        """Read the stride that ``est`` ends, if it ends a confident one (only while ``active``)."""
        if not self._confident_stride_end(est):
            return
        if self.learns_offsets:
            self._calibrate_offset(est, result)
        if self.learns_cadence:
            self._calibrate_cadence(est)
        self.strides += 1
        self._learn_typical_fit(est.fit_rms_deg)
        if self.recency_waits and self.strides == self.params.recency_after_strides:
            self.matcher.set_recency_half_life(self.half_life)

    def stride_state(self) -> np.ndarray:
        """The stride tracker's state after the last sample, as the compiled steps advance it
        (``IncrementalMatcher.run_steps``): (known, mode, phase, passed_mid, began_in_mode)."""
        last = self._last
        if last is None:
            return np.zeros(5)
        return np.array([1.0, last.mode, last.phase, float(last.passed_mid), float(last.began_in_mode)])

    def set_stride_state(self, state: np.ndarray) -> None:
        """Take the stride tracker's state in the form ``stride_state`` gives."""
        known, mode, phase, passed_mid, began_in_mode = state.tolist()
        self._last = _StrideTrack(int(mode), phase, passed_mid > 0, began_in_mode > 0) if known > 0 else None

    def _confident_stride_end(self, est: Estimate) -> bool:
        """True at a heel strike (the phase wrapped) that ends a stride reported as one mode (near
        copies count as one) from the previous heel strike on, whose phase passed mid-stride,
        confident and not held. A phase that flickers across the wrap (0.99, 0.01, 0.99, ...) ends
        one stride, not one per flicker; the stride in which the reported mode changed (a blend of
        two modes) is not read."""
        m, phase = est.mode_index, est.phase
        last = self._last
        near = self.near_copies
        if last is None:
            ends, midway, began = stride_step(False, 0.0, False, False, phase, self.params.mid_stride)
        else:
            same = last.mode == m or (near is not None and near[last.mode, m])
            ends, midway, began = stride_step(same, last.phase, last.passed_mid, last.began_in_mode, phase,
                                              self.params.mid_stride)
        self._last = _StrideTrack(m, phase, midway, began) if est.ready else None
        if not ends or est.held:
            return False
        confidence = est.confidence if near is None else _margin_over(est.sse, m, ~near[m])
        return confidence >= self.params.confidence

    def _calibrate_offset(self, est: Estimate, result: StepResult) -> None:
        """Move the sensor offsets towards this stride's window-vs-kernel mean difference."""
        m, p = est.mode_index, self.params
        variant = 0 if result.variant is None else int(result.variant[m])
        assert result.column is not None
        x = self.matcher.mean_offset(self.matcher.row_of(m, variant), int(result.column[m]))
        step = np.clip(x - self.sensor_offset_deg, -p.step_deg, p.step_deg)
        self.sensor_offset_deg = np.clip(self.sensor_offset_deg + p.offset_rate * step,
                                         -p.max_offset_deg, p.max_offset_deg)
        self.matcher.set_sensor_offset(self.sensor_offset_deg)

    def _calibrate_cadence(self, est: Estimate) -> None:
        """Move the learnt (log) time scale towards the reported mode's best one over all scales
        (read between them: ``best_log_scale``); from ``cadence_min_strides`` on, narrow."""
        x = self.matcher.best_log_scale(est.mode_index)
        self.cadence_strides += 1
        if self.cadence_strides == 1:
            level, var = x, 0.0
        else:  # a running mean over the first strides, then exponential forgetting
            rate = max(self.params.cadence_rate, 1.0 / self.cadence_strides)
            mean = math.log(self.cadence_scale)
            dev = x - mean
            level = mean + rate * dev
            var = self.cadence_spread ** 2 + rate * (dev * dev - self.cadence_spread ** 2)
        self.cadence_scale = math.exp(level)
        self.cadence_spread = math.sqrt(var)
        if self.cadence_strides >= self.params.cadence_min_strides:
            self._narrow_scales()

    def _start_band(self) -> tuple[np.ndarray | None, int]:
        """The scale band until the cadence is learnt: the scale nearest 1, and every scale for
        the ``scale_search_modes`` best-fitting modes (every scale for all without cadence
        learning)."""
        if not self.learns_cadence:
            return None, 0
        distance = np.abs(np.log(self.matcher.time_scales))
        band = np.zeros(distance.size, dtype=bool)
        band[int(distance.argmin())] = True
        return band, self.params.scale_search_modes

    def _narrow_scales(self) -> None:
        """Read modes only at the time scales within cadence_tolerance, or spread_factor running
        deviations if wider, of the learnt one (always the nearest)."""
        distance = np.abs(np.log(self.matcher.time_scales / self.cadence_scale))
        half = max(math.log1p(self.params.cadence_tolerance), self.params.spread_factor * self.cadence_spread)
        band = distance <= half + 1e-12
        band[int(distance.argmin())] = True
        self.matcher.set_scale_band(band)

    def _learn_typical_fit(self, fit_rms_deg: float) -> None:
        """Running mean of the squared RMS fit of confident strides (the mean of the first ones,
        then ``typical_fit_rate`` of the way per stride)."""
        self.fit_strides += 1
        rate = max(self.params.typical_fit_rate, 1.0 / self.fit_strides)
        f2 = fit_rms_deg * fit_rms_deg
        self.typical_fit2 = f2 if self.fit_strides == 1 else self.typical_fit2 + rate * (f2 - self.typical_fit2)
