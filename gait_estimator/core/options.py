"""The estimator's options: ``EstimatorConfig`` and the ``OPTIONS`` that describe it once for the
node's parameters, the CLI's flags and the docs.

Two presets: ``default`` (what works for a new wearer: rate handling, cadence variants, offset
tolerance and walking calibration, comparison per sample) and ``paper`` (the paper's algorithm,
which reproduces the reference implementation exactly). ``EstimatorConfig()`` is the default
preset; ``EstimatorConfig.preset("paper")`` the paper. Options flagged ``advanced`` are expert
knobs: node parameters ``advanced.<name>``, a separate CLI flag group, docs/options.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from .channels import CHANNELS
from .matcher import check_channel_weights, check_offset_tolerance, check_recency_half_life, check_time_scales

RESAMPLE_MODES = ("auto", "on", "off")
"""``resample``: ``auto`` = on when the input has time stamps (JointState stamps, a recording's
time column), off for unstamped input (timed on arrival, or by sample index)."""

DEFAULT_TIME_SCALES = (0.88, 0.92, 0.96, 1.0, 1.04, 1.08, 1.12)


@dataclass(frozen=True)
class Option:
    """One estimator option, as a node parameter and a CLI flag: its default (the ``default``
    preset), its value in the ``paper`` preset, and whether it is an expert knob."""

    name: str
    default: Any
    description: str
    paper: Any = None
    advanced: bool = False

    @property
    def paper_value(self) -> Any:
        return self.default if self.paper is None else self.paper


OPTIONS: tuple[Option, ...] = (
    Option("resample", "auto", "resample the input onto the library's sample rate from the stamps: auto (when "
           "the input is stamped), on, off", "off"),
    Option("channels", list(CHANNELS), "channels used for matching, e.g. [right_thigh, right_shank] for "
           "unilateral sensing"),
    Option("offset_calibration_rate", 0.15, "walking self-calibration of the sensor offsets: weight of one "
           "confident stride, [0, 1]; 0 = off", 0.0),
    Option("cadence_calibration_rate", 0.1, "walking self-calibration of the wearer's cadence: weight of one "
           "confident stride's time scale, [0, 1]; 0 = off", 0.0),
    Option("min_confidence", 0.0, "hold the last confident mode below this margin (error_2nd - error_best) / "
           "error_best; 0 = off"),
    Option("min_dwell_s", 0.0, "a new mode must win this long (s) before it is reported; 0 = off"),
    Option("transitions", "", "YAML file of allowed transitions (allowed_transitions: {MODE: [MODE, ...]}); "
           "'' = any"),
    Option("adapt_rate", 0.0, "online personalisation: weight of one confident stride in its mode's kernel, "
           "[0, 1]; 0 = off"),
    Option("states", True, "report stand (segments still) and unknown (no kernel fits) as the mode, no mode "
           "or phase while not ready (docs/controller.md); false = a library mode always", False),
    Option("max_gap_s", 0.5, "a longer gap (s) between samples restarts the window; 0 = never"),
    Option("calibration_reset_gap_s", 5.0, "a longer gap (s) between samples also forgets the learnt sensor "
           "offsets and cadence (sensors may have been re-donned); 0 = never", 0.0),
    # expert knobs
    Option("time_scales", list(DEFAULT_TIME_SCALES), "stride-duration factors of the kernel variants matched "
           "per mode (cadence ratio = 1/scale); [1.0] = the paper", [1.0], advanced=True),
    Option("offset_tolerance_deg", 2.0, "per-channel window-vs-kernel mean difference (deg), beyond the learnt "
           "sensor offset, that costs nothing; .inf = shapes only; 0 = none", 0.0, advanced=True),
    Option("cadence_tolerance", 0.04, "relative band around the learnt time scale in which modes are read "
           "(wider while strides spread)", advanced=True),
    Option("normalize_error", True, "compare modes by mean squared error per window sample instead of SSE",
           False, advanced=True),
    Option("recency_half_life", 0.3, "age (strides) at which a compared sample's weight halves (from the "
           "calibrations' 3rd stride on); 0 = uniform weights", 0.0, advanced=True),
    Option("channel_weights", [1.0, 1.0, 1.0, 1.0], "weight of each channel in the error, CHANNELS order, >= 0",
           advanced=True),
    Option("phase_rate_tau_s", 0.2, "time constant (s) of the phase-rate smoothing", advanced=True),
    Option("adapt_min_confidence", 0.2, "personalisation: lowest confidence margin allowed during an adapted "
           "stride", advanced=True),
    Option("adapt_max_step_deg", 5.0, "personalisation: per-sample clip (deg) of stride - kernel before "
           "weighting", advanced=True),
)
ADVANCED = frozenset(o.name for o in OPTIONS if o.advanced)
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


def _check_number(name: str, value: Any, low: float = 0.0, high: float = math.inf) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (low <= value <= high):
        bound = f"in [{low:g}, {high:g}]" if math.isfinite(high) else f">= {low:g}"
        raise ValueError(f"{name} must be a number {bound}, got {value!r}")


@dataclass(frozen=True)
class EstimatorConfig:
    """All estimator options; see OPTIONS for their meaning. Defaults = the ``default`` preset."""

    resample: str = "auto"
    time_scales: tuple[float, ...] = DEFAULT_TIME_SCALES
    offset_tolerance_deg: float = 2.0
    offset_calibration_rate: float = 0.15
    cadence_calibration_rate: float = 0.1
    cadence_tolerance: float = 0.04
    normalize_error: bool = True
    recency_half_life: float = 0.3
    channels: tuple[str, ...] = CHANNELS
    channel_weights: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    min_confidence: float = 0.0
    min_dwell_s: float = 0.0
    transitions: str = ""
    phase_rate_tau_s: float = 0.2
    adapt_rate: float = 0.0
    adapt_min_confidence: float = 0.2
    adapt_max_step_deg: float = 5.0
    states: bool = True
    max_gap_s: float = 0.5
    calibration_reset_gap_s: float = 5.0

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "resample", _resample_mode(self.resample))
        set_(self, "recency_half_life", check_recency_half_life(self.recency_half_life))
        set_(self, "channels", tuple(self.channels))
        set_(self, "channel_weights", tuple(float(w) for w in self.channel_weights))
        set_(self, "time_scales", tuple(float(s) for s in check_time_scales(self.time_scales)))
        set_(self, "offset_tolerance_deg", check_offset_tolerance(self.offset_tolerance_deg))
        unknown = [c for c in self.channels if c not in CHANNELS]
        if unknown or not self.channels:
            raise ValueError(f"channels must be a non-empty subset of {', '.join(CHANNELS)}, got {list(self.channels)}")
        check_channel_weights(self.channel_weights)
        check_channel_weights(self.effective_weights())
        for name in ("min_confidence", "min_dwell_s", "max_gap_s", "calibration_reset_gap_s", "adapt_min_confidence",
                     "cadence_tolerance"):
            _check_number(name, getattr(self, name))
        for name in ("offset_calibration_rate", "cadence_calibration_rate", "adapt_rate"):
            _check_number(name, getattr(self, name), 0.0, 1.0)
        if not (self.phase_rate_tau_s > 0 and math.isfinite(self.phase_rate_tau_s)):
            raise ValueError(f"phase_rate_tau_s must be > 0, got {self.phase_rate_tau_s!r}")
        if not (self.adapt_max_step_deg > 0 and math.isfinite(self.adapt_max_step_deg)):
            raise ValueError(f"adapt_max_step_deg must be > 0, got {self.adapt_max_step_deg!r}")

    @classmethod
    def preset(cls, name: str, **overrides: Any) -> EstimatorConfig:
        """The options of preset ``name`` (``default`` or ``paper``), then ``overrides``."""
        if name not in PRESETS:
            raise ValueError(f"preset must be one of {', '.join(PRESETS)}, got {name!r}")
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in PRESETS[name].items()}
        return cls().with_options(**{**values, **overrides})

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


def config_from_values(values: dict[str, Any], preset: str = "default") -> EstimatorConfig:
    """EstimatorConfig from option values by name (lists become tuples) on top of ``preset``."""
    return EstimatorConfig.preset(preset, **{k: tuple(v) if isinstance(v, (list, tuple)) else v for k, v in values.items()})
