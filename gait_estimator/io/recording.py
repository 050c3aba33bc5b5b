"""Recordings: time-stamped segment angles, optionally with mode labels and heel strikes.

The CSV formats (``read_recording`` in ``io.readers`` also knows rosbag2 directories):

* the project CSV: a header row with ``time_s``, the four angle columns
  ``right_thigh_deg, left_thigh_deg, right_shank_deg, left_shank_deg`` (or ``_rad``), optional
  ``mode`` (label) and ``heel_strike`` (0/1) columns; any other numeric column (e.g.
  ``right_foot_deg``) is kept in ``extra``;
* the reference recording CSV (first line ``Dimension:4xT``, then channel names, then rows),
  which has no time column: time is sample index / rate.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import numpy as np

from ..core.channels import CHANNELS, N_CHANNELS
from ..core.errors import RecordingError
from .atomic import atomic_open
from .library_io import DEFAULT_REFERENCE_RATE_HZ
from .read_options import ReadOptions

R = TypeVar("R", bound="Recording")


@dataclass
class Recording:
    """Segment angles over time.

    Attributes:
        time_s: Sample times, seconds, strictly increasing, shape (T,).
        angles_deg: Segment angles, degrees, CHANNELS order, shape (T, 4).
        labels: Per-sample mode label ('' = unlabelled), shape (T,), or None.
        heel_strike: Per-sample right heel strike flag, shape (T,), or None.
        extra: Other numeric columns by name (e.g. ``right_foot_deg``), each shape (T,).
        source: Where the samples came from (for messages).
        index: Index of every sample in the source (rows skipped as bad leave gaps), shape (T,).
        skipped: Number of source samples dropped as bad, by reason.
        time_from_rate: True when the source had no time stamps and time_s = index / rate.
    """

    time_s: np.ndarray
    angles_deg: np.ndarray
    labels: np.ndarray | None = None
    heel_strike: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    source: str = ""
    index: np.ndarray | None = None
    skipped: dict[str, int] = field(default_factory=dict)
    time_from_rate: bool = False
    PER_SAMPLE: ClassVar[tuple[str, ...]] = ("time_s", "angles_deg", "labels", "heel_strike", "index")
    """The fields with one row per sample (None or an array)."""

    def __post_init__(self) -> None:
        if self.index is None:
            self.index = np.arange(len(self.time_s))

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def median_rate_hz(self) -> float:
        """1 / median sample interval (Hz); nan for fewer than two samples."""
        if len(self) < 2:
            return math.nan
        return float(1.0 / np.median(np.diff(self.time_s)))

    def slice(self, start: int | None = None, stop: int | None = None) -> Recording:
        """Samples whose source index is in [start, stop) (both optional)."""
        idx = self.index
        keep = np.ones(len(self), dtype=bool)
        if start is not None:
            keep &= idx >= start
        if stop is not None:
            keep &= idx < stop
        return self.select(keep)

    def select(self: R, keep: np.ndarray, skipped: dict[str, int] | None = None) -> R:
        """The samples where ``keep`` (bool, (T,)) is true: every PER_SAMPLE field and ``extra``;
        the same type, its other fields kept; ``skipped`` replaces the counts."""
        rows = {f: None if getattr(self, f) is None else getattr(self, f)[keep] for f in self.PER_SAMPLE}
        return replace(self, **rows, extra={k: v[keep] for k, v in self.extra.items()},
                       skipped=dict(self.skipped if skipped is None else skipped))


# ---------------------------------------------------------------------------------------------
# Reference recording CSV

_DIMENSION_RE = re.compile(r"^\s*(?:[^;]*;)*\s*Dimension:(?P<rows>\d+)x(?P<cols>\d+)")


def _first_line(p: Path) -> str:
    try:
        with p.open(encoding="utf-8") as f:
            return f.readline()
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{p}: cannot read ({exc})") from None


def is_reference_csv(p: Path) -> bool:
    return p.is_file() and p.suffix.lower() == ".csv" and bool(_DIMENSION_RE.match(_first_line(p)))


def read_reference_csv(p: Path, options: ReadOptions | None = None, /, **values: Any) -> Recording:
    """Read the reference ``Dimension:4xT`` CSV; time = sample index / ``options.rate_hz``."""
    rate_hz = ReadOptions.of(options, values).rate_hz
    rate = DEFAULT_REFERENCE_RATE_HZ if rate_hz is None else float(rate_hz)
    if not (math.isfinite(rate) and rate > 0):
        raise RecordingError(f"{p}: invalid sample rate {rate_hz!r} for a recording without time stamps")
    m = _DIMENSION_RE.match(_first_line(p))
    assert m is not None
    n_ch, n = int(m["rows"]), int(m["cols"])
    if n_ch != N_CHANNELS:
        raise RecordingError(f"{p}: Dimension says {n_ch} channels, expected {N_CHANNELS}")
    rows: list[list[float]] = []
    with p.open(encoding="utf-8") as f:
        f.readline()
        f.readline()
        for lineno, line in enumerate(f, start=3):
            if not line.strip():
                continue
            parts = line.split(",")[:N_CHANNELS]
            try:
                rows.append([float(v) for v in parts])
            except ValueError:
                raise RecordingError(f"{p}:{lineno}: non-numeric value in {line.strip()!r}") from None
            if len(rows[-1]) != N_CHANNELS:
                raise RecordingError(f"{p}:{lineno}: expected {N_CHANNELS} values, got {len(rows[-1])}")
    if len(rows) != n:
        raise RecordingError(f"{p}: Dimension says {n} samples but the file has {len(rows)} rows")
    angles = np.array(rows, dtype=np.float64).reshape(-1, N_CHANNELS)
    index = np.arange(len(angles))
    return _drop_non_finite(
        Recording(time_s=index / rate, angles_deg=angles, source=str(p), index=index, time_from_rate=True)
    )


# ---------------------------------------------------------------------------------------------
# Project CSV

ANGLE_COLUMNS_DEG = tuple(f"{c}_deg" for c in CHANNELS)
ANGLE_COLUMNS_RAD = tuple(f"{c}_rad" for c in CHANNELS)


def expected_columns(p: Path) -> str:
    """What a CSV that is no recording holds and what one needs, for a one-line error."""
    found = [c.strip() for c in _first_line(p).split(",") if c.strip()]
    shown = ", ".join(found[:12]) + (f" ... ({len(found)} columns)" if len(found) > 12 else "")
    return (f"columns {shown or '(none)'}; expected time_s, {', '.join(ANGLE_COLUMNS_DEG)} (or _rad), or a "
            "reference CSV (first line Dimension:4xT)")


def is_project_csv(p: Path) -> bool:
    return p.is_file() and p.suffix.lower() == ".csv" and "time_s" in _first_line(p)


def read_project_csv(p: Path, options: ReadOptions | None = None, /, **values: Any) -> Recording:
    """Read the project recording CSV (see module docstring); no option concerns it."""
    ReadOptions.of(options, values)
    header, body = read_csv_table(p)
    cols = {name: i for i, name in enumerate(header)}
    if "time_s" not in cols:
        raise RecordingError(f"{p}: missing column 'time_s'")
    if all(c in cols for c in ANGLE_COLUMNS_DEG):
        angle_cols, scale = ANGLE_COLUMNS_DEG, 1.0
    elif all(c in cols for c in ANGLE_COLUMNS_RAD):
        angle_cols, scale = ANGLE_COLUMNS_RAD, 180.0 / math.pi
    else:
        missing = [c for c in ANGLE_COLUMNS_DEG if c not in cols]
        raise RecordingError(f"{p}: missing angle column(s) {', '.join(missing)} (or the _rad equivalents)")
    numeric = ["time_s", *angle_cols]
    extra_names = [h for h in header if h not in (*numeric, "mode", "heel_strike") and h]
    values = np.empty((len(body), len(numeric)))
    extra = {h: np.full(len(body), np.nan) for h in extra_names}
    labels = np.empty(len(body), dtype=object) if "mode" in cols else None
    heel = np.zeros(len(body), dtype=bool) if "heel_strike" in cols else None
    for r, row in enumerate(body):
        lineno = r + 2
        if len(row) < len(header):
            raise RecordingError(f"{p}:{lineno}: expected {len(header)} columns, got {len(row)}")
        try:
            values[r] = [float(row[cols[c]]) for c in numeric]
            for h in extra_names:
                cell = row[cols[h]].strip()
                extra[h][r] = float(cell) if cell else np.nan
            if heel is not None:
                heel[r] = _flag(row[cols["heel_strike"]])
        except ValueError as exc:
            raise RecordingError(f"{p}:{lineno}: {exc}") from None
        if labels is not None:
            labels[r] = row[cols["mode"]].strip()
    for h in list(extra):  # keep only columns that are numeric throughout
        if np.all(np.isnan(extra[h])):
            del extra[h]
    time_s = values[:, 0]
    rec = Recording(
        time_s=time_s,
        angles_deg=values[:, 1:] * scale,
        labels=labels,
        heel_strike=heel,
        extra=extra,
        source=str(p),
    )
    rec = _drop_non_finite(rec)
    bad = np.flatnonzero(np.diff(rec.time_s) <= 0)
    if bad.size:
        row = int(rec.index[bad[0] + 1]) + 2
        prev, cur = rec.time_s[bad[0]], rec.time_s[bad[0] + 1]
        raise RecordingError(f"{p}:{row}: time_s is not strictly increasing ({cur:g} after {prev:g})")
    return rec


def read_csv_table(p: Path, what: str = "") -> tuple[list[str], list[list[str]]]:
    """(header, rows that are not blank) of a CSV file; RecordingError ``cannot read{what}`` (one line)."""
    try:
        with p.open(encoding="utf-8", newline="") as f:
            reader = csv.reader(f)
            header = [h.strip() for h in next(reader, [])]
            return header, [row for row in reader if row and any(c.strip() for c in row)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise RecordingError(f"{p}: cannot read{what} ({exc})") from None


def _flag(cell: str) -> bool:
    c = cell.strip().lower()
    if c in ("1", "true", "yes"):
        return True
    if c in ("0", "false", "no", ""):
        return False
    raise ValueError(f"heel_strike must be 0 or 1, got {cell!r}")


def _drop_non_finite(rec: Recording) -> Recording:
    """Drop samples whose time or angles are not finite, counting them in ``skipped``."""
    ok = np.isfinite(rec.time_s) & np.isfinite(rec.angles_deg).all(axis=1)
    if ok.all():
        return rec
    return rec.select(ok, {**rec.skipped, "non_finite": int((~ok).sum())})


def write_project_csv(rec: Recording, path: str | Path) -> Path:
    """Write ``rec`` as a project CSV (degrees), including labels, heel strikes and extra columns
    (atomically: the old file or the new one, never a part)."""
    p = Path(path)
    header = ["time_s", *ANGLE_COLUMNS_DEG, *rec.extra]
    if rec.labels is not None:
        header.append("mode")
    if rec.heel_strike is not None:
        header.append("heel_strike")
    with atomic_open(p, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(header)
        for i in range(len(rec)):
            row: list[Any] = [f"{rec.time_s[i]:.6f}", *(f"{v:.9f}" for v in rec.angles_deg[i])]
            row += [f"{rec.extra[k][i]:.9f}" for k in rec.extra]
            if rec.labels is not None:
                row.append(rec.labels[i])
            if rec.heel_strike is not None:
                row.append(int(rec.heel_strike[i]))
            w.writerow(row)
    return p
