"""Teaching a mode live: strides collected from a stream of samples, a kernel built as ``train`` builds it.

``StrideCollector`` takes the samples of one wearer walking in one mode (time in seconds, four
angles in degrees, CHANNELS order) as they arrive and applies ``train``'s rules
(docs/training.md, "`train`: rules") to them online:

* the samples are resampled onto a uniform grid at the library's rate (without a library: the
  median rate of the samples, as ``train`` chooses it), anchored at the first sample;
* right heel strikes are the peaks of the heel-strike channel (right shank by default) found by
  ``strides.detect_peaks`` (the same prominence and distance rules); a peak counts once the
  samples reach ``min_stride_s`` past it (no later, higher peak can then replace it, and its
  prominence can only grow);
* consecutive heel strikes ``min_stride_s``-``max_stride_s`` apart are candidate strides; a
  longer interval is a stop or a turn, and a stream that runs longer than that without a heel
  strike is reported;
* after every new stride the duration and shape outlier rules (``training.reject_outliers``) run over
  all candidates: the strides they keep are the good ones;
* once ``strides`` good strides are in (never fewer than ``min_strides``), the kernel is
  ``training.train_mode`` on the candidates: the same averaging and rejection as ``train`` on a
  labels file covering the same strides.

Memory stays bounded however long nobody walks: each candidate keeps its own stretch of the
uniform grid (the same grid values ``train`` interpolates), and the stream itself is kept only
for the last ``max_stride_s + min_stride_s + KEEP_MARGIN_S`` seconds, enough to find the next
heel strike and the stride that ends there (a last heel strike before a stop whose prominence
shows only when walking resumes later than that is not used; ``train`` would use its stride).

Every event is returned as a line of text (``push``) for the node's log.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numpy as np

from .. import __version__
from .calibration import CalibrationParams
from .channels import CHANNELS
from .errors import GaitEstimatorError
from .kernels import KernelLibrary, KernelMode, near_duplicates
from .strides import DetectionOptions, detect_peaks
from .training import OutlierRule, StrideInfo, TrainOptions, judge_strides, train_mode

TEACH_STRIDES = 10
"""Default good strides per taught mode (the paper: about ten steady strides)."""
MAX_TEACH_STRIDES = 100
HEEL_STRIKE_CHANNEL = "right_shank"
ANALYSIS_PERIOD_S = 0.25
"""Stream time between two looks for new heel strikes."""
CANDIDATE_FACTOR = 4
"""At most this many times ``strides`` candidate strides are kept (the oldest go first)."""
KEEP_MARGIN_S = 1.0
"""Stream kept beyond the longest stride plus the heel-strike confirmation delay (s)."""
PIECE_MARGIN = 2
"""Grid samples a candidate keeps beyond each of its heel strikes (interpolation needs one)."""
NEAR_COPY_RMS_DEG = CalibrationParams.near_copy_rms_deg
NEAR_COPY_LENGTH_RATIO = CalibrationParams.near_copy_length_ratio
"""A taught kernel this close to another mode (shape RMS, degrees; |ln| of the length ratio) is
reported as a near copy: the walking calibration's rule for near copies (``CalibrationParams``)."""
LIVE_SOURCE = "taught live"
TAUGHT_LIBRARY = "taught"
"""Name of the library a node without one (``kernels: ''``) builds from its first taught mode."""
RATE_DIGITS = 6
"""Significant digits of a rate taken from the samples' stamps (nanosecond stamps of a 230 Hz
stream give 230.0000046 Hz; the sensor's rate is 230 Hz)."""
RATE_SAMPLES = 50
"""Samples needed before the median rate is taken (without a library) and strides are looked for."""


class Grid(NamedTuple):
    """Samples on the uniform grid: times (s), angles (deg, CHANNELS order)."""

    time_s: np.ndarray
    angles_deg: np.ndarray


@dataclass(frozen=True)
class TeachOptions:
    """How a mode is taught.

    Attributes:
        strides: Good strides to collect (at least ``min_strides``).
        channel: Heel-strike channel (one of CHANNELS); its maxima are right heel strikes.
        min_strides: ``train``'s ``--min-strides``: teaching never completes from fewer.
        detection: Heel-strike and stride limits (seconds, degrees), as ``train``'s.
        outliers: Duration and shape outlier rule, as ``train``'s.
    """

    strides: int = TEACH_STRIDES
    channel: str = HEEL_STRIKE_CHANNEL
    min_strides: int = TrainOptions().min_strides
    detection: DetectionOptions = field(default_factory=DetectionOptions)
    outliers: OutlierRule = field(default_factory=OutlierRule)

    def __post_init__(self) -> None:
        check_teach_strides(self.strides, self.min_strides)
        if self.channel not in CHANNELS:
            raise GaitEstimatorError(f"heel-strike channel must be one of {', '.join(CHANNELS)}, got {self.channel!r}")


def check_teach_strides(strides: Any, min_strides: int = TrainOptions().min_strides) -> None:
    """Raise a one-line GaitEstimatorError unless ``strides`` is a stride count teaching accepts."""
    if isinstance(strides, bool) or not isinstance(strides, int) or not min_strides <= strides <= MAX_TEACH_STRIDES:
        raise GaitEstimatorError(
            f"teach strides must be an integer {min_strides}..{MAX_TEACH_STRIDES} (train's --min-strides is "
            f"{min_strides}), got {strides!r}"
        )


@dataclass(frozen=True)
class TaughtMode:
    """The result of teaching one mode.

    Attributes:
        kernel: The new kernel (``info`` as ``train`` writes it).
        strides: Every candidate stride, kept or rejected (``rejected`` says why).
        heel_strikes: Number of heel strikes found while teaching.
    """

    kernel: KernelMode
    strides: list[StrideInfo]
    heel_strikes: int

    def summary(self) -> str:
        """One line: strides, duration, length, spread."""
        k, i = self.kernel, self.kernel.info
        return (
            f"{k.name}: {i['strides']} strides ({i['strides_found']} found, "
            f"{i['strides_found'] - i['strides']} rejected), duration {i['duration_mean_s']:.3f} "
            f"± {i['duration_std_s']:.3f} s, N={k.length} at {k.sample_rate_hz:g} Hz, "
            f"stride rms from kernel {i['stride_rms_from_kernel_deg']:.2f} deg"
        )


class StrideCollector:
    """Collects one mode's strides from a sample stream and builds its kernel (module docstring).

    Args:
        mode: Name of the mode being taught.
        options: Stride count, heel-strike channel, train's rules.
        rate_hz: Uniform rate of the kernel (the library's); None: the samples' median rate.
    """

    def __init__(self, mode: str, options: TeachOptions | None = None, rate_hz: float | None = None) -> None:
        if not isinstance(mode, str) or not mode.strip():
            raise GaitEstimatorError("the mode to teach needs a name")
        self.mode = mode
        self.options = options or TeachOptions()
        self.rate_hz = rate_hz
        self._channel = CHANNELS.index(self.options.channel)
        self._times: list[float] = []
        self._samples: list[Sequence[float]] = []
        self._anchor: float | None = None
        self._analysed_at = -math.inf
        self.heel_strikes: list[float] = []
        self.candidates: list[tuple[float, float]] = []
        self._pieces: list[Grid] = []  # per candidate: its stretch of the uniform grid
        self._reasons: list[str] = []
        self._not_strides = 0  # heel-strike intervals too long to be a stride (a stop or a turn)
        self._silence_reported = False
        self.result: TaughtMode | None = None

    @property
    def target(self) -> int:
        return self.options.strides

    @property
    def good(self) -> int:
        """Candidate strides the outlier rules keep so far."""
        return sum(1 for r in self._reasons if not r)

    @property
    def done(self) -> bool:
        return self.result is not None

    def _missed(self, gap_s: float) -> str:
        """', or a heel strike between not found' when ``gap_s`` is about two good strides long."""
        good = [b - a for (a, b), r in zip(self.candidates, self._reasons, strict=True) if not r]
        if not good:
            return ""
        med = float(np.median(good))
        return ", or a heel strike between not found" if abs(gap_s - 2.0 * med) <= 0.2 * med else ""

    def not_used(self) -> Counter:
        """Strides not used, by why: ``duration``, ``shape`` (outliers: turns and changes of pace
        show as these), ``stop or turn`` (a heel-strike interval too long for a stride)."""
        why = Counter(r.split()[0].rstrip(":") for r in self._reasons if r)
        if self._not_strides:
            why["stop or turn"] = self._not_strides
        return why

    def not_used_text(self) -> str:
        """``"4 not used: 2 duration, 2 shape"``, or '' when every stride was used."""
        why = self.not_used()
        return f"{why.total()} not used: " + ", ".join(f"{n} {reason}" for reason, n in why.items()) if why else ""

    def progress(self) -> str:
        """``"Slow: 6/10 strides"``, and ``"; 4 not used: 2 duration, 2 shape"`` when some were not."""
        not_used = self.not_used_text()
        return f"{self.mode}: {self.good}/{self.target} strides" + (f"; {not_used}" if not_used else "")

    def restart_stream(self) -> None:
        """The stream restarted (its stamps jumped back: a replayed recording, a restarted
        driver): the strides found so far stay; heel strikes are looked for afresh from the next
        sample (``push`` times may start again from any value)."""
        self._times.clear()
        self._samples.clear()
        self._anchor = None
        self._analysed_at = -math.inf
        self.heel_strikes = []
        self._silence_reported = False

    def set_target(self, strides: int) -> None:
        """Change the number of good strides to collect (before the kernel is built)."""
        self.options = replace(self.options, strides=strides)

    def push(self, time_s: float, sample_deg: Sequence[float]) -> list[str]:
        """Add one sample (seconds, increasing; four angles in degrees); returns the events it
        caused (new strides, rejections, the finished kernel), one line each."""
        if self.result is not None:
            return []
        if self._anchor is None:
            self._anchor = float(time_s)
        self._times.append(float(time_s))
        self._samples.append(sample_deg)
        if time_s - self._analysed_at < ANALYSIS_PERIOD_S:
            return []
        self._analysed_at = float(time_s)
        return self._analyse()

    def finish(self) -> list[str]:
        """Look at the samples so far now (instead of at the next analysis period)."""
        return [] if self.result is not None else self._analyse()

    # -----------------------------------------------------------------------------------------

    def _uniform(self) -> Grid | None:
        """The samples so far on the uniform grid anchored at the first sample."""
        t = np.asarray(self._times, dtype=np.float64)
        if t.size < RATE_SAMPLES or self._anchor is None:
            return None
        if self.rate_hz is None:  # train's default: the median rate; fixed once known, so the grid stays
            rate = float(f"{1.0 / np.median(np.diff(t)):.{RATE_DIGITS}g}")
            if not (math.isfinite(rate) and rate > 0):
                return None
            self.rate_hz = rate
        rate = self.rate_hz
        k0 = math.ceil((t[0] - self._anchor) * rate - 1e-6)
        k1 = math.floor((t[-1] - self._anchor) * rate + 1e-6)
        if k1 - k0 < 2:
            return None
        grid = self._anchor + np.arange(k0, k1 + 1) / rate
        x = np.asarray(self._samples, dtype=np.float64)
        angles = np.column_stack([np.interp(grid, t, x[:, c]) for c in range(x.shape[1])])
        return Grid(grid, angles)

    def _analyse(self) -> list[str]:
        uni = self._uniform()
        if uni is None:
            return []
        det = self.options.detection
        end = float(uni.time_s[-1])
        peaks = detect_peaks(uni.time_s, uni.angles_deg[:, self._channel], det)
        last = self.heel_strikes[-1] if self.heel_strikes else -math.inf
        new = peaks[(peaks > last + 1e-9) & (peaks <= end - det.min_stride_s)]
        events: list[str] = []
        added = False
        for h in new.tolist():
            if self.heel_strikes:
                a = self.heel_strikes[-1]
                if h - a <= det.max_stride_s and a >= uni.time_s[0]:
                    self.candidates.append((a, h))
                    self._pieces.append(_piece(uni, a, h))
                    self._reasons.append("")
                    added = True
                elif h - a <= det.max_stride_s:  # a heel strike confirmed too late: its start is gone
                    events.append(f"{self.mode}: stride at {a:.2f} s ({h - a:.2f} s) not used: its start "
                                  "was no longer kept (the heel strike ending it was found late)")
                else:
                    self._not_strides += 1
                    events.append(f"{self.mode}: {h - a:.2f} s from the heel strike at {a:.2f} s to the next at "
                                  f"{h:.2f} s: not a stride (> {det.max_stride_s:g} s: a stop or a turn"
                                  f"{self._missed(h - a)}), not used")
            self.heel_strikes.append(h)
            if end - h <= det.max_stride_s:  # walking again (not a heel strike confirmed late, e.g. before a stop)
                self._silence_reported = False
        since = self.heel_strikes[-1] if self.heel_strikes else float(uni.time_s[0])
        if end - since > det.max_stride_s + det.min_stride_s and not self._silence_reported:
            self._silence_reported = True
            events.append(
                f"{self.mode}: no heel strike found in the last {end - since:.1f} s ({self.options.channel} maxima "
                f"of >= {det.min_prominence_deg:g} deg prominence): not walking, or the channel does not swing; "
                + self.progress().split(": ", 1)[1]
            )
        if added:
            events += self._judge(uni)
        self._forget_before(end - (det.max_stride_s + det.min_stride_s + KEEP_MARGIN_S))
        return events

    def _judge(self, uni: Grid) -> list[str]:
        """Outlier rules over all candidates; events for the new stride and for changed verdicts;
        the kernel once enough strides are good."""
        if len(self.candidates) > CANDIDATE_FACTOR * self.target:
            drop = len(self.candidates) - CANDIDATE_FACTOR * self.target
            del self.candidates[:drop], self._reasons[:drop], self._pieces[:drop]
        rate = float(self.rate_hz)  # type: ignore[arg-type]
        bounds = np.array(self.candidates, dtype=np.float64)
        parts = [(LIVE_SOURCE, p, bounds[i:i + 1]) for i, p in enumerate(self._pieces)]
        _, reasons, _ = judge_strides(parts, rate, self.options.outliers)
        events = []
        before = self._reasons + [""] * (len(reasons) - len(self._reasons))
        newest = len(reasons) - 1
        for i, (old, now) in enumerate(zip(before, reasons, strict=True)):
            a, b = self.candidates[i]
            if i == newest:
                if now:
                    events.append(f"{self.mode}: stride at {a:.2f} s ({b - a:.2f} s) not used: {now}")
            elif now and not old:
                events.append(f"{self.mode}: stride at {a:.2f} s ({b - a:.2f} s) no longer used: {now}")
            elif old and not now:
                events.append(f"{self.mode}: stride at {a:.2f} s ({b - a:.2f} s) used again")
        self._reasons = reasons
        events.append(self.progress())
        if self.good >= max(self.target, self.options.min_strides):
            self._build(rate, bounds, parts)
            assert self.result is not None
            events.append(f"{self.mode}: kernel built from " + self.result.summary().split(": ", 1)[1])
        return events

    def _build(self, rate: float, bounds: np.ndarray, parts: list[tuple[str, Grid, np.ndarray]]) -> None:
        opts = self.options
        train = TrainOptions(min_strides=opts.min_strides, detection=opts.detection, outliers=opts.outliers)
        kernel, infos = train_mode(self.mode, parts, rate, train)
        info = dict(kernel.info)
        info["heel_strikes"] = f"{opts.channel} maxima, taught live"
        info["candidate_strides_s"] = [[round(float(a), 6), round(float(b), 6)] for a, b in bounds]
        self.result = TaughtMode(replace(kernel, info=info), infos, len(self.heel_strikes))

    def _forget_before(self, keep_from: float) -> None:
        """Drop stream samples before ``keep_from`` (s): no stride still to be found starts there."""
        i = int(np.searchsorted(np.asarray(self._times), keep_from, side="left"))
        if i > 0:
            del self._times[:i], self._samples[:i]

    @property
    def buffered(self) -> int:
        """Stream samples kept now (bounded: see the module docstring)."""
        return len(self._times)


def _piece(uni: Grid, start_s: float, end_s: float) -> Grid:
    """The grid samples of ``uni`` a stride from ``start_s`` to ``end_s`` is interpolated from."""
    i0, i1 = np.searchsorted(uni.time_s, [start_s, end_s])
    i0, i1 = max(0, int(i0) - PIECE_MARGIN), min(len(uni.time_s), int(i1) + PIECE_MARGIN)
    return Grid(uni.time_s[i0:i1].copy(), uni.angles_deg[i0:i1].copy())


# ---------------------------------------------------------------------------------------------
# The library


def with_mode(library: KernelLibrary | None, kernel: KernelMode,
              name: str = TAUGHT_LIBRARY) -> tuple[KernelLibrary, KernelMode | None]:
    """``library`` with ``kernel`` added (a new name, at the end) or in place of the mode of that
    name; a library of that one mode when ``library`` is None.

    Returns:
        (the new library, the replaced mode or None).
    """
    if library is None:
        provenance = {
            "source": "taught live in estimator_node",
            "built_by": f"gait_estimator {__version__} teach",
            "sample_rate_hz": kernel.sample_rate_hz,
            "taught": [kernel.name],
        }
        return KernelLibrary(name, (kernel,), provenance), None
    if abs(kernel.sample_rate_hz - library.sample_rate_hz) > 1e-9 * library.sample_rate_hz:
        raise GaitEstimatorError(
            f"mode {kernel.name!r} is at {kernel.sample_rate_hz:g} Hz, library {library.name!r} at "
            f"{library.sample_rate_hz:g} Hz"
        )
    old = next((m for m in library.modes if m.name == kernel.name), None)
    modes = tuple(kernel if m.name == kernel.name else m for m in library.modes) if old else (*library.modes, kernel)
    provenance = dict(library.provenance)
    taught = list(provenance.get("taught", []))
    provenance["taught"] = [*(t for t in taught if t != kernel.name), kernel.name]
    return KernelLibrary(library.name, modes, provenance, library.path), old


def near_copies(library: KernelLibrary, mode: str, channel_weights: np.ndarray | None = None) -> list[str]:
    """Modes of ``library`` whose kernels are near copies of ``mode``'s (NEAR_COPY_RMS_DEG,
    NEAR_COPY_LENGTH_RATIO; ``core.kernels.near_duplicates``)."""
    if len(library) < 2:
        return []
    near = near_duplicates(library, NEAR_COPY_RMS_DEG, NEAR_COPY_LENGTH_RATIO, channel_weights)
    i = library.mode_names.index(mode)
    return [n for j, n in enumerate(library.mode_names) if j != i and near[i, j]]


def change_summary(taught: TaughtMode, library: KernelLibrary, replaced: KernelMode | None,
                   copies: Sequence[str]) -> str:
    """One line for the log: what teaching changed in the library."""
    k = taught.kernel
    what = (f"replaced {k.name} (was N={replaced.length}, {replaced.stride_duration_s:.3f} s)" if replaced
            else f"added {k.name}")
    modes = f"{len(library)} mode{'s' if len(library) != 1 else ''}: " + ", ".join(library.mode_names)
    line = f"taught: {what}; {taught.summary()}; library '{library.name}' now {modes}"
    if copies:
        line += (f"; WARNING: {k.name} is a near copy of {', '.join(copies)} (shape RMS <= {NEAR_COPY_RMS_DEG:g} deg,"
                 " stride length within 2 %): the estimator can tell them apart only by noise")
    return line
