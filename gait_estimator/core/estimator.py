"""The estimator pipeline used by the node and the offline tools alike. One input sample goes

    GapCheck (gaps.py)               checks the sample and its stamp; a gap restarts the window
      -> UniformResampler            onto the library's clock (none, one or several grid samples)
      -> IncrementalMatcher          error of every mode at every shift (matcher.py)
      -> Supervisor.decide           THE decision: reported mode and phase (supervisor.py)
      -> StateTracker.step           not ready, walking, stand or unknown (states.py)
      -> WalkingCalibration          learns sensor offsets and cadence from the decision
      -> Personaliser                (adapt_rate > 0) pulls the reported mode's kernel to the wearer
      -> Estimate                    the supervisor's, in its state (the learning stages see it before)

``EstimatorConfig`` (options.py) holds the options, ``PipelineParams`` (pipeline.py) each stage's
parameters derived from them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from .adapt import KernelAdapter, Personaliser
from .calibration import WalkingCalibration
from .channels import Sample, sample_values
from .gaps import NO_GAP, GapCheck, GapParams, GapVerdict
from .kernels import KernelLibrary
from .options import (  # noqa: F401  (re-exported: the options live beside the pipeline for its users)
    DEFAULT_TIME_SCALES,
    GAP_OPTIONS,
    OPTIONS,
    PRESETS,
    RESAMPLE_MODES,
    EstimatorConfig,
    Option,
    config_from_values,
)
from .pipeline import PipelineParams
from .resample import UniformResampler
from .states import StateTracker
from .supervisor import Estimate, Supervisor


class Estimator:
    """Streams time-stamped samples through the pipeline (module docstring); every accepted
    sample gets exactly one estimate.

    With resampling, the matcher steps once per point of the library-rate grid the sample
    completes (none, one or several); the sample's estimate is the latest grid estimate carried
    forward to the sample's time (``Estimate.at``: its phase advanced by the phase rate over less
    than one grid interval).

    Args:
        library: Kernel library (degrees).
        config: Options; default = the ``default`` preset.
        stamped: The input carries real time stamps (resolves ``resample: auto``).
        backend: Matcher step implementation (``auto``, ``numba``, ``numpy``).
        params: The stages' parameters; default ``PipelineParams.from_config(config)`` (give it to
            change a tuning constant).
    """

    def __init__(self, library: KernelLibrary, config: EstimatorConfig | None = None, stamped: bool = True,
                 backend: str = "auto", params: PipelineParams | None = None) -> None:
        self.library = library
        self.config = config or EstimatorConfig()
        self.params = p = params or PipelineParams.from_config(self.config)
        self.stamped = bool(stamped)
        self.gaps = GapCheck(p.gaps)
        self.resampler = UniformResampler(library.sample_rate_hz) if self.config.resamples(self.stamped) else None
        self.matcher = p.match.build(library, backend)
        self.supervisor = Supervisor(library.mode_names, p.supervisor, active_channels=self.matcher.active_channels,
                                     normalized=p.match.normalize, time_scales=self.matcher.time_scales)
        self.calibration = WalkingCalibration(library, self.matcher, p.calibration, np.asarray(p.match.channel_weights))
        self.personaliser = Personaliser(library, p.adapt, self.matcher) if p.adapt.rate > 0 else None
        self.states = StateTracker(library, p.states, np.asarray(p.match.channel_weights))
        self.resets = 0
        """Window restarts caused by gaps longer than ``max_gap_s``."""
        self.calibration_resets = 0
        """Gaps longer than ``calibration_reset_gap_s`` that made the calibrations start again."""
        self.last_gap: GapVerdict = NO_GAP
        """What the gap before the last accepted sample did (``GapCheck``): the window restarted,
        the calibrations reset."""
        self.grid_estimate: Estimate | None = None
        """With resampling, the latest grid estimate (the one carried forward to input samples)."""

    @property
    def mode_names(self) -> list[str]:
        return self.library.mode_names

    @property
    def adapter(self) -> KernelAdapter | None:
        """The personalisation's kernels and stride counts (None with ``adapt_rate`` 0)."""
        return self.personaliser.adapter if self.personaliser is not None else None

    @property
    def sensor_offset_deg(self) -> np.ndarray:
        """The learnt sensor offsets (4,), degrees, CHANNELS order."""
        return self.calibration.sensor_offset_deg

    @property
    def cadence_scale(self) -> float:
        """The wearer's learnt stride-duration scale (nan until learnt); cadence ratio = 1 / it."""
        return self.calibration.cadence_scale

    @property
    def last_time(self) -> float | None:
        """Stamp (s) of the last accepted sample, None after a reset."""
        return self.gaps.last_time

    def update(self, time_s: float, sample_deg: Sequence[float] | np.ndarray) -> Estimate:
        """Consume one sample (4 angles, degrees, CHANNELS order) stamped ``time_s`` (seconds,
        strictly increasing); return its estimate.

        Raises ValueError for a non-finite sample or a non-increasing stamp; state is unchanged.
        """
        x = sample_values(sample_deg)  # four floats: no numpy call per sample before the matcher
        gap = self.gaps.admit(time_s, x)
        self.last_gap = gap if gap is NO_GAP else self.on_gap(gap)
        if self.resampler is None:
            return self._step(time_s, x)
        for t, p in self.resampler.push(time_s, x):
            self.grid_estimate = self._step(t, p)
        assert self.grid_estimate is not None  # the first sample of a stream is a grid point
        return self.grid_estimate.at(time_s)

    def on_gap(self, gap: GapVerdict) -> GapVerdict:
        """Do what a gap in the stamps asks (``GapCheck``): restart the window, forget the
        calibrations (when they learn); returns what was done."""
        if gap.restart_window:
            self._restart_window()
            self.resets += 1
        recalibrated = gap.reset_calibration and self.calibration.active
        if recalibrated:
            self.calibration.reset()
            self.calibration_resets += 1
        return gap if recalibrated == gap.reset_calibration else GapVerdict(gap.restart_window, False)

    def _step(self, time_s: float, x: Sample) -> Estimate:
        """One sample on the library's clock through matcher, supervisor and the learning stages."""
        result = self.matcher.step(x)
        est = self.supervisor.decide(time_s, result)
        if self.calibration.active:
            self.calibration.observe(est, result)
        if self.personaliser is not None:
            self.personaliser.observe(x, est, result)
        return self.states.step(time_s, x, est)

    # -----------------------------------------------------------------------------------------
    # Restarts and option changes

    def reset(self) -> None:
        """Restart from an empty window (as after a gap); what was learnt is kept."""
        self._restart_window()
        self.gaps.reset()

    def _restart_window(self) -> None:
        self.matcher.reset()
        self.supervisor.reset()
        self.states.reset()
        if self.resampler is not None:
            self.resampler.reset()
        if self.personaliser is not None:
            self.personaliser.adapter.reset()
        self.grid_estimate = None

    def reset_calibration(self) -> None:
        """Forget the learnt sensor offsets and cadence (after the sensors were re-donned, or for
        another wearer)."""
        self.calibration.reset()

    def pause_adaptation(self, paused: bool) -> None:
        """``paused`` True: personalisation (``adapt_rate`` > 0) adopts no stride until called with
        False; for input angles not known to be right yet (an IMU calibration not yet checked)."""
        if self.personaliser is not None:
            self.personaliser.paused = paused

    def set_gap_options(self, config: EstimatorConfig) -> None:
        """Take ``config``, which differs from this estimator's only in GAP_OPTIONS: keeps the
        window and what was learnt."""
        self.config = config
        self.gaps.params = GapParams(config.max_gap_s, config.calibration_reset_gap_s)

    def adopt_calibration(self, other: Estimator) -> None:
        """Start from the sensor offsets and cadence ``other`` has learnt (same sensors and
        wearer, new options)."""
        self.calibration.adopt(other.calibration)

    def adopt_adaptation(self, other: Estimator) -> int:
        """Start from the kernels ``other`` has personalised (same library, new options).

        Returns:
            The number of strides ``other`` had adopted; they are kept if this estimator
            personalises too (``adapt_rate`` > 0), dropped otherwise.
        """
        theirs = other.personaliser
        strides = int(theirs.adapter.accepted.sum()) if theirs is not None else 0
        if strides and self.personaliser is not None and theirs is not None:
            self.personaliser.adopt(theirs, other.library.mode_names == self.library.mode_names)
        return strides

    def adapted_library(self) -> KernelLibrary:
        """The library with the kernels as personalised so far (the original if adaptation is off)."""
        return self.adapter.adapted_library() if self.adapter is not None else self.library


@dataclass(frozen=True)
class EstimateTrace:
    """Estimates for a whole recording (T output samples, M modes)."""

    mode_names: list[str]
    time_s: np.ndarray  # (T,) seconds
    sample: np.ndarray  # (T,) source index of the latest input sample at or before time_s
    mode_index: np.ndarray  # (T,) the supervisor's library mode, whatever the state
    phase: np.ndarray  # (T,) nan unless walking (states on)
    ready: np.ndarray  # (T,) bool
    sse: np.ndarray  # (T, M) deg^2 (per window sample with normalize_error)
    phases: np.ndarray  # (T, M)
    raw_mode_index: np.ndarray  # (T,)
    confidence: np.ndarray  # (T,)
    fit_rms_deg: np.ndarray  # (T,)
    held: np.ndarray  # (T,) bool
    phase_rate: np.ndarray  # (T,) strides/s
    cadence_ratio: np.ndarray  # (T,) wearer cadence / kernel cadence of the reported mode (nan: one scale)
    state: np.ndarray  # (T,) EstimateState values (states.py)
    mode: np.ndarray  # (T,) object: the reported mode (a library mode, stand, unknown or '')

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def modes(self) -> list[str]:
        """The reported modes (``mode``) as a list."""
        return [str(m) for m in self.mode]


_TRACE_DTYPES: dict[str, Any] = {"mode_index": np.int64, "raw_mode_index": np.int64, "state": np.int64, "ready": bool,
                                 "held": bool, "mode": object}
"""Column dtypes of an ``EstimateTrace`` besides float64."""


def run_estimator(
    estimator: Estimator, time_s: np.ndarray, angles_deg: np.ndarray, index: np.ndarray | None = None
) -> EstimateTrace:
    """Stream a whole recording through ``estimator`` (fresh or not) and collect the estimates:
    in bulk (``core/batch.py``: the same results, without a Python step per sample) where the
    options allow it, else by ``Estimator.update`` sample by sample."""
    idx = np.arange(len(time_s)) if index is None else np.asarray(index)
    from .batch import run_batch

    columns = run_batch(estimator, time_s, angles_deg)
    if columns is not None:
        return EstimateTrace(mode_names=list(estimator.mode_names), sample=idx.astype(np.int64), **columns)
    rows = [(int(idx[i]), estimator.update(float(time_s[i]), angles_deg[i])) for i in range(len(time_s))]
    return trace_from_estimates(estimator.mode_names, rows)


def trace_from_estimates(mode_names: Sequence[str], rows: Sequence[tuple[int, Estimate]]) -> EstimateTrace:
    """Pack (source sample index, Estimate) pairs into arrays: every ``Estimate`` field a column."""
    m = len(mode_names)
    columns = {f.name: np.array([getattr(e, f.name) for _, e in rows], dtype=_TRACE_DTYPES.get(f.name, np.float64))
               for f in fields(Estimate)}
    columns["sse"], columns["phases"] = columns["sse"].reshape(-1, m), columns["phases"].reshape(-1, m)
    return EstimateTrace(mode_names=list(mode_names), sample=np.array([i for i, _ in rows], dtype=np.int64), **columns)
