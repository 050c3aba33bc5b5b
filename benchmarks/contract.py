#!/usr/bin/env python3
"""What a controller can trust (docs/controller.md): the states beside the mode, the units check
and the mode switches, measured. One command:

    python benchmarks/contract.py                # ~4 min: writes benchmarks/results/contract/contract.json, tables.md
    python benchmarks/contract.py --tables-only  # only tables.md, from the saved contract.json (make docs)
    git worktree add /tmp/old 1d47482            # then, Estimator.update here and there, interleaved:
    taskset -c 0 python benchmarks/contract.py --update-cost /tmp/old

Default preset throughout, ``states`` on ("after") and off ("before", the estimator without states).

* camargo_ab06 (5 level-walking trials with standing, turns in the walk): kernels trained on the
  first half of the walking of every trial (as benchmarks/imu.py), each whole trial streamed;
  fed the motion-capture angles or the project's own IMU angles (raw gyro + accelerometer
  through ``read_imu_bag``, tared on the first standing, right thigh and shank; the left channels
  are mocap; the data set's known IMU faults are not scored for it). Standing rows: labelled
  ``stand`` from 0.5 s after the wearer stops. Walking rows:
  the second half's walking from the second heel strike after a stop to the last one before the
  next (``between_stops``: the first stride after starting and the last before stopping are
  transitions).
* LG_2_Ramp (bundled able_bodied kernels): the standing 3.0-4.9 s and the stop and standing turn
  12.5-17.9 s, whole and without its steps (``stepping``), and what those steps are: their swings'
  knee flexion and the reported fit against the level kernels' and the labelled walking's; accuracy on
  data/swge/recordings/LG_2_Ramp_AB_Sample.labels.csv (level = Slow, Med or Fast).
* Multispeed (able_bodied): the standing before the belt starts and after it stops; switches
  against benchmarks/accuracy.py's cadence labels (every stride, ``label-strides --all-strides``).
* Synthetic (test/synthetic.py, able_bodied): new wearers walking with stops (``with_stops``);
  running-like strides (knee flexion x1.6 over 0.7 of the stride time), sit-to-stand and back,
  stepping while turning in place.
* Switches: a change of the reported mode (``stand`` and ``unknown`` included) is false when no
  labelled change came in the ``SWITCH_WINDOW_S`` before it (``evaluate.switch_metrics``); per
  minute of labelled walking; delay = from a labelled change to the first row reporting the new
  label's mode. Trade-off curves: each option in ``SWEEPS`` over its values, per set.
* Update cost (``--update-cost``): ``Estimator.update`` per sample (default preset, able_bodied,
  Multispeed stamped at 230 Hz) in this checkout and another, one process per round, alternating;
  the median and p99 over all rounds and their ratios (printed, not saved: machine load).
* Units: each bundled recording (and each camargo trial, mocap and IMU) fed in the right unit
  and in the wrong one (degrees read as radians, radians read as degrees) through ``UnitsCheck``:
  seconds to the verdict from the start and from the first step; the tests' synthetic recordings
  for false warnings.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "test"))

from common import ROUTE, machine, md_table  # noqa: E402
from synthetic import SyntheticConfig, generate, new_wearer, with_stops  # noqa: E402

from gait_estimator.analysis.evaluate import SWITCH_LEAD_S, SWITCH_WINDOW_S, switch_metrics  # noqa: E402
from gait_estimator.analysis.labels import read_label_ranges, with_ranges  # noqa: E402
from gait_estimator.analysis.train import TrainOptions, train_library  # noqa: E402
from gait_estimator.core.estimator import EstimateTrace, Estimator, EstimatorConfig, run_estimator  # noqa: E402
from gait_estimator.core.kernels import KernelLibrary, KernelMode  # noqa: E402
from gait_estimator.core.pipeline import PipelineParams  # noqa: E402
from gait_estimator.core.states import STANDING, UNKNOWN_STATE, WALKING  # noqa: E402
from gait_estimator.core.units import first_problem  # noqa: E402
from gait_estimator.io.library_io import load_library  # noqa: E402
from gait_estimator.io.readers import read_recording  # noqa: E402
from gait_estimator.io.recording import Recording  # noqa: E402

OUT = REPO / "benchmarks" / "results" / "contract"
CAMARGO = REPO / "data" / "camargo_ab06"
LG2 = REPO / "data" / "swge" / "recordings" / "LG_2_Ramp_AB_Sample.csv"
MULTISPEED = REPO / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv"
LG2_LABELS = REPO / "data" / "swge" / "recordings" / "LG_2_Ramp_AB_Sample.labels.csv"
MULTISPEED_LABELS = REPO / "benchmarks" / "results" / "accuracy" / "multispeed_labels_all.csv"
COMMAND = "`python benchmarks/contract.py`"
GRACE_S = 0.5
LEVEL = ("Slow", "Med", "Fast")


OPTIONS: dict[str, Any] = {}
"""Estimator options on top of the default preset (``--options``, and the switch sweeps)."""


def estimator(lib: KernelLibrary, states: bool = True, **tuning: Any) -> Estimator:
    config = EstimatorConfig(states=states, **OPTIONS)
    return Estimator(lib, config, params=PipelineParams.from_config(config, states=tuning) if tuning else None)


def run(lib: KernelLibrary, rec: Recording, states: bool = True, **tuning: Any) -> EstimateTrace:
    return run_estimator(estimator(lib, states, **tuning), rec.time_s, rec.angles_deg)


SWEEPS = {"min_dwell_s": (0.0, 0.1, 0.2, 0.3, 0.5, 0.75), "switch_back_margin": (0.0, 0.1, 0.2, 0.3, 0.5, 0.7, 0.9)}
"""The switch trade-off curves: values of each option, the others as ``--options`` leaves them."""


def switch_curves(sets: dict[str, tuple[KernelLibrary, list[tuple[Recording, np.ndarray]]]],
                  tuning: dict[str, Any]) -> dict[str, Any]:
    """False switches per minute and mean delay (states on) for each value of each option in
    SWEEPS, per set of (recording, truth labels as ``switch_metrics`` takes them)."""
    out: dict[str, Any] = {}
    for option, values in SWEEPS.items():
        kept = OPTIONS.pop(option, None)
        out[option] = {}
        for name, (lib, recs) in sets.items():
            out[option][name] = []
            for value in values:
                OPTIONS[option] = value
                rows = [{"after": switch_metrics(r.time_s, tr.mode, tr.ready, labels)}
                        for r, labels in recs for tr in [run(lib, r, True, **tuning)]]
                out[option][name].append({option: value, **pool_switches(rows, ("after",))["after"]})
        OPTIONS.pop(option)
        if kept is not None:
            OPTIONS[option] = kept
    return out


def share(mask: np.ndarray, of: np.ndarray) -> float:
    return float(np.count_nonzero(mask & of) / max(np.count_nonzero(of), 1))


def bouts(flags: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) of every run of True."""
    d = np.diff(np.r_[0, flags.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def after_start(t: np.ndarray, flags: np.ndarray, grace_s: float) -> np.ndarray:
    """Rows of ``flags`` at least ``grace_s`` after the start of their run."""
    out = np.zeros_like(flags)
    for a, b in bouts(flags):
        out[a:b] = t[a:b] >= t[a] + grace_s
    return out


def between_stops(rec: Recording) -> np.ndarray:
    """Rows from the second heel strike after a ``stand`` bout (walking is reported from the first
    whole stride after the wearer starts) to the last heel strike before the next one."""
    t, stand = rec.time_s, rec.labels == "stand"
    hs = t[rec.heel_strike]
    out = ~stand
    for a, b in bouts(stand):
        before = hs[hs < t[a]]
        after = hs[hs > t[b - 1]]
        out &= ~((t >= (before[-1] if before.size else t[a])) & (t < (after[1] if after.size > 1 else t[-1] + 1)))
    return out


# ---------------------------------------------------------------------------------------------
# camargo_ab06


def imu_angles(rec: Recording, tmp: Path, name: str) -> np.ndarray:
    """The trial's angles through the project's IMU path (raw input), right channels tared on the
    first standing as benchmarks/imu.py does."""
    import imu  # benchmarks/imu.py

    from gait_estimator.io.imu_bag import read_imu_bag, write_imu_bag

    stamps, gyro, acc, left = imu.trial_sensors(rec)
    bag = write_imu_bag(tmp / name, stamps, np.radians(gyro), acc, [None, left[1], None, left[3]])
    got = read_imu_bag(bag, imu_lateral_axes=["", "+z", "", "+z"], imu_proximal_axes=["", "+y", "", "+y"])
    a = got.angles_deg.copy()
    stand = imu.first_stand(rec)
    for c in (0, 2):
        a[:, c] -= (a[stand, c] - rec.angles_deg[stand, c]).mean()
    return a


def camargo_trials(tmp: Path) -> tuple[dict[str, list[Recording]], list[np.ndarray]]:
    """The five trials as fed (motion capture, the IMU path's angles) and each trial's samples of
    the data set's known right thigh and shank IMU faults (benchmarks/imu.py)."""
    import imu

    mocap = [read_recording(p) for p in sorted(CAMARGO.glob("levelground_*.csv"))]
    for r in mocap:
        r.source = Path(r.source).stem
    imus = [Recording(r.time_s, imu_angles(r, tmp, r.source), r.labels, r.heel_strike, {}, r.source) for r in mocap]
    faults = [imu.shank_faults(r, r.source) | imu.thigh_faults(r) for r in mocap]
    return {"mocap": mocap, "imu": imus}, faults


def first_half(rec: Recording) -> Recording:
    walk_t = rec.time_s[rec.labels != "stand"]
    mid = 0.5 * (walk_t[0] + walk_t[-1])
    labels = np.where((rec.labels == "stand") | (rec.time_s >= mid), "", rec.labels).astype(object)
    return Recording(rec.time_s, rec.angles_deg, labels, rec.heel_strike, {}, rec.source)


def camargo_library(trials: list[Recording]) -> KernelLibrary:
    """walk_slow, walk_normal, walk_fast from the first half of every trial's walking."""
    return train_library([first_half(r) for r in trials], "camargo", TrainOptions(heel_strikes="column", min_strides=2)).library


def camargo(trials: list[Recording], tuning: dict[str, Any], faults: list[np.ndarray] | None = None) -> dict[str, Any]:
    """``faults``: per trial, samples not scored (the IMU input's known sensor faults)."""
    lib = camargo_library(trials)
    out: dict[str, Any] = {"fit_limits_deg": {m.name: m.info["fit_limit_deg"] for m in lib.modes}}
    pooled: dict[str, list] = {k: [] for k in ("stand_rows", "stand_ok", "walk_rows", "walk_stand", "walk_unknown",
                                                "correct_before", "correct_after", "phase_before", "phase_after")}
    switch_rows = []
    excluded = 0
    lost: dict[str, Any] = {"rows_by_state": [0] * 4, "stretches": []}
    for i, rec in enumerate(trials):
        t, lab = rec.time_s, rec.labels
        scored = ~faults[i] if faults is not None else np.ones(len(rec), dtype=bool)
        excluded += int(np.count_nonzero(~scored))
        stand = lab == "stand"
        walk_t = t[~stand]
        second = t >= 0.5 * (walk_t[0] + walk_t[-1])
        walking = second & between_stops(rec) & scored
        late_stand = after_start(t, stand, GRACE_S) & scored
        before, after = run(lib, rec, False), run(lib, rec, True, **tuning)
        truth = phase_truth_column(rec)
        gone = walking & (before.mode == lab) & (after.mode != lab)
        lost["rows_by_state"] = (np.asarray(lost["rows_by_state"]) + np.bincount(after.state[gone], minlength=4)).tolist()
        rate = after.phase_rate * np.array([m.stride_duration_s for m in lib.modes])[after.mode_index]
        lost["stretches"] += [[rec.source, float(t[a]), float(t[b - 1]), float(np.median(rate[a:b]))]
                              for a, b in bouts(gone) if b - a >= 5]
        for key, tr in (("before", before), ("after", after)):
            ok = (tr.mode == lab) & walking
            pooled[f"correct_{key}"].append(int(np.count_nonzero(ok)))
            err = np.abs(((tr.phase - truth) + 0.5) % 1.0 - 0.5)
            pooled[f"phase_{key}"].append(err[ok & np.isfinite(truth)])
        pooled["stand_rows"].append(int(late_stand.sum()))
        pooled["stand_ok"].append(int(np.count_nonzero(late_stand & (after.state == STANDING))))
        pooled["walk_rows"].append(int(walking.sum()))
        pooled["walk_stand"].append(int(np.count_nonzero(walking & (after.state == STANDING))))
        pooled["walk_unknown"].append(int(np.count_nonzero(walking & (after.state == UNKNOWN_STATE))))
        switch_rows.append({"trial": rec.source, **{k: switch_metrics(t, tr.mode, tr.ready, lab)
                                                    for k, tr in (("before", before), ("after", after))}})
    n_walk = sum(pooled["walk_rows"])
    out.update({
        "fault_rows_not_scored": excluded,
        "stand_rows": sum(pooled["stand_rows"]), "stand_reported_stand": sum(pooled["stand_ok"]) / sum(pooled["stand_rows"]),
        "walking_rows": n_walk, "walking_reported_stand": sum(pooled["walk_stand"]) / n_walk,
        "walking_reported_unknown": sum(pooled["walk_unknown"]) / n_walk,
        "accuracy_before": sum(pooled["correct_before"]) / n_walk, "accuracy_after": sum(pooled["correct_after"]) / n_walk,
        "phase_error_before": float(np.mean(np.concatenate(pooled["phase_before"]))),
        "phase_error_after": float(np.mean(np.concatenate(pooled["phase_after"]))),
        "switches": pool_switches(switch_rows), "lost": lost,
    })
    return out


def phase_truth_column(rec: Recording) -> np.ndarray:
    """Phase between the recording's heel-strike flags (nan outside strides of at most 2 s)."""
    hs = rec.time_s[rec.heel_strike]
    out = np.full(len(rec), np.nan)
    k = np.searchsorted(hs, rec.time_s, side="right") - 1
    ok = (k >= 0) & (k < hs.size - 1)
    kk = np.where(ok, k, 0)
    dur = hs[np.minimum(kk + 1, hs.size - 1)] - hs[kk]
    ok &= dur <= 2.0
    out[ok] = ((rec.time_s - hs[kk]) / np.where(dur > 0, dur, 1.0))[ok]
    return out


def pool_switches(rows: list[dict[str, Any]], keys: tuple[str, ...] = ("before", "after")) -> dict[str, Any]:
    out = {}
    for key in keys:
        minutes = sum(r[key]["labelled_minutes"] for r in rows)
        false = sum(r[key]["false_switches"] for r in rows)
        delays = [d for r in rows for d in r[key]["delays_s"]]
        out[key] = {"false_switches": false, "labelled_minutes": minutes, "false_per_minute": false / max(minutes, 1e-9),
                    "labelled_changes": sum(r[key]["labelled_changes"] for r in rows),
                    "mean_delay_s": float(np.mean(delays)) if delays else None,
                    "missed_changes": sum(r[key]["missed_changes"] for r in rows)}
    return out


# ---------------------------------------------------------------------------------------------
# Bundled recordings


def lg2_labelled() -> tuple[Recording, np.ndarray]:
    """LG_2_Ramp with its labels, and the labels as ``switch_metrics`` takes them (level = Slow,
    Med or Fast)."""
    rec = with_ranges(read_recording(LG2), read_label_ranges(LG2_LABELS))
    lab = np.asarray(rec.labels, dtype=object)
    return rec, np.where(lab == "level", "|".join(LEVEL), lab)


def first_strides(rec: Recording, hs_s: np.ndarray) -> np.ndarray:
    """Labelled rows of the first stride after a stop (an unlabelled stretch of over 2 s): before
    the second heel strike from its end."""
    t, labelled = rec.time_s, np.asarray(rec.labels, dtype=object) != ""
    out = np.zeros(len(rec), dtype=bool)
    for a, b in bouts(~labelled):
        if b < len(rec) and t[b - 1] - t[a] > 2.0:
            after = hs_s[hs_s >= t[b] - 1e-6]
            out |= labelled & (t >= t[b]) & (t < (after[1] if after.size > 1 else t[-1] + 1))
    return out


STRETCHES = {"standing 3.0-4.9 s": (3.0, 4.9), "stop and standing turn 12.5-17.9 s": (12.5, 17.9)}
"""LG_2_Ramp's stretches without walking labels: standing still; the stop and standing turn."""
STEP_DEG, STEP_S = 30.0, 1.0
"""A step: a segment swinging STEP_DEG or more within STEP_S (standing, shifting weight and turning
on the spot move a segment less)."""


def stepping(rec: Recording) -> np.ndarray:
    """Rows whose STEP_S centred on them hold a step."""
    t, a = rec.time_s, rec.angles_deg
    lo = np.searchsorted(t, t - STEP_S / 2)
    hi = np.searchsorted(t, t + STEP_S / 2, side="right")
    out = np.zeros(len(t), dtype=bool)
    for i in range(0, len(t), 8):  # every 8th row, each deciding its 8
        out[i:i + 8] = np.ptp(a[lo[i]:hi[i]], axis=0).max() >= STEP_DEG
    return out


def swings(rec: Recording, rows: np.ndarray) -> list[list[Any]]:
    """The swings within ``rows``: [leg, time (s), knee flexion peak (thigh - shank, deg)], each a
    knee flexion maximum of 15 deg prominence or more, 0.4 s or more from the next."""
    from scipy.signal import find_peaks

    knee = rec.angles_deg[:, :2] - rec.angles_deg[:, 2:]
    out = []
    for leg, name in enumerate(("R", "L")):
        peaks = find_peaks(knee[:, leg], prominence=15.0, distance=max(1, int(0.4 * rec.median_rate_hz)))[0]
        out += [[name, float(rec.time_s[i]), float(knee[i, leg])] for i in peaks if rows[i]]
    return sorted(out, key=lambda s: s[1])


def lg2(ab: KernelLibrary, tuning: dict[str, Any]) -> dict[str, Any]:
    from gait_estimator.analysis.strides import heel_strikes

    rec, mapped = lg2_labelled()
    t = rec.time_s
    before, after = run(ab, rec, False), run(ab, rec, True, **tuning)
    out: dict[str, Any] = {}
    steps = stepping(rec)
    held = (after.state == STANDING) | (after.state == UNKNOWN_STATE)
    for name, (a, b) in STRETCHES.items():
        rows = (t >= a) & (t < b)
        out[name] = {"rows": int(rows.sum()), "target": "≥ 90 %", "stand": share(after.state == STANDING, rows),
                     "stand_or_unknown": share(held, rows), "steps": share(steps, rows),
                     "still_rows": int(np.count_nonzero(rows & ~steps)),
                     "still_stand_or_unknown": share(held, rows & ~steps),
                     "steps_walking": share(after.state == WALKING, rows & steps),
                     "steps_s": [[float(t[i]), float(t[j - 1])] for i, j in bouts(rows & steps)],
                     "before_walking_modes": share(before.ready, rows),
                     "swings": [[*w, bool(steps[np.searchsorted(t, w[1])])] for w in swings(rec, rows)],
                     "steps_fit_rms_deg": [float(np.median(after.fit_rms_deg[i:j])) for i, j in bouts(rows & steps)]}
    lab = np.asarray(rec.labels, dtype=object)
    labelled = lab != ""
    knees = [np.max(m.samples[:, :2] - m.samples[:, 2:], axis=0) for m in ab.modes if m.name in LEVEL]
    out["level_kernel_knee_peak_deg"] = [float(np.min(knees)), float(np.max(knees))]
    out["labelled_fit_rms_deg"] = [float(v) for v in np.percentile(after.fit_rms_deg[labelled & after.ready], [50, 95])]
    later = labelled & ~first_strides(rec, heel_strikes(rec, "right_foot").times_s)
    for key, tr in (("before", before), ("after", after)):
        ok = np.where(lab == "level", np.isin(tr.mode.astype(str), LEVEL), tr.mode == lab) & labelled
        out[f"accuracy_{key}"] = share(ok, labelled)
        out[f"accuracy_later_{key}"] = share(ok, later)
    out["switches"] = pool_switches([{k: switch_metrics(t, tr.mode, tr.ready, mapped) for k, tr in
                                      (("before", before), ("after", after))}])
    return out


def multispeed_labelled(ab: KernelLibrary) -> tuple[Recording, np.ndarray]:
    """Multispeed labelled with benchmarks/accuracy.py's cadence labels (every stride: Slow, Med,
    Fast by the nearest kernel stride duration), and the labels."""
    rec = with_ranges(read_recording(MULTISPEED, rate_hz=ab.sample_rate_hz), read_label_ranges(MULTISPEED_LABELS))
    return rec, rec.labels


def multispeed(ab: KernelLibrary, tuning: dict[str, Any]) -> dict[str, Any]:
    rec, labels = multispeed_labelled(ab)
    before, after = run(ab, rec, False), run(ab, rec, True, **tuning)
    t = rec.time_s
    moving = np.flatnonzero(np.abs(np.diff(rec.angles_deg, axis=0)).max(axis=1) * ab.sample_rate_hz > 20.0)
    start, end = t[moving[0]], t[moving[-1]]
    ready = after.ready
    first = ready & (t < start)
    last = t > end + GRACE_S
    return {"moves_from_s": float(start), "still_after_s": float(end),
            "start_stand": share(after.state == STANDING, first), "start_rows": int(first.sum()),
            "end_stand": share(after.state == STANDING, last), "end_rows": int(last.sum()),
            "switches": pool_switches([{k: switch_metrics(t, tr.mode, tr.ready, labels) for k, tr in
                                        (("before", before), ("after", after))}])}


# ---------------------------------------------------------------------------------------------
# Synthetic


def stops(ab: KernelLibrary, seeds: int, tuning: dict[str, Any]) -> dict[str, Any]:
    """New wearers walking Med with a stop of 4 s after stride 6 and 14: time from the segments
    coming to rest to ``stand``; from the first movement to a walking mode."""
    to_stand, to_walk, strides, walk_rows = [], [], [], []
    fade = 0.6
    for s in range(seeds):
        cfg = new_wearer(s)
        syn = generate(ab, [("Med", 10), ("Slow", 10)], cfg, seed=2000 + s)
        stand_pose = ab.mode("Med").samples[0] + np.asarray(cfg.channel_offset_deg)
        rec = with_stops(syn.recording, {6: 4.0, 14: 4.0}, stand_pose, seed=s, fade_s=fade)
        tr = run(ab, rec, True, **tuning)
        t = rec.time_s
        unlabelled = rec.labels == ""
        for a, b in bouts(unlabelled):
            rest, go = t[a] + fade, t[b - 1] - fade
            i = np.flatnonzero((t >= rest) & (tr.state == STANDING))
            to_stand.append(float(t[i[0]] - rest) if i.size else math.inf)
            j = np.flatnonzero((t >= go) & (tr.state == WALKING))
            to_walk.append(float(t[j[0]] - go) if j.size else math.inf)
        strides.append(float(np.median(syn.stride_durations_s)))
        labelled = ~unlabelled
        walk_rows.append((int(np.count_nonzero(labelled & (tr.state == WALKING))), int(labelled.sum()),
                          int(np.count_nonzero(labelled & (tr.state == STANDING)))))
    n = sum(n for _, n, _ in walk_rows)
    return {"stops": len(to_stand), "to_stand_max_s": max(to_stand), "to_stand_mean_s": float(np.mean(to_stand)),
            "to_walk_max_s": max(to_walk), "to_walk_mean_s": float(np.mean(to_walk)), "stride_s_min": min(strides),
            "walking_rows_walking": sum(w for w, _, _ in walk_rows) / n,
            "walking_rows_stand": sum(x for _, _, x in walk_rows) / n}


def running_library(ab: KernelLibrary) -> KernelLibrary:
    """Running-like strides: the Fast kernel with the knee flexion (shank - thigh) x1.6 and the
    stride 0.7 as long."""
    fast = ab.mode("Fast")
    k = fast.samples.copy()
    mean = k.mean(axis=0)
    knee = (k[:, 2:] - k[:, :2]) - (mean[2:] - mean[:2])
    k[:, 2:] += 0.6 * knee
    n = round(fast.length * 0.7)
    phi = np.linspace(0, 1, n, endpoint=False)
    src = np.linspace(0, 1, fast.length, endpoint=False)
    samples = np.stack([np.interp(phi, src, k[:, c], period=1.0) for c in range(4)], axis=1)
    return KernelLibrary("running", (KernelMode("run", samples, fast.sample_rate_hz),))


def sit_to_stand(rate_hz: float, cycles: int = 6, seed: int = 0) -> Recording:
    """Standing up from a chair and sitting down again, without pauses: thighs 0 -> 85 deg
    (horizontal), shanks 0 -> 10 deg, the trunk's lean not sensed; each half 1.6 s, cosine."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(cycles * 3.2 * rate_hz)) / rate_hz
    w = 0.5 * (1 - np.cos(2 * np.pi * t / 3.2))  # 0 standing, 1 seated
    x = np.stack([85 * w, 85 * w, 10 * w - 2, 10 * w - 2], axis=1) + 0.3 * rng.standard_normal((t.size, 4))
    return Recording(t, x, source="sit-to-stand")


def turn_in_place(rate_hz: float, seconds: float = 12.0, seed: int = 0) -> Recording:
    """Stepping round on the spot: each leg lifts in turn at 0.9 Hz (thigh +-15 deg, shank
    +-20 deg, alternating) around a standing pose."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate_hz)) / rate_hz
    lift = np.maximum(np.sin(2 * np.pi * 0.9 * t), 0.0)
    other = np.maximum(-np.sin(2 * np.pi * 0.9 * t), 0.0)
    x = np.stack([15 * lift, 15 * other, -20 * lift + 3, -20 * other + 3], axis=1) + 0.3 * rng.standard_normal((t.size, 4))
    return Recording(t, x, source="turn in place")


def unknown_activities(ab: KernelLibrary, seeds: int, tuning: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    run_lib = running_library(ab)
    rates = []
    for s in range(seeds):
        cfg = new_wearer(s, base=SyntheticConfig())
        rates.append(generate(run_lib, [("run", 14)], cfg, seed=3000 + s).recording)
    acts = {"running-like strides": rates,
            "sit-to-stand and back": [sit_to_stand(ab.sample_rate_hz, seed=s) for s in range(seeds)],
            "stepping round in place": [turn_in_place(ab.sample_rate_hz, seed=s) for s in range(seeds)]}
    for name, recs in acts.items():
        counts = np.zeros(4)
        for rec in recs:
            tr = run(ab, rec, True, **tuning)
            counts += np.bincount(tr.state[tr.ready], minlength=4)
        n = counts.sum()
        out[name] = {"rows": int(n), "unknown": counts[UNKNOWN_STATE] / n, "stand": counts[STANDING] / n,
                     "walking": counts[WALKING] / n}
    return out


def new_wearers(ab: KernelLibrary, seeds: int, tuning: dict[str, Any]) -> dict[str, Any]:
    """The cross-session route (benchmarks/common.py ROUTE) by synthetic new wearers."""
    rows, correct = 0, {"before": 0, "after": 0}
    unknown = stand = 0
    switch_rows = []
    for s in range(seeds):
        syn = generate(ab, ROUTE, new_wearer(s), seed=1000 + s)
        rec = syn.recording
        before, after = run(ab, rec, False), run(ab, rec, True, **tuning)
        lab = rec.labels
        ok = before.ready & (lab != "")
        rows += int(ok.sum())
        for key, tr in (("before", before), ("after", after)):
            correct[key] += int(np.count_nonzero(ok & (tr.mode == lab)))
        unknown += int(np.count_nonzero(ok & (after.state == UNKNOWN_STATE)))
        stand += int(np.count_nonzero(ok & (after.state == STANDING)))
        switch_rows.append({k: switch_metrics(rec.time_s, tr.mode, tr.ready, lab) for k, tr in
                            (("before", before), ("after", after))})
    return {"rows": rows, "accuracy_before": correct["before"] / rows, "accuracy_after": correct["after"] / rows,
            "unknown": unknown / rows, "stand": stand / rows, "switches": pool_switches(switch_rows)}


# ---------------------------------------------------------------------------------------------
# Units


def first_stride(rec: Recording) -> float:
    """Seconds from the start to the end of the first step (STEP_DEG within STEP_S)."""
    t, a = rec.time_s, rec.angles_deg
    lo = 0
    for i in range(0, len(t), 4):
        lo += int(np.searchsorted(t[lo:i + 1], t[i] - STEP_S))
        if np.ptp(a[lo:i + 1], axis=0).max() >= STEP_DEG:
            return float(t[i] - t[0])
    return math.inf


def moves_from(rec: Recording) -> float:
    """Seconds from the start to the first sample 5 deg or more from the first sample's angles."""
    far = np.abs(rec.angles_deg - rec.angles_deg[0]).max(axis=1) >= 5.0
    return float(rec.time_s[np.argmax(far)] - rec.time_s[0])


def units(recordings: dict[str, Recording]) -> dict[str, Any]:
    """Each recording through ``UnitsCheck`` as it is, and in the wrong unit both ways: seconds
    from the start to the verdict (None: no verdict)."""
    out = {}
    for name, rec in recordings.items():
        t = rec.time_s - rec.time_s[0]
        right = first_problem(t, rec.angles_deg)
        as_rad = first_problem(t, np.degrees(rec.angles_deg))
        as_deg = first_problem(t, np.radians(rec.angles_deg))
        out[name] = {"false_warning": right is not None, "deg_read_as_rad_s": as_rad[0] if as_rad else None,
                     "rad_read_as_deg_s": as_deg[0] if as_deg else None, "moves_from_s": moves_from(rec),
                     "first_stride_s": first_stride(rec)}
    return out


def test_recordings(ab: KernelLibrary, seeds: int) -> dict[str, Recording]:
    """The synthetic recordings of the tests, for false warnings: new wearers on the route and with
    stops, running-like strides, sit-to-stand, stepping round in place, and the angles the IMU tests
    synthesize sensors from (test/imu_synth.py: standing at 0, then walking blended in)."""
    from imu_synth import gait_angles

    out: dict[str, Recording] = {}
    run_lib = running_library(ab)
    for s in range(seeds):
        cfg = new_wearer(s)
        out[f"new wearer {s}"] = generate(ab, ROUTE, cfg, seed=1000 + s).recording
        syn = generate(ab, [("Med", 10), ("Slow", 10)], cfg, seed=2000 + s)
        pose = ab.mode("Med").samples[0] + np.asarray(cfg.channel_offset_deg)
        out[f"stops {s}"] = with_stops(syn.recording, {6: 4.0, 14: 4.0}, pose, seed=s, fade_s=0.6)
        out[f"running-like {s}"] = generate(run_lib, [("run", 14)], new_wearer(s, base=SyntheticConfig()),
                                            seed=3000 + s).recording
        out[f"sit-to-stand {s}"] = sit_to_stand(ab.sample_rate_hz, seed=s)
        out[f"turn in place {s}"] = turn_in_place(ab.sample_rate_hz, seed=s)
        for rate in (100.0, 200.0):
            a = gait_angles(rate, walk_s=8.0, seed=s)
            out[f"IMU test angles {rate:g} Hz {s}"] = Recording(np.arange(len(a)) / rate, a, source="imu_synth")
    return out


# ---------------------------------------------------------------------------------------------


def compute(seeds: int, tuning: dict[str, Any]) -> dict[str, Any]:
    ab = load_library("able_bodied")
    with tempfile.TemporaryDirectory() as tmp:
        trials, faults = camargo_trials(Path(tmp))
    result: dict[str, Any] = {"machine": machine(), "date": datetime.now(timezone.utc).strftime("%Y-%m-%d"),
                              "tuning": tuning}
    result["camargo"] = {kind: camargo(recs, tuning, faults if kind == "imu" else None) for kind, recs in trials.items()}
    result["lg2"] = lg2(ab, tuning)
    result["multispeed"] = multispeed(ab, tuning)
    result["stops"] = stops(ab, seeds, tuning)
    result["unknown_activities"] = unknown_activities(ab, seeds, tuning)
    result["new_wearers"] = new_wearers(ab, seeds, tuning)
    recordings = {"LG_2_Ramp": read_recording(LG2), "Multispeed": read_recording(MULTISPEED, rate_hz=ab.sample_rate_hz)}
    for kind, recs in trials.items():
        recordings.update({f"{r.source} ({kind})": r for r in recs})
    result["units"] = units(recordings)
    result["units_synthetic"] = units(test_recordings(ab, seeds))
    sets = {f"camargo_ab06 {kind}": (camargo_library(recs), [(r, r.labels) for r in recs]) for kind, recs in trials.items()}
    sets["LG_2_Ramp"] = (ab, [lg2_labelled()])
    wearers = [generate(ab, ROUTE, new_wearer(s), seed=1000 + s).recording for s in range(seeds)]
    sets["synthetic new wearers"] = (ab, [(r, r.labels) for r in wearers])
    sets["Multispeed"] = (ab, [multispeed_labelled(ab)])
    result["switch_curves"] = switch_curves(sets, tuning)
    return result


def pct(x: float | None, digits: int = 1) -> str:
    return "—" if x is None else f"{100 * x:.{digits}f} %"


def write_tables(r: dict[str, Any], out: Path) -> str:
    c = COMMAND
    cam = r["camargo"]
    rows = []
    for kind, name in (("mocap", "motion capture"), ("imu", "the project's IMU angles")):
        m = cam[kind]
        rows += [
            [f"camargo_ab06, {name}: `stand` rows (from {GRACE_S} s after the stop) reported `stand`",
             f"{pct(m['stand_reported_stand'])} of {m['stand_rows']:,}", "≥ 95 %", c],
            [f"camargo_ab06, {name}: walking rows (turns included) reported `stand` / `unknown`",
             f"{pct(m['walking_reported_stand'], 2)} / {pct(m['walking_reported_unknown'])} of {m['walking_rows']:,}",
             "≤ 0.5 % / ≤ 5 %", c],
            [f"camargo_ab06, {name}: accuracy on walking rows, before → after",
             f"{pct(m['accuracy_before'])} → {pct(m['accuracy_after'])}", "no worse", c],
            [f"camargo_ab06, {name}: walking rows correct before, not after: reported `unknown`; `stand`; another "
             "mode (stretches of 5 rows or more: stride rate over the kernel's, median)",
             f"{m['lost']['rows_by_state'][3]}; {m['lost']['rows_by_state'][2]}; {m['lost']['rows_by_state'][1]} ("
             + ", ".join(f"{n} {a:.2f}-{b:.2f} s: {r:.2f}" for n, a, b, r in m["lost"]["stretches"]) + ")", "—", c],
            [f"camargo_ab06, {name}: phase error (correct rows), before → after",
             f"{pct(m['phase_error_before'], 2)} → {pct(m['phase_error_after'], 2)}", "no worse", c],
        ]
    lg = r["lg2"]
    for name, v in lg.items():
        if isinstance(v, dict) and "rows" in v:
            rows.append([f"LG_2_Ramp {name}: reported `stand` or `unknown` (`stand` alone)",
                         f"{pct(v['stand_or_unknown'])} ({pct(v['stand'])}) of {v['rows']:,}", v["target"], c])
            if v["steps"] > 0.05:
                rows.append([f"LG_2_Ramp {name}: rows within a step (a segment swinging {STEP_DEG:g}° within "
                             f"{STEP_S:g} s centred on them): when, share, reported walking; the other rows → "
                             "`stand` or `unknown`",
                             ", ".join(f"{a:.2f}-{b:.2f} s" for a, b in v["steps_s"]) + f": {pct(v['steps'])}, "
                             f"{pct(v['steps_walking'])}; {pct(v['still_stand_or_unknown'])} of {v['still_rows']:,}",
                             "—", c])
            if "swings" in v and v["steps"] > 0.05:
                rows.append([f"LG_2_Ramp {name}: swings (knee flexion peaks; * within a step); each step's reported "
                             "fit, median; the level kernels' knee peaks; labelled rows' fit, median / 95th pct",
                             ", ".join(f"{leg} {s:.2f} s {k:.0f}°{'*' if st else ''}" for leg, s, k, st in v["swings"])
                             + "; " + ", ".join(f"{f:.1f}°" for f in v["steps_fit_rms_deg"])
                             + "; {:.0f}-{:.0f}°; {:.1f}° / {:.1f}°".format(*lg["level_kernel_knee_peak_deg"],
                                                                          *lg["labelled_fit_rms_deg"]), "—", c])
    rows.append(["LG_2_Ramp labelled accuracy (able_bodied, level = Slow/Med/Fast), before → after; "
                 "without the first stride after each stop",
                 f"{pct(lg['accuracy_before'])} → {pct(lg['accuracy_after'])}; "
                 f"{pct(lg['accuracy_later_before'])} → {pct(lg['accuracy_later_after'])}", "no worse", c])
    ms = r["multispeed"]
    rows.append(["Multispeed standing before the belt starts / after it stops: `stand`",
                 f"{pct(ms['start_stand'])} of {ms['start_rows']:,} / {pct(ms['end_stand'])} of {ms['end_rows']:,}", "—", c])
    st = r["stops"]
    rows += [
        [f"synthetic new wearers, {st['stops']} stops: segments at rest → `stand`, mean / worst",
         f"{st['to_stand_mean_s']:.2f} s / {st['to_stand_max_s']:.2f} s", "≤ 0.5 s", c],
        ["synthetic stops: first movement → a walking mode, mean / worst (shortest stride)",
         f"{st['to_walk_mean_s']:.2f} s / {st['to_walk_max_s']:.2f} s ({st['stride_s_min']:.2f} s)", "≤ one stride", c],
    ]
    for name, v in r["unknown_activities"].items():
        rows.append([f"synthetic {name}: ready rows reported `unknown` (`stand`)",
                     f"{pct(v['unknown'])} ({pct(v['stand'])}) of {v['rows']:,}",
                     "≥ 90 %" if "stepping" not in name else "—", c])
    nw = r["new_wearers"]
    rows.append(["synthetic new wearers (cross-session route): accuracy before → after; `unknown`",
                 f"{pct(nw['accuracy_before'])} → {pct(nw['accuracy_after'])}; {pct(nw['unknown'])}", "—", c])
    u, us = r["units"], r["units_synthetic"]
    rows.append([f"units: {len(u)} recordings (bundled, camargo mocap and IMU) and {len(us)} synthetic (the tests'): "
                 "false warnings; wrong unit flagged (worst): degrees read as radians, from the start / radians read "
                 "as degrees, from the first step (a segment swinging 30° within 1 s)",
                 f"{units_false(r)}; {units_worst(u)}", "0; ≤ 2 s", c])
    urows = [[name, "yes" if v["false_warning"] else "no", _s(v["deg_read_as_rad_s"]), _s(v["rad_read_as_deg_s"]),
              _s(v["moves_from_s"]), _s(v["first_stride_s"]), _s(_after(v["rad_read_as_deg_s"], v["first_stride_s"]))]
             for name, v in u.items()]
    sw = [["camargo_ab06 motion capture", cam["mocap"]["switches"]], ["camargo_ab06 IMU", cam["imu"]["switches"]],
          ["LG_2_Ramp (able_bodied)", lg["switches"]], ["Multispeed (able_bodied, cadence labels)", ms["switches"]],
          ["synthetic new wearers", nw["switches"]]]
    srows = []
    for name, s in sw:
        b, a = s["before"], s["after"]
        srows.append([name, f"{b['labelled_minutes']:.1f}", str(b["labelled_changes"]),
                      f"{b['false_per_minute']:.1f} → {a['false_per_minute']:.1f}",
                      f"{_s(b['mean_delay_s'])} → {_s(a['mean_delay_s'])}",
                      f"{b['missed_changes']} → {a['missed_changes']}"])
    text = "\n".join([
        "# Controller contract", "",
        "## Summary", "",
        f"{COMMAND} (deterministic), AMD EPYC 2 vCPU host, {r['date']}; default preset, before = `states: false`.", "",
        summary(r), "",
        "## Targets", "",
        md_table(["measure", "result", "target", "measured with"], rows), "",
        "## Switches", "",
        "A change of the reported mode (`stand`, `unknown` included) with no labelled change from "
        f"{SWITCH_WINDOW_S:g} s before it to {SWITCH_LEAD_S:g} s after it is false; delay: labelled change → "
        f"first row with its mode. {COMMAND}.", "",
        md_table(["recording", "labelled min", "labelled changes", "false switches / min", "mean delay",
                  "changes missed"], srows), "",
        *curve_sections(r["switch_curves"]),
        "## Units", "",
        "Each recording through `UnitsCheck` as it is (a verdict: false warning) and in the wrong unit: seconds "
        "from the start to the verdict; the first 5° from the first sample's angles; the first step (a segment "
        f"swinging 30° within 1 s); radians read as degrees flagged after that step. {COMMAND}.", "",
        md_table(["recording", "false warning", "deg read as rad", "rad read as deg", "first 5°", "first step",
                  "rad as deg after the step"], urows), "",
        f"{len(us)} synthetic recordings of the tests (new wearers, stops, running-like, sit-to-stand, turning in "
        f"place, the IMU tests' angles): {sum(v['false_warning'] for v in us.values())} false warnings.", "",
    ])
    out.mkdir(parents=True, exist_ok=True)
    (out / "tables.md").write_text(text, encoding="utf-8")
    return text


CURVES = {"min_dwell_s": ("Dwell", "a new mode must win this long before it is reported", "{:g} s"),
          "switch_back_margin": ("Switch-back margin", "the mode reported before the current one is reported again "
                                 "only when its error is below (1 − margin) × the current mode's", "{:g}")}
"""Per swept option: section title, meaning, column format."""


def curve_sections(curves: dict[str, Any]) -> list[str]:
    """One section per swept option: false switches per minute / mean delay per set and value."""
    out = []
    for option, by_set in curves.items():
        title, meaning, fmt = CURVES[option]
        values = [p[option] for p in next(iter(by_set.values()))]
        out += [f"### {title}", "",
                f"States on, `{option}` ({meaning}) from 0, other options as given: false switches per minute / mean "
                f"delay (labelled changes not reported within {SWITCH_WINDOW_S:g} s: missed). {COMMAND}.", "",
                md_table(["recording", *(fmt.format(v) for v in values)],
                         [[name, *(f"{p['false_per_minute']:.1f} / {_s(p['mean_delay_s'])}"
                                   + (f" ({p['missed_changes']} missed)" if p["missed_changes"] else "") for p in points)]
                          for name, points in by_set.items()]), ""]
    return out


def summary(r: dict[str, Any]) -> str:
    """The short table of docs/controller.md."""
    cm, ci, lg, st = r["camargo"]["mocap"], r["camargo"]["imu"], r["lg2"], r["stops"]
    turn, still = lg["stop and standing turn 12.5-17.9 s"], lg["standing 3.0-4.9 s"]
    ua, u = r["unknown_activities"], r["units"]
    nw = r["new_wearers"]
    sw = {k: v["switches"]["after"] for k, v in (("LG_2_Ramp", lg), ("new wearers", nw), ("camargo", cm))}
    rows = [
        ["camargo_ab06 `stand` rows (0.5 s after stopping) → `stand`, mocap / IMU",
         f"{pct(cm['stand_reported_stand'])} / {pct(ci['stand_reported_stand'])}", "≥ 95 %"],
        ["camargo_ab06 walking rows (turns too) → `stand`; `unknown`, mocap / IMU",
         f"{pct(cm['walking_reported_stand'], 2)}; {pct(cm['walking_reported_unknown'])} / "
         f"{pct(ci['walking_reported_stand'], 2)}; {pct(ci['walking_reported_unknown'])}", "≤ 0.5 %; ≤ 5 %"],
        ["camargo_ab06 walking accuracy, before → after, mocap / IMU",
         f"{pct(cm['accuracy_before'])} → {pct(cm['accuracy_after'])} / "
         f"{pct(ci['accuracy_before'])} → {pct(ci['accuracy_after'])}", "no worse"],
        ["camargo_ab06 phase error, before → after, mocap / IMU",
         f"{pct(cm['phase_error_before'], 2)} → {pct(cm['phase_error_after'], 2)} / "
         f"{pct(ci['phase_error_before'], 2)} → {pct(ci['phase_error_after'], 2)}", "no worse"],
        ["LG_2_Ramp standing; stop and turn (without steps) → `stand` or `unknown`",
         f"{pct(still['stand_or_unknown'])}; {pct(turn['stand_or_unknown'])} ({pct(turn['still_stand_or_unknown'])})",
         "≥ 90 %"],
        ["LG_2_Ramp accuracy, before → after; without each start's first stride",
         f"{pct(lg['accuracy_before'])} → {pct(lg['accuracy_after'])}; "
         f"{pct(lg['accuracy_later_before'])} → {pct(lg['accuracy_later_after'])}", "no worse"],
        [f"synthetic stops: rest → `stand`; start → walking (worst of {st['stops']})",
         f"{st['to_stand_max_s']:.2f} s; {st['to_walk_max_s']:.2f} s (stride {st['stride_s_min']:.2f} s)",
         "≤ 0.5 s; ≤ 1 stride"],
        ["synthetic running-like; sit-to-stand → `unknown`",
         f"{pct(ua['running-like strides']['unknown'])}; {pct(ua['sit-to-stand and back']['unknown'])}", "≥ 90 %"],
        [f"units, {len(u) + len(r['units_synthetic'])} recordings: false warnings; latest flag, deg as rad / rad as "
         "deg after a step", f"{units_false(r)}; {units_worst(u)}", "0; ≤ 2 s"],
        *[[f"{k}: false switches / min; mean delay", f"{v['false_per_minute']:.1f}; {_s(v['mean_delay_s'])}",
           "< 2; ≤ 0.75 s"] for k, v in sw.items()],
    ]
    return md_table(["figure", "measured", "target"], rows)


def _s(v: float | None) -> str:
    return "—" if v is None or not math.isfinite(v) else f"{v:.2f} s"


def _after(v: float | None, since: float) -> float | None:
    return None if v is None else v - since


def units_false(r: dict[str, Any]) -> int:
    return sum(v["false_warning"] for key in ("units", "units_synthetic") for v in r[key].values())


def units_worst(u: dict[str, Any]) -> str:
    """The latest verdicts: degrees read as radians from the start, radians read as degrees from the
    first step."""
    rad = max(v["deg_read_as_rad_s"] or math.inf for v in u.values())
    deg = max(_after(v["rad_read_as_deg_s"], v["first_stride_s"]) or math.inf for v in u.values())
    return f"{rad:.2f} s / {deg:.2f} s"


ROUND = r"""
import json, sys, time
import numpy as np
from gait_estimator import Estimator, load_library
from gait_estimator.io.readers import read_recording
lib = load_library("able_bodied")
rec = read_recording(sys.argv[1])
t = np.arange(len(rec)) / 230.0
rows = [tuple(r) for r in rec.angles_deg.tolist()]
est = Estimator(lib)
for i in range(2000):
    est.update(float(t[i]), rows[i])
est = Estimator(lib)
out = []
clock = time.perf_counter_ns
for i in range(len(rows)):
    a = clock()
    est.update(float(t[i]), rows[i])
    out.append(clock() - a)
print(json.dumps(out))
"""


def one_round(src: Path) -> np.ndarray:
    """One process running ROUND with ``src`` first on the path: per-sample times, us."""
    env = {**os.environ, "PYTHONPATH": str(src)}
    rec = REPO / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv"
    run = subprocess.run([sys.executable, "-c", ROUND, str(rec)], env=env, cwd=src, capture_output=True, text=True,
                         check=True)
    return np.asarray(json.loads(run.stdout), dtype=np.float64) / 1e3


def update_cost(other: Path, rounds: int) -> None:
    times: dict[str, list[np.ndarray]] = {"this": [], "other": []}
    for _ in range(rounds):
        for name, src in (("other", other.resolve()), ("this", REPO)):
            times[name].append(one_round(src))
    stats = {k: (float(np.median(np.concatenate(v))), float(np.percentile(np.concatenate(v), 99))) for k, v in times.items()}
    for k, (med, p99) in stats.items():
        print(f"{k:<6} median {med:7.2f} us  p99 {p99:7.2f} us")
    print(f"this / other: median x{stats['this'][0] / stats['other'][0]:.3f}, p99 x{stats['this'][1] / stats['other'][1]:.3f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--tables-only", action="store_true")
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--tuning", default="{}", help="StateParams fields as JSON, to try other thresholds")
    ap.add_argument("--options", default="{}", help="estimator options as JSON on top of the default preset")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--update-cost", type=Path, metavar="CHECKOUT", help="only time Estimator.update here and in CHECKOUT")
    ap.add_argument("--rounds", type=int, default=6, help="--update-cost rounds (default 6)")
    args = ap.parse_args(argv)
    if args.update_cost:
        update_cost(args.update_cost, args.rounds)
        return 0
    path = args.out / "contract.json"
    OPTIONS.update(json.loads(args.options))
    if not args.tables_only:
        result = compute(args.seeds, json.loads(args.tuning))
        args.out.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(result, indent=1), encoding="utf-8")
    print(write_tables(json.loads(path.read_text(encoding="utf-8")), args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
