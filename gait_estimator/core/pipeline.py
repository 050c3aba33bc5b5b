"""The parameters of every estimator stage, derived from the options (``EstimatorConfig``).

Each stage takes its own frozen dataclass: ``GapParams`` (gaps.py), ``MatchParams`` (here: the
matcher belongs to the hot path), ``SupervisorParams`` (supervisor.py), ``CalibrationParams``
(calibration.py), ``AdaptParams`` (adapt.py), ``StateParams`` (states.py). Their tuning fields (not options) keep their
defaults unless ``PipelineParams.from_config`` is given overrides, e.g. for an experiment::

    PipelineParams.from_config(config, calibration={"near_copy_rms_deg": 0.0})
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from .adapt import AdaptParams
from .calibration import CalibrationParams
from .gaps import GapParams
from .kernels import KernelLibrary
from .matcher import IncrementalMatcher
from .options import EstimatorConfig
from .states import StateParams
from .supervisor import SupervisorParams


@dataclass(frozen=True)
class MatchParams:
    """Matcher settings (the options of the same names; see core/matcher.py).

    Attributes:
        channel_weights: Weight per channel (CHANNELS order), channels not used at 0.
        time_scales: Stride-duration factors of the kernel variants.
        offset_tolerance_deg: Per-channel mean offset that costs nothing, degrees.
        normalize: Compare by mean squared error per window sample instead of SSE.
        recency_half_life: Age (strides) at which a sample's weight halves; 0 = uniform.
    """

    channel_weights: tuple[float, ...] = EstimatorConfig.channel_weights
    time_scales: tuple[float, ...] = EstimatorConfig.time_scales
    offset_tolerance_deg: float = EstimatorConfig.offset_tolerance_deg
    normalize: bool = EstimatorConfig.normalize_error
    recency_half_life: float = EstimatorConfig.recency_half_life

    def build(self, library: KernelLibrary, backend: str = "auto") -> IncrementalMatcher:
        return IncrementalMatcher(
            library, channel_weights=self.channel_weights, time_scales=self.time_scales,
            offset_tolerance_deg=self.offset_tolerance_deg, normalize=self.normalize,
            recency_half_life=self.recency_half_life, backend=backend,
        )


@dataclass(frozen=True)
class PipelineParams:
    """The parameters of every stage of one estimator."""

    gaps: GapParams
    match: MatchParams
    supervisor: SupervisorParams
    calibration: CalibrationParams
    adapt: AdaptParams
    states: StateParams

    @classmethod
    def from_config(cls, config: EstimatorConfig, **tuning: Mapping[str, Any]) -> PipelineParams:
        """The stages' parameters for ``config``; ``tuning`` overrides fields by stage name
        (``calibration={"near_copy_rms_deg": 0.0}``)."""
        c = config
        params = cls(
            gaps=GapParams(c.max_gap_s, c.calibration_reset_gap_s),
            match=MatchParams(tuple(c.effective_weights().tolist()), c.time_scales, c.offset_tolerance_deg,
                              c.normalize_error, c.recency_half_life),
            supervisor=SupervisorParams(c.min_confidence, c.min_dwell_s, c.switch_back_margin, c.transitions,
                                        c.phase_rate_tau_s),
            calibration=CalibrationParams(c.offset_calibration_rate, c.cadence_calibration_rate, c.cadence_tolerance),
            adapt=AdaptParams(c.adapt_rate, c.adapt_min_confidence, c.adapt_max_step_deg),
            states=StateParams(enabled=bool(c.states)),
        )
        unknown = set(tuning) - {"gaps", "match", "supervisor", "calibration", "adapt", "states"}
        if unknown:
            raise ValueError(f"unknown estimator stage(s): {', '.join(sorted(unknown))}")
        return replace(params, **{stage: replace(getattr(params, stage), **v) for stage, v in tuning.items()})
