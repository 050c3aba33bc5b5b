"""Training kernels: labelled recordings -> strides -> outlier rejection -> average per mode.

The rules (paper, "Data Processing"): docs/training.md, "`train`: rules". Resampling and heel
strikes come from ``strides``; outlier rejection and averaging from ``core.training`` (shared
with live teaching).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..core.errors import GaitEstimatorError
from ..core.kernels import KernelLibrary, KernelMode
from ..core.strides import stride_bounds
from ..core.training import StrideInfo, TrainOptions, train_mode
from ..io.recording import Recording
from .strides import heel_strikes, resample_uniform


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
