"""Right heel strikes and strides from a uniformly sampled signal: what ``train`` and live teaching
find strides with (numpy only).

Heel-strike detection rule (documented in docs/training.md): the signal (right foot angle for level
and ramp walking, right shank angle for stairs, both degrees, sagittal plane, positive =
toes/shank rotated forward) is resampled to a uniform rate, then ``find_peaks`` keeps maxima that

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

MIN_STRIDE_S = 0.6
"""Shortest accepted stride (s): faster than brisk walking/jogging cadence (~200 strides/min is 0.3 s/step)."""

MAX_STRIDE_S = 2.5
"""Longest accepted stride (s): slower than the paper's slowest mode (PR stair ascent, ~1.85 s)."""

MIN_PROMINENCE_DEG = 20.0
"""Smallest peak prominence (deg) accepted as a heel strike."""


@dataclass(frozen=True)
class DetectionOptions:
    """Parameters of heel-strike detection and stride segmentation (seconds, degrees)."""

    min_stride_s: float = MIN_STRIDE_S
    max_stride_s: float = MAX_STRIDE_S
    min_prominence_deg: float = MIN_PROMINENCE_DEG


def find_peaks(x: np.ndarray, distance: int, prominence: float) -> np.ndarray:
    """Indices of the maxima of ``x`` that ``scipy.signal.find_peaks(x, distance=distance,
    prominence=prominence)`` returns: local maxima (a flat top counts once, at its middle sample,
    rounded down), the highest first keeping the others ``distance`` samples away, then those of
    at least ``prominence``."""
    x = np.asarray(x, dtype=np.float64)
    if x.size < 3:
        return np.empty(0, dtype=np.intp)
    starts = np.flatnonzero(np.r_[True, x[1:] != x[:-1]])  # runs of equal samples
    ends = np.r_[starts[1:] - 1, x.size - 1]
    v = x[starts]
    top = np.flatnonzero((v[1:-1] > v[:-2]) & (v[1:-1] > v[2:])) + 1
    peaks = (starts[top] + ends[top]) // 2
    keep = np.ones(peaks.size, dtype=bool)
    for j in np.argsort(x[peaks])[::-1]:  # scipy's order, ties included
        if keep[j]:
            near = np.abs(peaks - peaks[j]) < distance
            near[j] = False
            keep &= ~near
    peaks = peaks[keep]
    prominent = np.zeros(peaks.size, dtype=bool)
    for i, p in enumerate(peaks):
        higher_left = np.flatnonzero(x[:p] > x[p])
        higher_right = np.flatnonzero(x[p + 1:] > x[p])
        left = x[(higher_left[-1] + 1 if higher_left.size else 0):p + 1].min()
        right = x[p:(p + 1 + higher_right[0] if higher_right.size else x.size)].min()
        prominent[i] = x[p] - max(left, right) >= prominence
    return peaks[prominent]


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
    peaks = find_peaks(x, distance, options.min_prominence_deg)
    peaks = peaks[(peaks > 0) & (peaks < x.size - 1)]
    y0, y1, y2 = x[peaks - 1], x[peaks], x[peaks + 1]
    denom = y0 - 2.0 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(denom < 0, 0.5 * (y0 - y2) / denom, 0.0)
    return t[peaks] + np.clip(delta, -0.5, 0.5) * dt


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
