"""The estimator pipeline used by the node and the offline tools alike:

    time-stamped sample -> [gap check] -> [resampling to the library rate] -> matcher
                        -> supervisor -> Estimate

``EstimatorConfig`` holds every option; ``OPTIONS`` describes them once for both the node's
parameters and the CLI's flags. All defaults reproduce the paper / reference implementation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from .channels import CHANNELS
from .kernels import KernelLibrary
from .matcher import IncrementalMatcher, check_channel_weights, check_window_fraction
from .resample import UniformResampler
from .supervisor import Estimate, Supervisor, load_transitions


@dataclass(frozen=True)
class Option:
    """One estimator option, as a node parameter and a CLI flag."""

    name: str
    default: Any
    description: str


OPTIONS: tuple[Option, ...] = (
    Option("window_fraction", 1.0, "fraction of each stride compared, (0, 1]; 1.0 = the paper's full stride"),
    Option("channels", list(CHANNELS), "channels used for matching (subset of right_thigh, left_thigh, right_shank, "
           "left_shank), e.g. [right_thigh, right_shank] for unilateral sensing"),
    Option("channel_weights", [1.0, 1.0, 1.0, 1.0], "weight of each channel in the SSE, CHANNELS order, >= 0"),
    Option("subsample_phase", False, "parabolic interpolation of the SSE minimum for a phase finer than 1/N"),
    Option("resample", False, "resample the input onto the library's sample rate by linear interpolation of the stamps"),
    Option("min_confidence", 0.0, "below this margin ((SSE_2nd - SSE_best) / SSE_best) hold the last confident mode; 0 = off"),
    Option("min_dwell_samples", 0, "a new mode must win this many consecutive samples before it is reported; 0 = off"),
    Option("min_dwell_s", 0.0, "a new mode must win this long (s) before it is reported; 0 = off"),
    Option("transitions", "", "YAML file of allowed transitions (allowed_transitions: {MODE: [MODE, ...]}); '' = any"),
    Option("phase_rate_tau_s", 0.2, "time constant (s) of the phase-rate smoothing"),
    Option("max_gap_s", 0.5, "a longer gap (s) between samples restarts the window (not ready until refilled); 0 = never"),
)


@dataclass(frozen=True)
class EstimatorConfig:
    """All estimator options; see OPTIONS for their meaning. Defaults = the paper."""

    window_fraction: float = 1.0
    channels: tuple[str, ...] = CHANNELS
    channel_weights: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    subsample_phase: bool = False
    resample: bool = False
    min_confidence: float = 0.0
    min_dwell_samples: int = 0
    min_dwell_s: float = 0.0
    transitions: str = ""
    phase_rate_tau_s: float = 0.2
    max_gap_s: float = 0.5

    def __post_init__(self) -> None:
        check_window_fraction(self.window_fraction)
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "channel_weights", tuple(float(w) for w in self.channel_weights))
        unknown = [c for c in self.channels if c not in CHANNELS]
        if unknown or not self.channels:
            raise ValueError(f"channels must be a non-empty subset of {', '.join(CHANNELS)}, got {list(self.channels)}")
        check_channel_weights(self.effective_weights())
        for name in ("min_confidence", "min_dwell_s", "max_gap_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v >= 0 and not math.isnan(v)):
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
        if not (isinstance(self.min_dwell_samples, int) and self.min_dwell_samples >= 0):
            raise ValueError(f"min_dwell_samples must be an integer >= 0, got {self.min_dwell_samples!r}")
        if not (self.phase_rate_tau_s > 0 and math.isfinite(self.phase_rate_tau_s)):
            raise ValueError(f"phase_rate_tau_s must be > 0, got {self.phase_rate_tau_s!r}")

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


class Estimator:
    """Streams time-stamped samples through gap check, resampling, matcher and supervisor.

    Args:
        library: Kernel library (degrees).
        config: Options; default = the paper.
    """

    def __init__(self, library: KernelLibrary, config: EstimatorConfig | None = None) -> None:
        self.library = library
        self.config = config or EstimatorConfig()
        c = self.config
        self.matcher = IncrementalMatcher(
            library, window_fraction=c.window_fraction, channel_weights=c.effective_weights(), subsample=c.subsample_phase
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
        )
        self.resampler = UniformResampler(library.sample_rate_hz) if c.resample else None
        self.last_time: float | None = None
        self.resets = 0

    @property
    def mode_names(self) -> list[str]:
        return self.library.mode_names

    def reset(self) -> None:
        """Restart from an empty window (as after a gap)."""
        self.matcher.reset()
        self.supervisor.reset()
        if self.resampler is not None:
            self.resampler.reset()
        self.last_time = None

    def gap_exceeded(self, time_s: float) -> bool:
        """True if a sample at ``time_s`` comes more than max_gap_s after the previous one."""
        gap = self.config.max_gap_s
        return self.last_time is not None and gap > 0 and time_s - self.last_time > gap

    def update(self, time_s: float, sample_deg: Sequence[float] | np.ndarray) -> list[Estimate]:
        """Consume one sample (4 angles, degrees, CHANNELS order) stamped ``time_s`` (seconds,
        strictly increasing); returns the estimates it produces: one, or with resampling zero or
        more (one per grid point reached).

        Raises ValueError for a non-finite sample or a non-increasing stamp; state is unchanged.
        """
        x = np.asarray(sample_deg, dtype=np.float64).reshape(len(CHANNELS))
        if not np.isfinite(x).all() or not math.isfinite(time_s):
            raise ValueError(f"non-finite sample {x.tolist()} at {time_s}")
        if self.last_time is not None and time_s <= self.last_time:
            raise ValueError(f"stamp {time_s} is not after the previous {self.last_time}")
        if self.gap_exceeded(time_s):
            self.reset()
            self.resets += 1
        self.last_time = time_s
        points = self.resampler.push(time_s, x) if self.resampler is not None else [(time_s, x)]
        return [self.supervisor.update(t, self.matcher.step(p)) for t, p in points]


@dataclass(frozen=True)
class EstimateTrace:
    """Estimates for a whole recording (T output samples, M modes)."""

    mode_names: list[str]
    time_s: np.ndarray  # (T,) seconds
    sample: np.ndarray  # (T,) source index of the latest input sample at or before time_s
    mode_index: np.ndarray  # (T,)
    phase: np.ndarray  # (T,)
    ready: np.ndarray  # (T,) bool
    sse: np.ndarray  # (T, M) deg^2
    phases: np.ndarray  # (T, M)
    raw_mode_index: np.ndarray  # (T,)
    confidence: np.ndarray  # (T,)
    fit_rms_deg: np.ndarray  # (T,)
    held: np.ndarray  # (T,) bool
    phase_rate: np.ndarray  # (T,) strides/s

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def modes(self) -> list[str]:
        return [self.mode_names[i] for i in self.mode_index]


def run_estimator(
    estimator: Estimator, time_s: np.ndarray, angles_deg: np.ndarray, index: np.ndarray | None = None
) -> EstimateTrace:
    """Stream a whole recording through ``estimator`` (fresh or not) and collect the estimates."""
    idx = np.arange(len(time_s)) if index is None else np.asarray(index)
    rows: list[tuple[int, Estimate]] = []
    for i in range(len(time_s)):
        for est in estimator.update(float(time_s[i]), angles_deg[i]):
            rows.append((int(idx[i]), est))
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
    )


# ---------------------------------------------------------------------------------------------
# Command-line flags for the options (the node declares the same OPTIONS as parameters)


def add_estimator_arguments(parser: Any, skip: Sequence[str] = ("max_gap_s",)) -> None:
    """Add ``--window-fraction`` ... flags (one per OPTIONS entry not in ``skip``) to ``parser``."""
    group = parser.add_argument_group("estimator options (defaults = the paper)")
    for opt in OPTIONS:
        if opt.name in skip:
            continue
        flag = "--" + opt.name.replace("_", "-")
        if isinstance(opt.default, bool):
            group.add_argument(flag, dest=opt.name, action="store_true", help=opt.description)
        elif isinstance(opt.default, list):
            kind = float if isinstance(opt.default[0], float) else str
            group.add_argument(flag, dest=opt.name, nargs="+", type=kind, metavar="V", help=opt.description)
        else:
            group.add_argument(flag, dest=opt.name, type=type(opt.default), metavar="V", help=opt.description)


def config_from_args(args: Any, **overrides: Any) -> EstimatorConfig:
    """EstimatorConfig from parsed flags (absent flags keep the defaults); raises ValueError."""
    values = {}
    for opt in OPTIONS:
        v = getattr(args, opt.name, None)
        if v is not None and v is not False:
            values[opt.name] = tuple(v) if isinstance(v, list) else v
    values.update({k: v for k, v in overrides.items() if v is not None})
    return EstimatorConfig().with_options(**values)
