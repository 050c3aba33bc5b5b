#!/usr/bin/env python3
"""Cross-session benchmark: the estimator as a new wearer meets it (docs/results.md).

    python benchmarks/cross_session.py --jobs 2       # ~6 min -> benchmarks/results/cross_session/
    python benchmarks/cross_session.py --settings "default,paper" --datasets SYN-NEW,LG2-AB --seeds 3
    python benchmarks/cross_session.py --add 'mine={"offset_tolerance_deg": 4.0}'
    python benchmarks/cross_session.py --tables-only  # rewrite tables.md from summary.json

Every data set goes through ``run_estimator`` (the code behind ``gait-estimator process``: in bulk
where the options allow, else ``Estimator.update`` sample by sample, with the same results) under
every *setting*: a named dict of options on top of the preset its ``preset`` key names (``default``
if none), as ``gait-estimator process --preset P`` with option flags does (``SETTINGS``; ``--add
NAME=JSON`` adds one). ``"<table>"`` as the ``transitions`` value stands for the data set's
allowed-transitions file. Settings naming an option this build does not
have are skipped (listed in summary.json); settings that resolve to the same configuration run once.
Metrics come from ``gait_estimator.analysis.evaluate.evaluate`` via common.part_stats/pool.

Data sets (``--datasets``):

* ``SYN-NEW``: ``--seeds`` synthetic new wearers (test/synthetic.py ``new_wearer``: offsets +-8 deg,
  amplitude +-15 %, cadence +-12 %, noise 0.2-1 deg, 100-500 Hz with interval jitter) walking the
  78-stride route of all 7 modes (common.ROUTE), bundled able_bodied kernels; ``SYN-NEW-L`` scores
  Slow/Med/Fast as one class. ``SYN-SELF``: the route walked by the kernels' own person (in-sample).
* ``LG2-AB``: LG_2_Ramp at its raw stamps with the able_bodied kernels (``level`` = Slow, Med or
  Fast); ``LG2-AB@230``: its 230 Hz copy as benchmarks/accuracy.py makes it.
* ``MS-LG2``: Multispeed with level/RA/RD kernels trained on LG_2_Ramp (every stride is level).
  ``LG2-MS``: LG_2_Ramp with Slow/Med/Fast kernels trained on Multispeed (level rows only).
* ``RATES``: synthetic wearer 0 and Multispeed at 100/200/230/500 Hz and with +-2 ms jitter.

After the accuracy runs, the wall time of each ``Estimator.update`` call on input samples 500-2499
of every data set's first part is measured (configurations interleaved sample by sample).
Writes ``summary.json`` and ``tables.md`` (copied into docs by ``make docs``) into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import os
import shlex
import sys
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from common import (
    DATASETS,
    DET,
    MS_CSV,
    REPO,
    ROUTE,
    TABLE,
    Dataset,
    Part,
    column_hs,
    data_root,
    lg2_able_bodied,
    lg2_uniform,
    machine,
    multispeed,
    part_stats,
    pool,
    rate_variants,
    relabel,
    train_lg2,
)
from cross_session_report import RATE_REFERENCE, targets, write_tables
from synthetic import SyntheticConfig, generate, new_wearer

from gait_estimator.analysis.labels import LabelRange, duration_labels, merge_steady, with_ranges
from gait_estimator.analysis.strides import heel_strikes
from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.core.kernels import KernelLibrary
from gait_estimator.core.strides import stride_bounds
from gait_estimator.io.library_io import load_library
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording

# ---------------------------------------------------------------------------------------------
# Settings: named option sets on top of a preset (config_of)

TABLE_VALUE = "<table>"
"""``transitions`` value replaced by the data set's allowed-transitions file ('' when it has none)."""

PAPER: dict[str, Any] = {"preset": "paper"}
"""The paper's algorithm (the reference implementation's options): EstimatorConfig.preset("paper")."""

P = {"preset": "paper"}
DEFAULTS = EstimatorConfig.preset("default")
SETTINGS: dict[str, dict[str, Any]] = {
    "default": {},
    "paper": PAPER,
    "paper + resample": {**P, "resample": "auto"},
    "paper + resample + time scales": {**P, "resample": "auto", "time_scales": list(DEFAULTS.time_scales),
                                       "normalize_error": True},
    "paper + resample + offset calibration": {**P, "resample": "auto", "offset_tolerance_deg": 2.0,
                                              "offset_calibration_rate": DEFAULTS.offset_calibration_rate},
    "default: one time scale": {"time_scales": [1.0]},
    "default: 3 time scales ±8 %": {"time_scales": [0.92, 1.0, 1.08]},
    "default: 5 time scales ±12 %": {"time_scales": [0.88, 0.94, 1.0, 1.06, 1.12]},
    "default: no calibration": {"offset_calibration_rate": 0.0},
    "default: no calibration + tolerance 4°": {"offset_calibration_rate": 0.0, "offset_tolerance_deg": 4.0},
    "default: calibration 0.1": {"offset_calibration_rate": 0.1},
    "default: calibration 0.2": {"offset_calibration_rate": 0.2},
    "default: tolerance 0°": {"offset_tolerance_deg": 0.0},
    "default: tolerance 4°": {"offset_tolerance_deg": 4.0},
    "default: shapes only": {"offset_tolerance_deg": math.inf, "offset_calibration_rate": 0.0},
    "default: no cadence calibration": {"cadence_calibration_rate": 0.0},
    "default: cadence calibration 0.2": {"cadence_calibration_rate": 0.2},
    "default: cadence tolerance 8 %": {"cadence_tolerance": 0.08},
    "default: cadence tolerance 4 %": {"cadence_tolerance": 0.04},
    "default: SSE (not per sample)": {"normalize_error": False},
    "default: uniform weights": {"recency_half_life": 0.0},
    "default: recency half-life 0.2": {"recency_half_life": 0.2},
    "default: recency half-life 0.5": {"recency_half_life": 0.5},
    "default + min_dwell_s 0.1": {"min_dwell_s": 0.1},
    "default + transitions table": {"transitions": TABLE_VALUE},
    "default + personalisation 0.1": {"adapt_rate": 0.1},
    "default + personalisation 0.3": {"adapt_rate": 0.3},
}
"""Every setting is run on every data set except RATES (``RATE_SETTINGS`` only). A ``preset`` key
picks the preset the other options apply to (default: ``default``)."""

RATE_SETTINGS = ("default", "paper", "paper + resample")
"""Settings run on the RATES variants (each variant is a whole recording: keep this short)."""

SELF_SETTINGS = ("default", "paper", "default: uniform weights")
"""Settings run on SYN-SELF (the in-sample reference for SYN-NEW)."""

SPEEDS = ("Slow", "Med", "Fast")
"""The level-walking speed classes: a new wearer's cadence (+-12 %) and amplitude (+-15 %) span
the differences between them, so SYN-NEW-L also scores them as one class."""

DATASET_KEYS = ("SYN-NEW", "SYN-SELF", "LG2-AB", "LG2-AB@230", "MS-LG2", "LG2-MS", "RATES")

TIMED = (500, 2500)
"""Input samples [start, stop) of each data set's first part whose update calls are timed."""

LG2_TABLE_YAML = (
    "# Allowed transitions for the 3-mode LG_2_Ramp library (written by benchmarks/cross_session.py):\n"
    "# as config/transitions.yaml, no direct ramp ascent <-> ramp descent.\n"
    "allowed_transitions:\n  level: [RA, RD]\n  RA: [level]\n  RD: [level]\n"
)


# ---------------------------------------------------------------------------------------------
# Data sets


def syn_new(ab: KernelLibrary, seeds: int) -> tuple[Dataset, list[dict[str, Any]]]:
    parts, wearers = [], []
    for s in range(seeds):
        cfg = new_wearer(s)
        syn = generate(ab, ROUTE, cfg, seed=1000 + s, source=f"wearer {s}")
        parts.append(Part(f"wearer {s}", syn.recording, syn.recording, column_hs(syn.recording), synthetic=syn))
        wearers.append({"seed": s, "rate_hz": cfg.rate_hz, "jitter": cfg.jitter, "cadence": cfg.cadence,
                        "offset_deg": list(cfg.channel_offset_deg), "gain": list(cfg.channel_gain),
                        "noise_sd_deg": cfg.noise_sd_deg, "samples": len(syn.recording),
                        "duration_s": float(syn.recording.time_s[-1])})
    return Dataset("SYN-NEW", f"{seeds} synthetic new wearers, able_bodied kernels", ab, parts, str(TABLE)), wearers


def syn_self(ab: KernelLibrary, seeds: int) -> Dataset:
    """SYN-NEW's route walked by the kernels' own person (in-sample), at the library's rate."""
    parts = []
    for s in range(seeds):
        syn = generate(ab, ROUTE, SyntheticConfig(), seed=1000 + s, source=f"own person {s}")
        parts.append(Part(syn.recording.source, syn.recording, syn.recording, column_hs(syn.recording), synthetic=syn))
    return Dataset("SYN-SELF", f"SYN-NEW's route walked {seeds} times by the kernels' own person (in-sample reference)",
                   ab, parts, str(TABLE))


def lg2_raw_part(shared: Path) -> Part:
    """LG_2_Ramp at its raw stamps, labelled, heel strikes from the right foot angle (median rate)."""
    raw, _ = lg2_uniform(shared, None)
    hs = heel_strikes(raw, "right_foot", None, DET)
    return Part("LG_2_Ramp raw", raw, raw, hs, {"level": ("Slow", "Med", "Fast")})


def every_stride_level(rec: Recording, source: str) -> Part:
    """Multispeed with every stride (right-shank heel strikes, 0.6-2.5 s) labelled ``level``."""
    hs = heel_strikes(rec, source, None, DET)
    bounds, _ = stride_bounds(hs.times_s, DET)
    ranges: list[LabelRange] = []
    for a, b in bounds:
        if ranges and math.isclose(ranges[-1].end_s, a, abs_tol=1e-9):
            ranges[-1] = LabelRange(ranges[-1].start_s, float(b), "level")
        else:
            ranges.append(LabelRange(float(a), float(b), "level"))
    truth = with_ranges(rec, ranges)
    return Part("Multispeed", rec, truth, hs)


def r4(x: float) -> float:
    """Label files hold times with 4 decimals (write_label_ranges)."""
    return float(f"{x:.4f}")


def train_multispeed(shared: Path, ab: KernelLibrary) -> KernelLibrary:
    """Slow/Med/Fast kernels as benchmarks/accuracy.py trains them: ``label-strides --modes
    Slow,Med,Fast --heel-strikes right_shank`` (steady strides), the first half of
    every range), ``train --heel-strikes right_shank`` on the first halves."""
    rec = read_recording(shared / MS_CSV, rate_hz=ab.sample_rate_hz)
    hs = heel_strikes(rec, "right_shank", None, DET)
    bounds, _ = stride_bounds(hs.times_s, DET)
    durations = {n: ab.mode(n).stride_duration_s for n in ("Slow", "Med", "Fast")}
    ranges = [LabelRange(r4(r.start_s), r4(r.end_s), r.mode) for r in merge_steady(duration_labels(bounds, durations, 0.15))]
    first = [LabelRange(r.start_s, r4(0.5 * (r.start_s + r.end_s)), r.mode) for r in ranges]
    return train_library([with_ranges(rec, first)], "multispeed", TrainOptions(heel_strikes="right_shank")).library


def kernel_check(lib: KernelLibrary, path: Path) -> dict[str, Any]:
    """Largest difference from the kernels benchmarks/accuracy.py wrote (same procedure, via the CLI)."""
    if not path.is_file():
        return {"file": str(path.relative_to(REPO)), "skipped": "not found"}
    ref = load_library(str(path))
    same = ref.mode_names == lib.mode_names and all(a.length == b.length for a, b in zip(ref.modes, lib.modes, strict=True))
    diff = max(float(np.abs(a.samples - b.samples).max()) for a, b in zip(ref.modes, lib.modes, strict=True)) if same else None
    return {"file": str(path.relative_to(REPO)), "same_modes_and_lengths": same, "max_abs_diff_deg": diff}


def build_datasets(keys: Sequence[str], seeds: int, out: Path) -> dict[str, Any]:
    """Fill DATASETS with the requested data sets; returns notes for the summary."""
    shared = data_root()
    ab = load_library("able_bodied")
    notes: dict[str, Any] = {"kernel_checks": {}}
    lg2_table = out / "transitions_lg2.yaml"
    lg2_table.write_text(LG2_TABLE_YAML, encoding="utf-8")
    if "SYN-NEW" in keys:
        ds, notes["wearers"] = syn_new(ab, seeds)
        DATASETS[ds.key] = ds
        level = {m: SPEEDS for m in SPEEDS}
        DATASETS["SYN-NEW-L"] = replace(
            ds, key="SYN-NEW-L", title=f"{ds.title}; Slow, Med and Fast count as one level-walking class",
            parts=[replace(p, label_map=level) for p in ds.parts])
    if "SYN-SELF" in keys:
        DATASETS["SYN-SELF"] = syn_self(ab, seeds)
    if "LG2-AB" in keys:
        DATASETS["LG2-AB"] = Dataset("LG2-AB", "LG_2_Ramp (raw stamps), able_bodied kernels", ab, [lg2_raw_part(shared)],
                                     str(TABLE))
    if "LG2-AB@230" in keys:
        ds = lg2_able_bodied(shared, ab)
        ds.key, ds.title = "LG2-AB@230", "LG_2_Ramp (230 Hz copy), able_bodied kernels"
        DATASETS[ds.key] = ds
    if "MS-LG2" in keys:
        lib = train_lg2(shared)
        notes["kernel_checks"]["lg2"] = kernel_check(lib, REPO / "benchmarks/results/accuracy/lg2_kernels.yaml")
        rec = read_recording(shared / MS_CSV, rate_hz=ab.sample_rate_hz)
        DATASETS["MS-LG2"] = Dataset("MS-LG2", "Multispeed, level/RA/RD kernels trained on LG_2_Ramp", lib,
                                     [every_stride_level(rec, "right_shank")], str(lg2_table))
    if "LG2-MS" in keys:
        lib = train_multispeed(shared, ab)
        notes["kernel_checks"]["multispeed"] = kernel_check(lib, REPO / "benchmarks/results/accuracy/multispeed_kernels.yaml")
        part = lg2_raw_part(shared)
        part.label_map = {"level": ("Slow", "Med", "Fast"), "RA": (), "RD": ()}
        DATASETS["LG2-MS"] = Dataset("LG2-MS", "LG_2_Ramp (raw stamps), Slow/Med/Fast kernels trained on Multispeed "
                                     "(level rows only: accuracy is 100 % by construction)", lib, [part], "")
    if "RATES" in keys:
        base = replace(new_wearer(0), rate_hz=None, jitter=0.0)  # wearer 0 at the library rate, uniform
        variants = {"100 Hz": {"rate_hz": 100.0}, "200 Hz": {"rate_hz": 200.0}, RATE_REFERENCE: {},
                    "500 Hz": {"rate_hz": 500.0}, "230 Hz ±2 ms off the grid": {"stamp_jitter_s": 0.002}}
        for name, change in variants.items():
            syn = generate(ab, ROUTE, replace(base, **change), seed=1000, source=f"wearer 0 {name}")
            key = f"RATES-SYN {name}"
            DATASETS[key] = Dataset(key, name, ab, [Part(syn.recording.source, syn.recording, syn.recording,
                                                          column_hs(syn.recording), synthetic=syn)], str(TABLE))
        ms = multispeed(shared, ab)
        for name, rec in rate_variants(ms.parts[0], ab.sample_rate_hz).items():
            label = RATE_REFERENCE if name.endswith("(original)") else name
            key = f"RATES-MS {label}"
            DATASETS[key] = Dataset(key, label, ab, [relabel(ms.parts[0], rec)], str(TABLE))
    return notes


# ---------------------------------------------------------------------------------------------
# Settings -> configurations


def resolve(options: dict[str, Any], ds: Dataset) -> dict[str, Any]:
    return {k: (ds.table if k == "transitions" and v == TABLE_VALUE else v) for k, v in options.items()}


def config_of(options: dict[str, Any]) -> EstimatorConfig:
    """The configuration of a setting: its ``preset`` (default ``default``), then its options."""
    opts = {k: tuple(v) if isinstance(v, list) else v for k, v in options.items()}
    return EstimatorConfig.preset(opts.pop("preset", "default"), **opts)


def make_estimator(ds: Dataset, part: Part, options: dict[str, Any]) -> Estimator:
    """As ``gait-estimator process`` makes it: a recording without stamps counts as unstamped."""
    return Estimator(ds.library, config_of(options), stamped=not part.feed.time_from_rate)


def config_key(options: dict[str, Any]) -> str:
    """Identity of the configuration an option set gives (equal configurations run once)."""
    return repr(config_of(options))


def usable_settings(settings: dict[str, dict[str, Any]]) -> tuple[dict[str, dict[str, Any]], dict[str, str]]:
    """(settings this EstimatorConfig accepts, skipped name -> reason)."""
    ok, skipped = {}, {}
    for name, opts in settings.items():
        try:
            config_of({k: ("" if v == TABLE_VALUE else v) for k, v in opts.items()})
        except (ValueError, TypeError) as exc:
            skipped[name] = str(exc)
            continue
        ok[name] = opts
    return ok, skipped


def settings_of(key: str, settings: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    if key.startswith("RATES-"):
        return {n: o for n, o in settings.items() if n in RATE_SETTINGS}
    if key == "SYN-SELF":
        return {n: o for n, o in settings.items() if n in SELF_SETTINGS}
    return settings


# ---------------------------------------------------------------------------------------------
# Running


Run = tuple[str, int, str, dict[str, Any]]
"""(data set key, part index, configuration key, options)."""


def run_part(run: Run) -> dict[str, Any]:
    key, i, _, options = run
    ds = DATASETS[key]
    part = ds.parts[i]
    est = make_estimator(ds, part, options)
    trace = run_estimator(est, part.feed.time_s, part.feed.angles_deg, part.feed.index)
    stats = part_stats(ds, part, trace, ("steady_modes",))
    stats["resets"] = est.resets
    stats["updates"] = len(part.feed)
    stats["estimates"] = len(trace)
    return stats


def run_all(runs: Sequence[Run], jobs: int) -> list[dict[str, Any]]:
    order = sorted(range(len(runs)), key=lambda k: -len(DATASETS[runs[k][0]].parts[runs[k][1]].feed))
    todo = [runs[k] for k in order]
    done = 0
    results: list[dict[str, Any]] = [{}] * len(runs)
    if jobs > 1:
        with multiprocessing.get_context("fork").Pool(jobs) as p:
            for k, res in zip(order, p.imap(run_part, todo, chunksize=1), strict=True):
                results[k] = res
                done += 1
                if done % 20 == 0:
                    print(f"  {done}/{len(runs)} runs", flush=True)
    else:
        for k, run in zip(order, todo, strict=True):
            results[k] = run_part(run)
    return results


def time_updates(ds: Dataset, configs: dict[str, dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Wall time of each Estimator.update call on input samples TIMED of the first part, the
    configurations interleaved sample by sample (see module docstring)."""
    feed = ds.parts[0].feed
    stop = min(TIMED[1], len(feed))
    ests = {k: make_estimator(ds, ds.parts[0], o) for k, o in configs.items()}
    ns = {k: np.zeros(stop - TIMED[0], dtype=np.int64) for k in configs}
    outputs = dict.fromkeys(configs, 0)
    clock = time.perf_counter_ns
    for i in range(stop):
        t, x = float(feed.time_s[i]), feed.angles_deg[i]
        for k, est in ests.items():
            t0 = clock()
            est.update(t, x)
            dt = clock() - t0
            n = 1
            if i >= TIMED[0]:
                ns[k][i - TIMED[0]] = dt
                outputs[k] += n
    return {k: {"median_us": float(np.median(v)) / 1e3, "p99_us": float(np.percentile(v, 99)) / 1e3,
                "per_estimate_us": float(v.sum()) / 1e3 / max(outputs[k], 1), "updates": int(v.size),
                "estimates": outputs[k]} for k, v in ns.items()}


def selected(args: argparse.Namespace) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """(settings, data set keys) from --add/--settings/--datasets; ValueError names the flag."""
    settings = dict(SETTINGS)
    for item in args.add or []:
        name, _, text = item.partition("=")
        try:
            opts = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"--add {item!r}: expected NAME=JSON object ({exc})") from None
        if not name.strip() or "," in name or not isinstance(opts, dict):
            raise ValueError(f"--add {item!r}: expected NAME=JSON object (NAME without commas), "
                             "e.g. 'mine={\"resample\": true}'")
        settings[name.strip()] = opts
    if args.settings:
        names = [n.strip() for n in args.settings.split(",") if n.strip()]
        unknown = [n for n in names if n not in settings]
        if unknown:
            raise ValueError(f"--settings: unknown setting(s) {', '.join(unknown)} (known: {', '.join(settings)})")
        settings = {n: settings[n] for n in names}
    keys = list(DATASET_KEYS) if not args.datasets else [k.strip() for k in args.datasets.split(",") if k.strip()]
    bad = [k for k in keys if k not in DATASET_KEYS]
    if bad:
        raise ValueError(f"--datasets: unknown data set(s) {', '.join(bad)} (known: {', '.join(DATASET_KEYS)})")
    if args.seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {args.seeds}")
    return settings, keys


def compute(args: argparse.Namespace, out: Path) -> dict[str, Any]:
    settings, keys = selected(args)
    settings, skipped = usable_settings(settings)
    for name, why in skipped.items():
        print(f"skipped setting {name!r}: {why}", flush=True)

    start = time.perf_counter()
    load = [os.getloadavg()[0]]
    notes = build_datasets(keys, args.seeds, out)
    print(f"data sets ready after {time.perf_counter() - start:.0f} s", flush=True)

    # distinct configurations per data set
    plan: dict[str, dict[str, str]] = {}  # data set -> setting -> config key
    configs: dict[str, dict[str, dict[str, Any]]] = {}  # data set -> config key -> options
    for key, ds in DATASETS.items():
        for name, opts in settings_of(key, settings).items():
            o = resolve(opts, ds)
            ck = config_key(o)
            plan.setdefault(key, {})[name] = ck
            configs.setdefault(key, {}).setdefault(ck, o)
    runs: list[Run] = [(key, i, ck, o) for key, cs in configs.items() for ck, o in cs.items()
                       for i in range(len(DATASETS[key].parts))]
    print(f"{len(runs)} runs ({sum(len(c) for c in configs.values())} data set x configuration) on {args.jobs} "
          f"worker(s) ...", flush=True)
    stats = run_all(runs, args.jobs)
    print(f"estimation and evaluation done after {time.perf_counter() - start:.0f} s", flush=True)
    by_config: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for (key, _, ck, _), st in zip(runs, stats, strict=True):
        by_config.setdefault((key, ck), []).append(st)

    timing: dict[str, dict[str, Any]] = {}
    for key, cs in configs.items():
        if key.startswith("RATES-"):
            continue
        t = time_updates(DATASETS[key], cs)
        timing[key] = {name: t[ck] for name, ck in plan[key].items()}
    print(f"timing done after {time.perf_counter() - start:.0f} s", flush=True)
    load.append(os.getloadavg()[0])

    results: dict[str, dict[str, Any]] = {}
    per_part: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for key, names in plan.items():
        results[key], per_part[key] = {}, {}
        for name, ck in names.items():
            sts = by_config[(key, ck)]
            m = pool(sts)
            m["per_mode_steady_accuracy"], m["per_mode_steady_samples"] = per_mode_steady(sts)
            m["resets"] = sum(s["resets"] for s in sts)
            m["estimates"] = sum(s["estimates"] for s in sts)
            m["same_configuration_as"] = next((n for n, c in names.items() if c == ck and n != name), None)
            if key in timing:
                m["cost"] = timing[key][name]
            results[key][name] = m
            if len(sts) > 1 or key == "SYN-NEW":
                per_part[key][name] = [pool([s]) for s in sts]
    paper_cfg = config_of(PAPER)
    res: dict[str, Any] = {
        "settings": settings, "skipped_settings": skipped,
        "default_configuration": repr(EstimatorConfig()),
        "default_is_paper": EstimatorConfig() == paper_cfg,
        "datasets": {k: {"title": ds.title, "library": ds.library.name, "modes": ds.library.mode_names,
                         "library_rate_hz": ds.library.sample_rate_hz, "parts": [p.name for p in ds.parts],
                         "feed_median_rate_hz": [p.feed.median_rate_hz for p in ds.parts],
                         "duration_s": sum(float(p.feed.time_s[-1] - p.feed.time_s[0]) for p in ds.parts),
                         "transitions_file": os.path.relpath(ds.table, REPO) if ds.table else ""}
                     for k, ds in DATASETS.items()},
        "results": results, "per_part": per_part, "notes": notes, "seeds": args.seeds, "timed_samples": list(TIMED),
        "machine": {**machine(), "cpu_model": cpu_model(), "load_average_1min_start_end": load},
    }
    res["targets"] = targets(res)
    return res


def cpu_model() -> str:
    try:
        lines = Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines()
    except OSError:
        return ""
    return next((ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")), "")


def per_mode_steady(stats: Sequence[dict[str, Any]]) -> tuple[dict[str, float | None], dict[str, int]]:
    """(steady accuracy, steady rows) per truth mode, pooled over parts."""
    out: dict[str, list[int]] = {}
    for s in stats:
        for n, (c, e) in s.get("per_mode_steady", {}).items():
            acc = out.setdefault(n, [0, 0])
            acc[0] += c
            acc[1] += e
    return {n: (c / e if e else None) for n, (c, e) in out.items()}, {n: e for n, (_, e) in out.items()}


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=str(REPO / "benchmarks/results/cross_session"), help="output directory")
    ap.add_argument("--settings", help=f"comma-separated setting names (default: all: {', '.join(SETTINGS)})".replace("%", "%%"))
    ap.add_argument("--add", action="append", metavar="NAME=JSON",
                    help="add a setting, e.g. 'mine={\"resample\": true}' (repeatable; select with --settings too)")
    ap.add_argument("--datasets", help=f"comma-separated data sets (default: all: {', '.join(DATASET_KEYS)})")
    ap.add_argument("--seeds", type=int, default=5, help="synthetic new wearers in SYN-NEW (default 5)")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="worker processes (default 2)")
    ap.add_argument("--tables-only", action="store_true", help="only rewrite tables.md from the --out summary.json")
    args = ap.parse_args(argv)
    try:
        selected(args)
    except ValueError as exc:
        ap.error(str(exc))  # one line, exit code 2
    start = time.perf_counter()
    out = Path(args.out)
    if args.tables_only:
        res = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        res["targets"] = targets(res)
        write_tables(res, out)
        print(f"wrote {out}/tables.md from {out}/summary.json")
        return 0
    out.mkdir(parents=True, exist_ok=True)
    res = compute(args, out)
    res["command"] = "python benchmarks/cross_session.py " + shlex.join(argv if argv is not None else sys.argv[1:])
    res["command"] = res["command"].strip()
    res["runtime_s"] = round(time.perf_counter() - start, 1)
    (out / "summary.json").write_text(json.dumps(res, indent=1, default=float) + "\n", encoding="utf-8")
    print(write_tables(res, out))
    print(f"wrote {out}/summary.json, tables.md in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
