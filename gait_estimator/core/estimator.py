"""The estimator pipeline used by the node and the offline tools alike:

    time-stamped sample -> [gap check] -> [resampling to the library rate] -> matcher
                        -> supervisor -> [personalisation] -> Estimate

``EstimatorConfig`` holds every option; ``OPTIONS`` describes them once for both the node's
parameters and the CLI's flags. Two presets: ``default`` (what works for a new wearer: rate
handling, cadence variants, offset tolerance, comparison per sample) and ``paper`` (the paper's
algorithm, which reproduces the reference implementation exactly). ``EstimatorConfig()`` is the
default preset; ``EstimatorConfig.preset("paper")`` the paper.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple

import numpy as np

from .adapt import AdaptOptions, KernelAdapter
from .channels import CHANNELS, N_CHANNELS, Sample, sample_values
from .kernels import KernelLibrary, near_duplicates
from .matcher import (
    IncrementalMatcher,
    check_channel_weights,
    check_offset_tolerance,
    check_recency_half_life,
    check_time_scales,
)
from .resample import UniformResampler
from .stride_reader import SUGGESTED_EVIDENCE_DEG2S, StrideStartReader
from .supervisor import Estimate, Supervisor, load_transitions, relative_margin

RESAMPLE_MODES = ("auto", "on", "off")
"""``resample``: ``auto`` = on when the input has time stamps (JointState stamps, a recording's
time column), off for unstamped input (timed on arrival, or by sample index)."""

DEFAULT_TIME_SCALES = (0.88, 0.92, 0.96, 1.0, 1.04, 1.08, 1.12)
RECENCY_HALF_LIFE = 0.3
OFFSET_CALIBRATION_RATE = 0.15
CADENCE_CALIBRATION_RATE = 0.1
"""Defaults of ``recency_half_life`` (strides) and of the two walking calibrations' rates: chosen by
experiments/cross_session.py (docs/new_wearer.md)."""
CALIBRATION_RESET_GAP_S = 5.0
"""Default of ``calibration_reset_gap_s``: a stream that stops this long may have had its sensors
re-donned (docs/new_wearer.md, re-donned sensors)."""
CALIBRATION_CONFIDENCE = 0.1
CALIBRATION_STEP_DEG = 5.0
CALIBRATION_MAX_DEG = 15.0
MID_STRIDE = (0.25, 0.75)
"""A heel strike ends a stride for the calibrations only if the phase was in this range since the
previous one."""
NEAR_COPY_RMS_DEG = 1.0
NEAR_COPY_LENGTH_RATIO = 0.02
"""Modes whose kernels are this close (shape RMS, degrees; |ln| of the stride-length ratio) count
as one for the calibrations (``near_duplicates``): half the offset band and the cadence band of the
defaults, so reading a stride against either copy moves the offsets and the time scale by less
than the matcher already lets pass. Without this a library holding near copies (e.g. one kernel
per ramp angle) would never give a confident stride, and would never calibrate."""
READER_FIT_GATE = 1.0
"""The stride-start reader starts a reading only at a heel strike where the reported mode fitted
the stride that ended (its RMS fit over the window) within this factor of how the wearer's
confident strides usually fit: a stride that starts a new mode follows a stride the old mode
explained, while in turns, stops or a treadmill slowing down no kernel fits the strides before
either (docs/new_wearer.md)."""
READER_SWITCH_FIT = 1.25
"""The stride-start reader's mode is reported only while its RMS fit since the heel strike is
within this factor of how the wearer's confident strides usually fit: when a walk stops (or turns),
no kernel fits the stride that starts, and the least bad one is no new mode
(experiments/reader_heldout.py, docs/new_wearer.md)."""
READER_PHASE_AGREEMENT = 0.2
"""Where the stride-start reader reports another mode, the supervised phase (the previous mode's,
over the whole window) is kept if it is within this of the reader's (time since the heel strike
over the new mode's stride), the reader's taken otherwise. The reader's own is the better on the
synthetic wearers, the supervised one on the real recordings (experiments/stride_reader.py,
docs/new_wearer.md)."""
CADENCE_MIN_STRIDES = 3
"""Confident strides the cadence calibration reads before it narrows the time scales, and the
calibrations read before recency weighting starts."""
CADENCE_SPREAD_FACTOR = 2.0
"""The band is at least this many running RMS deviations of the strides' log time scale wide on
each side: a wearer whose strides do not keep one cadence across modes and speeds (e.g. one level
kernel for every walking speed) is not narrowed."""


@dataclass(frozen=True)
class Option:
    """One estimator option, as a node parameter and a CLI flag: its default (the ``default``
    preset) and its value in the ``paper`` preset."""

    name: str
    default: Any
    description: str
    paper: Any = None

    @property
    def paper_value(self) -> Any:
        return self.default if self.paper is None else self.paper


OPTIONS: tuple[Option, ...] = (
    Option("resample", "auto", "resample the input onto the library's sample rate by linear interpolation of the "
           "stamps: auto (when the input is stamped), on, off", "off"),
    Option("time_scales", list(DEFAULT_TIME_SCALES), "stride-duration factors of the kernel variants matched per "
           "mode (cadence robustness; the chosen one gives cadence_ratio = 1/scale); [1.0] = the paper",
           [1.0]),
    Option("offset_tolerance_deg", 2.0, "per-channel difference (deg) between window and kernel means, beyond the "
           "learnt sensor offset, that costs nothing (sensor mounting); .inf = shapes only; 0 = none, as the paper",
           0.0),
    Option("offset_calibration_rate", OFFSET_CALIBRATION_RATE, "walking self-calibration of the sensor offsets: "
           "weight of one confident stride's window-vs-kernel mean difference in the running offset estimate, "
           "[0, 1]; 0 = off", 0.0),
    Option("cadence_calibration_rate", CADENCE_CALIBRATION_RATE, "walking self-calibration of the wearer's cadence: "
           "weight of one confident stride's best time scale in the running (log) scale estimate, [0, 1]; after 3 "
           "strides every mode is read only at time scales near it (speed classes at the wearer's own cadence); "
           "0 = off", 0.0),
    Option("cadence_tolerance", 0.04, "cadence calibration: relative band around the learnt time scale in which "
           "a mode may be read (0.04: 4 percent either side; wider while the strides' scales spread more; "
           "the nearest scale always counts)"),
    Option("normalize_error", True, "compare modes by mean squared error per window sample instead of SSE", False),
    Option("window_fraction", 1.0, "fraction of each stride compared, (0, 1]; 1.0 = the paper's full stride"),
    Option("recency_half_life", RECENCY_HALF_LIFE, "weight the compared samples by age: a sample's weight halves every "
           "this many strides (the newest part of the stride counts most, so a mode change shows sooner); with "
           "the walking calibrations on, from their 3rd stride on; whole-stride window only (not used with "
           "window_fraction < 1); 0 = uniform weights, as the paper", 0.0),
    Option("channels", list(CHANNELS), "channels used for matching (subset of right_thigh, left_thigh, right_shank, "
           "left_shank), e.g. [right_thigh, right_shank] for unilateral sensing"),
    Option("channel_weights", [1.0, 1.0, 1.0, 1.0], "weight of each channel in the SSE, CHANNELS order, >= 0"),
    Option("subsample_phase", False, "parabolic interpolation of the error minimum for a phase finer than 1/N"),
    Option("min_confidence", 0.0, "below this margin ((error_2nd - error_best) / error_best) hold the last "
           "confident mode; 0 = off"),
    Option("min_dwell_samples", 0, "a new mode must win this many consecutive samples before it is reported; 0 = off"),
    Option("min_dwell_s", 0.0, "a new mode must win this long (s) before it is reported; 0 = off"),
    Option("transitions", "", "YAML file of allowed transitions (allowed_transitions: {MODE: [MODE, ...]}); '' = any"),
    Option("phase_rate_tau_s", 0.2, "time constant (s) of the phase-rate smoothing"),
    Option("adapt_rate", 0.0, "online personalisation: weight of one confident stride in its mode's kernel, "
           "[0, 1]; 0 = off"),
    Option("adapt_min_confidence", 0.2, "personalisation: lowest confidence margin allowed during an adapted stride"),
    Option("adapt_max_step_deg", 5.0, "personalisation: per-sample clip (deg) of stride - kernel before weighting "
           "(one stride moves a kernel by at most adapt_rate x this)"),
    Option("switch_evidence_deg2s", 0.0, f"stride-start reader (opt-in, e.g. {SUGGESTED_EVIDENCE_DEG2S:g}): from every "
           "heel strike after a stride "
           "the reported mode fitted as well as the wearer's strides usually fit, compare the stride so far with "
           "the start of every kernel (joined to the pose at the heel strike) and report another mode once its "
           "squared error there is this much (deg^2 s) below every other's, from a quarter of its stride on and "
           "while it fits about as well as usual, so a mode change shows within the stride it starts in "
           "(allowed transitions respected; dwell and confidence holds apply to the matcher "
           "only); 0 = off"),
    Option("max_gap_s", 0.5, "a longer gap (s) between samples restarts the window (not ready until refilled); 0 = never"),
    Option("calibration_reset_gap_s", CALIBRATION_RESET_GAP_S, "a longer gap (s) between samples also forgets the "
           "learnt sensor offsets and cadence, as reset_calibration does (the sensors may have been re-donned "
           "meanwhile); 0 = never", 0.0),
)
GAP_OPTIONS = frozenset({"max_gap_s", "calibration_reset_gap_s"})
"""Options read at every update: changing them keeps the window and what was learnt."""

PRESETS: dict[str, dict[str, Any]] = {
    "default": {o.name: o.default for o in OPTIONS},
    "paper": {o.name: o.paper_value for o in OPTIONS},
}
"""Option values of each preset (lists as given in OPTIONS)."""


def _resample_mode(value: Any) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    v = str(value).strip().lower()
    aliases = {"true": "on", "false": "off", "yes": "on", "no": "off", "1": "on", "0": "off"}
    v = aliases.get(v, v)
    if v not in RESAMPLE_MODES:
        raise ValueError(f"resample must be one of {', '.join(RESAMPLE_MODES)}, got {value!r}")
    return v


@dataclass(frozen=True)
class EstimatorConfig:
    """All estimator options; see OPTIONS for their meaning. Defaults = the ``default`` preset."""

    resample: str = "auto"
    time_scales: tuple[float, ...] = DEFAULT_TIME_SCALES
    offset_tolerance_deg: float = 2.0
    offset_calibration_rate: float = OFFSET_CALIBRATION_RATE
    cadence_calibration_rate: float = CADENCE_CALIBRATION_RATE
    cadence_tolerance: float = 0.04
    normalize_error: bool = True
    window_fraction: float = 1.0
    recency_half_life: float = RECENCY_HALF_LIFE
    channels: tuple[str, ...] = CHANNELS
    channel_weights: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    subsample_phase: bool = False
    min_confidence: float = 0.0
    min_dwell_samples: int = 0
    min_dwell_s: float = 0.0
    transitions: str = ""
    phase_rate_tau_s: float = 0.2
    adapt_rate: float = 0.0
    adapt_min_confidence: float = 0.2
    adapt_max_step_deg: float = 5.0
    switch_evidence_deg2s: float = 0.0
    max_gap_s: float = 0.5
    calibration_reset_gap_s: float = CALIBRATION_RESET_GAP_S

    def __post_init__(self) -> None:
        object.__setattr__(self, "resample", _resample_mode(self.resample))
        if not (0.0 < float(self.window_fraction) <= 1.0):
            raise ValueError(f"window_fraction must be in (0, 1], got {self.window_fraction!r}")
        object.__setattr__(self, "recency_half_life", check_recency_half_life(self.recency_half_life))
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "channel_weights", tuple(float(w) for w in self.channel_weights))
        object.__setattr__(self, "time_scales", tuple(float(s) for s in check_time_scales(self.time_scales)))
        object.__setattr__(self, "offset_tolerance_deg", check_offset_tolerance(self.offset_tolerance_deg))
        unknown = [c for c in self.channels if c not in CHANNELS]
        if unknown or not self.channels:
            raise ValueError(f"channels must be a non-empty subset of {', '.join(CHANNELS)}, got {list(self.channels)}")
        check_channel_weights(self.channel_weights)
        check_channel_weights(self.effective_weights())
        for name in ("min_confidence", "min_dwell_s", "max_gap_s", "calibration_reset_gap_s", "adapt_min_confidence",
                     "switch_evidence_deg2s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, (int, float)) and v >= 0 and not math.isnan(v)):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
        dwell = self.min_dwell_samples
        if isinstance(dwell, bool) or not (isinstance(dwell, int) and dwell >= 0):
            raise ValueError(f"min_dwell_samples must be an integer >= 0, got {self.min_dwell_samples!r}")
        if not (self.phase_rate_tau_s > 0 and math.isfinite(self.phase_rate_tau_s)):
            raise ValueError(f"phase_rate_tau_s must be > 0, got {self.phase_rate_tau_s!r}")
        if not (0.0 <= self.offset_calibration_rate <= 1.0):
            raise ValueError(f"offset_calibration_rate must be in [0, 1], got {self.offset_calibration_rate!r}")
        if not (0.0 <= self.cadence_calibration_rate <= 1.0):
            raise ValueError(f"cadence_calibration_rate must be in [0, 1], got {self.cadence_calibration_rate!r}")
        if isinstance(self.cadence_tolerance, bool) or not (self.cadence_tolerance >= 0):
            raise ValueError(f"cadence_tolerance must be a number >= 0, got {self.cadence_tolerance!r}")
        if not (0.0 <= self.adapt_rate <= 1.0):
            raise ValueError(f"adapt_rate must be in [0, 1], got {self.adapt_rate!r}")
        if not (self.adapt_max_step_deg > 0 and math.isfinite(self.adapt_max_step_deg)):
            raise ValueError(f"adapt_max_step_deg must be > 0, got {self.adapt_max_step_deg!r}")

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> EstimatorConfig:
        """The options of preset ``name`` (``default`` or ``paper``), then ``overrides``."""
        if name not in PRESETS:
            raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {name!r}")
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in PRESETS[name].items()}
        return cls().with_options(**{**values, **overrides})

    @property
    def effective_recency_half_life(self) -> float:
        """recency_half_life, or 0 with a shorter window (window_fraction < 1), which it does not apply to."""
        return self.recency_half_life if self.window_fraction == 1.0 else 0.0

    def effective_weights(self) -> np.ndarray:
        """channel_weights with channels outside ``channels`` set to 0."""
        mask = np.array([c in self.channels for c in CHANNELS], dtype=np.float64)
        return np.asarray(self.channel_weights, dtype=np.float64) * mask

    def with_options(self, **values: Any) -> EstimatorConfig:
        names = {f.name for f in fields(self)}
        unknown = set(values) - names
        if unknown:
            raise ValueError(f"unknown estimator option(s): {', '.join(sorted(unknown))}")
        return replace(self, **values)

    def changed_from(self, preset: str) -> dict[str, Any]:
        """Options whose value differs from preset ``preset``."""
        base = EstimatorConfig.preset(preset)
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) != getattr(base, f.name)}

    def preset_name(self) -> str | None:
        """The preset these options equal, if any."""
        return next((p for p in PRESETS if not self.changed_from(p)), None)

    def resamples(self, stamped: bool) -> bool:
        """Whether input with (``stamped``) or without real time stamps is resampled."""
        return self.resample == "on" or (self.resample == "auto" and stamped)


class _StrideTrack(NamedTuple):
    """What the walking calibrations know of the stride in progress, after the last sample."""

    mode: int  # reported mode
    phase: float  # its phase
    passed_mid: bool  # the phase was mid-stride (MID_STRIDE) since the stride began
    began_in_mode: bool  # the stride began at a heel strike of this mode (not at a mode change)


def _margin_over(sse: np.ndarray, mode: int, rivals: np.ndarray) -> float:
    """The supervisor's confidence margin of ``mode`` against the ``rivals`` (bool mask) only
    (inf without rivals)."""
    return relative_margin(float(sse[mode]), float(sse[rivals].min()) if rivals.any() else math.inf)


class Estimator:
    """Streams time-stamped samples through gap check, resampling, matcher, supervisor and
    personalisation; every accepted sample gets exactly one estimate.

    With resampling, the matcher steps once per point of the library-rate grid the sample
    completes (none, one or several); the sample's estimate is the latest grid estimate, stamped
    with the sample's time and its phase advanced by the phase rate over the time since that grid
    point (less than one grid interval).

    Args:
        library: Kernel library (degrees).
        config: Options; default = the ``default`` preset.
        stamped: The input carries real time stamps (resolves ``resample: auto``).
        backend: Matcher step implementation (``auto``, ``numba``, ``numpy``).
    """

    def __init__(
        self, library: KernelLibrary, config: EstimatorConfig | None = None, stamped: bool = True, backend: str = "auto"
    ) -> None:
        self.library = library
        self.config = config or EstimatorConfig()
        c = self.config
        self.matcher = IncrementalMatcher(
            library,
            channel_weights=c.effective_weights(),
            time_scales=c.time_scales,
            offset_tolerance_deg=c.offset_tolerance_deg,
            normalize=c.normalize_error,
            recency_half_life=c.effective_recency_half_life,
            backend=backend,
        )
        allowed = load_transitions(c.transitions, library.mode_names) if c.transitions else None
        self.supervisor = Supervisor(
            library.mode_names,
            active_channels=self.matcher.active_channels,
            min_confidence=c.min_confidence,
            min_dwell_samples=c.min_dwell_samples,
            min_dwell_s=c.min_dwell_s,
            allowed=allowed,
            phase_rate_tau_s=c.phase_rate_tau_s,
            normalized=c.normalize_error,
            time_scales=self.matcher.time_scales,
        )
        self.reader: StrideStartReader | None = None
        if c.switch_evidence_deg2s > 0:
            self.reader = StrideStartReader(library, c.effective_weights(), c.switch_evidence_deg2s, allowed,
                                            self.matcher.backend)
        self._reader_phase = math.nan  # the supervised phase at the previous step, for its heel strikes
        self.fit_strides = 0
        self.typical_fit2 = math.nan
        """Mean squared RMS fit (deg^2) of the confident strides read so far (``fit_strides``)."""
        self.stamped = bool(stamped)
        self.resampler = UniformResampler(library.sample_rate_hz) if c.resamples(stamped) else None
        self.adapter: KernelAdapter | None = None
        if c.adapt_rate > 0:
            options = AdaptOptions(c.adapt_rate, c.adapt_min_confidence, c.adapt_max_step_deg)
            self.adapter = KernelAdapter(library, options)
            self._history = np.zeros((2 * self.matcher.max_length, N_CHANNELS))  # the last stride, however long
        self.sensor_offset_deg = np.zeros(N_CHANNELS)
        self.cadence_scale = math.nan
        """The wearer's learnt stride-duration scale (their strides last this times the kernels'); nan
        until a confident stride was read. 1 / cadence_scale is their cadence ratio."""
        self.cadence_strides = 0
        self.cadence_spread = 0.0
        """Running RMS deviation of the strides' log time scale from the learnt one."""
        self._learns_cadence = c.cadence_calibration_rate > 0 and self.matcher.n_scales > 1
        self._calibrates = c.offset_calibration_rate > 0 or self._learns_cadence  # a walking calibration is on
        self.calibration_strides = 0
        """Strides the walking calibrations have read since they (re)started."""
        self.calibration_resets = 0
        """Gaps longer than ``calibration_reset_gap_s`` that made the calibrations start again."""
        self._near_copies: np.ndarray | None = None  # (M, M) bool, when the library holds near copies
        if self._calibrates:
            near = near_duplicates(library, NEAR_COPY_RMS_DEG, NEAR_COPY_LENGTH_RATIO, c.effective_weights())
            self._near_copies = near if near.sum() > len(library) else None
        # Recency weighting waits for the calibrations: before the sensor offsets and cadence are
        # learnt, its shorter memory cannot tell the speed classes apart well enough to be confident.
        self._recency_waits = self.matcher.recency_half_life > 0 and self._calibrates
        if self._recency_waits:
            self.matcher.start_uniform()  # until the switch, which rebuilds the weighted sums from the window
        self._calib_last: _StrideTrack | None = None
        self.last_time: float | None = None
        self.resets = 0
        self._last: Estimate | None = None

    @property
    def mode_names(self) -> list[str]:
        return self.library.mode_names

    def reset(self) -> None:
        """Restart from an empty window (as after a gap); adapted kernels are kept."""
        self.matcher.reset()
        self.supervisor.reset()
        if self.resampler is not None:
            self.resampler.reset()
        if self.adapter is not None:
            self.adapter.reset()
        if self.reader is not None:
            self.reader.reset()
            self._reader_phase = math.nan
        self.last_time = None
        self._last = None

    def update(self, time_s: float, sample_deg: Sequence[float] | np.ndarray) -> Estimate:
        """Consume one sample (4 angles, degrees, CHANNELS order) stamped ``time_s`` (seconds,
        strictly increasing); return its estimate.

        Raises ValueError for a non-finite sample or a non-increasing stamp; state is unchanged.
        """
        x = sample_values(sample_deg)  # four floats: no numpy call per sample before the matcher
        if not (math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2]) and math.isfinite(x[3])
                and math.isfinite(time_s)):
            raise ValueError(f"non-finite sample {list(x)} at {time_s}")
        if self.last_time is not None and time_s <= self.last_time:
            raise ValueError(f"stamp {time_s} is not after the previous {self.last_time}")
        if self.last_time is not None:
            gap = time_s - self.last_time
            if 0 < self.config.max_gap_s < gap:
                self.reset()
                self.resets += 1
            if self._calibrates and 0 < self.config.calibration_reset_gap_s < gap:
                self.reset_calibration()
                self.calibration_resets += 1
        self.last_time = time_s
        if self.resampler is None:
            est = self._step(time_s, x)
        else:
            for t, p in self.resampler.push(time_s, x):
                self._last = self._step(t, p)
            assert self._last is not None  # the first sample of a stream is a grid point
            est = self._restamped(self._last, time_s)
        return est

    def _step(self, time_s: float, x: Sample) -> Estimate:
        result = self.matcher.step(x)
        est = self.supervisor.update(time_s, result)
        if (self._calibrates or self.reader is not None) and self._confident_stride_end(est):
            self._calibrate_stride(est, result)
        if self.adapter is not None:
            self._adapt(x, est, result)
        if self.reader is not None:
            est = self._read_stride(x, est, result)
        return est

    def _calibrate_stride(self, est: Estimate, result: Any) -> None:
        """The walking calibrations at the end of a confident stride (``_confident_stride_end``)."""
        c = self.config
        if c.offset_calibration_rate > 0:
            self._calibrate_offset(est, result)
        if self._learns_cadence:
            self._calibrate_cadence(est)
        if self._calibrates:
            self.calibration_strides += 1
        self._learn_typical_fit(est.fit_rms_deg)
        if self._recency_waits and self.calibration_strides == CADENCE_MIN_STRIDES:
            self.matcher.set_recency_half_life(c.effective_recency_half_life)

    def _read_stride(self, x: Sample, est: Estimate, result: Any) -> Estimate:
        """The stride-start reader's look at this sample: a reading starts at a heel strike of the
        supervised estimate (its phase wrapped) after a stride it fitted as well as usual
        (READER_FIT_GATE), and the reader's mode is reported where it differs."""
        reader = self.reader
        assert reader is not None
        last, self._reader_phase = self._reader_phase, est.phase if est.ready else math.nan
        if est.phase < last - 0.5:
            if est.fit_rms_deg ** 2 <= READER_FIT_GATE ** 2 * self.typical_fit2:  # False while nan
                band = self.matcher.time_scales[self.matcher.scale_band]
                bound = READER_SWITCH_FIT ** 2 * self.typical_fit2 * self.matcher.active_channels
                reader.start(x, est.mode_index, self.sensor_offset_deg, band, max_mean_error=bound)
            else:
                reader.reset()
            return est
        read = reader.step(x)
        if read is None or read[0] == est.mode_index:  # nothing to add where the matcher agrees
            return est
        m, phase, scale = read
        if abs((est.phase - phase + 0.5) % 1.0 - 0.5) < READER_PHASE_AGREEMENT:
            phase = est.phase  # the stride's phase clock goes on through the change (it is the steadier)
        sse = est.sse
        others = np.ones(sse.shape[0], dtype=bool)
        others[m] = False
        return Estimate(
            time_s=est.time_s, mode_index=m, mode=self.library.mode_names[m], phase=phase, ready=True, sse=sse,
            phases=est.phases, raw_mode_index=est.raw_mode_index, confidence=_margin_over(sse, m, others),
            fit_rms_deg=self.supervisor.fit_rms(float(sse[m]), int(result.window[m])), held=False,
            phase_rate=est.phase_rate, cadence_ratio=1.0 / scale if self.matcher.n_scales > 1 else math.nan,
        )

    def _learn_typical_fit(self, fit_rms_deg: float) -> None:
        """Running mean of the squared RMS fit of confident strides (the mean of the first ten,
        then a tenth of the way per stride): how well this wearer's strides usually fit."""
        self.fit_strides += 1
        rate = max(0.1, 1.0 / self.fit_strides)
        f2 = fit_rms_deg * fit_rms_deg
        self.typical_fit2 = f2 if self.fit_strides == 1 else self.typical_fit2 + rate * (f2 - self.typical_fit2)

    def reset_calibration(self) -> None:
        """Forget the learnt sensor offsets and cadence (e.g. after the sensors were re-donned,
        or for another wearer), and how well the wearer's strides usually fit; a stride-start
        reading in progress (at the old offsets) stops."""
        if self.reader is not None:
            self.reader.reset()
        self.fit_strides = 0
        self.typical_fit2 = math.nan
        self.sensor_offset_deg = np.zeros(N_CHANNELS)
        self.matcher.set_sensor_offset(self.sensor_offset_deg)
        self.cadence_scale = math.nan
        self.cadence_strides = 0
        self.cadence_spread = 0.0
        self.matcher.set_scale_band(None)
        self._calib_last = None
        self.calibration_strides = 0
        if self._recency_waits:
            self.matcher.start_uniform()

    def adopt_calibration(self, other: Estimator) -> None:
        """Start from the sensor offsets and cadence ``other`` has learnt (same sensors and
        wearer, new options)."""
        if self.config.offset_calibration_rate > 0 and np.any(other.sensor_offset_deg != 0):
            self.sensor_offset_deg = other.sensor_offset_deg.copy()
            self.matcher.set_sensor_offset(self.sensor_offset_deg)
        if self._learns_cadence and other.cadence_strides:
            self.cadence_scale, self.cadence_strides = other.cadence_scale, other.cadence_strides
            self.cadence_spread = other.cadence_spread
            self._narrow_scales()
        if self._calibrates:
            self.calibration_strides = other.calibration_strides
        self.fit_strides, self.typical_fit2 = other.fit_strides, other.typical_fit2
        if self._recency_waits and self.calibration_strides >= CADENCE_MIN_STRIDES:
            self.matcher.set_recency_half_life(self.config.effective_recency_half_life)

    def adopt_adaptation(self, other: Estimator) -> int:
        """Start from the kernels ``other`` has personalised (same library, new options).

        Returns:
            The number of strides ``other`` had adopted; they are kept if this estimator
            personalises too (``adapt_rate`` > 0), dropped otherwise.
        """
        theirs = other.adapter
        strides = int(theirs.accepted.sum()) if theirs is not None else 0
        mine = self.adapter
        if not strides or mine is None or other.library.mode_names != self.library.mode_names:
            return strides
        mine.adopt(theirs)
        for m in np.flatnonzero(mine.accepted):  # once per option change, not per sample
            self.matcher.set_kernel(int(m), mine.kernels[m])
            if self.reader is not None:
                self.reader.set_kernel(int(m), mine.kernels[m])
        return strides

    def _confident_stride_end(self, est: Estimate) -> bool:
        """True at a heel strike (the phase wrapped) that ends a stride reported as one mode from
        the previous heel strike on, whose phase passed mid-stride (MID_STRIDE), confident (margin
        >= CALIBRATION_CONFIDENCE) and not held: where the calibrations read. Near copies of a mode
        (NEAR_COPY_RMS_DEG) count as that mode here. A phase that
        flickers across the wrap (0.99, 0.01, 0.99, ...) ends one stride, not one per flicker; the
        stride in which the reported mode changed (a blend of two modes) is not read."""
        m, phase = est.mode_index, est.phase
        last = self._calib_last
        near = self._near_copies
        same = last is not None and (last.mode == m or (near is not None and near[last.mode, m]))
        wrapped = same and phase < last.phase - 0.5
        passed_mid = same and last.passed_mid
        whole = same and last.began_in_mode
        midway = MID_STRIDE[0] <= phase < MID_STRIDE[1] or (passed_mid and not wrapped)
        self._calib_last = _StrideTrack(m, phase, midway, wrapped or whole) if est.ready else None
        if not (wrapped and whole and passed_mid) or est.held:
            return False
        confidence = est.confidence if near is None else _margin_over(est.sse, m, ~near[m])
        return confidence >= CALIBRATION_CONFIDENCE

    def _calibrate_offset(self, est: Estimate, result: Any) -> None:
        """Move the sensor offset estimate towards this stride's window-vs-kernel mean difference."""
        m = est.mode_index
        variant = 0 if result.variant is None else int(result.variant[m])
        x = self.matcher.mean_offset(m * self.matcher.n_scales + variant, int(result.column[m]))
        step = np.clip(x - self.sensor_offset_deg, -CALIBRATION_STEP_DEG, CALIBRATION_STEP_DEG)
        self.sensor_offset_deg = np.clip(self.sensor_offset_deg + self.config.offset_calibration_rate * step,
                                         -CALIBRATION_MAX_DEG, CALIBRATION_MAX_DEG)
        self.matcher.set_sensor_offset(self.sensor_offset_deg)

    def _calibrate_cadence(self, est: Estimate) -> None:
        """Move the learnt time scale (in log) towards the reported mode's best time scale over
        all scales (not only the band), read between them (``best_log_scale``); from the
        CADENCE_MIN_STRIDES-th stride on, read every mode only near it (``_narrow_scales``). One
        wearer's strides in every mode scale alike, so the speed classes of a faster or slower
        wearer are told apart at their own cadence."""
        x = self.matcher.best_log_scale(est.mode_index)
        self.cadence_strides += 1
        if self.cadence_strides == 1:
            level, var = x, 0.0
        else:  # a running mean over the first strides, then exponential forgetting
            rate = max(self.config.cadence_calibration_rate, 1.0 / self.cadence_strides)
            mean = math.log(self.cadence_scale)
            dev = x - mean
            level = mean + rate * dev
            var = self.cadence_spread ** 2 + rate * (dev * dev - self.cadence_spread ** 2)
        self.cadence_scale = math.exp(level)
        self.cadence_spread = math.sqrt(var)
        if self.cadence_strides >= CADENCE_MIN_STRIDES:
            self._narrow_scales()

    def _narrow_scales(self) -> None:
        """Let the matcher read modes only at the time scales within cadence_tolerance, or
        CADENCE_SPREAD_FACTOR running deviations if wider, of the learnt one (always the nearest)."""
        distance = np.abs(np.log(self.matcher.time_scales / self.cadence_scale))
        half = max(math.log1p(self.config.cadence_tolerance), CADENCE_SPREAD_FACTOR * self.cadence_spread)
        band = distance <= half + 1e-12
        band[int(distance.argmin())] = True
        self.matcher.set_scale_band(band)

    @staticmethod
    def _restamped(est: Estimate, time_s: float) -> Estimate:
        dt = time_s - est.time_s
        if dt <= 0.0:
            return est
        phase = est.phase
        if est.ready and math.isfinite(est.phase_rate):
            phase = (phase + est.phase_rate * dt) % 1.0
            if phase >= 1.0:
                phase = 0.0
        return est.restamped(time_s, phase)

    # -----------------------------------------------------------------------------------------
    # Personalisation

    def _adapt(self, x: Sample, est: Estimate, result: Any) -> None:
        adapter = self.adapter
        assert adapter is not None
        step = self.matcher.steps - 1  # this sample's number since the window (re)started
        h = self._history.shape[0]
        self._history[step % h] = x
        m = est.mode_index
        start = adapter.stride_start
        if est.ready and start is not None and adapter.ends_stride(m, est.phase) and step - start <= h:
            stride = self._history[np.arange(start, step) % h]
            variant = 0 if result.variant is None else int(result.variant[m])
            new = adapter.finish_stride(m, stride, float(self.matcher.lengths[m * self.matcher.n_scales + variant]))
            if new is not None:
                self.matcher.set_kernel(m, new)
                if self.reader is not None:
                    self.reader.set_kernel(m, new)
        adapter.track(step, m, est.phase, est.held, est.confidence, est.ready)

    def adapted_library(self) -> KernelLibrary:
        """The library with the kernels as personalised so far (the original if adaptation is off)."""
        return self.adapter.adapted_library() if self.adapter is not None else self.library


@dataclass(frozen=True)
class EstimateTrace:
    """Estimates for a whole recording (T output samples, M modes)."""

    mode_names: list[str]
    time_s: np.ndarray  # (T,) seconds
    sample: np.ndarray  # (T,) source index of the latest input sample at or before time_s
    mode_index: np.ndarray  # (T,)
    phase: np.ndarray  # (T,)
    ready: np.ndarray  # (T,) bool
    sse: np.ndarray  # (T, M) deg^2 (per window sample with normalize_error)
    phases: np.ndarray  # (T, M)
    raw_mode_index: np.ndarray  # (T,)
    confidence: np.ndarray  # (T,)
    fit_rms_deg: np.ndarray  # (T,)
    held: np.ndarray  # (T,) bool
    phase_rate: np.ndarray  # (T,) strides/s
    cadence_ratio: np.ndarray  # (T,) wearer cadence / kernel cadence of the reported mode (nan: one scale)

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def modes(self) -> list[str]:
        return [self.mode_names[i] for i in self.mode_index]


def run_estimator(
    estimator: Estimator, time_s: np.ndarray, angles_deg: np.ndarray, index: np.ndarray | None = None
) -> EstimateTrace:
    """Stream a whole recording through ``estimator`` (fresh or not) and collect the estimates:
    in bulk (``core/batch.py``, the same results many times faster) where the options allow it,
    else by ``Estimator.update`` sample by sample."""
    idx = np.arange(len(time_s)) if index is None else np.asarray(index)
    from .batch import run_batch  # (batch builds on this module)

    trace = run_batch(estimator, time_s, angles_deg, idx)
    if trace is not None:
        return trace
    rows = [(int(idx[i]), estimator.update(float(time_s[i]), angles_deg[i])) for i in range(len(time_s))]
    return trace_from_estimates(estimator.mode_names, rows)


def trace_from_estimates(mode_names: Sequence[str], rows: Sequence[tuple[int, Estimate]]) -> EstimateTrace:
    """Pack (source sample index, Estimate) pairs into arrays."""
    m = len(mode_names)
    ests = [e for _, e in rows]

    def col(name: str, dtype: Any = np.float64) -> np.ndarray:
        return np.array([getattr(e, name) for e in ests], dtype=dtype)

    return EstimateTrace(
        mode_names=list(mode_names),
        time_s=col("time_s"),
        sample=np.array([i for i, _ in rows], dtype=np.int64),
        mode_index=col("mode_index", np.int64),
        phase=col("phase"),
        ready=col("ready", bool),
        sse=np.array([e.sse for e in ests]).reshape(-1, m),
        phases=np.array([e.phases for e in ests]).reshape(-1, m),
        raw_mode_index=col("raw_mode_index", np.int64),
        confidence=col("confidence"),
        fit_rms_deg=col("fit_rms_deg"),
        held=col("held", bool),
        phase_rate=col("phase_rate"),
        cadence_ratio=col("cadence_ratio"),
    )


# ---------------------------------------------------------------------------------------------
# Command-line flags for the options (the node declares the same OPTIONS as parameters)


def add_estimator_arguments(parser: Any, skip: Sequence[str] = ("max_gap_s",)) -> None:
    """Add ``--preset`` and one flag per OPTIONS entry not in ``skip`` (``--window-fraction`` ...)
    to ``parser``; absent flags take the preset's value."""
    group = parser.add_argument_group("estimator options (default: the 'default' preset)")
    group.add_argument("--preset", choices=tuple(PRESETS), default="default",
                       help="option values to start from: default (robust for a new wearer) or paper (the paper's "
                       "algorithm, reproduces the reference implementation); the flags below override it")
    for opt in OPTIONS:
        if opt.name in skip:
            continue
        flag = "--" + opt.name.replace("_", "-")
        if opt.name == "resample":
            group.add_argument(flag, dest=opt.name, nargs="?", const="on", choices=RESAMPLE_MODES, help=opt.description)
        elif isinstance(opt.default, bool):
            group.add_argument(flag, dest=opt.name, action=argparse.BooleanOptionalAction, default=None,
                               help=opt.description)
        elif isinstance(opt.default, list):
            kind = float if isinstance(opt.default[0], float) else str
            group.add_argument(flag, dest=opt.name, nargs="+", type=kind, metavar="V", help=opt.description)
        else:
            group.add_argument(flag, dest=opt.name, type=type(opt.default), metavar="V", help=opt.description)


def config_from_args(args: Any, **overrides: Any) -> EstimatorConfig:
    """EstimatorConfig from parsed flags: the ``--preset``'s values, then the flags given, then
    ``overrides`` (None values ignored); raises ValueError."""
    values: dict[str, Any] = {}
    for opt in OPTIONS:
        v = getattr(args, opt.name, None)
        if v is not None:
            values[opt.name] = tuple(v) if isinstance(v, list) else v
    values.update({k: v for k, v in overrides.items() if v is not None})
    return EstimatorConfig.preset(getattr(args, "preset", None) or "default", **values)


def config_from_values(values: Mapping[str, Any], preset: str = "default") -> EstimatorConfig:
    """EstimatorConfig from option values by name (lists become tuples) on top of ``preset``."""
    return EstimatorConfig.preset(preset, **{k: tuple(v) if isinstance(v, (list, tuple)) else v for k, v in values.items()})
