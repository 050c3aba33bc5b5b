"""A mode's kernel from its candidate strides, as ``train`` builds it (docs/training.md, "`train`:
rules") and live teaching too: outliers rejected per mode, first by duration, then by shape
(``reject_outliers``); the kept strides time-normalised to N_m = round(mean kept duration x rate)
samples and averaged sample by sample: that is the kernel (degrees, row 0 = right heel strike).

Outlier rule (robust, one pass each; sigma = 1.4826 x median absolute deviation):

* duration: reject when |d - median(d)| > max(3.5 sigma_d, 10 % of median(d));
* shape: every stride time-normalised to round(median duration x rate) samples; its distance
  is the RMS (over samples and the 4 channels, deg) from the sample-wise median stride; reject
  when distance > median(dist) + max(3.5 sigma_dist, median(dist)) (i.e. also at least twice
  the typical distance).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from .adapt import robust_sigma
from .errors import GaitEstimatorError
from .kernels import REFERENCE_MODE_IDS, KernelMode, make_mode
from .states import FIT_LIMIT_KEY
from .strides import DetectionOptions, normalise_strides


class Samples(Protocol):
    """Uniformly resampled stretch of a recording (a ``Recording``): times (s), angles (deg)."""

    time_s: np.ndarray
    angles_deg: np.ndarray


@dataclass(frozen=True)
class OutlierRule:
    """Robust outlier thresholds (see module docstring).

    Attributes:
        duration_sigmas: Reject strides whose duration is more than this many robust sigmas from the median...
        duration_floor: ...and more than this fraction of the median duration from it.
        shape_sigmas: Reject strides whose shape distance exceeds the median by this many robust sigmas...
        shape_floor: ...and by this multiple of the median distance.
    """

    duration_sigmas: float = 3.5
    duration_floor: float = 0.10
    shape_sigmas: float = 3.5
    shape_floor: float = 1.0


@dataclass(frozen=True)
class TrainOptions:
    """Everything ``train_library`` needs besides the recordings."""

    heel_strikes: str = "auto"
    rate_hz: float | None = None
    min_strides: int = 3
    detection: DetectionOptions = field(default_factory=DetectionOptions)
    outliers: OutlierRule = field(default_factory=OutlierRule)


@dataclass(frozen=True)
class StrideInfo:
    """One candidate stride of a mode (times in seconds of its recording)."""

    source: str
    start_s: float
    duration_s: float
    shape_rms_deg: float = math.nan
    rejected: str = ""  # '' = kept, else the reason

    def as_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"source": self.source, "start_s": round(self.start_s, 4), "duration_s": round(self.duration_s, 4)}
        if math.isfinite(self.shape_rms_deg):
            d["shape_rms_deg"] = round(self.shape_rms_deg, 3)
        if self.rejected:
            d["reason"] = self.rejected
        return d


def reject_outliers(durations_s: np.ndarray, strides: np.ndarray, rule: OutlierRule) -> tuple[list[str], np.ndarray]:
    """Apply the duration then the shape rule.

    Args:
        durations_s: Stride durations (s), shape (S,).
        strides: Strides time-normalised to one length, (S, L, 4), degrees.
        rule: Thresholds.

    Returns:
        (reasons, distances): per stride '' (kept) or why it was rejected; the shape distance
        (RMS deg from the median stride of the duration-kept strides; nan when not computed).
    """
    d = np.asarray(durations_s, dtype=np.float64)
    reasons = [""] * d.size
    med = float(np.median(d))
    limit = max(rule.duration_sigmas * robust_sigma(d), rule.duration_floor * med)
    for i in np.flatnonzero(np.abs(d - med) > limit):
        reasons[i] = f"duration {d[i]:.3f} s deviates from the median {med:.3f} s by more than {limit:.3f} s"
        k = round(d[i] / med)
        if k >= 2 and abs(d[i] - k * med) <= k * limit:  # the length of k strides
            reasons[i] += f" (about {k} strides: {k - 1} heel strike{'s' if k > 2 else ''} between not found)"
    keep = np.array([not r for r in reasons])
    dist = np.full(d.size, np.nan)
    if keep.sum() >= 2:
        template = np.median(strides[keep], axis=0)
        dist = np.sqrt(np.mean((strides - template[None]) ** 2, axis=(1, 2)))
        kd = dist[keep]
        mdist = float(np.median(kd))
        climit = mdist + max(rule.shape_sigmas * robust_sigma(kd), rule.shape_floor * mdist)
        for i in np.flatnonzero(keep & (dist > climit)):
            reasons[i] = f"shape: RMS {dist[i]:.2f} deg from the median stride exceeds {climit:.2f} deg"
    return reasons, dist


def judge_strides(parts: list[tuple[str, Samples, np.ndarray]], rate: float,
                  rule: OutlierRule) -> tuple[np.ndarray, list[str], np.ndarray]:
    """The candidate strides of ``parts`` (as ``train_mode``'s) time-normalised to round(median
    duration x ``rate``) samples and judged by ``reject_outliers``: (durations s, reasons, distances)."""
    durations = np.concatenate([b[:, 1] - b[:, 0] for _, _, b in parts])
    base_len = max(2, round(float(np.median(durations)) * rate))
    normalised = np.concatenate([normalise_strides(u.time_s, u.angles_deg, b, base_len) for _, u, b in parts])
    return (durations, *reject_outliers(durations, normalised, rule))


def train_mode(
    mode: str, parts: list[tuple[str, Samples, np.ndarray]], rate: float, opts: TrainOptions
) -> tuple[KernelMode, list[StrideInfo]]:
    """One mode's kernel from its candidate strides (module docstring).

    Args:
        mode: Mode name.
        parts: Per source: (source name, its uniform resampling at ``rate``, stride bounds (S, 2) s).
        rate: The uniform rate (Hz), stored with the kernel.
        opts: Minimum strides and outlier rule.

    Raises:
        GaitEstimatorError: fewer than ``opts.min_strides`` strides left after outlier rejection.
    """
    durations, reasons, dist = judge_strides(parts, rate, opts.outliers)
    keep = np.array([not r for r in reasons])
    starts = np.concatenate([b[:, 0] for _, _, b in parts])
    srcs = [s for s, _, b in parts for _ in range(len(b))]
    infos = [
        StrideInfo(srcs[i], float(starts[i]), float(durations[i]), float(dist[i]), reasons[i]) for i in range(len(durations))
    ]
    n_kept = int(keep.sum())
    if n_kept < opts.min_strides:
        raise GaitEstimatorError(
            f"mode {mode!r}: only {n_kept} usable stride(s), need at least {opts.min_strides} "
            f"({len(durations)} found, {len(durations) - n_kept} rejected as outliers)"
        )
    kd = durations[keep]
    length = max(2, round(float(kd.mean()) * rate))
    kept_parts = []
    i = 0
    for _, u, b in parts:
        k = keep[i : i + len(b)]
        i += len(b)
        if k.any():
            kept_parts.append(normalise_strides(u.time_s, u.angles_deg, b[k], length))
    strides = np.concatenate(kept_parts)
    kernel = strides.mean(axis=0)
    spread = np.sqrt(np.mean((strides - kernel[None]) ** 2, axis=(1, 2)))
    info = {
        "strides": n_kept,
        "strides_found": len(durations),
        "duration_mean_s": round(float(kd.mean()), 5),
        "duration_std_s": round(float(kd.std(ddof=1)) if n_kept > 1 else 0.0, 5),
        "duration_min_s": round(float(kd.min()), 5),
        "duration_max_s": round(float(kd.max()), 5),
        "stride_rms_from_kernel_deg": round(float(spread.mean()), 4),
        FIT_LIMIT_KEY: round(float(spread.max()), 4),  # the worst stride's RMS from the kernel
        "sample_rate_hz": rate,
        "rejected": [s.as_dict() for s in infos if s.rejected],
        "sources": sorted({s for s, _, _ in parts}),
    }
    return make_mode(mode, kernel, rate, REFERENCE_MODE_IDS.get(mode, 0), info), infos
