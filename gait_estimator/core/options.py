"""The estimator's options: each one an ``EstimatorConfig`` field written once (``option``: its
default, ``paper`` value and description), and the ``OPTIONS`` made from them for the node's
parameters, the CLI's flags and the docs (test_options.py checks the YAML and the docs' tables).

Two presets: ``default`` (what works for a new wearer: rate handling, cadence variants, offset
tolerance and walking calibration, comparison per sample) and ``paper`` (the paper's algorithm,
which reproduces the reference implementation exactly). ``EstimatorConfig()`` is the default
preset; ``EstimatorConfig.preset("paper")`` the paper. Options flagged ``advanced`` are expert
knobs: node parameters ``advanced.<name>``, a separate CLI flag group, docs/options.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
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


def option(default: Any, description: str, paper: Any = None, advanced: bool = False) -> Any:
    """An ``EstimatorConfig`` field that is an option (see ``Option``): the one place its default,
    description and ``paper`` value are written."""
    return field(default=default, metadata={"description": description, "paper": paper, "advanced": advanced})


def _resample_mode(value: Any) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    v = str(value).strip().lower()
    aliases = {"true": "on", "false": "off", "yes": "on", "no": "off", "1": "on", "0": "off"}
    v = aliases.get(v, v)
    if v not in RESAMPLE_MODES:
        raise ValueError(f"resample must be one of {', '.join(RESAMPLE_MODES)}, got {value!r}")
    return v


def _check_number(name: str, value: Any, low: float = 0.0, high: float = math.inf, open_high: bool = False) -> None:
    number = not isinstance(value, bool) and isinstance(value, (int, float))
    if not number or not (low <= value <= high) or (open_high and value == high):
        bound = f"in [{low:g}, {high:g}{')' if open_high else ']'}" if math.isfinite(high) else f">= {low:g}"
        raise ValueError(f"{name} must be a number {bound}, got {value!r}")


@dataclass(frozen=True)
class EstimatorConfig:
    """All estimator options, each declared once here (``option``): ``OPTIONS`` (node parameters, CLI
    flags, docs) is made from these fields. Defaults = the ``default`` preset."""

    resample: str = option("auto", "resample the input onto the library's sample rate from the stamps: auto "
                           "(when the input is stamped), on, off", "off")
    channels: tuple[str, ...] = option(CHANNELS, "channels used for matching, e.g. [right_thigh, right_shank] "
                                       "for unilateral sensing")
    offset_calibration_rate: float = option(0.15, "walking self-calibration of the sensor offsets: weight of one "
                                            "confident stride, [0, 1]; 0 = off", 0.0)
    cadence_calibration_rate: float = option(0.1, "walking self-calibration of the wearer's cadence: weight of one "
                                             "confident stride's time scale, [0, 1]; 0 = off", 0.0)
    min_confidence: float = option(0.0, "hold the last confident mode below this margin (error_2nd - error_best) "
                                   "/ error_best; 0 = off")
    min_dwell_s: float = option(0.0, "a new mode must win this long (s) before it is reported; 0 = off")
    switch_back_margin: float = option(0.0, "the mode reported before the current one is reported again only when its "
                                       "error is below (1 - this) x the current mode's, [0, 1); 0 = off")
    transitions: str = option("", "YAML file of allowed transitions (allowed_transitions: {MODE: [MODE, ...]}); "
                              "'' = any")
    adapt_rate: float = option(0.0, "online personalisation: weight of one confident stride in its mode's kernel, "
                               "[0, 1]; 0 = off")
    states: bool = option(True, "report stand (segments still) and unknown (no kernel fits) as the mode, no mode "
                          "or phase while not ready (docs/controller.md); false = a library mode always", False)
    max_gap_s: float = option(0.5, "a longer gap (s) between samples restarts the window; 0 = never")
    calibration_reset_gap_s: float = option(5.0, "a longer gap (s) between samples also forgets the learnt sensor "
                                            "offsets and cadence (sensors may have been re-donned); 0 = never", 0.0)
    # expert knobs
    time_scales: tuple[float, ...] = option(DEFAULT_TIME_SCALES, "stride-duration factors of the kernel variants "
                                            "matched per mode (cadence ratio = 1/scale); [1.0] = the paper", [1.0],
                                            advanced=True)
    offset_tolerance_deg: float = option(2.0, "per-channel window-vs-kernel mean difference (deg), beyond the "
                                         "learnt sensor offset, that costs nothing; .inf = shapes only; 0 = none",
                                         0.0, advanced=True)
    cadence_tolerance: float = option(0.02, "relative band around the learnt time scale in which modes are read "
                                      "(wider while strides spread)", advanced=True)
    normalize_error: bool = option(True, "compare modes by mean squared error per window sample instead of SSE",
                                   False, advanced=True)
    recency_half_life: float = option(0.3, "age (strides) at which a compared sample's weight halves (from the "
                                      "calibrations' 3rd stride on); 0 = uniform weights", 0.0, advanced=True)
    channel_weights: tuple[float, ...] = option((1.0, 1.0, 1.0, 1.0), "weight of each channel in the error, "
                                                "CHANNELS order, >= 0", advanced=True)
    phase_rate_tau_s: float = option(0.2, "time constant (s) of the phase-rate smoothing", advanced=True)
    adapt_min_confidence: float = option(0.2, "personalisation: lowest confidence margin allowed during an "
                                         "adapted stride", advanced=True)
    adapt_max_step_deg: float = option(5.0, "personalisation: per-sample clip (deg) of stride - kernel before "
                                       "weighting", advanced=True)

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
        _check_number("switch_back_margin", self.switch_back_margin, 0.0, 1.0, open_high=True)
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


OPTIONS: tuple[Option, ...] = tuple(
    Option(f.name, list(f.default) if isinstance(f.default, tuple) else f.default, **f.metadata)
    for f in fields(EstimatorConfig)
)
"""The options in declaration order (list defaults as node parameters take them)."""
ADVANCED = frozenset(o.name for o in OPTIONS if o.advanced)
GAP_OPTIONS = frozenset({"max_gap_s", "calibration_reset_gap_s"})
"""Options read at every update: changing them keeps the window and what was learnt."""

PRESETS: dict[str, dict[str, Any]] = {
    "default": {o.name: o.default for o in OPTIONS},
    "paper": {o.name: o.paper_value for o in OPTIONS},
}
"""Option values of each preset (lists as given in OPTIONS)."""


def config_from_values(values: dict[str, Any], preset: str = "default") -> EstimatorConfig:
    """EstimatorConfig from option values by name (lists become tuples) on top of ``preset``."""
    return EstimatorConfig.preset(preset, **{k: tuple(v) if isinstance(v, (list, tuple)) else v for k, v in values.items()})
