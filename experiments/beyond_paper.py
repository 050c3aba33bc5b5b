#!/usr/bin/env python3
"""Measurements of the estimator options beyond the paper (issue 6; docs/beyond_paper.md).

Every number and table of that page comes from this script:

    python experiments/beyond_paper.py                      # -> experiments/results/beyond/
    python experiments/beyond_paper.py --out DIR --seeds 5 --jobs 2

Run from anywhere with gait_estimator importable; the recordings are the project's bundled
data/swge. Writes ``summary.json`` (all metrics), ``tables.md`` (the tables of
docs/beyond_paper.md, copied in by ``make docs``) and two figures into the output directory.
Runtime ≈ 2-3 min on 2 cores.

Data sets (all evaluated with ``gait_estimator.analysis.evaluate.evaluate``, the code behind
``gait-estimator evaluate``; predictions come from ``Estimator``, the code behind ``process``):

* ``MS``: Multispeed_Walk_AB, bundled able_bodied kernels, every stride within 15 % of a kernel
  duration labelled Slow/Med/Fast (``label-strides --all-strides``, right-shank heel strikes), as in
  experiments/run.sh.
* ``LG2-AB``: LG_2_Ramp resampled to 230 Hz (``gait-estimator resample``), able_bodied kernels,
  experiments/lg2_ramp_labels.csv, ``level`` accepted as Slow, Med or Fast.
* ``LG2-own``: LG_2_Ramp at its median rate with kernels trained on it (in-sample, 3 modes).
* ``SYN``: synthetic recordings (test/synthetic.py) from the able_bodied kernels walking a route
  with 12 mode changes that respects config/transitions.yaml, several seeds, pooled.
* ``SYN-rev``: the route Slow, Med, Fast, RA, RD, SA, SD (three direct ascent/descent reversals,
  which config/transitions.yaml forbids), only for the transition-supervision section.
* ``SYN-cad``: synthetic strides whose cadence swings +-8 % around the kernels', only for the
  phase-rate section.
* ``RI:...``: Multispeed and synthetic seed 0 at 100/200/500 Hz and with +-2 ms jitter, and
  LG_2_Ramp with its raw stamps, for the rate-invariance section.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gait_estimator.analysis.evaluate import PredictionTable, circular_error, evaluate, settle_time, time_in_run
from gait_estimator.analysis.labels import duration_labels, merge_steady, read_label_ranges, with_ranges
from gait_estimator.analysis.strides import (
    DetectionOptions,
    HeelStrikes,
    heel_strikes,
    nearest_index,
    resample_uniform,
    stride_bounds,
)
from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.core.estimator import EstimateTrace, Estimator, EstimatorConfig, trace_from_estimates
from gait_estimator.core.kernels import KernelLibrary
from gait_estimator.io.library_io import load_library
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording, write_project_csv

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
from synthetic import Synthetic, SyntheticConfig, generate  # noqa: E402  (test helper, after sys.path)

DET = DetectionOptions()
TABLE = REPO / "config" / "transitions.yaml"
RIGHT = ("right_thigh", "right_shank")
LEFT = ("left_thigh", "left_shank")

ROUTE = [
    ("Slow", 6), ("Med", 6), ("Fast", 6), ("RA", 6), ("SA", 6), ("Med", 6), ("SD", 6),
    ("RD", 6), ("Slow", 6), ("SA", 6), ("Fast", 6), ("RD", 6), ("Med", 6),
]
"""Synthetic route: 78 strides, 12 mode changes, all allowed by config/transitions.yaml."""
ROUTE_REVERSALS = [("Slow", 6), ("Med", 6), ("Fast", 6), ("RA", 6), ("RD", 6), ("SA", 6), ("SD", 6)]
"""The route of the issue's example: RA -> RD, RD -> SA and SA -> SD are direct reversals."""


# ---------------------------------------------------------------------------------------------
# Data sets


@dataclass
class Part:
    """One recording: what the estimator is fed, and the truth evaluate compares with."""

    name: str
    feed: Recording
    truth: Recording
    hs: HeelStrikes | None
    label_map: dict[str, tuple[str, ...]] = field(default_factory=dict)
    synthetic: Synthetic | None = None


@dataclass
class Dataset:
    key: str
    title: str
    library: KernelLibrary
    parts: list[Part]
    table: str = ""  # allowed-transitions YAML for this library ('' = none)


def data_root() -> Path:
    """The project root: the paper's data are bundled under data/swge."""
    return REPO


def multispeed(shared: Path, ab: KernelLibrary) -> Dataset:
    """Multispeed, all strides within 15 % of a kernel duration labelled (run.sh --all-strides)."""
    path = shared / "data/swge/recordings/Multispeed_Walk_AB.csv"
    rec = read_recording(path, rate_hz=ab.sample_rate_hz)
    hs = heel_strikes(rec, "right_shank", None, DET)
    bounds, _ = stride_bounds(hs.times_s, DET)
    durations = {n: ab.mode(n).stride_duration_s for n in ("Slow", "Med", "Fast")}
    ranges = merge_steady(duration_labels(bounds, durations, 0.15), steady_only=False)
    truth = with_ranges(rec, ranges)
    return Dataset("MS", "Multispeed, able_bodied kernels", ab, [Part("Multispeed", rec, truth, hs)], str(TABLE))


def lg2_uniform(shared: Path, rate_hz: float | None) -> tuple[Recording, Recording]:
    """(raw labelled LG_2_Ramp, its uniform copy at ``rate_hz`` with heel-strike flags) as
    ``gait-estimator resample --labels ... --heel-strikes right_foot`` writes it."""
    raw = read_recording(shared / "data/swge/recordings/LG_2_Ramp_AB_Sample.csv")
    raw = with_ranges(raw, read_label_ranges(REPO / "experiments/lg2_ramp_labels.csv"))
    rate = rate_hz or raw.median_rate_hz
    uni = resample_uniform(raw, rate)
    hs = heel_strikes(raw, "right_foot", rate, DET)
    flags = np.zeros(len(uni), dtype=bool)
    flags[nearest_index(uni.time_s, hs.times_s)] = True
    uni.heel_strike = flags
    return raw, uni


def column_hs(rec: Recording) -> HeelStrikes:
    return heel_strikes(rec, "column", None, DET)


def lg2_able_bodied(shared: Path, ab: KernelLibrary) -> Dataset:
    _, uni = lg2_uniform(shared, ab.sample_rate_hz)
    part = Part("LG_2_Ramp@230", uni, uni, column_hs(uni), {"level": ("Slow", "Med", "Fast")})
    return Dataset("LG2-AB", "LG_2_Ramp, able_bodied kernels", ab, [part], str(TABLE))


def lg2_own(shared: Path, out: Path) -> Dataset:
    raw, _ = lg2_uniform(shared, None)
    lib = train_library([raw], "lg2", TrainOptions(heel_strikes="right_foot")).library
    _, uni = lg2_uniform(shared, lib.sample_rate_hz)
    table = out / "transitions_lg2.yaml"
    table.write_text(
        "# Allowed transitions for the 3-mode LG_2_Ramp library (written by experiments/beyond_paper.py):\n"
        "# as config/transitions.yaml, no direct ramp ascent <-> ramp descent.\n"
        "allowed_transitions:\n  level: [RA, RD]\n  RA: [level]\n  RD: [level]\n",
        encoding="utf-8",
    )
    part = Part("LG_2_Ramp@own", uni, uni, column_hs(uni))
    return Dataset("LG2-own", "LG_2_Ramp, kernels trained on it (in-sample)", lib, [part], str(table))


def synthetic_part(lib: KernelLibrary, route: Sequence[tuple[str, int]], seed: int, name: str) -> Part:
    syn = generate(lib, route, SyntheticConfig(), seed=seed, source=name)
    rec = syn.recording
    return Part(name, rec, rec, column_hs(rec), synthetic=syn)


def synthetic(ab: KernelLibrary, seeds: int) -> Dataset:
    parts = [synthetic_part(ab, ROUTE, s, f"synthetic seed {s}") for s in range(seeds)]
    return Dataset("SYN", f"synthetic route, {seeds} seeds", ab, parts, str(TABLE))


CADENCE_ROUTE = [("Med", 16), ("RA", 8), ("Med", 8), ("RD", 8), ("Med", 8)]
CADENCE_SWING = 0.08
"""SYN-cad: stride k lasts (1 + 0.08 sin(2 pi k / 24)) x its usual duration: a slow +-8 % cadence
swing the kernels do not contain, which a controller scheduling by phase rate must follow."""


def synthetic_cadence(ab: KernelLibrary, seeds: int) -> Dataset:
    n = sum(c for _, c in CADENCE_ROUTE)
    scale = {k: 1.0 + CADENCE_SWING * math.sin(2 * math.pi * k / 24) for k in range(n)}
    parts = []
    for s in range(seeds):
        syn = generate(ab, CADENCE_ROUTE, SyntheticConfig(), seed=200 + s, duration_scale=scale, source=f"cadence seed {s}")
        parts.append(Part(f"cadence seed {s}", syn.recording, syn.recording, column_hs(syn.recording), synthetic=syn))
    return Dataset("SYN-cad", f"synthetic, ±8 % cadence swing, {seeds} seeds", ab, parts, str(TABLE))


def synthetic_reversals(ab: KernelLibrary, seeds: int) -> Dataset:
    parts = [synthetic_part(ab, ROUTE_REVERSALS, 100 + s, f"synthetic reversals seed {s}") for s in range(seeds)]
    return Dataset("SYN-rev", f"synthetic route with reversals, {seeds} seeds", ab, parts, str(TABLE))


# ---------------------------------------------------------------------------------------------
# Running and evaluating

MATCHER_FIELDS = ("window_fraction", "channels", "channel_weights", "subsample_phase", "resample")
DATASETS: dict[str, Dataset] = {}  # filled in main() before the worker pool forks


def matcher_key(options: dict[str, Any]) -> tuple:
    c = EstimatorConfig().with_options(**options)
    return tuple((f, getattr(c, f)) for f in MATCHER_FIELDS)


def run_group(ds: Dataset, part: Part, settings: Sequence[dict[str, Any]]) -> list[EstimateTrace]:
    """Estimate ``part`` under each option set of ``settings`` (all with the same matcher options).

    The first setting runs through ``Estimator.update`` (as ``process`` does) while its matcher's
    step results are recorded; the other settings' supervisors replay those results, which is
    what ``Estimator.update`` would do with them (checked: no gap restarted the window).
    """
    est = Estimator(ds.library, EstimatorConfig().with_options(**settings[0]))
    results: list[Any] = []
    step = est.matcher.step

    def recording_step(x: np.ndarray) -> Any:
        results.append(step(x))
        return results[-1]

    est.matcher.step = recording_step  # type: ignore[method-assign]
    rows = []
    for i in range(len(part.feed)):
        for e in est.update(float(part.feed.time_s[i]), part.feed.angles_deg[i]):
            rows.append((int(part.feed.index[i]), e))
    if est.resets:
        raise RuntimeError(f"{part.name}: {est.resets} gap restart(s); replaying supervisors would be wrong")
    traces = [trace_from_estimates(ds.library.mode_names, rows)]
    for options in settings[1:]:
        sup = Estimator(ds.library, EstimatorConfig().with_options(**options)).supervisor
        replay = [(k, sup.update(e.time_s, r)) for (k, e), r in zip(rows, results, strict=True)]
        traces.append(trace_from_estimates(ds.library.mode_names, replay))
    return traces


def prediction_table(trace: EstimateTrace, source: str) -> PredictionTable:
    modes = np.asarray(trace.mode_names, dtype=object)[trace.mode_index]
    return PredictionTable(trace.time_s, trace.sample, modes, trace.phase, trace.ready, trace.sse, list(trace.mode_names), source)


def switches(trace: EstimateTrace) -> int:
    """Changes of the reported mode between consecutive ready rows."""
    m = trace.mode_index[trace.ready]
    return int(np.count_nonzero(m[1:] != m[:-1]))


def part_stats(ds: Dataset, part: Part, trace: EstimateTrace, collect: Sequence[str] = ()) -> dict[str, Any]:
    """Raw counts of one part (pooled over parts by ``pool``)."""
    pred = prediction_table(trace, part.name)
    ev = evaluate(pred, part.truth, part.hs, part.label_map, DET)
    m, al = ev.metrics, ev.aligned
    evald, correct = al.evaluated, al.correct & al.evaluated
    err = circular_error(al.phase, np.nan_to_num(al.phase_true))
    has_phase = evald & np.isfinite(al.phase_true)
    good = has_phase & correct
    held = trace.held & evald
    st = m["steady"]
    out: dict[str, Any] = {
        "evaluated": int(evald.sum()),
        "correct": int(correct.sum()),
        "steady": st["samples"],
        "steady_correct": round((st["accuracy"] or 0.0) * st["samples"]),
        "ph_sum": float(err[good].sum()),
        "ph_n": int(good.sum()),
        "ph_max": float(err[good].max()) if good.any() else 0.0,
        "ph_all_sum": float(err[has_phase].sum()),
        "ph_all_n": int(has_phase.sum()),
        "held": int(held.sum()),
        "nonheld_correct": int((correct & ~trace.held).sum()),
        "delays": [e["delay_s"] for e in m["transitions"]["events"] if e["delay_s"] is not None],
        "transitions": m["transitions"]["count"],
        "missed": m["transitions"]["missed"],
        "switches": switches(trace),
        "duration_s": float(trace.time_s[-1] - trace.time_s[0]),
        "per_mode": {str(n): [int((correct & (al.truth == n)).sum()), int((evald & (al.truth == n)).sum())]
                     for n in dict.fromkeys(al.truth[evald].tolist())},
    }
    if "confidence" in collect:
        out["conf"] = trace.confidence[evald].tolist()
        out["fit"] = trace.fit_rms_deg[evald].tolist()
        out["ok"] = correct[evald].tolist()
    if "rate" in collect:
        steady = evald & (time_in_run(al.time_s, al.truth) >= settle_time(pred))
        out["rate"] = phase_rate_errors(ds, trace, al.heel_strikes_s, evald, steady)
    if "trace" in collect:
        out["trace"] = {
            "time_s": trace.time_s.tolist(), "mode": trace.mode_index.tolist(), "phase": trace.phase.tolist(),
            "ready": trace.ready.tolist(), "confidence": trace.confidence.tolist(),
        }
    return out


def phase_rate_errors(
    ds: Dataset, trace: EstimateTrace, hs: np.ndarray, ok: np.ndarray, steady: np.ndarray
) -> dict[str, list[float]]:
    """Relative errors against the true stride frequency (1 / duration of the stride a row lies
    in, from the truth heel strikes) of the smoothed phase rate and, as the "before", of the
    reported mode's nominal kernel stride frequency (rate / N_m), on the ``ok`` rows inside
    strides (evaluated rows, whatever mode they report: a controller uses the rate regardless);
    ``steady`` as in evaluate (at least one matcher window into a labelled run)."""
    bounds, _ = stride_bounds(np.sort(hs), DET)
    t = trace.time_s
    k = np.searchsorted(bounds[:, 0], t, side="right") - 1
    kk = np.clip(k, 0, len(bounds) - 1)
    inside = (k >= 0) & (t < bounds[kk, 1])
    f_true = 1.0 / (bounds[kk, 1] - bounds[kk, 0])
    f_nominal = ds.library.sample_rate_hz / ds.library.lengths[trace.mode_index]
    rows = ok & inside & np.isfinite(trace.phase_rate)
    rel = trace.phase_rate / f_true - 1.0
    rel_nom = f_nominal / f_true - 1.0
    return {
        "rel": rel[rows].tolist(), "rel_nominal": rel_nom[rows].tolist(),
        "rel_steady": rel[rows & steady].tolist(), "rel_nominal_steady": rel_nom[rows & steady].tolist(),
    }


def pool(stats: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Combine part stats into metrics (fractions; delays in s)."""

    def total(key: str) -> float:
        return sum(s[key] for s in stats)

    def ratio(a: float, b: float) -> float | None:
        return a / b if b else None

    delays = [d for s in stats for d in s["delays"]]
    ev = total("evaluated")
    out: dict[str, Any] = {
        "evaluated": int(ev),
        "accuracy": ratio(total("correct"), ev),
        "steady_accuracy": ratio(total("steady_correct"), total("steady")),
        "phase_error_mean": ratio(total("ph_sum"), total("ph_n")),
        "phase_error_max": max(s["ph_max"] for s in stats),
        "phase_error_all_mean": ratio(total("ph_all_sum"), total("ph_all_n")),
        "held_fraction": ratio(total("held"), ev),
        "nonheld_accuracy": ratio(total("nonheld_correct"), ev - total("held")),
        "transitions": int(total("transitions")),
        "missed": int(total("missed")),
        "mean_delay_s": float(np.mean(delays)) if delays else None,
        "median_delay_s": float(np.median(delays)) if delays else None,
        "max_delay_s": float(np.max(delays)) if delays else None,
        "switches": int(total("switches")),
        "switches_per_min": 60.0 * total("switches") / total("duration_s"),
        "per_mode_accuracy": {},
    }
    modes = list(dict.fromkeys(n for s in stats for n in s["per_mode"]))
    for n in modes:
        c = sum(s["per_mode"].get(n, [0, 0])[0] for s in stats)
        e = sum(s["per_mode"].get(n, [0, 0])[1] for s in stats)
        out["per_mode_accuracy"][n] = ratio(c, e)
    for key in ("conf", "fit", "ok"):
        if key in stats[0]:
            out[key] = [v for s in stats for v in s[key]]
    if "rate" in stats[0]:
        out["rate"] = {k: [v for s in stats for v in s["rate"][k]] for k in stats[0]["rate"]}
    if "trace" in stats[0]:
        out["trace"] = [s["trace"] for s in stats]
    return out


Setting = tuple[str, tuple[tuple[str, Any], ...], tuple[str, ...]]
"""(label, options as sorted items, what to collect besides the metrics)."""


@dataclass(frozen=True)
class Task:
    dataset: str
    settings: tuple[Setting, ...]  # all with the same matcher options


def run_task(task: Task) -> dict[str, dict[str, Any]]:
    ds = DATASETS[task.dataset]
    options = [dict(o) for _, o, _ in task.settings]
    per_setting: list[list[dict[str, Any]]] = [[] for _ in options]
    for part in ds.parts:
        for i, trace in enumerate(run_group(ds, part, options)):
            per_setting[i].append(part_stats(ds, part, trace, task.settings[i][2]))
    return {label: pool(stats) for (label, _, _), stats in zip(task.settings, per_setting, strict=True)}


def make_tasks(
    dataset: str, settings: dict[str, dict[str, Any]], collect: dict[str, Sequence[str]] | None = None
) -> list[Task]:
    """Group settings sharing matcher options into one task each; ``collect[label]`` = extras."""
    groups: dict[tuple, list[Setting]] = {}
    for label, opts in settings.items():
        extra = tuple((collect or {}).get(label, ()))
        groups.setdefault(matcher_key(opts), []).append((label, tuple(sorted(opts.items())), extra))
    return [Task(dataset, tuple(g)) for g in groups.values()]


def run_all(tasks: Sequence[Task], jobs: int) -> dict[tuple[str, str], dict[str, Any]]:
    if jobs > 1:
        with multiprocessing.get_context("fork").Pool(jobs) as p:
            results = p.map(run_task, tasks, chunksize=1)
    else:
        results = [run_task(t) for t in tasks]
    out = {}
    for task, res in zip(tasks, results, strict=True):
        for label, metrics in res.items():
            out[(task.dataset, label)] = metrics
    return out


# ---------------------------------------------------------------------------------------------
# Rate invariance: one recording at other rates / with jitter, processed with and without --resample

JITTER_S = 0.002


def relabel(part: Part, rec: Recording) -> Part:
    """``part`` with the estimator fed ``rec`` (other sampling of the same motion); truth labels
    at ``rec``'s times from the original truth (nearest sample), heel strikes unchanged."""
    labels = None
    if part.truth.labels is not None:
        labels = part.truth.labels[nearest_index(part.truth.time_s, rec.time_s)]
    truth = Recording(time_s=rec.time_s, angles_deg=rec.angles_deg, labels=labels, source=rec.source)
    return Part(rec.source, rec, truth, part.hs, part.label_map)


def rate_variants(part: Part, rate_hz: float, seed: int = 7) -> dict[str, Recording]:
    """The part's uniform recording resampled (cubic spline through its samples: a sensor at
    another rate samples the same continuous motion) to 100/200/500 Hz, sampled at the nominal
    times +-2 ms (jitter, correct stamps), and the original samples with stamps +-2 ms off."""
    from scipy.interpolate import CubicSpline

    rec = part.feed
    t0, t1 = float(rec.time_s[0]), float(rec.time_s[-1])
    spline = CubicSpline(rec.time_s, rec.angles_deg, axis=0)
    rng = np.random.default_rng(seed)

    def make(t: np.ndarray, name: str, angles: np.ndarray | None = None) -> Recording:
        a = spline(t) if angles is None else angles
        return Recording(time_s=t, angles_deg=a, source=f"{part.name} {name}")

    out = {f"{rate_hz:g} Hz (original)": rec}
    for hz in (100.0, 200.0, 500.0):
        out[f"{hz:g} Hz"] = make(t0 + np.arange(math.floor((t1 - t0) * hz) + 1) / hz, f"{hz:g} Hz")
    jit = rng.uniform(-JITTER_S, JITTER_S, len(rec))
    jit[0] = 0.0  # keep the first stamp: the resampling grid then coincides with the original samples
    jittered = rec.time_s + jit
    out[f"{rate_hz:g} Hz, sampled ±2 ms off the grid"] = make(jittered, "jitter")
    out[f"{rate_hz:g} Hz, stamps ±2 ms wrong"] = make(jittered, "stamp noise", rec.angles_deg)
    return out


def compare_traces(ref: dict[str, list], other: dict[str, list], rate_hz: float, t0: float) -> dict[str, Any]:
    """Mode agreement and phase difference of ``other`` against ``ref`` (the original-rate run),
    at ref's grid times t0 + i / rate (nearest for non-grid rows); rows ready in both."""
    rt, rm, rp, rr = (np.asarray(ref[k]) for k in ("time_s", "mode", "phase", "ready"))
    ot, om, op, orr = (np.asarray(other[k]) for k in ("time_s", "mode", "phase", "ready"))
    i = np.rint((ot - t0) * rate_hz).astype(np.int64)
    ok = (i >= 0) & (i < rt.size)
    i = np.clip(i, 0, rt.size - 1)
    ok &= orr & rr[i] & (np.abs(rt[i] - ot) < 0.5 / rate_hz)
    same = ok & (om == rm[i])
    d = circular_error(op[same], rp[i][same])
    margins = np.asarray(ref["confidence"])[i[ok & ~same]]
    return {
        "max_reference_margin_where_modes_differ": float(margins.max()) if margins.size else None,
        "rows": int(ok.sum()),
        "rows_other_mode": int((ok & ~same).sum()),
        "rows_phase_over_0.5pct": int((d > 0.005).sum()),
        "mode_agreement": float(same.sum() / ok.sum()) if ok.any() else None,
        "phase_diff_mean": float(d.mean()) if d.size else None,
        "phase_diff_p99": float(np.percentile(d, 99)) if d.size else None,
        "phase_diff_max": float(d.max()) if d.size else None,
        "phase_diff_over_0.5pct": float((d > 0.005).mean()) if d.size else None,
    }


# ---------------------------------------------------------------------------------------------
# The experiments


def settings_for(ds: Dataset) -> dict[str, dict[str, dict[str, Any]]]:
    """Section -> setting label -> options (all on top of the defaults = the paper)."""
    table = {"transitions": ds.table}
    return {
        "confidence": {f"{c:g}": ({"min_confidence": c} if c else {}) for c in (0, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0)},
        "supervision": {
            "off (paper)": {},
            **{f"min_dwell_s {d:g}": {"min_dwell_s": d} for d in (0.05, 0.1, 0.2, 0.3, 0.5)},
            "transitions table": table,
            "table + min_dwell_s 0.1": {**table, "min_dwell_s": 0.1},
        },
        "window": {
            "1.0 (paper)": {},
            "0.75": {"window_fraction": 0.75},
            "0.5": {"window_fraction": 0.5},
            "0.5 + min_dwell_s 0.1": {"window_fraction": 0.5, "min_dwell_s": 0.1},
        },
        "channels": {
            "bilateral (paper)": {},
            "right_thigh + right_shank": {"channels": RIGHT},
            "left_thigh + left_shank": {"channels": LEFT},
        },
        "subsample": {
            "off (paper)": {},
            "on": {"subsample_phase": True},
            "off, window 0.5": {"window_fraction": 0.5},
            "on, window 0.5": {"subsample_phase": True, "window_fraction": 0.5},
        },
        "phase_rate": {
            **{
                f"tau {t:g} s" + (" (default)" if t == 0.2 else ""): ({"phase_rate_tau_s": t} if t != 0.2 else {})
                for t in (0.05, 0.2, 0.5, 1.0)
            },
            "tau 0.2 s + subsample": {"subsample_phase": True},
            "tau 0.2 s + window 0.5": {"window_fraction": 0.5},
        },
    }


MAIN = ("MS", "LG2-AB", "LG2-own", "SYN")


def option_key(opts: dict[str, Any]) -> str:
    """Key of an option set, the same for every data set (the transitions file named generically)."""
    return json.dumps({k: ("<table>" if k == "transitions" else v) for k, v in opts.items()}, sort_keys=True)


def build_tasks(seeds: int) -> tuple[list[Task], dict[str, dict[str, str]]]:
    """Tasks for every (data set, distinct option set); also section -> setting -> option key."""
    tasks: list[Task] = []
    index: dict[str, dict[str, str]] = {}
    for key in MAIN:
        ds = DATASETS[key]
        unique: dict[str, dict[str, Any]] = {}
        for section, settings in settings_for(ds).items():
            for label, opts in settings.items():
                okey = option_key(opts)
                unique[okey] = opts
                index.setdefault(section, {})[label] = okey
        collect: dict[str, list[str]] = {option_key({}): ["confidence"]}
        for okey in index["phase_rate"].values():
            collect.setdefault(okey, []).append("rate")
        tasks += make_tasks(key, unique, collect)
    cad = settings_for(DATASETS["SYN-cad"])["phase_rate"]
    tasks += make_tasks("SYN-cad", {option_key(o): o for o in cad.values()}, {option_key(o): ["rate"] for o in cad.values()})
    rev = DATASETS["SYN-rev"]
    sup = settings_for(rev)["supervision"]
    tasks += make_tasks("SYN-rev", {option_key(o): o for o in sup.values()})
    for key in [k for k in DATASETS if k.startswith("RI:")]:
        tasks += make_tasks(key, {"no": {}, "resample": {"resample": True}}, {"no": ["trace"], "resample": ["trace"]})
    # longest first: better load balance over the workers
    tasks.sort(key=lambda t: -sum(len(p.feed) for p in DATASETS[t.dataset].parts) * (2 + len(t.settings)))
    return tasks, index


def auroc(score: np.ndarray, positive: np.ndarray) -> float | None:
    """P(score of a random positive > score of a random negative) (ties count half)."""
    from scipy.stats import rankdata

    pos, neg = int(positive.sum()), int((~positive).sum())
    if not pos or not neg:
        return None
    r = rankdata(score)
    return float((r[positive].sum() - pos * (pos + 1) / 2) / (pos * neg))


def confidence_distributions(m: dict[str, Any]) -> dict[str, Any]:
    c, f, ok = np.asarray(m["conf"]), np.asarray(m["fit"]), np.asarray(m["ok"], dtype=bool)

    def q(a: np.ndarray) -> list[float] | None:
        return np.percentile(a, [10, 50, 90]).tolist() if a.size else None

    return {
        "correct": int(ok.sum()), "wrong": int((~ok).sum()),
        "margin_correct_p10_50_90": q(c[ok]), "margin_wrong_p10_50_90": q(c[~ok]),
        "fit_correct_p10_50_90": q(f[ok]), "fit_wrong_p10_50_90": q(f[~ok]),
        "auroc_margin": auroc(c, ok), "auroc_fit": auroc(-f, ok),
    }


def rate_summary(m: dict[str, Any]) -> dict[str, Any]:
    r = {k: np.asarray(v) for k, v in m["rate"].items()}

    def s(a: np.ndarray) -> dict[str, float | None]:
        if not a.size:
            return {"mean_abs": None, "bias": None, "p95_abs": None, "rows": 0}
        return {"mean_abs": float(np.abs(a).mean()), "bias": float(a.mean()), "p95_abs": float(np.percentile(np.abs(a), 95)),
                "rows": int(a.size)}

    return {"phase_rate": s(r["rel"]), "phase_rate_steady": s(r["rel_steady"]),
            "nominal": s(r["rel_nominal"]), "nominal_steady": s(r["rel_nominal_steady"])}


def strip(m: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in m.items() if k not in ("conf", "fit", "ok", "rate", "trace")}


# ---------------------------------------------------------------------------------------------
# Output: Markdown tables and figures


def pct(v: float | None, digits: int = 1) -> str:
    return "–" if v is None else f"{100 * v:.{digits}f} %"


def sec(v: float | None) -> str:
    return "–" if v is None else f"{v:.2f} s"


def md_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def delay_cell(m: dict[str, Any]) -> str:
    miss = f", {m['missed']} missed" if m["missed"] else ""
    return f"{sec(m['mean_delay_s'])}{miss}"


def write_tables(res: dict[str, Any], out: Path) -> str:
    R, idx = res["results"], res["index"]
    cols = [k for k in MAIN]
    names = res["titles"]
    parts = ["Data: " + "; ".join(f"**{k}** = {v}" for k, v in names.items()) + "."]

    def get(key: str, section: str, label: str) -> dict[str, Any]:
        return R[key][idx[section][label]]

    # 1. confidence
    rows = []
    for k in cols:
        d = res["confidence"][k]

        def q(name: str, d: dict[str, Any] = d) -> str:
            lo, mid, hi = d[name]
            return f"{mid:.2f} [{lo:.2f}–{hi:.2f}]"

        rows.append([k, f"{d['correct']} / {d['wrong']}", q("margin_correct_p10_50_90"), q("margin_wrong_p10_50_90"),
                     q("fit_correct_p10_50_90"), q("fit_wrong_p10_50_90"), f"{d['auroc_margin']:.2f}", f"{d['auroc_fit']:.2f}"])
    parts.append("### Table 1a: confidence on correct vs wrong samples (defaults)\n\n" + md_table(
        ["data", "correct / wrong", "margin, correct: median [p10–p90]", "margin, wrong", "fit RMS (deg), correct",
         "fit RMS, wrong", "AUROC margin", "AUROC fit"], rows))
    rows = []
    for label in idx["confidence"]:
        row = [label if label != "0" else "0 (off, paper)"]
        for k in cols:
            m = get(k, "confidence", label)
            held = f"{pct(m['nonheld_accuracy'])} ({pct(m['held_fraction'])})"
            row.append(f"{held}; {pct(m['accuracy'])}; {sec(m['mean_delay_s'])}")
        rows.append(row)
    parts.append("### Table 1b: `min_confidence` — accuracy on non-held samples (held fraction); accuracy of "
                 "all samples (held ones report the last confident mode); mean transition delay\n\n"
                 + md_table(["min_confidence", *cols], rows))

    # 2. supervision
    rows = []
    for label in idx["supervision"]:
        row = [label]
        for k in cols:
            m = get(k, "supervision", label)
            row.append(f"{pct(m['accuracy'])}; {pct(m['steady_accuracy'])}; {delay_cell(m)}; {m['switches_per_min']:.1f}")
        rev = R["SYN-rev"][idx["supervision"][label]]
        row.append(f"{pct(rev['accuracy'])}; {delay_cell(rev)}; {rev['switches_per_min']:.1f}")
        rows.append(row)
    truth_rate = []
    for k in [*cols, "SYN-rev"]:
        m = R[k][idx["supervision"]["off (paper)"]]
        truth_rate.append(f"{m['transitions']} changes, {60 * m['transitions'] / res['durations'][k]:.1f}/min")
    rows.append(["(truth)", *truth_rate])
    parts.append("### Table 2: transition supervision — accuracy; steady accuracy; mean transition delay; "
                 "reported mode changes per minute\n\n" + md_table(["setting", *cols, "SYN-rev (acc; delay; changes/min)"], rows))

    # 3. window fraction
    rows = []
    for label in idx["window"]:
        row = [label]
        for k in cols:
            m = get(k, "window", label)
            row.append(f"{pct(m['accuracy'])}; {pct(m['steady_accuracy'])}; {delay_cell(m)}; {pct(m['phase_error_mean'], 2)}; "
                       f"{m['switches_per_min']:.1f}")
        rows.append(row)
    parts.append("### Table 3: `window_fraction` — accuracy; steady accuracy; mean transition delay; phase error "
                 "(correct rows); mode changes per minute\n\n" + md_table(["window_fraction", *cols], rows))

    # 4. rate invariance
    rows = []
    for base, variants in res["rate_invariance"].items():
        for name, by in variants.items():
            for mode in ("no", "resample"):
                c = by[mode]
                rows.append([base, name, "yes" if mode == "resample" else "no",
                             f"{pct(c['mode_agreement'], 2)} ({c['rows_other_mode']})",
                             pct(c["phase_diff_mean"], 3), pct(c["phase_diff_p99"], 2),
                             f"{pct(c['phase_diff_max'], 2)} ({c['rows_phase_over_0.5pct']})",
                             pct(c["accuracy"]), pct(c["phase_error_mean"], 2)])
    parts.append("### Table 4: rate invariance — against the original-rate run (no resampling): mode agreement and "
                 "phase difference (same-mode rows); against the truth: accuracy, phase error\n\n" + md_table(
                     ["recording", "input", "`--resample`", "mode agreement (rows differing)", "phase diff mean", "p99",
                      "max (rows > 0.5 %)", "accuracy", "phase error"], rows))

    # 5. channels
    rows = []
    for label in idx["channels"]:
        row = [label]
        for k in cols:
            m = get(k, "channels", label)
            row.append(f"{pct(m['accuracy'])}; {pct(m['steady_accuracy'])}; {pct(m['phase_error_mean'], 2)}")
        rows.append(row)
    parts.append("### Table 5: channels — accuracy; steady accuracy; phase error (correct rows)\n\n"
                 + md_table(["channels", *cols], rows))

    # 6. sub-sample phase
    rows = []
    for label in idx["subsample"]:
        row = [label]
        for k in cols:
            m = get(k, "subsample", label)
            row.append(f"{pct(m['phase_error_mean'], 3)}; {pct(m['phase_error_all_mean'], 3)}; {pct(m['phase_error_max'], 2)}")
        rows.append(row)
    parts.append("### Table 6: sub-sample phase — phase error mean over correct rows; over all evaluated rows; max "
                 "(correct rows)\n\n" + md_table(["subsample_phase", *cols], rows))

    # 7. phase rate
    rcols = [*cols, "SYN-cad"]

    def rate_cell(a: dict[str, Any], b: dict[str, Any]) -> str:
        return f"{pct(a['mean_abs'], 2)} ({pct(a['bias'], 1)}); {pct(b['mean_abs'], 2)}"

    first = next(iter(idx["phase_rate"]))
    rows = [["nominal kernel frequency of the reported mode (no phase rate)",
             *(rate_cell(res["phase_rate"][k][first]["nominal"], res["phase_rate"][k][first]["nominal_steady"]) for k in rcols)]]
    for label in idx["phase_rate"]:
        rows.append([f"`phase_rate`, {label}", *(rate_cell(res["phase_rate"][k][label]["phase_rate"],
                                                         res["phase_rate"][k][label]["phase_rate_steady"]) for k in rcols)])
    parts.append("### Table 7: phase rate vs the true stride frequency (1 / duration of the current stride) — mean "
                 "absolute relative error (bias) over evaluated rows; mean absolute error over steady rows\n\n"
                 + md_table(["estimate", *rcols], rows))
    text = "\n\n".join(parts) + "\n"
    (out / "tables.md").write_text(text, encoding="utf-8")
    return text


def figures(res: dict[str, Any], raw: dict[str, dict[str, Any]], out: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    R, idx = res["results"], res["index"]
    # Figure 1: confidence distributions
    fig = Figure(figsize=(13, 6))
    FigureCanvasAgg(fig)
    axes = fig.subplots(2, len(MAIN))
    for j, k in enumerate(MAIN):
        m = raw[k]
        c, f, ok = np.asarray(m["conf"]), np.asarray(m["fit"]), np.asarray(m["ok"], dtype=bool)
        bins = np.logspace(-3, 3, 49)
        fb = np.linspace(0, 20, 81)
        for okv, lab, col in ((ok, "correct", "tab:green"), (~ok, "wrong", "tab:red")):
            w = np.full(int(okv.sum()), 1.0 / max(int(okv.sum()), 1))  # each group sums to 1
            axes[0, j].hist(np.clip(c[okv], 1e-3, 1e3), bins=bins, weights=w, alpha=0.5, color=col, label=f"{lab} ({okv.sum()})")
            axes[1, j].hist(np.clip(f[okv], 0, 20), bins=fb, weights=w, alpha=0.5, color=col, label=lab)
        axes[0, j].set_xscale("log")
        axes[0, j].legend(fontsize=7)
        axes[0, j].set_title(f"{k}: margin (AUROC {res['confidence'][k]['auroc_margin']:.2f})", fontsize=10)
        axes[1, j].set_title(f"{k}: fit RMS, deg (AUROC {res['confidence'][k]['auroc_fit']:.2f})", fontsize=10)
        axes[0, j].set_xlabel("(SSE_2nd - SSE_best) / SSE_best")
        axes[1, j].set_xlabel("deg")
    axes[0, 0].set_ylabel("fraction of the group's samples")
    axes[1, 0].set_ylabel("fraction of the group's samples")
    fig.suptitle("Confidence of the default estimator on correctly and wrongly classified evaluated samples "
                 "(margin clipped to [1e-3, 1e3], fit RMS to 20 deg)", fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "confidence.png", dpi=100)

    # Figure 2: accuracy vs transition delay
    fig = Figure(figsize=(13, 3.8))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(MAIN))
    series = [
        ("window_fraction", "window", ["1.0 (paper)", "0.75", "0.5"], "tab:blue", "o-"),
        ("min_dwell_s", "supervision", ["off (paper)", "min_dwell_s 0.05", "min_dwell_s 0.1", "min_dwell_s 0.2",
                                        "min_dwell_s 0.3", "min_dwell_s 0.5"], "tab:orange", "s-"),
        ("min_confidence", "confidence", ["0", "0.05", "0.1", "0.2", "0.5"], "tab:purple", "^-"),
    ]
    for j, k in enumerate(MAIN):
        ax = axes[j]
        for name, section, labels, col, style in series:
            ms = [R[k][idx[section][lab]] for lab in labels]
            x = [m["mean_delay_s"] for m in ms]
            y = [100 * m["accuracy"] for m in ms]
            ax.plot(x, y, style, color=col, label=name, ms=4)
            ax.annotate(labels[-1].split()[-1], (x[-1], y[-1]), fontsize=7)
        ax.plot([x[0]], [y[0]], "k*", ms=10, label="paper (defaults)")
        ax.set_title(k, fontsize=10)
        ax.set_xlabel("mean transition delay (s)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("accuracy (%)")
    axes[0].legend(fontsize=7)
    fig.suptitle("Accuracy vs mean transition delay (each curve starts at the paper's defaults; label = last value)",
                 fontsize=11)
    fig.tight_layout()
    fig.savefig(out / "tradeoff.png", dpi=100)


# ---------------------------------------------------------------------------------------------
# CLI cross-check: the in-process pipeline gives what `gait-estimator process` + `evaluate` give


def cli_check(shared: Path, in_process: dict[str, Any]) -> dict[str, Any]:
    exe = shutil.which("gait-estimator", path=str(Path(sys.executable).parent)) or shutil.which("gait-estimator")
    if exe is None:
        return {"skipped": "gait-estimator not found"}
    _, uni = lg2_uniform(shared, 230.0)
    with tempfile.TemporaryDirectory() as tmp:
        csv_path = write_project_csv(uni, Path(tmp) / "lg2_230.csv")
        flags = ["--window-fraction", "0.5", "--min-dwell-s", "0.1"]
        subprocess.run([exe, "process", str(csv_path), "--kernels", "able_bodied", *flags, "--out", f"{tmp}/p.csv", "--quiet"],
                       check=True, capture_output=True)
        subprocess.run([exe, "evaluate", "--predictions", f"{tmp}/p.csv", "--truth", str(csv_path), "--label-map",
                        "level=Slow|Med|Fast", "--out-dir", f"{tmp}/ev"], check=True, capture_output=True)
        cli = json.loads((Path(tmp) / "ev" / "metrics.json").read_text(encoding="utf-8"))
    delays = [e["delay_s"] for e in cli["transitions"]["events"] if e["delay_s"] is not None]
    ok = (abs(cli["accuracy"] - in_process["accuracy"]) < 1e-12
          and abs(float(np.mean(delays)) - in_process["mean_delay_s"]) < 1e-5
          and abs(cli["phase_error_mean"] - in_process["phase_error_mean"]) < 1e-6)
    return {"command": f"gait-estimator process LG2@230 --kernels able_bodied {' '.join(flags)} + evaluate",
            "cli_accuracy": cli["accuracy"], "script_accuracy": in_process["accuracy"],
            "cli_phase_error_mean": cli["phase_error_mean"], "script_phase_error_mean": in_process["phase_error_mean"],
            "agree": ok}


# ---------------------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(REPO / "experiments/results/beyond"), help="output directory")
    ap.add_argument("--seeds", type=int, default=5, help="synthetic recordings per route (default 5)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="worker processes (default 2)")
    ap.add_argument("--no-cli-check", action="store_true", help="skip the gait-estimator CLI cross-check")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    res, raw_base = compute(args, out)
    res["command"] = "python experiments/beyond_paper.py " + " ".join(argv if argv is not None else sys.argv[1:])
    res["runtime_s"] = round(time.perf_counter() - start, 1)
    report(res, raw_base, out)
    print(f"wrote {out}/summary.json, tables.md, confidence.png, tradeoff.png in {time.perf_counter() - start:.0f} s")
    return 0


def compute(args: argparse.Namespace, out: Path) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Run every experiment; returns (summary, the default runs' raw confidence data)."""
    start = time.perf_counter()
    shared = data_root()
    ab = load_library("able_bodied")

    for ds in (multispeed(shared, ab), lg2_able_bodied(shared, ab), lg2_own(shared, out), synthetic(ab, args.seeds),
               synthetic_reversals(ab, args.seeds), synthetic_cadence(ab, args.seeds)):
        DATASETS[ds.key] = ds
    # rate-invariance data sets: Multispeed and synthetic seed 0, each at other rates / with jitter
    ri_bases = {"Multispeed": DATASETS["MS"], "synthetic seed 0": DATASETS["SYN"]}
    for base, ds in ri_bases.items():
        part = ds.parts[0]
        for name, rec in rate_variants(part, ds.library.sample_rate_hz).items():
            DATASETS[f"RI:{base}:{name}"] = Dataset(f"RI:{base}:{name}", name, ds.library, [relabel(part, rec)])
    # LG_2_Ramp's real, irregular stamps vs its 230 Hz copy (the reference, as run.sh makes it)
    raw, _ = lg2_uniform(shared, ab.sample_rate_hz)
    copy = DATASETS["LG2-AB"].parts[0]
    for name, part in (("230 Hz copy (gait-estimator resample)", copy),
                       ("raw stamps (1.7–10 ms apart)", Part("LG_2_Ramp raw", raw, raw, copy.hs, copy.label_map))):
        DATASETS[f"RI:LG_2_Ramp:{name}"] = Dataset(f"RI:LG_2_Ramp:{name}", name, ab, [part])

    tasks, index = build_tasks(args.seeds)
    print(f"{len(tasks)} tasks on {args.jobs} worker(s) ...", flush=True)
    results = run_all(tasks, args.jobs)
    print(f"estimation and evaluation done after {time.perf_counter() - start:.0f} s", flush=True)

    res: dict[str, Any] = {"index": index, "results": {}, "confidence": {}, "phase_rate": {}, "rate_invariance": {}}
    raw_base: dict[str, dict[str, Any]] = {}
    for key in [*MAIN, "SYN-rev"]:
        res["results"][key] = {okey: strip(m) for (k, okey), m in results.items() if k == key}
    for key in MAIN:
        base = results[(key, option_key({}))]
        raw_base[key] = base
        res["confidence"][key] = confidence_distributions(base)
    for key in [*MAIN, "SYN-cad"]:
        res["phase_rate"][key] = {label: rate_summary(results[(key, okey)]) for label, okey in index["phase_rate"].items()}
    res["durations"] = {
        k: sum(float(p.feed.time_s[-1] - p.feed.time_s[0]) for p in DATASETS[k].parts) for k in [*MAIN, "SYN-rev"]
    }

    for base in [*ri_bases, "LG_2_Ramp"]:
        keys = [k for k in DATASETS if k.startswith(f"RI:{base}:")]
        ref = results[(keys[0], "no")]["trace"][0]
        ref_name = keys[0].split(":", 2)[2]
        t0 = ref["time_s"][0]
        rate = ab.sample_rate_hz
        res["rate_invariance"][base] = {}
        for k in keys:
            by = {}
            for mode in ("no", "resample"):
                m = results[(k, mode)]
                by[mode] = {**compare_traces(ref, m["trace"][0], rate, t0), "accuracy": m["accuracy"],
                            "phase_error_mean": m["phase_error_mean"], "reference": ref_name}
            res["rate_invariance"][base][k.split(":", 2)[2]] = by

    if not args.no_cli_check:
        key = option_key({"min_dwell_s": 0.1, "window_fraction": 0.5})
        res["cli_check"] = cli_check(shared, res["results"]["LG2-AB"][key])
        print(f"CLI cross-check: {res['cli_check']}", flush=True)

    res["machine"] = {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
                      "cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__}
    res["seeds"] = args.seeds
    res["titles"] = {k: DATASETS[k].title for k in [*MAIN, "SYN-rev", "SYN-cad"]}
    return res, raw_base


def report(res: dict[str, Any], raw_base: dict[str, dict[str, Any]], out: Path) -> None:
    (out / "summary.json").write_text(json.dumps(res, indent=1, default=float) + "\n", encoding="utf-8")
    print(write_tables(res, out))
    figures(res, raw_base, out)


if __name__ == "__main__":
    sys.exit(main())
