"""Training kernels: labelled recordings -> strides -> outlier rejection -> average per mode.

Pipeline (paper, "Data Processing"; docs/training.md, "`train`: rules"):

1. Each recording is resampled to one uniform rate (default: the median of the recordings'
   median sample rates), which the library records.
2. Right heel strikes come from the ``heel_strike`` column or are detected (``strides``);
   consecutive heel strikes 0.6-2.5 s apart form strides.
3. A stride belongs to mode m when every source sample in its inner 94 % (3 % of the duration
   left out at either end) is labelled m; strides spanning two labels are skipped (reported),
   unlabelled strides are ignored.
4. Outliers are rejected per mode, first by duration, then by shape (``reject_outliers``).
5. The kept strides are time-normalised to N_m = round(mean kept duration x rate) samples and
   averaged sample by sample: that is the kernel (degrees, row 0 = right heel strike).

Outlier rule (robust, one pass each; sigma = 1.4826 x median absolute deviation):

* duration: reject when |d - median(d)| > max(3.5 sigma_d, 10 % of median(d));
* shape: every stride time-normalised to round(median duration x rate) samples; its distance
  is the RMS (over samples and the 4 channels, deg) from the sample-wise median stride; reject
  when distance > median(dist) + max(3.5 sigma_dist, median(dist)) (i.e. also at least twice
  the typical distance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..core.errors import GaitEstimatorError
from ..core.kernels import KernelLibrary, KernelMode, make_mode
from ..core.states import FIT_LIMIT_KEY, fit_limit_deg
from ..io.library_io import REFERENCE_MODE_IDS
from ..io.recording import Recording
from .strides import DetectionOptions, heel_strikes, normalise_strides, resample_uniform, stride_bounds

MAD_TO_SIGMA = 1.4826
"""Scale from median absolute deviation to a normal standard deviation."""


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


@dataclass(frozen=True)
class TrainResult:
    """The trained library and what happened to every stride.

    Attributes:
        library: The kernels (one mode per label, in order of first appearance).
        strides: Per mode, every candidate stride (kept and rejected), in time order.
        skipped: Strides not used for any mode: spanning two labels (reported per recording).
        heel_strikes: Per recording source, how heel strikes were found and how many.
    """

    library: KernelLibrary
    strides: dict[str, list[StrideInfo]]
    skipped: list[dict[str, Any]]
    heel_strikes: dict[str, dict[str, Any]]


def robust_sigma(x: np.ndarray) -> float:
    """1.4826 x median absolute deviation of ``x`` (a robust standard deviation)."""
    x = np.asarray(x, dtype=np.float64)
    return float(MAD_TO_SIGMA * np.median(np.abs(x - np.median(x)))) if x.size else math.nan


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


def default_rate(recordings: Sequence[Recording]) -> float:
    """Median of the recordings' median sample rates (Hz)."""
    rates = [r.median_rate_hz for r in recordings]
    if not rates or not all(math.isfinite(r) and r > 0 for r in rates):
        raise GaitEstimatorError("cannot determine a sample rate: a recording has fewer than two samples")
    return float(np.median(rates))


LABEL_MARGIN = 0.03
"""Fraction of a stride at either end whose labels are not checked (absorbs heel-strike timing
differences of a few samples between how label ranges and strides were found)."""


def _stride_labels(rec: Recording, bounds: np.ndarray) -> list[set[str]]:
    """Set of labels of the source samples inside the inner part of each stride [start, end)."""
    assert rec.labels is not None
    margin = LABEL_MARGIN * (bounds[:, 1] - bounds[:, 0])
    lo = np.searchsorted(rec.time_s, bounds[:, 0] + margin, side="left")
    hi = np.searchsorted(rec.time_s, bounds[:, 1] - margin, side="left")
    return [set(rec.labels[a:b].tolist()) for a, b in zip(lo, hi, strict=True)]


def train_library(recordings: Sequence[Recording], name: str, options: TrainOptions | None = None) -> TrainResult:
    """Build a kernel library from labelled recordings.

    Args:
        recordings: Recordings with per-sample ``labels`` (''= unlabelled); any sampling.
        name: Library name.
        options: Heel-strike source, rate, minimum strides, detection and outlier parameters.

    Raises:
        GaitEstimatorError: missing labels/columns, no heel strikes, or a mode with fewer than
            ``min_strides`` usable strides (one line naming the file or mode).
    """
    opts = options or TrainOptions()
    if not recordings:
        raise GaitEstimatorError("no recordings to train from")
    rate = opts.rate_hz if opts.rate_hz is not None else default_rate(recordings)
    if not (math.isfinite(rate) and rate > 0):
        raise GaitEstimatorError(f"invalid sample rate {rate!r} Hz")

    order: list[str] = []
    segments: dict[str, list[tuple[str, Recording, np.ndarray]]] = {}  # mode -> [(source, uniform, bounds)]
    skipped: list[dict[str, Any]] = []
    hs_report: dict[str, dict[str, Any]] = {}
    for rec in recordings:
        if rec.labels is None:
            raise GaitEstimatorError(f"{rec.source}: no 'mode' column (give --mode NAME or --labels RANGES.csv)")
        for lab in rec.labels:
            if lab and lab not in order:
                order.append(lab)
        per_mode, hs_report[rec.source] = _labelled_strides(rec, rate, opts, skipped)
        uni = resample_uniform(rec, rate)
        for mode, rows in per_mode.items():
            segments.setdefault(mode, []).append((rec.source, uni, np.array(rows)))

    modes: list[KernelMode] = []
    report: dict[str, list[StrideInfo]] = {}
    for mode in order:
        parts = segments.get(mode, [])
        if not parts:
            raise GaitEstimatorError(
                f"mode {mode!r}: no complete stride inside its labelled samples (need {opts.min_strides})"
            )
        kernel, infos = train_mode(mode, parts, rate, opts)
        report[mode] = infos
        modes.append(kernel)
    lib = KernelLibrary(name, tuple(modes), _provenance([r.source for r in recordings], rate, opts, hs_report))
    return TrainResult(lib, report, skipped, hs_report)


def _labelled_strides(rec: Recording, rate: float, opts: TrainOptions,
                      skipped: list[dict[str, Any]]) -> tuple[dict[str, list[np.ndarray]], dict[str, Any]]:
    """The strides of ``rec`` within one label each, as (start, end) seconds per mode, and the
    heel-strike report of ``rec``; strides spanning labels are appended to ``skipped``."""
    hs = heel_strikes(rec, opts.heel_strikes, rate, opts.detection)
    if hs.times_s.size == 0:
        raise GaitEstimatorError(f"{rec.source}: no heel strikes found ({hs.method})")
    bounds, not_strides = stride_bounds(hs.times_s, opts.detection)
    report = {
        "method": hs.method,
        "heel_strikes": int(hs.times_s.size),
        "intervals_outside_limits": [[round(a, 4), round(b, 4)] for a, b in not_strides.tolist()],
    }
    per_mode: dict[str, list[np.ndarray]] = {}
    for (a, b), labs in zip(bounds, _stride_labels(rec, bounds), strict=True):
        named = labs - {""}
        if len(named) > 1 or (named and "" in labs):
            skipped.append({"source": rec.source, "start_s": round(float(a), 4), "duration_s": round(float(b - a), 4),
                            "reason": "spans labels " + ", ".join(sorted(repr(x) for x in labs))})
        elif named:
            per_mode.setdefault(next(iter(named)), []).append(np.array([a, b]))
    return per_mode, report


def _provenance(sources: list[str], rate: float, opts: TrainOptions, hs_report: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """The trained library's provenance: sources, version, rate, rules and the data's license."""
    provenance = {
        "source": "trained from " + ", ".join(sources),
        "built_by": f"gait-estimator train (gait_estimator {__version__})",
        "sample_rate_hz": rate,
        "heel_strikes": {k: v["method"] for k, v in hs_report.items()},
        "rules": {
            "stride_s": [opts.detection.min_stride_s, opts.detection.max_stride_s],
            "peak_prominence_deg": opts.detection.min_prominence_deg,
            "duration_outlier": f"|d - median| > max({opts.outliers.duration_sigmas:g} sigma, "
            f"{opts.outliers.duration_floor:g} x median)",
            "shape_outlier": f"rms > median + max({opts.outliers.shape_sigmas:g} sigma, {opts.outliers.shape_floor:g} x median)",
            "sigma": "1.4826 x median absolute deviation",
            "min_strides": opts.min_strides,
        },
    }
    lic = _data_license(sources)
    if lic:
        provenance["license"] = lic
    return provenance


def _data_license(sources: Sequence[str]) -> str:
    """Text of the first LICENSE file in the directory of a source recording or the one above
    (e.g. ``swge/LICENSE`` for ``swge/recordings/*.csv``), so kernels derived from licensed data
    carry its attribution; '' when there is none."""
    for src in sources:
        p = Path(src)
        if not p.exists():
            continue
        for parent in list(p.resolve().parents)[:2]:
            lic = parent / "LICENSE"
            if lic.is_file():
                try:
                    return lic.read_text(encoding="utf-8").strip()
                except (OSError, UnicodeDecodeError):
                    return ""
    return ""


def train_mode(
    mode: str, parts: list[tuple[str, Recording, np.ndarray]], rate: float, opts: TrainOptions
) -> tuple[KernelMode, list[StrideInfo]]:
    """One mode's kernel from its candidate strides (rules 4-5 of the module docstring).

    Args:
        mode: Mode name.
        parts: Per source: (source name, its uniform resampling at ``rate``, stride bounds (S, 2) s).
        rate: The uniform rate (Hz), stored with the kernel.
        opts: Minimum strides and outlier rule.

    Raises:
        GaitEstimatorError: fewer than ``opts.min_strides`` strides left after outlier rejection.
    """
    durations = np.concatenate([b[:, 1] - b[:, 0] for _, _, b in parts])
    base_len = max(2, round(float(np.median(durations)) * rate))
    normalised = np.concatenate([normalise_strides(u.time_s, u.angles_deg, b, base_len) for _, u, b in parts])
    reasons, dist = reject_outliers(durations, normalised, opts.outliers)
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
        FIT_LIMIT_KEY: round(fit_limit_deg(strides, kernel), 4),
        "sample_rate_hz": rate,
        "rejected": [s.as_dict() for s in infos if s.rejected],
        "sources": sorted({s for s, _, _ in parts}),
    }
    return make_mode(mode, kernel, rate, REFERENCE_MODE_IDS.get(mode, 0), info), infos


def format_report(result: TrainResult) -> str:
    """Human-readable summary: heel strikes per recording, per-mode strides and rejections."""
    lib = result.library
    lines = [f"library '{lib.name}': {len(lib)} modes at {lib.sample_rate_hz:.6g} Hz"]
    for src, hs in result.heel_strikes.items():
        lines.append(f"{src}: {hs['heel_strikes']} heel strikes ({hs['method']})")
        if hs["intervals_outside_limits"]:
            iv = ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in hs["intervals_outside_limits"])
            lines.append(f"  not strides (interval outside limits): {iv}")
    lines.append(f"{'mode':<10} {'strides':>7} {'found':>5} {'dur_mean_s':>10} {'dur_std_s':>9} {'N':>5} {'rms_deg':>7}")
    for m in lib.modes:
        i = m.info
        lines.append(
            f"{m.name:<10} {i['strides']:>7} {i['strides_found']:>5} {i['duration_mean_s']:>10.3f} "
            f"{i['duration_std_s']:>9.3f} {m.length:>5} {i['stride_rms_from_kernel_deg']:>7.2f}"
        )
    for mode, infos in result.strides.items():
        for s in infos:
            if s.rejected:
                lines.append(f"rejected {mode} stride at {s.start_s:.3f} s ({s.source}): {s.rejected}")
    for s in result.skipped:
        lines.append(f"skipped stride at {s['start_s']:.3f} s ({s['source']}): {s['reason']}")
    return "\n".join(lines)
