"""Evaluating predictions against truth: mode accuracy, confusion, phase error, transition delay.

Matching rows by time, evaluated rows, phase truth and error, ``steady`` and transitions are
defined in docs/training.md, "``evaluate``: definitions" (``match_times``, ``phase_truth``,
``time_in_run``, ``transitions`` implement them).

Switches (``switch_metrics``): a change of the reported mode between consecutive ready rows
(``stand`` and ``unknown`` included) is *false* when it falls on a labelled walking row (not
``stand``) and no truth label changed from ``SWITCH_WINDOW_S`` before it to ``SWITCH_LEAD_S``
after it (labels mark motion to a few tenths of a second); per minute of labelled walking.
Delay: from a change of the truth label to the first ready row reporting a mode accepted for
the new label, within ``SWITCH_WINDOW_S`` (else missed).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import GaitEstimatorError
from ..core.strides import DetectionOptions, stride_bounds
from ..io.recording import Recording, read_csv_table
from .strides import HeelStrikes, nearest_index


@dataclass(frozen=True)
class PredictionTable:
    """Rows of a predictions CSV (``time_s, sample, mode, phase, ready, sse_<mode>...``).

    Attributes:
        time_s: (T,) seconds. sample: (T,) source sample index. mode: (T,) predicted mode names.
        phase: (T,) [0, 1). ready: (T,) bool. sse: (T, M) deg^2 per mode, ``sse_modes`` order.
    """

    time_s: np.ndarray
    sample: np.ndarray
    mode: np.ndarray
    phase: np.ndarray
    ready: np.ndarray
    sse: np.ndarray
    sse_modes: list[str]
    source: str = ""


def read_predictions_csv(path: str | Path) -> PredictionTable:
    """Read a predictions CSV written by ``gait-estimator process``."""
    p = Path(path)
    header, rows = read_csv_table(p, " predictions")
    need = ("time_s", "mode", "phase", "ready")
    missing = [c for c in need if c not in header]
    if missing:
        raise GaitEstimatorError(f"{p}: missing column(s) {', '.join(missing)} (expected a 'gait-estimator process' CSV)")
    if not rows:
        raise GaitEstimatorError(f"{p}: no prediction rows")
    col = {h: i for i, h in enumerate(header)}
    sse_cols = [h for h in header if h.startswith("sse_")]
    try:
        cells = np.array(rows, dtype=object)
        if cells.ndim != 2 or cells.shape[1] != len(header):
            raise ValueError("rows have different numbers of columns than the header")
        time_s = cells[:, col["time_s"]].astype(np.float64)
        phase = cells[:, col["phase"]].astype(np.float64)
        ready = cells[:, col["ready"]].astype(np.int64).astype(bool)
        sample = cells[:, col["sample"]].astype(np.int64) if "sample" in col else np.arange(len(rows))
        sse = cells[:, [col[c] for c in sse_cols]].astype(np.float64) if sse_cols else np.empty((len(rows), 0))
    except ValueError as exc:
        raise GaitEstimatorError(f"{p}: malformed predictions ({exc})") from None
    mode = np.array([m.strip() for m in cells[:, col["mode"]]], dtype=object)
    order = np.argsort(time_s, kind="stable")
    return PredictionTable(
        time_s[order], sample[order], mode[order], phase[order], ready[order], sse[order],
        [c[4:] for c in sse_cols], str(p),
    )


def circular_error(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Circular distance between phases in [0, 1): min(|a-b|, 1-|a-b|), in [0, 0.5]."""
    e = np.mod(np.abs(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)), 1.0)
    return np.minimum(e, 1.0 - e)


def phase_truth(
    time_s: np.ndarray, heel_strike_times_s: np.ndarray, options: DetectionOptions | None = None
) -> np.ndarray:
    """True gait phase [0, 1) at ``time_s`` (s): linear between consecutive right heel strikes
    forming a stride (see ``strides.stride_bounds``); nan outside complete strides."""
    bounds, _ = stride_bounds(np.sort(np.asarray(heel_strike_times_s, dtype=np.float64)), options)
    t = np.asarray(time_s, dtype=np.float64)
    out = np.full(t.shape, np.nan)
    if len(bounds) == 0:
        return out
    k = np.searchsorted(bounds[:, 0], t, side="right") - 1
    ok = k >= 0
    kk = np.where(ok, k, 0)
    start, end = bounds[kk, 0], bounds[kk, 1]
    ok &= t < end
    out[ok] = ((t - start) / (end - start))[ok]
    return out


@dataclass(frozen=True)
class Aligned:
    """Prediction rows with their truth (all arrays shape (T,) unless noted).

    Attributes:
        time_s: Prediction times (s). pred: predicted mode names. phase: predicted phase.
        ready: matcher ready. sse: (T, M) deg^2, ``sse_modes`` order. truth: truth label after
        the label map ('' = none/unmatched). correct: prediction accepted for ``truth``.
        phase_true: phase truth (nan = none). evaluated: matched & ready & labelled.
    """

    time_s: np.ndarray
    pred: np.ndarray
    phase: np.ndarray
    ready: np.ndarray
    sse: np.ndarray
    sse_modes: list[str]
    truth: np.ndarray
    correct: np.ndarray
    phase_true: np.ndarray
    evaluated: np.ndarray
    heel_strikes_s: np.ndarray = field(default_factory=lambda: np.empty(0))


@dataclass(frozen=True)
class Evaluation:
    """Metrics (JSON-ready dict) and the aligned rows they were computed from."""

    metrics: dict[str, Any]
    aligned: Aligned


def _apply_label_map(
    labels: np.ndarray, label_map: Mapping[str, tuple[str, ...]]
) -> tuple[np.ndarray, dict[str, tuple[str, ...]]]:
    """Rename/drop truth labels; return (labels, accepted predictions per label)."""
    out = np.asarray(labels, dtype=object).copy()
    accepted: dict[str, tuple[str, ...]] = {}
    for name in dict.fromkeys(out.tolist()):
        if not name:
            continue
        target = label_map.get(name, (name,))
        if not target:
            out[out == name] = ""
        elif len(target) == 1:
            out[out == name] = target[0]
            accepted[target[0]] = target
        else:
            accepted[name] = target
    return out, accepted


MAX_TRUTH_GAP_S = 0.25
"""Prediction rows inside a gap longer than this between truth samples are not matched (s)."""


def match_times(truth_s: np.ndarray, pred_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Nearest truth sample of every prediction time (s).

    A row is matched when it lies within half the median truth interval of a truth sample, or
    between two truth samples at most ``MAX_TRUTH_GAP_S`` apart (so predictions on a resampled
    grid match an irregular truth).

    Returns:
        (nearest index, matched flags, tolerance in s = half the median truth interval).
    """
    ts = np.asarray(truth_s, dtype=np.float64)
    tp = np.asarray(pred_s, dtype=np.float64)
    if ts.size < 2:
        near = np.zeros(tp.size, dtype=np.int64)
        return near, np.abs(ts[near] - tp) <= 1e-9 if ts.size else np.zeros(tp.size, dtype=bool), 0.0
    tol = 0.5 * float(np.median(np.diff(ts)))
    near = nearest_index(ts, tp)
    right = np.clip(np.searchsorted(ts, tp), 1, ts.size - 1)
    bracketed = (tp >= ts[0]) & (tp <= ts[-1]) & (ts[right] - ts[right - 1] <= MAX_TRUTH_GAP_S)
    matched = (np.abs(ts[near] - tp) <= tol + 1e-9) | bracketed
    return near, matched, tol


def evaluate(
    pred: PredictionTable,
    truth: Recording,
    heel_strikes: HeelStrikes | None = None,
    label_map: Mapping[str, tuple[str, ...]] | None = None,
    options: DetectionOptions | None = None,
) -> Evaluation:
    """Compare ``pred`` with ``truth`` (labels and heel strikes); see the module docstring.

    Args:
        pred: Predictions (times in the truth recording's time base, seconds).
        truth: Recording with per-sample ``labels`` (None = no labels).
        heel_strikes: Right heel strikes for phase truth (None = no phase truth).
        label_map: truth label -> accepted predicted names (one = rename; empty = drop).
        options: Stride limits used for phase truth.
    """
    if len(truth) == 0:
        raise GaitEstimatorError(f"{truth.source}: truth recording has no samples")
    label_map = label_map or {}
    t = pred.time_s
    near, matched, tol = match_times(truth.time_s, t)
    raw = truth.labels[near] if truth.labels is not None else np.full(len(t), "", dtype=object)
    raw = np.where(matched, raw, "").astype(object)
    labels, accepted = _apply_label_map(raw, label_map)
    correct = np.zeros(len(t), dtype=bool)
    for name, acc in accepted.items():
        rows = labels == name
        correct[rows] = np.isin(pred.mode[rows].astype(str), list(acc))
    hs = heel_strikes.times_s if heel_strikes is not None else np.empty(0)
    ph_true = phase_truth(t, hs, options) if hs.size else np.full(len(t), np.nan)
    ph_true[~matched] = np.nan
    evaluated = matched & pred.ready & (labels != "")
    al = Aligned(t, pred.mode, pred.phase, pred.ready, pred.sse, pred.sse_modes, labels, correct, ph_true, evaluated, hs)
    err = circular_error(pred.phase, np.nan_to_num(ph_true))
    has_phase = evaluated & np.isfinite(ph_true) & np.isfinite(pred.phase)
    good = has_phase & correct
    names, matrix = _confusion(pred, labels, evaluated)
    settle = settle_time(pred)
    steady = evaluated & (time_in_run(t, labels) >= settle)
    metrics: dict[str, Any] = {
        "predictions": pred.source,
        "truth": truth.source,
        "label_map": {k: "|".join(v) for k, v in label_map.items()},
        "accuracy": _ratio(correct[evaluated].sum(), evaluated.sum()),
        "confusion": {
            "labels": names,
            "matrix": matrix.tolist(),
            "rows": "truth",
            "columns": "predicted",
            "prediction_modes": [n for n in names if n in pred.sse_modes or (pred.mode[evaluated] == n).any()],
        },
        "per_mode": _per_mode(al, names, accepted, err, steady),
        **_stats(err[good], "phase_error"),
        **_stats(err[has_phase], "phase_error_all"),
        "steady": {
            "settle_s": settle,
            "samples": int(steady.sum()),
            "accuracy": _ratio(correct[steady].sum(), steady.sum()),
            **_stats(err[good & steady], "phase_error"),
        },
        "transitions": transitions(al, accepted),
        "switches": {k: v for k, v in switch_metrics(t, pred.mode, pred.ready & matched, np.array(
            ["|".join(accepted.get(x, (x,))) if x else "" for x in labels], dtype=object)).items() if k != "delays_s"},
        "samples": {
            "predictions": len(t),
            "matched": int(matched.sum()),
            "ready": int((matched & pred.ready).sum()),
            "evaluated": int(evaluated.sum()),
            "with_phase_truth": int(has_phase.sum()),
            "match_tolerance_s": tol,
        },
        "phase_truth": _phase_truth_counts(heel_strikes, options),
        "warnings": _time_base_warnings(t, truth.time_s, matched) + _label_warnings(raw, labels, evaluated, accepted,
                                                                                   pred.sse_modes),
        "units": "phase errors are fractions of a stride (0.01 = 1 % of the gait cycle); delays in seconds",
    }
    return Evaluation(metrics, al)


MIN_MATCHED_SHARE = 0.9
"""Below this share of prediction rows matched to truth times, ``evaluate`` warns."""


def _time_base_warnings(pred_s: np.ndarray, truth_s: np.ndarray, matched: np.ndarray) -> list[str]:
    """A warning when few prediction rows fall on the truth's times: most likely the two count
    time from different origins (a bag's ``convert``/``process`` output starts at 0 s)."""
    if not len(pred_s) or matched.mean() >= MIN_MATCHED_SHARE:
        return []
    return [f"only {int(matched.sum())} of {len(pred_s)} prediction rows fall on the truth's times (predictions "
            f"{pred_s[0]:.2f}-{pred_s[-1]:.2f} s, truth {truth_s[0]:.2f}-{truth_s[-1]:.2f} s): do both count "
            "time from the same origin? (outputs of bags start at 0 s)"]


def _label_warnings(raw: np.ndarray, labels: np.ndarray, evaluated: np.ndarray,
                    accepted: Mapping[str, tuple[str, ...]], modes: Sequence[str]) -> list[str]:
    """A warning per truth label (``raw``, before ``--label-map``; ``labels`` after) that no mode of
    the predictions' library can match: its rows all count as wrong (e.g. ``stand`` scored against
    walking kernels)."""
    if not modes:  # predictions without the library's mode names
        return []
    out = []
    for name, acc in accepted.items():
        rows = evaluated & (labels == name)
        if rows.any() and not set(acc) & set(modes):
            truth = sorted(set(raw[rows].tolist()))
            shown = ", ".join(repr(x) for x in truth) + (f" (as {name!r})" if truth != [name] else "")
            out.append(f"truth label {shown} ({int(rows.sum())} rows) is no mode of the predictions "
                       f"({', '.join(modes)}): every row counts as wrong; --label-map {truth[0]}= leaves it out, "
                       f"{truth[0]}=MODE renames it")
    return out


def _per_mode(al: Aligned, names: list[str], accepted: Mapping[str, tuple[str, ...]], err: np.ndarray,
              steady: np.ndarray) -> dict[str, dict[str, Any]]:
    """The metrics of every truth mode with evaluated samples: accuracy (all and steady), phase error."""
    labels, correct, evaluated = al.truth, al.correct, al.evaluated
    has_phase = evaluated & np.isfinite(al.phase_true)
    good = has_phase & correct
    return {
        n: {
            "samples": int(rows.sum()),
            "accuracy": _ratio(correct[rows].sum(), rows.sum()),
            "steady_samples": int((rows & steady).sum()),
            "steady_accuracy": _ratio(correct[rows & steady].sum(), (rows & steady).sum()),
            "accepted_predictions": list(accepted.get(n, (n,))),
            **_stats(err[good & rows], "phase_error"),
            **_stats(err[has_phase & rows], "phase_error_all"),
        }
        for n, rows in ((n, evaluated & (labels == n)) for n in names if (labels[evaluated] == n).any())
    }


def _phase_truth_counts(heel_strikes: HeelStrikes | None, options: DetectionOptions | None) -> dict[str, Any]:
    """Where the phase truth came from: heel-strike method, count and whole strides."""
    hs = heel_strikes.times_s if heel_strikes is not None else np.empty(0)
    return {
        "heel_strikes": heel_strikes.method if heel_strikes is not None else "none",
        "count": int(hs.size),
        "strides": len(stride_bounds(np.sort(hs), options)[0]) if hs.size else 0,
    }


def _confusion(pred: PredictionTable, labels: np.ndarray, evaluated: np.ndarray) -> tuple[list[str], np.ndarray]:
    """(mode names: the library's, then any other predicted or truth label; counts [truth, predicted])."""
    names = list(pred.sse_modes)
    for m in [*pred.mode[evaluated].tolist(), *labels[evaluated].tolist()]:
        if m not in names:
            names.append(m)
    index = {n: i for i, n in enumerate(names)}
    matrix = np.zeros((len(names), len(names)), dtype=np.int64)
    np.add.at(matrix, ([index[x] for x in labels[evaluated]], [index[x] for x in pred.mode[evaluated]]), 1)
    return names, matrix


def settle_time(pred: PredictionTable) -> float:
    """The matcher's window length (s): time from the first prediction row to the first ready one
    plus one sample interval (``process`` starts from a fresh state); 0 when never ready."""
    ready = np.flatnonzero(pred.ready)
    if ready.size == 0 or len(pred.time_s) < 2:
        return 0.0
    dt = float(np.median(np.diff(pred.time_s)))
    return float(pred.time_s[ready[0]] - pred.time_s[0]) + dt


def time_in_run(time_s: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Seconds since the start of each row's run of identical consecutive labels (inf for '')."""
    t = np.asarray(time_s, dtype=np.float64)
    lab = np.asarray(labels, dtype=object)
    if t.size == 0:
        return t.copy()
    start = np.r_[True, lab[1:] != lab[:-1]]
    first = np.maximum.accumulate(np.where(start, np.arange(t.size), 0))
    out = t - t[first]
    out[lab == ""] = np.inf
    return out


def _ratio(num: Any, den: Any) -> float | None:
    return float(num) / float(den) if den else None


def _stats(e: np.ndarray, prefix: str) -> dict[str, Any]:
    if e.size == 0:
        return {f"{prefix}_mean": None, f"{prefix}_std": None, f"{prefix}_max": None, f"{prefix}_samples": 0}
    return {
        f"{prefix}_mean": float(e.mean()),
        f"{prefix}_std": float(e.std()),
        f"{prefix}_max": float(e.max()),
        f"{prefix}_samples": int(e.size),
    }


def transitions(al: Aligned, accepted: Mapping[str, tuple[str, ...]]) -> dict[str, Any]:
    """Truth mode changes and how long the estimator took to follow (docs/training.md)."""
    rows = np.flatnonzero(al.truth != "")
    events: list[dict[str, Any]] = []
    if rows.size:
        lab = al.truth[rows]
        cut = np.flatnonzero(lab[1:] != lab[:-1]) + 1
        starts = np.r_[0, cut]
        ends = np.r_[cut, lab.size] - 1  # inclusive, positions in rows
        for k in range(1, len(starts)):
            prev_end = rows[ends[k - 1]]
            first, last = rows[starts[k]], rows[ends[k]]
            new = lab[starts[k]]
            ok = al.ready[prev_end + 1 : last + 1] & np.isin(
                al.pred[prev_end + 1 : last + 1].astype(str), list(accepted.get(new, (new,)))
            )
            hit = np.flatnonzero(ok)
            delay = float(al.time_s[prev_end + 1 + hit[0]] - al.time_s[first]) if hit.size else None
            gap = float(al.time_s[first] - al.time_s[prev_end + 1]) if first > prev_end + 1 else 0.0
            events.append(
                {
                    "time_s": float(al.time_s[first]),
                    "from": str(lab[starts[k - 1]]),
                    "to": str(new),
                    "delay_s": delay,
                    "unlabelled_gap_s": gap,
                }
            )
    delays = [e["delay_s"] for e in events if e["delay_s"] is not None]
    return {
        "count": len(events),
        "detected": len(delays),
        "missed": len(events) - len(delays),
        "mean_delay_s": float(np.mean(delays)) if delays else None,
        "events": events,
    }


def format_metrics(m: Mapping[str, Any]) -> str:
    """Short human-readable summary of ``metrics`` (percentages)."""

    def pct(v: Any) -> str:
        return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:.2f} %"

    s = m["samples"]
    lines = [f"warning: {w}" for w in m.get("warnings", [])] + [
        f"evaluated {s['evaluated']} of {s['predictions']} prediction rows (ready, labelled, matched); "
        f"{s['with_phase_truth']} with phase truth ({m['phase_truth']['heel_strikes']})",
        f"accuracy {pct(m['accuracy'])}; phase error (correct rows) mean {pct(m['phase_error_mean'])} "
        f"std {pct(m['phase_error_std'])} max {pct(m['phase_error_max'])}; all rows max {pct(m['phase_error_all_max'])}",
        f"{'mode':<10} {'samples':>7} {'accuracy':>9} {'ph_mean':>8} {'ph_std':>8} {'ph_max':>8}",
    ]
    for name, pm in m["per_mode"].items():
        lines.append(
            f"{name:<10} {pm['samples']:>7} {pct(pm['accuracy']):>9} {pct(pm['phase_error_mean']):>8} "
            f"{pct(pm['phase_error_std']):>8} {pct(pm['phase_error_max']):>8}"
        )
    st = m["steady"]
    lines.append(
        f"steady (>= {st['settle_s']:.2f} s into a labelled run): {st['samples']} rows, accuracy {pct(st['accuracy'])}, "
        f"phase error mean {pct(st['phase_error_mean'])}"
    )
    tr = m["transitions"]
    delay = "n/a" if tr["mean_delay_s"] is None else f"{tr['mean_delay_s']:.2f} s"
    lines.append(f"transitions: {tr['count']} ({tr['missed']} missed), mean delay {delay}")
    sw = m.get("switches")
    if sw:
        lines.append(f"switches: {sw['false_switches']} false in {sw['labelled_minutes']:.2f} min of labelled walking "
                     f"({sw['false_per_minute']:.2f} / min)")
    return "\n".join(lines)


SWITCH_WINDOW_S = 2.0
"""A reported change of mode within this long after a labelled change is explained by it: walking
is reported from the first whole stride after a start (up to ~1.7 s)."""
SWITCH_LEAD_S = 0.5
"""... or this long before it."""


def switch_metrics(time_s: np.ndarray, mode: np.ndarray, ready: np.ndarray, labels: np.ndarray,
                   window_s: float = SWITCH_WINDOW_S) -> dict[str, Any]:
    """False switches and delays (module docstring) of the reported ``mode`` (T,) against the
    truth ``labels`` (T,): '' = unlabelled, else the accepted modes joined by ``|``."""
    t = np.asarray(time_s, dtype=np.float64)
    mode, labels = np.asarray(mode).astype(str), np.asarray(labels).astype(str)
    ready = np.asarray(ready, dtype=bool)
    changed = np.flatnonzero(labels[1:] != labels[:-1]) + 1
    change_t = t[changed]
    rows = np.flatnonzero(ready[1:] & ready[:-1] & (mode[1:] != mode[:-1])) + 1
    walking = (labels != "") & (labels != "stand")
    k = np.searchsorted(change_t, t[rows] + SWITCH_LEAD_S, side="right") - 1
    explained = (k >= 0) & (t[rows] - change_t[np.maximum(k, 0)] <= window_s)
    false = int(np.count_nonzero(~explained & walking[rows]))
    dt = np.diff(t, append=t[-1]) if t.size else t
    minutes = float(dt[walking].sum() / 60.0)
    delays, missed = [], 0
    for i in changed:
        if labels[i] == "":
            continue
        accepted = labels[i].split("|")
        j = i + np.flatnonzero(ready[i:] & np.isin(mode[i:], accepted) & (t[i:] <= t[i] + window_s))[:1]
        if j.size:
            delays.append(float(t[j[0]] - t[i]))
        else:
            missed += 1
    return {"false_switches": false, "labelled_minutes": minutes, "false_per_minute": false / minutes if minutes else 0.0,
            "labelled_changes": len(delays) + missed, "missed_changes": missed, "delays_s": delays,
            "mean_delay_s": float(np.mean(delays)) if delays else None}
