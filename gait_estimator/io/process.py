"""Offline processing: run the matcher over a recording and write or summarise the predictions."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import missing_extra
from ..core.estimator import EstimateTrace, Estimator, EstimatorConfig, run_estimator
from ..core.kernels import RESERVED_MODE_NAMES, KernelLibrary
from .atomic import atomic_open
from .library_io import load_library
from .outputs import Predictions
from .readers import read_recording
from .recording import Recording
from .resources import DEFAULT_LIBRARY


@dataclass(frozen=True)
class Segment:
    """A run of consecutive ready samples with the same predicted mode."""

    mode: str
    start_s: float
    end_s: float
    samples: int


def predict(recording: Recording, library: KernelLibrary, config: EstimatorConfig | None = None) -> Predictions:
    """Run a fresh Estimator (default options: the ``default`` preset) over every sample of
    ``recording``; one prediction per sample. A recording without time stamps (time = sample /
    rate) counts as unstamped for ``resample: auto``."""
    est = Estimator(library, config, stamped=not recording.time_from_rate)
    trace = run_estimator(est, recording.time_s, recording.angles_deg, recording.index)
    return Predictions(trace.time_s, trace.sample, trace, est.adapted_library() if est.adapter else None)


def run_recording(source: str | Path | Recording, kernels: str | Path | KernelLibrary = DEFAULT_LIBRARY,
                  config: EstimatorConfig | None = None) -> EstimateTrace:
    """Run a fresh Estimator over a whole recording: one estimate per input sample.

    Args:
        source: A recording (project or reference CSV, rosbag2 directory/.mcap/.db3) or a
            ``Recording``; sources without time stamps are timed at the library's rate.
        kernels: Kernel library: a file, a directory, a bundled name or a ``KernelLibrary``.
        config: Estimator options; None = the ``default`` preset.

    Raises:
        GaitEstimatorError: an unreadable recording or library (one line naming it).
    """
    lib = kernels if isinstance(kernels, KernelLibrary) else load_library(kernels)
    try:
        rec = source if isinstance(source, Recording) else read_recording(source, rate_hz=lib.sample_rate_hz)
    except ImportError as exc:  # a bag without the 'bags' extra
        raise missing_extra(exc) or exc from None
    return predict(rec, lib, config).trace


PREDICTION_COLUMNS = ("time_s", "sample", "mode", "phase", "ready")
"""First columns of the predictions CSV; then sse_<mode> per mode, then EXTRA_COLUMNS."""
EXTRA_COLUMNS = ("confidence", "fit_rms_deg", "held", "phase_rate", "raw_mode", "cadence_ratio", "state")


def write_predictions_csv(pred: Predictions, path: str | Path) -> Path:
    """Write ``time_s, sample, mode, phase, ready, sse_<mode>..., confidence, fit_rms_deg, held,
    phase_rate, raw_mode, cadence_ratio, state`` (mode: the reported mode, ``stand``, ``unknown``
    or empty; match error in deg^2, or deg^2 per sample with ``normalize_error``; fit in deg;
    phase rate in strides/s; cadence ratio nan with one time scale; state: ``EstimateState``),
    atomically (the old file or the new one, never a part)."""
    p = Path(path)
    tr = pred.trace
    names = np.asarray(tr.mode_names, dtype=object)
    with atomic_open(p, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([*PREDICTION_COLUMNS, *(f"sse_{m}" for m in tr.mode_names), *EXTRA_COLUMNS])
        for i in range(len(pred.time_s)):
            w.writerow(
                [
                    f"{pred.time_s[i]:.6f}",
                    int(pred.sample[i]),
                    tr.mode[i],
                    f"{tr.phase[i]:.9f}",
                    int(tr.ready[i]),
                    *(f"{v:.9g}" for v in tr.sse[i]),
                    f"{tr.confidence[i]:.6g}",
                    f"{tr.fit_rms_deg[i]:.6g}",
                    int(tr.held[i]),
                    f"{tr.phase_rate[i]:.6g}",
                    names[tr.raw_mode_index[i]],
                    f"{tr.cadence_ratio[i]:.6g}",
                    int(tr.state[i]),
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
    names = np.asarray(tr.modes, dtype=object)[ready]
    breaks = np.flatnonzero((names[1:] != names[:-1]) | (np.diff(ready) != 1)) + 1
    for run in np.split(np.arange(ready.size), breaks):
        first, last = ready[run[0]], ready[run[-1]]
        out.append(Segment(str(names[run[0]]), float(pred.time_s[first]), float(pred.time_s[last]), run.size))
    return out


def format_summary(pred: Predictions, library: KernelLibrary, source: str) -> str:
    """A human-readable summary: counts per mode and the mode segments with their times."""
    tr = pred.trace
    n = len(pred.time_s)
    ready = int(tr.ready.sum())
    first = np.flatnonzero(tr.ready)
    filled = f"window full after {int(first[0]) + 1} samples" if first.size else "window never full"
    lines = [f"{source}: {n} samples, {ready} ready ({filled}); library '{library.name}' ({len(library)} modes)"]
    if ready:
        names, counts = np.unique(np.asarray(tr.modes, dtype=str)[tr.ready], return_counts=True)
        order = {m: i for i, m in enumerate([*tr.mode_names, *RESERVED_MODE_NAMES])}
        share = ", ".join(f"{m} {c / ready:.1%}" for m, c in sorted(zip(names, counts, strict=True),
                                                                      key=lambda mc: order.get(mc[0], len(order))))
        lines.append(f"predicted modes (ready samples): {share}")
    lines.append("segments:")
    for s in segments(pred):
        lines.append(f"  {s.start_s:8.2f} s - {s.end_s:8.2f} s  {s.mode:<8} ({s.samples} samples)")
    return "\n".join(lines)
