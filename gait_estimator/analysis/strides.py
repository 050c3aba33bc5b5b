"""Uniform resampling, right heel-strike detection and stride segmentation.

Shared by ``train`` (kernels are averages of strides), ``evaluate`` (phase truth runs linearly
from one right heel strike to the next) and the label tools.

Heel-strike detection rule (documented in docs/training.md): the signal (right foot angle for level
and ramp walking, right shank angle for stairs, both degrees, sagittal plane, positive =
toes/shank rotated forward) is resampled to a uniform rate, then ``scipy.signal.find_peaks``
keeps maxima that

* are at least ``MIN_STRIDE_S`` apart (a right heel strike cannot follow the previous one
  sooner than the shortest physiological stride; the higher peak wins), and
* have a prominence of at least ``MIN_PROMINENCE_DEG`` (the foot and shank swing through
  40-100 deg per stride; small wiggles while standing or turning are not heel strikes).

Every peak time is refined to sub-sample precision by a parabola through the peak sample and
its two neighbours. Consecutive heel strikes form a stride only when their interval lies in
[``MIN_STRIDE_S``, ``MAX_STRIDE_S``]; longer intervals (standing, turning) are not strides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import RecordingError
from ..io.recording import Recording

MIN_STRIDE_S = 0.6
"""Shortest accepted stride (s): faster than brisk walking/jogging cadence (~200 strides/min is 0.3 s/step)."""

MAX_STRIDE_S = 2.5
"""Longest accepted stride (s): slower than the paper's slowest mode (PR stair ascent, ~1.85 s)."""

MIN_PROMINENCE_DEG = 20.0
"""Smallest peak prominence (deg) accepted as a heel strike."""

HEEL_STRIKE_SOURCES = ("auto", "column", "right_foot", "right_shank")
"""``--heel-strikes`` choices; ``auto`` = column if present, else right_foot if present, else right_shank."""

_SIGNAL_COLUMNS = {"right_foot": "right_foot_deg", "right_shank": "right_shank_deg"}


@dataclass(frozen=True)
class DetectionOptions:
    """Parameters of heel-strike detection and stride segmentation (seconds, degrees)."""

    min_stride_s: float = MIN_STRIDE_S
    max_stride_s: float = MAX_STRIDE_S
    min_prominence_deg: float = MIN_PROMINENCE_DEG


@dataclass(frozen=True)
class HeelStrikes:
    """Right heel-strike times of one recording.

    Attributes:
        times_s: Heel-strike times, seconds, increasing, shape (H,).
        method: How they were found, e.g. ``"right_foot_deg peaks"`` or ``"heel_strike column"``.
    """

    times_s: np.ndarray
    method: str


def resample_uniform(rec: Recording, rate_hz: float) -> Recording:
    """Resample ``rec`` to ``rate_hz`` (Hz) from its first time stamp to its last.

    Angles and extra columns are linearly interpolated in time; labels take the value of the
    nearest source sample; heel-strike flags move to the nearest new sample. ``index`` of the
    result is the new sample number (0, 1, ...).
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise RecordingError(f"{rec.source}: invalid resampling rate {rate_hz!r} Hz")
    if len(rec) < 2:
        raise RecordingError(f"{rec.source}: need at least 2 samples to resample, got {len(rec)}")
    t0, t1 = float(rec.time_s[0]), float(rec.time_s[-1])
    n = math.floor((t1 - t0) * rate_hz + 1e-6) + 1
    t = t0 + np.arange(n) / rate_hz
    angles = np.column_stack([np.interp(t, rec.time_s, rec.angles_deg[:, c]) for c in range(rec.angles_deg.shape[1])])
    extra = {k: np.interp(t, rec.time_s, v) for k, v in rec.extra.items()}
    labels = None
    if rec.labels is not None:
        labels = rec.labels[nearest_index(rec.time_s, t)]
    heel = None
    if rec.heel_strike is not None:
        heel = np.zeros(n, dtype=bool)
        heel[nearest_index(t, rec.time_s[rec.heel_strike])] = True
    return Recording(time_s=t, angles_deg=angles, labels=labels, heel_strike=heel, extra=extra, source=rec.source)


def nearest_index(grid: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Index of the element of increasing ``grid`` nearest to each of ``times`` (same units)."""
    grid = np.asarray(grid, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    right = np.clip(np.searchsorted(grid, times), 1, len(grid) - 1)
    left = right - 1
    return np.where(np.abs(times - grid[left]) <= np.abs(grid[right] - times), left, right)


def detect_peaks(
    time_s: np.ndarray, signal_deg: np.ndarray, options: DetectionOptions | None = None
) -> np.ndarray:
    """Heel-strike times (s) from maxima of a uniformly sampled signal (deg); see module docstring."""
    options = options or DetectionOptions()
    t = np.asarray(time_s, dtype=np.float64)
    x = np.asarray(signal_deg, dtype=np.float64)
    if t.size < 3:
        return np.empty(0)
    dt = float(np.median(np.diff(t)))
    distance = max(1, math.floor(options.min_stride_s / dt))
    from scipy.signal import find_peaks  # the 'analysis' extra; imported here so the CLI starts without it

    peaks, _ = find_peaks(x, distance=distance, prominence=options.min_prominence_deg)
    peaks = peaks[(peaks > 0) & (peaks < x.size - 1)]
    y0, y1, y2 = x[peaks - 1], x[peaks], x[peaks + 1]
    denom = y0 - 2.0 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(denom < 0, 0.5 * (y0 - y2) / denom, 0.0)
    return t[peaks] + np.clip(delta, -0.5, 0.5) * dt


def resolve_source(rec: Recording, source: str) -> str:
    """Turn ``auto`` into a concrete heel-strike source for ``rec``; check the others exist."""
    if source not in HEEL_STRIKE_SOURCES:
        raise RecordingError(f"unknown heel-strike source {source!r} (choose from {', '.join(HEEL_STRIKE_SOURCES)})")
    if source == "auto":
        if rec.heel_strike is not None:
            return "column"
        return "right_foot" if "right_foot_deg" in rec.extra else "right_shank"
    if source == "column" and rec.heel_strike is None:
        raise RecordingError(
            f"{rec.source}: missing column 'heel_strike' (use --heel-strikes right_foot or right_shank to detect them)"
        )
    if source == "right_foot" and "right_foot_deg" not in rec.extra:
        raise RecordingError(
            f"{rec.source}: missing column 'right_foot_deg' needed to detect heel strikes from the right foot angle"
        )
    return source


def heel_strikes(
    rec: Recording,
    source: str = "auto",
    rate_hz: float | None = None,
    options: DetectionOptions | None = None,
) -> HeelStrikes:
    """Right heel strikes of ``rec``.

    Args:
        rec: The recording (any sampling).
        source: ``column`` (the ``heel_strike`` flags), ``right_foot``/``right_shank`` (peaks of
            that angle, detected after resampling to ``rate_hz``), or ``auto``.
        rate_hz: Uniform rate (Hz) for detection; default the recording's median rate.
        options: Detection limits.

    Raises:
        RecordingError: the source's column is missing.
    """
    options = options or DetectionOptions()
    source = resolve_source(rec, source)
    if source == "column":
        assert rec.heel_strike is not None
        return HeelStrikes(np.asarray(rec.time_s[rec.heel_strike], dtype=np.float64), "heel_strike column")
    rate = rec.median_rate_hz if rate_hz is None else rate_hz
    uni = resample_uniform(rec, rate)
    col = _SIGNAL_COLUMNS[source]
    x = uni.angles_deg[:, 2] if source == "right_shank" else uni.extra[col]
    times = detect_peaks(uni.time_s, x, options)
    return HeelStrikes(
        times,
        f"{col} peaks (prominence >= {options.min_prominence_deg:g} deg, >= {options.min_stride_s:g} s apart, "
        f"at {rate:.6g} Hz)",
    )


def stride_bounds(
    times_s: np.ndarray, options: DetectionOptions | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Strides between consecutive heel strikes.

    Returns:
        (bounds, too_long_or_short): ``bounds`` (S, 2) start/end times (s) of the intervals whose
        duration lies in [min_stride_s, max_stride_s]; the second array (R, 2) holds the others.
    """
    options = options or DetectionOptions()
    h = np.asarray(times_s, dtype=np.float64)
    pairs = np.column_stack([h[:-1], h[1:]]) if h.size >= 2 else np.empty((0, 2))
    d = pairs[:, 1] - pairs[:, 0]
    ok = (d >= options.min_stride_s) & (d <= options.max_stride_s)
    return pairs[ok], pairs[~ok]


def normalise_strides(
    time_s: np.ndarray, values: np.ndarray, bounds: np.ndarray, length: int
) -> np.ndarray:
    """Time-normalise strides to ``length`` samples each.

    Sample j of stride s is ``values`` interpolated linearly at
    ``start_s + j / length * (end_s - start_s)``, j = 0 .. length-1 (phase j/length; the end heel
    strike itself is the next stride's sample 0).

    Args:
        time_s: Increasing sample times (s), shape (T,).
        values: Samples, shape (T, C) (degrees).
        bounds: Stride start/end times (s), shape (S, 2).
        length: Samples per normalised stride.

    Returns:
        Array (S, length, C).
    """
    b = np.asarray(bounds, dtype=np.float64).reshape(-1, 2)
    phase = np.arange(length) / length
    when = b[:, :1] + phase[None, :] * (b[:, 1:] - b[:, :1])  # (S, length)
    v = np.asarray(values, dtype=np.float64)
    out = np.stack([np.interp(when.ravel(), time_s, v[:, c]) for c in range(v.shape[1])], axis=-1)
    return out.reshape(b.shape[0], length, v.shape[1])
