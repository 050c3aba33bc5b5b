"""Uniform resampling, right heel-strike detection and stride segmentation.

Shared by ``train`` (kernels are averages of strides), ``evaluate`` (phase truth runs linearly
from one right heel strike to the next) and the label tools.

Heel strikes are found by ``core.strides`` (its rule: docs/training.md); this module adds
the recording side: resampling, where the signal comes from, strides per recording.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..core.errors import RecordingError
from ..core.strides import DetectionOptions, detect_peaks
from ..io.recording import Recording

HEEL_STRIKE_SOURCES = ("auto", "column", "right_foot", "right_shank")
"""``--heel-strikes`` choices; ``auto`` = column if present, else right_foot if present, else right_shank."""

_SIGNAL_COLUMNS = {"right_foot": "right_foot_deg", "right_shank": "right_shank_deg"}


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

