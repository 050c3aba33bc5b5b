"""Evaluation figures (PNG): confusion matrix, phase error per mode, time series.

Uses matplotlib's object API with the Agg canvas only (no pyplot, no display needed, the global
backend is left alone).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from .evaluate import Aligned

_DPI = 110


def _save(fig: Figure, path: str | Path) -> Path:
    """Lay ``fig`` out and write it as PNG."""
    p = Path(path)
    fig.tight_layout()
    FigureCanvasAgg(fig)
    fig.savefig(p, dpi=_DPI)
    return p


def plot_confusion(metrics: Mapping[str, Any], path: str | Path, title: str = "") -> Path:
    """Confusion matrix: rows = truth labels that occur, columns = all predicted labels; each cell
    shows the count and the percentage of its row; colour = row percentage."""
    conf = metrics["confusion"]
    names = list(conf["labels"])
    mat = np.asarray(conf["matrix"], dtype=np.int64).reshape(len(names), len(names))
    rows = [i for i in range(len(names)) if mat[i].sum() > 0]
    predicted = set(conf.get("prediction_modes", names))
    cols = [j for j in range(len(names)) if names[j] in predicted or mat[:, j].sum() > 0]
    sub = mat[np.ix_(rows, cols)] if rows else np.zeros((1, len(cols)), dtype=np.int64)
    pct = 100.0 * sub / np.maximum(sub.sum(axis=1, keepdims=True), 1)
    fig = Figure(figsize=(max(7.5, 1.1 * len(cols) + 2.2), 0.8 * max(len(rows), 1) + 1.8))
    ax = fig.add_subplot()
    im = ax.imshow(pct, cmap="Blues", vmin=0, vmax=100, aspect="auto")
    for r in range(sub.shape[0]):
        for c in range(sub.shape[1]):
            if sub[r, c] or pct[r, c]:
                color = "white" if pct[r, c] > 60 else "black"
                ax.text(c, r, f"{sub[r, c]}\n{pct[r, c]:.1f} %", ha="center", va="center", fontsize=8, color=color)
    per = metrics.get("per_mode", {})
    for r, i in enumerate(rows):
        for c, j in enumerate(cols):
            if names[j] in per.get(names[i], {}).get("accepted_predictions", ()):
                ax.add_patch(Rectangle((c - 0.5, r - 0.5), 1, 1, fill=False, edgecolor="tab:green", lw=2, clip_on=False))
    ax.set_xticks(range(len(cols)), [names[j] for j in cols])
    ax.set_yticks(range(len(rows)), [names[i] for i in rows])
    ax.set_xlabel("predicted mode (green frame: counted as correct)")
    ax.set_ylabel("true mode")
    acc = metrics.get("accuracy")
    head = "confusion matrix" + (f" (accuracy {100 * acc:.1f} %)" if acc is not None else "")
    ax.set_title((title + "\n" if title else "") + head)
    fig.colorbar(im, ax=ax, label="% of true-mode samples")
    return _save(fig, path)


def plot_phase_error(metrics: Mapping[str, Any], path: str | Path, title: str = "") -> Path:
    """Bars of mean +/- std phase error (% of a stride) per true mode, correctly classified samples."""
    per = metrics["per_mode"]
    names = [n for n, pm in per.items() if pm["phase_error_mean"] is not None]
    means = np.array([100 * per[n]["phase_error_mean"] for n in names])
    stds = np.array([100 * per[n]["phase_error_std"] for n in names])
    fig = Figure(figsize=(max(7.0, 1.0 * len(names) + 2.5), 3.8))
    ax = fig.add_subplot()
    if names:
        x = np.arange(len(names))
        ax.bar(x, means, yerr=stds, capsize=4, color="tab:blue", alpha=0.8)
        for i, n in enumerate(names):
            pm = per[n]
            top = means[i] + stds[i] + 0.02 * max(1.0, float((means + stds).max()))
            ax.text(i, top, f"{means[i]:.2f} %\nn={pm['phase_error_samples']}", ha="center", va="bottom", fontsize=7)
        ax.set_xticks(x, names)
        ax.set_ylim(0, max(1.0, float((means + stds).max()) * 1.35))
    else:
        ax.text(0.5, 0.5, "no phase truth", ha="center", va="center", transform=ax.transAxes)
    overall = metrics.get("phase_error_mean")
    if overall is not None:
        ax.axhline(100 * overall, color="k", ls="--", lw=0.8, label=f"all modes {100 * overall:.2f} %")
        ax.legend(loc="upper left", fontsize=8)
    ax.set_ylabel("phase error (% of stride)")
    ax.set_xlabel("true mode")
    ax.set_title((title + "\n" if title else "") + "phase error, correctly classified samples (mean ± std)")
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, path)


def _break_wraps(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaNs where a phase series wraps (drops by more than half a stride) or has gaps."""
    y = y.astype(np.float64)
    cut = np.flatnonzero((np.abs(np.diff(y)) > 0.5) | ~np.isfinite(y[1:]) | ~np.isfinite(y[:-1])) + 1
    return np.insert(t, cut, np.nan), np.insert(y, cut, np.nan)


def _break_changes(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaNs where a piecewise-constant series changes value (no vertical connectors)."""
    cut = np.flatnonzero(y[1:] != y[:-1]) + 1
    return np.insert(t.astype(np.float64), cut, np.nan), np.insert(y, cut, np.nan)


def plot_timeseries(al: Aligned, path: str | Path, title: str = "", window: tuple[float, float] | None = None) -> Path:
    """Three panels over time (like the paper's multispeed figure): per-mode minimum SSE (log),
    predicted vs true mode, estimated vs true phase (% of stride). ``window`` = (start, end) s."""
    keep = np.ones(al.time_s.size, dtype=bool)
    if window is not None:
        keep = (al.time_s >= window[0]) & (al.time_s <= window[1])
    t = al.time_s[keep]
    fig = Figure(figsize=(14.5, 8.5))
    ax_sse, ax_mode, ax_ph = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [1.3, 1, 1.1]})
    colors = {m: f"C{i % 10}" for i, m in enumerate(al.sse_modes)}
    for i, m in enumerate(al.sse_modes):
        ax_sse.plot(t, np.maximum(al.sse[keep, i], 1e-3), lw=0.9, color=colors[m], label=m)
    ax_sse.set_yscale("log")
    ax_sse.set_ylabel("min SSE (deg²)")

    names = list(al.sse_modes)
    for m in [*al.pred[keep].tolist(), *al.truth[keep].tolist()]:
        if m and m not in names:
            names.append(m)
    level = {n: i for i, n in enumerate(names)}
    truth_y = np.array([level.get(x, np.nan) if x else np.nan for x in al.truth[keep]], dtype=np.float64)
    pred_y = np.array([level.get(x, np.nan) for x in al.pred[keep]], dtype=np.float64)  # '': not ready
    pred_ready = np.where(al.ready[keep], pred_y, np.nan)
    pred_wait = np.where(~al.ready[keep], pred_y, np.nan)
    tb, yb = _break_changes(t, truth_y)
    ax_mode.plot(tb, yb, color="0.3", lw=6, alpha=0.35, solid_capstyle="butt", label="true mode")
    ax_mode.plot(t, pred_ready, color="tab:red", lw=1.2, label="predicted")
    ax_mode.plot(t, pred_wait, color="tab:red", lw=1.0, ls=":", alpha=0.6, label="predicted (window not full)")
    wrong = al.evaluated[keep] & ~al.correct[keep]
    if wrong.any():
        ax_mode.plot(t[wrong], pred_y[wrong], "x", color="k", ms=3, label="misclassified")
    ax_mode.set_yticks(range(len(names)), names)
    ax_mode.set_ylim(-0.6, len(names) - 0.4)
    ax_mode.invert_yaxis()
    ax_mode.set_ylabel("mode")

    tt, yt = _break_wraps(t, 100 * al.phase_true[keep])
    ax_ph.plot(tt, yt, color="0.3", lw=3, alpha=0.4, label="true phase")
    te, ye = _break_wraps(t, 100 * np.where(al.ready[keep], al.phase[keep], np.nan))
    ax_ph.plot(te, ye, color="tab:blue", lw=0.9, label="estimated phase")
    ax_ph.set_ylim(-3, 103)
    ax_ph.set_ylabel("gait phase (%)")
    ax_ph.set_xlabel("time (s)")
    for ax in (ax_sse, ax_mode, ax_ph):
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.005, 1.0))
        ax.grid(alpha=0.3)
    if t.size:
        ax_ph.set_xlim(float(t[0]), float(t[-1]))
    fig.suptitle(title or "mode and phase over time")
    return _save(fig, path)
