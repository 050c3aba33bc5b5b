"""Offline processing: run the matcher over a recording and write or summarise the predictions."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .kernels import KernelLibrary
from .matcher import IncrementalMatcher, MatchTrace
from .recording import Recording


@dataclass(frozen=True)
class Predictions:
    """Matcher output aligned with the recording samples it came from."""

    time_s: np.ndarray  # (T,) seconds, the input samples' times
    sample: np.ndarray  # (T,) index of each sample in the source recording
    trace: MatchTrace


@dataclass(frozen=True)
class Segment:
    """A run of consecutive ready samples with the same predicted mode."""

    mode: str
    start_s: float
    end_s: float
    samples: int


def predict(recording: Recording, library: KernelLibrary) -> Predictions:
    """Run a fresh IncrementalMatcher over every sample of ``recording``."""
    matcher = IncrementalMatcher(library)
    trace = matcher.run(recording.angles_deg)
    return Predictions(recording.time_s, np.asarray(recording.index), trace)


def write_predictions_csv(pred: Predictions, path: str | Path) -> Path:
    """Write ``time_s, sample, mode, phase, ready, sse_<mode>...`` (SSE in deg^2)."""
    p = Path(path)
    tr = pred.trace
    names = np.asarray(tr.mode_names, dtype=object)[tr.mode_index]
    with p.open("w", encoding="utf-8", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_s", "sample", "mode", "phase", "ready", *(f"sse_{m}" for m in tr.mode_names)])
        for i in range(len(pred.time_s)):
            w.writerow(
                [
                    f"{pred.time_s[i]:.6f}",
                    int(pred.sample[i]),
                    names[i],
                    f"{tr.phase[i]:.9f}",
                    int(tr.ready[i]),
                    *(f"{v:.9g}" for v in tr.sse[i]),
                ]
            )
    return p


def segments(pred: Predictions) -> list[Segment]:
    """Consecutive ready samples grouped by predicted mode."""
    tr = pred.trace
    out: list[Segment] = []
    ready = np.flatnonzero(tr.ready)
    if ready.size == 0:
        return out
    idx = tr.mode_index[ready]
    breaks = np.flatnonzero((np.diff(idx) != 0) | (np.diff(ready) != 1)) + 1
    for run in np.split(np.arange(ready.size), breaks):
        first, last = ready[run[0]], ready[run[-1]]
        out.append(Segment(tr.mode_names[idx[run[0]]], float(pred.time_s[first]), float(pred.time_s[last]), run.size))
    return out


def format_summary(pred: Predictions, library: KernelLibrary, source: str) -> str:
    """A human-readable summary: counts per mode and the mode segments with their times."""
    tr = pred.trace
    n = len(pred.time_s)
    ready = int(tr.ready.sum())
    lines = [
        f"{source}: {n} samples, {ready} ready (window full after {library.lengths.max()} samples); "
        f"library '{library.name}' ({len(library)} modes)"
    ]
    if ready:
        counts = np.bincount(tr.mode_index[tr.ready], minlength=len(library))
        share = ", ".join(f"{m} {c / ready:.1%}" for m, c in zip(tr.mode_names, counts, strict=True) if c)
        lines.append(f"predicted modes (ready samples): {share}")
    lines.append("segments:")
    for s in segments(pred):
        lines.append(f"  {s.start_s:8.2f} s - {s.end_s:8.2f} s  {s.mode:<8} ({s.samples} samples)")
    return "\n".join(lines)
