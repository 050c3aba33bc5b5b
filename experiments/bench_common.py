"""Shared pieces of the estimator benchmarks in experiments/ (beyond_paper.py, cross_session.py).

Data sets as the benchmarks feed them (``Part``: what the estimator is fed and the truth
``gait_estimator.analysis.evaluate.evaluate`` compares with; ``Dataset``: parts and a kernel
library), the bundled recordings (Multispeed, LG_2_Ramp), running option sets through
``Estimator`` in worker processes, per-part counts (``part_stats``) pooled into metrics
(``pool``), rate variants of a recording, and the Markdown table helpers.

Not a module of the package: the scripts import it from their own directory.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import platform
import shlex
import sys
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
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "test"))
from synthetic import Synthetic, SyntheticConfig, generate  # noqa: E402  (test helper, after sys.path)

DET = DetectionOptions()
TABLE = REPO / "config" / "transitions.yaml"
LG2_CSV = "data/swge/recordings/LG_2_Ramp_AB_Sample.csv"
MS_CSV = "data/swge/recordings/Multispeed_Walk_AB.csv"
LG2_LABELS = REPO / "experiments/lg2_ramp_labels.csv"

ROUTE = [
    ("Slow", 6), ("Med", 6), ("Fast", 6), ("RA", 6), ("SA", 6), ("Med", 6), ("SD", 6),
    ("RD", 6), ("Slow", 6), ("SA", 6), ("Fast", 6), ("RD", 6), ("Med", 6),
]
"""Synthetic route: 78 strides, 12 mode changes, all allowed by config/transitions.yaml."""


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


def synthetic_part(lib: KernelLibrary, route: Sequence[tuple[str, int]], seed: int, name: str) -> Part:
    syn = generate(lib, route, SyntheticConfig(), seed=seed, source=name)
    rec = syn.recording
    return Part(name, rec, rec, column_hs(rec), synthetic=syn)



# ---------------------------------------------------------------------------------------------
# Running and evaluating

DATASETS: dict[str, Dataset] = {}  # filled in main() before the worker pool forks


def paper_config(options: dict[str, Any]) -> EstimatorConfig:
    """The paper preset with ``options`` on top: the base of the issue-6 measurements."""
    return EstimatorConfig.preset("paper", **{k: tuple(v) if isinstance(v, list) else v for k, v in options.items()})


def matcher_key(options: dict[str, Any]) -> tuple:
    """Settings are grouped by this (one task each); every setting runs its own estimator."""
    return tuple(sorted((k, repr(v)) for k, v in options.items()))


def run_group(ds: Dataset, part: Part, settings: Sequence[dict[str, Any]]) -> list[EstimateTrace]:
    """Estimate ``part`` under each option set of ``settings`` (on top of the paper preset), each
    through its own ``Estimator.update`` as ``process`` does (a recording without time stamps
    counts as unstamped)."""
    traces = []
    for options in settings:
        est = Estimator(ds.library, paper_config(options), stamped=not part.feed.time_from_rate)
        rows = [(int(part.feed.index[i]), est.update(float(part.feed.time_s[i]), part.feed.angles_deg[i]))
                for i in range(len(part.feed))]
        traces.append(trace_from_estimates(ds.library.mode_names, rows))
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
    if "steady_modes" in collect:
        steady = evald & (time_in_run(al.time_s, al.truth) >= settle_time(pred))
        out["per_mode_steady"] = {n: [int((correct & steady & (al.truth == n)).sum()), int((steady & (al.truth == n)).sum())]
                                  for n in dict.fromkeys(al.truth[evald].tolist())}
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
            "phase_rate": trace.phase_rate.tolist(),
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
    """Mode agreement and phase difference of ``other`` against ``ref`` (the original-rate run,
    one row per grid time t0 + i / rate): every ``other`` row at time t is compared with the
    reference as the estimator reports it at t, i.e. its last row at or before t with the phase
    advanced by its phase rate over the time since (as ``Estimator`` does between grid points);
    rows ready in both."""
    rt, rm, rp, rr = (np.asarray(ref[k]) for k in ("time_s", "mode", "phase", "ready"))
    rate_ref = np.nan_to_num(np.asarray(ref["phase_rate"], dtype=np.float64))
    ot, om, op, orr = (np.asarray(other[k]) for k in ("time_s", "mode", "phase", "ready"))
    i = np.floor((ot - t0) * rate_hz + 1e-6).astype(np.int64)
    ok = (i >= 0) & (i < rt.size)
    i = np.clip(i, 0, rt.size - 1)
    ok &= orr & rr[i] & (np.abs(ot - rt[i]) < 1.0 / rate_hz)
    same = ok & (om == rm[i])
    ref_phase = np.mod(rp[i] + rate_ref[i] * np.maximum(ot - rt[i], 0.0), 1.0)
    d = circular_error(op[same], ref_phase[same])
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



def machine() -> dict[str, Any]:
    """Where the numbers were measured."""
    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpus": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__}


def train_lg2(shared: Path) -> KernelLibrary:
    """level/RA/RD kernels trained on LG_2_Ramp as experiments/run.sh trains them
    (``gait-estimator train LG2 --labels experiments/lg2_ramp_labels.csv --heel-strikes right_foot``:
    raw stamps, the library at the recording's median rate)."""
    raw, _ = lg2_uniform(shared, None)
    return train_library([raw], "lg2", TrainOptions(heel_strikes="right_foot")).library


def machine_text() -> str:
    """The machine a script's tables were measured on, for their first line."""
    from gait_estimator.analysis.bench import machine_info

    m = machine_info()
    return (f"{m['processor']}, {m['cpus_allowed']} CPUs, Python {m['python']}, numpy {m['numpy']}, "
            f"numba {m['numba'] or 'not installed'}")


def recording_stats(lib: KernelLibrary, rec: Recording, trace: EstimateTrace) -> dict[str, Any]:
    """``part_stats`` of ``trace`` against a recording that carries its own truth (labels and a
    heel-strike column, as synthetic recordings do)."""
    part = Part(rec.source, rec, rec, column_hs(rec))
    return part_stats(Dataset("", "", lib, [part]), part, trace)


def run_script_jobs(
    script: str, argv: Sequence[str] | None, run: Any, jobs: Sequence[Any], workers: int
) -> tuple[list[Any], str, float]:
    """``run`` over ``jobs`` in ``workers`` forked processes (in order); also the command line that
    reruns the script (``script`` with ``argv``, default sys.argv) and the seconds it took."""
    t0 = time.perf_counter()
    with multiprocessing.get_context("fork").Pool(workers) as p:
        results = p.map(run, jobs, chunksize=1)
    command = shlex.join(["python", f"experiments/{script}", *(sys.argv[1:] if argv is None else argv)])
    return results, command, time.perf_counter() - t0


def write_report(out: Path, text: str, summary: Any) -> None:
    """``out``/tables.md (``text``, also printed) and ``out``/summary.json."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "tables.md").write_text(text, encoding="utf-8")
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    print(text)
