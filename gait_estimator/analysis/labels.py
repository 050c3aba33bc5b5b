"""Mode labels for recordings: whole-file modes, time-range files, labels from stride durations.

Label range file (CSV, ``#`` starts a comment line)::

    start_s,end_s,mode
    6.722,11.265,RA

A sample at time t gets ``mode`` when ``start_s <= t < end_s``; samples in no range are
unlabelled (''). Ranges must not overlap. A recording's range file may sit beside it as
``<name>.labels.csv`` (``labels_beside``): the bundled LG_2_Ramp's does.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..core.errors import GaitEstimatorError
from ..io.atomic import atomic_open
from ..io.recording import Recording

LABELS_SUFFIX = ".labels.csv"


def labels_beside(recording: str | Path) -> Path | None:
    """The label range file beside ``recording`` (``walk.csv``, ``walk_bag/`` ->
    ``walk.labels.csv``), or None when there is none."""
    p = Path(recording)
    q = p.with_name((p.stem if p.suffix and not p.is_dir() else p.name) + LABELS_SUFFIX)
    return q if q.is_file() else None


@dataclass(frozen=True)
class LabelRange:
    """Samples with ``start_s <= time < end_s`` (seconds, recording time) have mode ``mode``."""

    start_s: float
    end_s: float
    mode: str


def read_label_ranges(path: str | Path) -> list[LabelRange]:
    """Read a label range file (see module docstring); errors name the file and line."""
    p = Path(path)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise GaitEstimatorError(f"{p}: cannot read label ranges ({exc})") from None
    rows = [(n, line) for n, line in enumerate(lines, start=1) if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise GaitEstimatorError(f"{p}: no label ranges (expected a header 'start_s,end_s,mode' and rows)")
    header = [h.strip() for h in next(csv.reader([rows[0][1]]))]
    need = ("start_s", "end_s", "mode")
    missing = [c for c in need if c not in header]
    if missing:
        raise GaitEstimatorError(f"{p}:{rows[0][0]}: missing column(s) {', '.join(missing)} in the header")
    col = {c: header.index(c) for c in need}
    out: list[LabelRange] = []
    for lineno, line in rows[1:]:
        cells = [c.strip() for c in next(csv.reader([line]))]
        if len(cells) < len(header):
            raise GaitEstimatorError(f"{p}:{lineno}: expected {len(header)} columns, got {len(cells)}")
        try:
            start, end = float(cells[col["start_s"]]), float(cells[col["end_s"]])
        except ValueError:
            raise GaitEstimatorError(f"{p}:{lineno}: start_s/end_s must be numbers, got {line.strip()!r}") from None
        mode = cells[col["mode"]]
        if not (math.isfinite(start) and math.isfinite(end) and end > start):
            raise GaitEstimatorError(f"{p}:{lineno}: end_s ({end:g}) must be greater than start_s ({start:g})")
        if not mode:
            raise GaitEstimatorError(f"{p}:{lineno}: empty mode")
        out.append(LabelRange(start, end, mode))
    out.sort(key=lambda r: r.start_s)
    for a, b in itertools.pairwise(out):
        if b.start_s < a.end_s:
            raise GaitEstimatorError(
                f"{p}: ranges overlap: {a.mode} {a.start_s:g}-{a.end_s:g} s and {b.mode} {b.start_s:g}-{b.end_s:g} s"
            )
    return out


def write_label_ranges(ranges: Sequence[LabelRange], path: str | Path, comments: Sequence[str] = ()) -> Path:
    """Write ``ranges`` as a label range file, ``comments`` as leading ``#`` lines (atomically)."""
    p = Path(path)
    with atomic_open(p, "w", newline="") as f:
        for c in comments:
            for line in str(c).splitlines() or [""]:
                f.write(f"# {line}".rstrip() + "\n")
        w = csv.writer(f)
        w.writerow(["start_s", "end_s", "mode"])
        for r in ranges:
            w.writerow([f"{r.start_s:.4f}", f"{r.end_s:.4f}", r.mode])
    return p


def labels_from_ranges(time_s: np.ndarray, ranges: Sequence[LabelRange]) -> np.ndarray:
    """Per-sample labels (object array, '' = unlabelled) for sample times ``time_s`` (s)."""
    t = np.asarray(time_s, dtype=np.float64)
    labels = np.full(t.shape, "", dtype=object)
    for r in ranges:
        labels[(t >= r.start_s) & (t < r.end_s)] = r.mode
    return labels


def with_labels(rec: Recording, labels: np.ndarray) -> Recording:
    """A copy of ``rec`` with per-sample ``labels`` (shape (T,))."""
    lab = np.asarray(labels, dtype=object)
    if lab.shape != (len(rec),):
        raise GaitEstimatorError(f"{rec.source}: {lab.shape[0]} labels for {len(rec)} samples")
    return replace(rec, labels=lab)


def with_mode(rec: Recording, mode: str) -> Recording:
    """A copy of ``rec`` with every sample labelled ``mode`` (``--mode NAME``)."""
    return with_labels(rec, np.full(len(rec), mode, dtype=object))


def with_ranges(rec: Recording, ranges: Sequence[LabelRange]) -> Recording:
    """A copy of ``rec`` labelled from time ranges (replacing any ``mode`` column)."""
    return with_labels(rec, labels_from_ranges(rec.time_s, ranges))


def parse_label_map(text: str | None) -> dict[str, tuple[str, ...]]:
    """Parse ``truth=pred,...`` (``pred`` may be ``A|B`` for several accepted predictions, or
    empty to leave that truth label out of the evaluation)."""
    out: dict[str, tuple[str, ...]] = {}
    if not text:
        return out
    for item in text.split(","):
        if not item.strip():
            continue
        if "=" not in item:
            raise GaitEstimatorError(f"--label-map: expected truth=pred, got {item.strip()!r}")
        truth, pred = (s.strip() for s in item.split("=", 1))
        if not truth:
            raise GaitEstimatorError(f"--label-map: empty truth label in {item.strip()!r}")
        out[truth] = tuple(p.strip() for p in pred.split("|") if p.strip())
    return out


# ---------------------------------------------------------------------------------------------
# Labels from stride durations


@dataclass(frozen=True)
class StrideLabel:
    """One stride's duration-based class."""

    start_s: float
    end_s: float
    nearest: str  # mode whose kernel stride duration is nearest ('' when none is within tolerance)
    relative_error: float  # (duration - nearest kernel duration) / nearest kernel duration
    steady: bool  # nearest equals that of both neighbouring strides (contiguous strides)


def duration_labels(
    bounds: np.ndarray,
    kernel_durations_s: Mapping[str, float],
    tolerance: float = 0.15,
) -> list[StrideLabel]:
    """Classify strides by the nearest kernel stride duration and mark steady ones.

    A stride (start/end heel-strike times, s) is given the mode whose kernel stride duration
    ``N_m / rate`` is nearest to its own duration, provided the relative difference is within
    ``tolerance``; otherwise none. It is *steady* when the strides immediately before and after
    it exist (share its heel strikes) and have the same nearest mode, i.e. the cadence did not
    change across three consecutive strides.
    """
    b = np.asarray(bounds, dtype=np.float64).reshape(-1, 2)
    names = list(kernel_durations_s)
    ref = np.array([kernel_durations_s[n] for n in names], dtype=np.float64)
    d = b[:, 1] - b[:, 0]
    best = np.abs(d[:, None] - ref[None, :]).argmin(axis=1) if ref.size else np.zeros(len(d), dtype=int)
    rel = d / ref[best] - 1.0 if ref.size else np.full(len(d), np.inf)
    nearest = [names[k] if abs(r) <= tolerance else "" for k, r in zip(best, rel, strict=True)]
    out = []
    for i in range(len(d)):
        prev_ok = i > 0 and np.isclose(b[i - 1, 1], b[i, 0]) and nearest[i - 1] == nearest[i]
        next_ok = i + 1 < len(d) and np.isclose(b[i + 1, 0], b[i, 1]) and nearest[i + 1] == nearest[i]
        steady = bool(nearest[i] and prev_ok and next_ok)
        out.append(StrideLabel(float(b[i, 0]), float(b[i, 1]), nearest[i], float(rel[i]), steady))
    return out


def merge_steady(strides: Sequence[StrideLabel], steady_only: bool = True) -> list[LabelRange]:
    """Label ranges covering the steady strides (or, with ``steady_only=False``, every stride
    with a nearest mode), adjacent strides of one mode merged."""
    out: list[LabelRange] = []
    for s in strides:
        if not (s.steady if steady_only else s.nearest):
            continue
        if out and out[-1].mode == s.nearest and math.isclose(out[-1].end_s, s.start_s, abs_tol=1e-9):
            out[-1] = LabelRange(out[-1].start_s, s.end_s, s.nearest)
        else:
            out.append(LabelRange(s.start_s, s.end_s, s.nearest))
    return out
