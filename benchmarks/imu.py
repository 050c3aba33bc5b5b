"""IMU input (issue 27, docs/imu.md): real IMUs vs motion capture, the estimator fed with either,
synthetic checks and the per-sample conversion cost. One command:

    python benchmarks/imu.py                # writes benchmarks/results/imu/imu.json and tables.md
    python benchmarks/imu.py --tables-only  # only tables.md, from the saved imu.json (make docs)
    python benchmarks/imu.py --bags DIR     # only the trials as bags of four Imu topics, to try them

* camargo_ab06 (data/camargo_ab06, 5 level-walking trials, raw right thigh/shank IMUs at 200 Hz):
  each trial is written as a rosbag2 bag of four sensor_msgs/Imu topics and read back with
  ``read_imu_bag`` (the code of ``gait-estimator convert``); the mounting is learnt from the bag.
  The dataset has no left-leg IMUs: the left thigh/shank "IMUs" are virtual sensors that carry
  the motion-capture left angles as exact orientations (configured axes), so the left channels
  are the mocap angles and every figure below is about the right thigh and shank.
  - **orientation** input: each right IMU's orientation computed with imufusion (its defaults, as
    a driver running Fusion would publish it), sent as the quaternion;
  - **raw** input: gyro + accelerometer only (orientation_covariance[0] = -1): the project's
    fusion (imufusion's AHRS ported, compiled with numba; gyro bias from the standing pose).
  RMS of IMU - mocap over the walking samples after the standing tare (IMU - mocap mean over the
  first standing bout removed), per segment.
* Estimator: kernels (walk_slow, walk_normal, walk_fast; heel strikes from the data set) trained
  on the first half of every trial, tested on the second half (default options), fed with the
  raw-input IMU angles or with the mocap angles; the estimates' ``fit_rms_deg`` while the wearer
  stands (no mode fits) and walks.
* Synthetic (test/imu_synth.py): random mountings, exact quaternions; raw input with noise and
  gyro bias.
* Fusion settings: per segment, scored on the walking after the first standing (what the node puts
  out; angles as read offline, ``offline_ups``), chosen leave-one-trial-out from FUSION_GRID
  (``select_fusion``); where the best on all five is not the shipped one, the estimator fed with
  it (``in_sample_estimator``).
* Calibration check (``calibration_checks``): the node's check of a saved calibration on the
  first walking (``check_stream``), for the raw-input calibration learnt on each trial
  checked on every trial (the same sensors, no false alarm wanted), and on each trial with its
  right thigh or shank sensor turned about the segment's long axis by TURNS_DEG (the recorded
  gyro and accelerometer rotated into the turned sensor's frame).
* Gyro bias of a calibration made earlier (``bias_sources``): each trial's learnt mounts on each
  other trial, fused with the saved biases, with this trial's standing-pose biases (what the node
  uses when a standing pose ends before the check's verdict), or with none.
* The node's own calibration (``imu_live.py``): each trial through a replay of estimator_node's
  IMU input flow (pinned to a real node's by a test), which learns the mounting live; the angles
  it puts out from then on against mocap.
* Cost: SensorInput.convert for four sensors + pairing + the four angles, per paired sample
  (best of 3 rounds by median), the inputs built as the node builds them (rate from the stamps,
  per-segment fusion settings); the message fields as Python floats, as the node reads them.
  Raw input also without numba (a process with GAIT_ESTIMATOR_NO_NUMBA: the fusion's step as
  plain Python).
  With rclpy installed also the node's decoding of one serialised Imu message (``read_imu``
  from its CDR bytes) next to rclpy's ``deserialize_message`` and field access, interleaved.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "test"))

from imu_live import live_runs  # noqa: E402

from gait_estimator.analysis.evaluate import PredictionTable, evaluate  # noqa: E402
from gait_estimator.analysis.strides import heel_strikes  # noqa: E402
from gait_estimator.analysis.train import TrainOptions, train_library  # noqa: E402
from gait_estimator.core.ahrs import fuse_raw, fuse_raw_backwards  # noqa: E402
from gait_estimator.core.imu import (  # noqa: E402
    FUSION_BY_CHANNEL,
    STANDARD_GRAVITY,
    FusionParams,
    ImuCalibration,
    SegmentMount,
    ups_from_quaternions,
)
from gait_estimator.core.imu_angles import ImuAngles  # noqa: E402
from gait_estimator.core.imu_calibrator import ImuCalibrator, check_stream  # noqa: E402
from gait_estimator.core.imu_pairing import ImuPairer, SensorInput  # noqa: E402
from gait_estimator.io.imu_bag import read_imu_bag, write_imu_bag  # noqa: E402
from gait_estimator.io.process import predict  # noqa: E402
from gait_estimator.io.recording import Recording, read_project_csv  # noqa: E402

DATA = REPO / "data" / "camargo_ab06"
OUT = REPO / "benchmarks" / "results" / "imu"
BASE_NS = 1_700_000_000 * 1_000_000_000
RIGHT = {"thigh": 0, "shank": 2}
S0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # sensor = segment axes (fwd, prox, right)


def virtual_quaternions(theta_deg: np.ndarray) -> np.ndarray:
    """Exact orientations (x, y, z, w) of a sensor whose axes are the segment's (x forward,
    y proximal, z right) at sagittal angle theta."""
    from scipy.spatial.transform import Rotation

    return (Rotation.from_euler("y", -np.radians(theta_deg)[:, None]) * Rotation.from_matrix(S0)).as_quat()


def fusion_quaternions(t: np.ndarray, gyro_dps: np.ndarray, acc_g: np.ndarray) -> np.ndarray:
    """imufusion with its default settings (what a driver running Fusion publishes), x, y, z, w."""
    import imufusion

    ahrs = imufusion.Ahrs()
    ahrs.set_settings(imufusion.AhrsSettings(sample_rate=1.0 / float(np.median(np.diff(t)))))
    out = np.empty((len(t), 4))
    for i in range(len(t)):
        ahrs.update_no_magnetometer(gyro_dps[i], acc_g[i])
        w, x, y, z = ahrs.get_quaternion()
        out[i] = (x, y, z, w)
    return out


def first_stand(rec: Recording) -> np.ndarray:
    stand = rec.labels == "stand"
    keep = np.zeros(len(rec), dtype=bool)
    i = int(np.argmax(stand))
    j = i
    while j < len(rec) and stand[j]:
        j += 1
    keep[i:j] = True
    return keep


def shank_faults(rec: Recording, trial: str) -> np.ndarray:
    """Samples whose right-shank IMU data the data set's README lists as faulty ("Known issues":
    gyro sign flips, motion-capture-like patches, the first-row spike of ccw_fast), from each
    fault to the next standing bout, where the fusion settles on the accelerometer again; for a
    fault before the first standing bout also the samples before it, which offline reading fuses
    backwards from that bout."""
    stats = json.loads((DATA / "stats.json").read_text())["trials"][trial + ".csv"]
    starts = [f[0] for f in stats["gyro_sign_flips"]["shank_Gyro_Y"]]
    starts += [iv[0] for iv in stats["shank_gyro_y_ik_like"]["intervals"]]
    if trial == "levelground_ccw_fast":
        starts.append(14.425)
    stand = rec.labels == "stand"
    bad = np.zeros(len(rec), dtype=bool)
    first = rec.time_s[np.argmax(stand)]
    for s in starts:
        after = (rec.time_s >= s) & stand
        end = rec.time_s[np.argmax(after)] if after.any() else np.inf
        bad |= ((rec.time_s >= s) | (s < first)) & (rec.time_s < end)
    return bad


THIGH_ACC_JUMP_MPS2 = 1.0
"""A step of the right thigh's accelerometer larger than this from one sample to the next while
standing starts ``thigh_faults`` (data/camargo_ab06/README.md "Known issues")."""


def _thigh_acc_steps(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """The right thigh's accelerometer (T, 3), m/s^2, and the size of each sample's step from the
    previous one (T,; 0 for the first)."""
    acc = np.stack([rec.extra[f"right_thigh_acc_{k}_mps2"] for k in "xyz"], axis=1)
    return acc, np.r_[0.0, np.linalg.norm(np.diff(acc, axis=0), axis=1)]


def thigh_faults(rec: Recording) -> np.ndarray:
    """Samples of the right thigh IMU from its first accelerometer step > THIGH_ACC_JUMP_MPS2 while
    standing to the end of the trial; none without such a step (``thigh_fault_evidence``)."""
    _, step = _thigh_acc_steps(rec)
    jumps = np.flatnonzero((step > THIGH_ACC_JUMP_MPS2) & (rec.labels == "stand"))
    bad = np.zeros(len(rec), dtype=bool)
    if jumps.size:
        bad[jumps[0]:] = True
    return bad


def thigh_fault_evidence(rec: Recording) -> dict | None:
    """What sets a ``thigh_faults`` start apart, or None: the accelerometer step (m/s^2) and its
    ratio to the median step while standing; the accelerometer's tilt (atan2(acc_y, -acc_x), the
    data README's thigh frame) minus mocap over the standing 0.5 s before and after (deg); the
    median |second difference| of gyro z (deg/s) and the correlation of gyro y and z with the
    mocap thigh rate, before and after the start."""
    bad = thigh_faults(rec)
    if not bad.any():
        return None
    ex, t, i = rec.extra, rec.time_s, int(np.argmax(bad))
    acc, step = _thigh_acc_steps(rec)
    gyro = {k: ex[f"right_thigh_gyro_{k}_dps"] for k in "yz"}
    stand = rec.labels == "stand"
    tilt = np.degrees(np.arctan2(acc[:, 1], -acc[:, 0])) - rec.angles_deg[:, 0]
    near = {"before": stand & (t >= t[i] - 0.5) & (t < t[i]), "after": stand & (t > t[i]) & (t <= t[i] + 0.5)}
    rate = np.gradient(rec.angles_deg[:, 0], t)
    parts = {"before": slice(0, i), "after": slice(i, None)}
    return {
        "start_s": float(t[i]), "step_mps2": float(step[i]), "step_ratio": float(step[i] / np.median(step[stand])),
        "walking_after_s": float((~stand[i:]).sum() * np.median(np.diff(t))),
        **{f"tilt_minus_mocap_{k}_deg": float(tilt[m].mean()) for k, m in near.items()},
        **{f"gyro_z_second_difference_{k}_dps": float(np.median(np.abs(np.diff(gyro["z"][sl], 2))))
           for k, sl in parts.items()},
        **{f"r_gyro_{ax}_{k}": float(np.corrcoef(gyro[ax][sl], rate[sl])[0, 1]) for ax in "yz" for k, sl in parts.items()},
    }


def trial_sensors(rec: Recording) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, np.ndarray]]:
    """A trial's sensors as ``write_imu_bag`` takes them: stamps (ns), gyro (4, T, 3) deg/s and
    accelerometer (4, T, 3) m/s^2 of the right thigh and shank (zeros elsewhere), and the left
    channels' virtual orientations (x, y, z, w) from the mocap angles."""
    t, ex = rec.time_s, rec.extra
    gyro = np.zeros((4, len(t), 3))
    acc = np.zeros((4, len(t), 3))
    for seg, c in RIGHT.items():
        gyro[c] = np.stack([ex[f"right_{seg}_gyro_{k}_dps"] for k in "xyz"], axis=1)
        acc[c] = np.stack([ex[f"right_{seg}_acc_{k}_mps2"] for k in "xyz"], axis=1)
    left = {c: virtual_quaternions(rec.angles_deg[:, c]) for c in (1, 3)}
    return BASE_NS + np.round(t * 1e9).astype(np.int64), gyro, acc, left


def write_bags(out: Path) -> list[Path]:
    """Each trial as a bag of four Imu topics, raw (``<trial>``, time from its first message), and
    its recording with the same time origin (``<trial>_truth.csv``: labels, heel strikes, mocap
    angles) for ``evaluate``: to try the IMU path without sensors."""
    from dataclasses import replace

    from gait_estimator.io.recording import write_project_csv

    out.mkdir(parents=True, exist_ok=True)
    written = []
    for path in sorted(DATA.glob("levelground_*.csv")):
        rec = read_project_csv(path)
        stamps, gyro, acc, left = trial_sensors(rec)
        written.append(write_imu_bag(out / path.stem, stamps, np.radians(gyro), acc, [None, left[1], None, left[3]]))
        truth = replace(rec, time_s=rec.time_s - rec.time_s[0], extra={})
        written.append(write_project_csv(truth, out / f"{path.stem}_truth.csv"))
    return written


def trial_imu(path: Path, tmp: Path) -> dict:
    """Per trial: angles from the orientation and the raw bags, tared; RMS vs mocap; the samples of
    the data set's IMU faults per right segment (``faults``)."""
    rec = read_project_csv(path)
    t, mocap = rec.time_s, rec.angles_deg
    stamps, gyro, acc, left = trial_sensors(rec)
    configured = {"imu_lateral_axes": ["", "+z", "", "+z"], "imu_proximal_axes": ["", "+y", "", "+y"]}
    out: dict = {"trial": path.stem, "samples": len(t), "thigh_fault": thigh_fault_evidence(rec)}
    faults = {RIGHT["thigh"]: thigh_faults(rec), RIGHT["shank"]: shank_faults(rec, path.stem)}
    angles = {}
    for kind in ("orientation", "raw"):
        if kind == "orientation":
            q = [fusion_quaternions(t, gyro[c], acc[c] / STANDARD_GRAVITY) if c in (0, 2) else left[c] for c in range(4)]
        else:
            q = [None, left[1], None, left[3]]
        bag = write_imu_bag(tmp / f"{path.stem}_{kind}", stamps, np.radians(gyro), acc, q)
        got = read_imu_bag(bag, **configured)
        assert len(got) == len(t), (path, kind, len(got), got.skipped)
        a = got.angles_deg.copy()
        stand = first_stand(rec)
        for c in (0, 2):
            a[:, c] -= (a[stand, c] - mocap[stand, c]).mean()  # the standing tare
        walk = rec.labels != "stand"
        out[kind] = {seg: float(np.sqrt(np.mean((a[walk, c] - mocap[walk, c]) ** 2))) for seg, c in RIGHT.items()}
        clean = {c: walk & ~bad for c, bad in faults.items()}
        after = t > t[stand][-1]  # what the node puts out: nothing before its standing pose
        for seg, c in RIGHT.items():
            out[kind][f"{seg}_clean"] = float(np.sqrt(np.mean((a[clean[c], c] - mocap[clean[c], c]) ** 2)))
            out[kind][f"{seg}_clean_share"] = float(clean[c].sum() / walk.sum())
            sel = after & clean[c]
            out[kind][f"{seg}_after"] = float(np.sqrt(np.mean((a[sel, c] - mocap[sel, c]) ** 2)))
            out[kind][f"{seg}_after_n"] = int(sel.sum())
        out[kind + "_r"] = {seg: float(np.corrcoef(a[walk, c], mocap[walk, c])[0, 1]) for seg, c in RIGHT.items()}
        out[kind + "_calibration"] = got.calibration.summary().split("; left_thigh")[0] + "; " + \
            got.calibration.summary().split("; ")[2]
        angles[kind] = a
        if kind == "raw":
            mounts = {c: got.calibration.mounts[c] for c in RIGHT.values()}
            backwards_until = got.fused_backwards_until
    virtual_ups = {c: ups_from_quaternions(left[c]) for c in left}
    return {"stats": out, "angles": angles, "rec": rec, "gyro": gyro, "acc_g": acc / STANDARD_GRAVITY, "mounts": mounts,
            "faults": faults, "virtual_ups": virtual_ups, "backwards_until": backwards_until}


FUSION_GRID = [FusionParams(gain=g) for g in (0.2, 0.3, 0.5, 1.0)] + [
    FusionParams(gain=g, quasi_gain=q, quasi_rate_dps=r)
    for g in (0.2, 0.3, 0.5) for q in (1.0, 2.0, 5.0) for r in (30.0, 60.0) if q > g]
"""Fusion settings tried per segment by ``select_fusion``."""


def offline_ups(tr: dict, c: int, bias: tuple, params: FusionParams) -> np.ndarray:
    """One right sensor's up directions (T, 3) as ``read_imu_bag`` fuses them, with gyro ``bias``
    and fusion ``params``: forwards, and backwards up to the end of the first still stretch."""
    t, gyro, acc, k = tr["rec"].time_s, tr["gyro"][c], tr["acc_g"][c], tr["backwards_until"]
    ups = fuse_raw(t, gyro, acc, bias, params)
    if k:
        ups[:k] = fuse_raw_backwards(t[:k], gyro[:k], acc[:k], bias, params)
    return ups


def _tared_angles(tr: dict, c: int, mount: SegmentMount, bias: tuple, params: FusionParams) -> np.ndarray:
    """One right segment's raw-input angles (deg, T) from ``offline_ups`` with ``mount``, gyro
    ``bias`` and fusion ``params``, tared as ``trial_imu``."""
    rec = tr["rec"]
    a = mount.angles_deg(offline_ups(tr, c, bias, params))
    stand = first_stand(rec)
    return a - (a[stand] - rec.angles_deg[stand, c]).mean()


def _after_rms(tr: dict, c: int, mount: SegmentMount, bias: tuple, params: FusionParams | None = None) -> float:
    """RMS (deg) of ``_tared_angles`` (fusion ``params``, default: the node's) vs mocap, on the
    walking after the first standing (what the node puts out) without the data set's faults."""
    rec = tr["rec"]
    a = _tared_angles(tr, c, mount, bias, FUSION_BY_CHANNEL[c] if params is None else params)
    stand, mocap = first_stand(rec), rec.angles_deg[:, c]
    sel = (rec.labels != "stand") & ~tr["faults"][c] & (rec.time_s > rec.time_s[stand][-1])
    return float(np.sqrt(np.mean((a[sel] - mocap[sel]) ** 2)))


def select_fusion(trials: list[dict]) -> dict:
    """Leave-one-trial-out choice of the fusion settings per segment from FUSION_GRID: for each
    trial, the settings best on the other four, scored on it (held out); and the settings best
    on all five (in-sample)."""
    def name(p: FusionParams) -> str:
        return f"gain {p.gain:g}" + ("" if p.quasi_gain is None else f", {p.quasi_gain:g} below {p.quasi_rate_dps:g} deg/s")

    out = {}
    for seg, c in RIGHT.items():
        rms = np.array([[_after_rms(tr, c, tr["mounts"][c], tr["mounts"][c].gyro_bias_dps, p) for tr in trials]
                        for p in FUSION_GRID])  # (settings, trials)
        held = {}
        for k, tr in enumerate(trials):
            best = int(np.argmin(np.delete(rms, k, axis=1).mean(axis=1)))
            held[tr["stats"]["trial"]] = {"settings": name(FUSION_GRID[best]), "rms_deg": float(rms[best, k])}
        best = int(np.argmin(rms.mean(axis=1)))
        out[seg] = {"held_out": held, "held_out_mean_deg": float(np.mean([h["rms_deg"] for h in held.values()])),
                    "in_sample": name(FUSION_GRID[best]), "in_sample_mean_deg": float(rms[best].mean()),
                    "in_sample_index": best, "shipped": name(FUSION_BY_CHANNEL[c])}
    return out


def in_sample_estimator(trials: list[dict], selection: dict) -> dict:
    """``estimator_runs`` (all samples, without the shank faults) for each segment whose in-sample
    best settings (``select_fusion``) are not the shipped ones, its raw angles fused with them."""
    out = {}
    for seg, c in RIGHT.items():
        params, changed = FUSION_GRID[selection[seg]["in_sample_index"]], []
        if params == FUSION_BY_CHANNEL[c]:
            continue
        for tr in trials:
            m, a = tr["mounts"][c], tr["angles"]["raw"].copy()
            a[:, c] = _tared_angles(tr, c, m, m.gyro_bias_dps, params)
            changed.append({**tr, "angles": {**tr["angles"], "raw": a}})
        out[seg] = {"settings": selection[seg]["in_sample"], "all": estimator_runs(changed),
                    "without_faults": estimator_runs(changed, skip_faults=True)}
    return out


def halves(rec: Recording, angles: np.ndarray, unscored: np.ndarray | None = None) -> tuple[Recording, Recording]:
    """First and second half (by walking time); samples in ``unscored`` lose their label (not
    evaluated, and not trained on)."""
    walk_t = rec.time_s[rec.labels != "stand"]
    mid = 0.5 * (walk_t[0] + walk_t[-1])
    labels = np.where(rec.labels == "stand", "", rec.labels).astype(object)
    if unscored is not None:
        labels[unscored] = ""
    full = Recording(rec.time_s, angles, labels, rec.heel_strike, {}, rec.source)
    return full.select(rec.time_s < mid), full.select(rec.time_s >= mid)


def estimator_runs(trials: list[dict], skip_faults: bool = False) -> dict:
    """Accuracy and phase error, kernels from first halves, tested on second halves; with
    ``skip_faults``, the samples of the data set's shank IMU faults are neither trained on nor
    scored (for both inputs). The thigh's (``thigh_faults``, at the end of the walk) are kept:
    every input, mocap included, misclassifies them, so leaving them out would raise the accuracy
    for reasons unrelated to the IMU (the phase error, over correct rows, is the same either way)."""
    out = {}
    sets = {"mocap": lambda tr: tr["rec"].angles_deg, "imu_raw": lambda tr: tr["angles"]["raw"]}
    faults = [tr["faults"][RIGHT["shank"]] if skip_faults else None for tr in trials]
    parts = {name: [halves(tr["rec"], get(tr), f) for tr, f in zip(trials, faults, strict=True)]
             for name, get in sets.items()}
    for train_on, test_on in (("mocap", "mocap"), ("imu_raw", "imu_raw"), ("mocap", "imu_raw")):
        options = TrainOptions(heel_strikes="column", min_strides=2)  # walk_slow: one trial, 2-3 strides per half
        lib = train_library([p[0] for p in parts[train_on]], f"camargo_{train_on}", options).library
        n = correct = 0
        err_sum = err_n = 0.0
        fit: dict[str, list[np.ndarray]] = {"stand": [], "walk": []}
        for (_, test), trial in zip(parts[test_on], trials, strict=True):
            pred = predict(test, lib)
            tr = pred.trace
            rec = trial["rec"]
            standing = rec.labels[np.searchsorted(rec.time_s, test.time_s)] == "stand"
            fit["stand"].append(tr.fit_rms_deg[tr.ready & standing])
            fit["walk"].append(tr.fit_rms_deg[tr.ready & (test.labels != "")])
            modes = np.asarray(tr.mode_names, dtype=object)[tr.mode_index]
            table = PredictionTable(tr.time_s, tr.sample, modes, tr.phase, tr.ready, tr.sse, list(tr.mode_names), test.source)
            m = evaluate(table, test, heel_strikes(test, "column")).metrics
            ev = m["samples"]["evaluated"]
            n += ev
            correct += (m["accuracy"] or 0.0) * ev
            k = m["phase_error_samples"]
            if k:
                err_sum += m["phase_error_mean"] * k
                err_n += k
        stand, walk = (np.concatenate(fit[k]) for k in ("stand", "walk"))
        out[f"{train_on}->{test_on}"] = {"accuracy": correct / n, "phase_error_mean": err_sum / err_n, "samples": n,
                                         "modes": lib.mode_names, "standing_samples": int(stand.size),
                                         "fit_rms_standing_p5_p50_deg": np.percentile(stand, [5, 50]).tolist(),
                                         "fit_rms_walking_p50_p95_deg": np.percentile(walk, [50, 95]).tolist()}
    return out


def bias_sources(trials: list[dict]) -> dict:
    """Each trial's learnt raw-input mounts used on each other trial, fused with: the saved gyro
    biases (the other trial's), the biases of this trial's standing pose (what the node measures
    for a calibration made earlier, as for a learnt one), or none."""
    out: dict = {}
    for seg, c in RIGHT.items():
        runs = [(tr_a["mounts"][c], tr) for tr_a in trials for tr in trials if tr_a is not tr]
        out[seg] = {
            "saved": float(np.mean([_after_rms(tr, c, m, m.gyro_bias_dps) for m, tr in runs])),
            "standing": float(np.mean([_after_rms(tr, c, m, tr["mounts"][c].gyro_bias_dps) for m, tr in runs])),
            "none": float(np.mean([_after_rms(tr, c, m, (0.0, 0.0, 0.0)) for m, tr in runs])),
            "runs": len(runs),
        }
    return out


def bias_table(r: dict) -> str:
    b = r["bias_sources"]
    rows = ["| a calibration made earlier, fused with the gyro biases | right thigh RMS | right shank RMS |",
            "|---|---|---|"]
    for key, name in (("saved", "saved with it (another trial's)"), ("standing", "of this trial's standing pose"),
                      ("none", "none (zero)")):
        rows.append(f"| {name} | {b['thigh'][key]:.2f}° | {b['shank'][key]:.2f}° |")
    return "\n".join(rows)


TURNS_DEG = (20.0, 45.0, 90.0, 180.0)
"""Sensor turns about the segment's long axis tried by ``calibration_checks`` (around the check's
limit, ``ImuLearnParams.max_axis_change_deg``)."""


def first_check(tr: dict, cal: ImuCalibration, turn: tuple[int, float] | None = None) -> dict:
    """The node's first check of ``cal`` on one trial (raw input fused with the calibration's gyro
    biases, as the node applies a saved file's), optionally with sensor c turned by deg."""
    from scipy.spatial.transform import Rotation

    rec = tr["rec"]
    t = rec.time_s
    gyro, acc = tr["gyro"].copy(), tr["acc_g"].copy()
    if turn is not None:
        c, deg = turn
        rot = Rotation.from_rotvec(np.radians(deg) * np.asarray(cal.mounts[c].proximal)).as_matrix()
        gyro[c], acc[c] = gyro[c] @ rot, acc[c] @ rot  # each row v -> rot.T v: the turned sensor's frame
    ups = np.empty((4, len(t), 3))
    for c in RIGHT.values():
        ups[c] = fuse_raw(t, gyro[c], acc[c], cal.mounts[c].gyro_bias_dps, FUSION_BY_CHANNEL[c])
    for c, up in tr["virtual_ups"].items():  # the virtual left sensors: orientations without rates
        ups[c] = up
        gyro[c] = np.nan
    found, k, _, _ = check_stream(t, ups.transpose(1, 0, 2), gyro.transpose(1, 0, 2), acc.transpose(1, 0, 2), cal)
    if found is None:
        return {"fits": None}
    walking = (rec.labels != "stand")[:k + 1]
    change = max(found.axis_change_deg[c] for c in RIGHT.values())  # NaN: the knee alone decided
    return {"fits": found.fits, "axis_change_deg": None if np.isnan(change) else change,
            "knee_extension_deg": found.knee_extension_deg[0], "at_s": float(t[k]),
            "walking_s": float(np.diff(t[:k + 1])[walking[1:]].sum())}


def calibration_checks(trials: list[dict]) -> dict:
    """The node's check of a saved calibration on camargo (module docstring): each trial's
    raw-input calibration checked on every trial, and each trial's own with a turned sensor."""
    left = SegmentMount.from_axes("+z", "+y")
    cals = {tr["stats"]["trial"]: ImuCalibration((tr["mounts"][0], left, tr["mounts"][2], left)) for tr in trials}
    same = [{"from": a, "on": tr["stats"]["trial"], **first_check(tr, cal)} for a, cal in cals.items() for tr in trials]
    turned = [{"trial": tr["stats"]["trial"], "segment": seg, "turn_deg": deg,
               **first_check(tr, cals[tr["stats"]["trial"]], (c, deg))}
              for tr in trials for seg, c in RIGHT.items() for deg in TURNS_DEG]
    return {"same_sensors": same, "turned": turned}


def synthetic(seeds: int = 6) -> dict:
    from imu_synth import gait_angles, random_mounts, synthesize

    from gait_estimator.core.imu_learn import learn_calibration

    ang = gait_angles(200.0, walk_s=18.0)
    worst_q = worst_r = 0.0
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        s = synthesize(ang, 200.0, random_mounts(rng), rng, acc_noise_g=0.02, gyro_noise_dps=0.5, gyro_bias_dps=2.0)
        ups = np.stack([ups_from_quaternions(s.quat_xyzw[c]) for c in range(4)])
        cal, _, _ = learn_calibration(s.time_s, ups)
        got = np.stack([cal.mounts[c].angles_deg(ups[c]) for c in range(4)], axis=1)
        worst_q = max(worst_q, float(np.sqrt(np.mean((got - s.angles_deg) ** 2, axis=0)).max()))
        first = np.stack([fuse_raw(s.time_s, s.gyro_dps[c], s.acc_g[c], params=FUSION_BY_CHANNEL[c]) for c in range(4)])
        _, st, _ = learn_calibration(s.time_s, first, gyro_dps=s.gyro_dps, acc_g=s.acc_g)
        ups = np.stack([fuse_raw(s.time_s, s.gyro_dps[c], s.acc_g[c], st.gyro_bias_dps[c], FUSION_BY_CHANNEL[c])
                        for c in range(4)])
        cal, _, _ = learn_calibration(s.time_s, ups, gyro_dps=s.gyro_dps, acc_g=s.acc_g)
        got = np.stack([cal.mounts[c].angles_deg(ups[c]) for c in range(4)], axis=1)
        late = s.time_s >= 10.0
        worst_r = max(worst_r, float(np.sqrt(np.mean((got - s.angles_deg)[late] ** 2, axis=0)).max()))
    return {"mountings": seeds, "orientation_worst_rms_deg": worst_q, "raw_worst_rms_after_10s_deg": worst_r}


def _ignore_angles(angles: tuple[float, ...], stamp_ns: int) -> None:
    """``ImuAngles.sample``'s emit for timing it: where the node passes the angles on."""


UNCOMPILED = "raw, without numba (plain Python)"
"""The cost row of raw input in a process without numba."""


def conversion_cost(n: int = 20000, rounds: int = 3, kinds: tuple[str, ...] = ("orientation", "raw")) -> dict:
    """us per four-sensor sample: convert x4 + pair + angles (median, p99), each input of
    ``kinds``, as the node's ImuInput does it (``ImuAngles`` with a calibration in use); of
    ``rounds`` rounds of ``n`` samples, the one with the lowest median (the machine is shared)."""
    rng = np.random.default_rng(0)
    cal = ImuCalibration(tuple(SegmentMount.from_axes("+z", "-x") for _ in range(4)))
    q = rng.normal(size=(n, 4, 4))
    w = rng.normal(0, 1, size=(n, 4, 3))
    a = rng.normal(0, 1, size=(n, 4, 3)) + np.array([0.0, 0.0, 9.8])
    out = {}
    for kind in [k for _ in range(rounds) for k in kinds]:
        cov0 = 0.0 if kind == "orientation" else -1.0
        inputs = [SensorInput(None, "", FUSION_BY_CHANNEL[c], 0.5) for c in range(4)]  # as the node builds them
        converts = [sensor.convert for sensor in inputs]
        pairer, sample = ImuPairer(), ImuAngles(inputs, ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, cal)).sample
        emit = _ignore_angles
        # Python floats, as the node reads them (numpy scalars would make the arithmetic slower)
        rows = [[(tuple(q[k, c].tolist()), tuple(w[k, c].tolist()), tuple(a[k, c].tolist())) for c in range(4)]
                for k in range(n)]
        times = np.empty(n)
        clock = time.perf_counter_ns
        for k in range(n):
            stamp = BASE_NS + k * 5_000_000
            t0 = clock()
            for c, (convert, (qq, ww, aa)) in enumerate(zip(converts, rows[k], strict=True)):
                for sample_ns, items in pairer.push(c, stamp, convert(stamp, qq, cov0, ww, aa)):
                    sample(sample_ns, items, emit)  # as the node's ImuInput._sample
            times[k] = clock() - t0
        times = times[n // 10:]
        this = {"median_us": float(np.median(times)) / 1e3, "p99_us": float(np.percentile(times, 99)) / 1e3,
                "rounds": rounds}
        if kind not in out or this["median_us"] < out[kind]["median_us"]:
            out[kind] = this
    return out


def costs() -> dict:
    """``conversion_cost`` here, then its raw row in a process without numba (``UNCOMPILED``)."""
    import subprocess

    out = conversion_cost()
    env = {**os.environ, "GAIT_ESTIMATOR_NO_NUMBA": "1"}
    r = subprocess.run([sys.executable, __file__, "--raw-cost-json"], env=env, capture_output=True, text=True,
                       check=True)
    out[UNCOMPILED] = json.loads(r.stdout)
    return out


def decode_cost(n: int = 5000, rounds: int = 3) -> dict:
    """us per Imu message: the node's ``read_imu`` vs rclpy (median, p99; best round by median);
    empty without rclpy."""
    try:
        from rclpy.serialization import deserialize_message, serialize_message
        from sensor_msgs.msg import Imu
    except ImportError:
        return {}
    from gait_estimator.io.cdr import read_imu

    m = Imu()
    m.header.frame_id, m.header.stamp.sec = "right_thigh", 1_700_000_000
    m.orientation_covariance[0], m.angular_velocity.x, m.linear_acceleration.z = -1.0, 0.3, 9.8
    data = serialize_message(m)

    def with_rclpy(b: bytes) -> tuple:
        msg = deserialize_message(b, Imu)
        o, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
        return (msg.header.stamp, msg.header.frame_id, (o.x, o.y, o.z, o.w), msg.orientation_covariance[0],
                (w.x, w.y, w.z), (a.x, a.y, a.z))

    out: dict = {}
    clock = time.perf_counter_ns
    for _ in range(rounds):
        for name, fn in (("read_imu (the node)", read_imu), ("rclpy deserialize_message", with_rclpy)):
            times = np.empty(n)
            for i in range(n):
                t0 = clock()
                fn(data)
                times[i] = clock() - t0
            this = {"median_us": float(np.median(times)) / 1e3, "p99_us": float(np.percentile(times, 99)) / 1e3}
            if name not in out or this["median_us"] < out[name]["median_us"]:
                out[name] = this
    return out


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--tables-only", action="store_true", help="only rewrite tables.md from the saved imu.json")
    ap.add_argument("--bags", type=Path, metavar="DIR", help="only write the trials as bags of four Imu topics "
                    "and their recordings from 0 s to DIR (to try the IMU path offline)")
    ap.add_argument("--raw-cost-json", action="store_true", help=argparse.SUPPRESS)  # costs()' subprocess
    args = ap.parse_args(argv)
    if args.raw_cost_json:
        print(json.dumps(conversion_cost(kinds=("raw",))["raw"]))
        return 0
    if args.bags:
        print("\n".join(f"wrote {p}" for p in write_bags(args.bags)))
        return 0
    if args.tables_only:
        print(write_tables(args.out))
        return 0
    started = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        trials = [trial_imu(p, Path(tmp)) for p in sorted(DATA.glob("levelground_*.csv"))]
    result = {
        "command": "python benchmarks/imu.py",
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d"),
        "machine": machine(),
        "trials": [tr["stats"] for tr in trials],
        "estimator": estimator_runs(trials),
        "estimator_without_faults": estimator_runs(trials, skip_faults=True),
        "fusion_selection": (selection := select_fusion(trials)),
        "estimator_in_sample_fusion": in_sample_estimator(trials, selection),
        "calibration_check": calibration_checks(trials),
        "bias_sources": bias_sources(trials),
        "live": live_runs(trials, {tr["stats"]["trial"]: {c: virtual_quaternions(tr["rec"].angles_deg[:, c]) for c in (1, 3)}
                                   for tr in trials}),
        "synthetic": synthetic(),
        "cost": costs(),
        "decode": decode_cost(),
    }
    for kind in ("orientation", "raw"):
        result[f"mean_rms_{kind}"] = {seg: float(np.mean([tr["stats"][kind][seg] for tr in trials]))
                                      for seg in (*RIGHT, "thigh_clean", "shank_clean", "thigh_after", "shank_after")}
        result[f"pooled_rms_{kind}"] = {seg: pooled_rms([tr["stats"][kind] for tr in trials], f"{seg}_after")
                                        for seg in RIGHT}
    result["seconds"] = round(time.time() - started, 1)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "imu.json").write_text(json.dumps(result, indent=1) + "\n")
    print(write_tables(args.out))
    return 0


def pooled_rms(stats: list[dict], key: str) -> float:
    """The RMS (deg) over every trial's samples together: each trial's ``key`` RMS weighted by its count."""
    n = np.array([s[f"{key}_n"] for s in stats], dtype=float)
    return float(np.sqrt(np.sum(n * np.array([s[key] for s in stats]) ** 2) / n.sum()))


def write_tables(out: Path) -> str:
    """tables.md from imu.json: per-trial figures, then the sections docs/imu.md copies
    (``imu#Angles``, ``imu#Estimator``, ``imu#Cost``); returns it."""
    r = json.loads((out / "imu.json").read_text(encoding="utf-8"))
    text = "\n".join(["### Per trial", "", per_trial(r), "### Thigh IMU faults", "", thigh_fault_table(r), "",
                      "### Angles", "", angles_table(r), "",
                      "### Fusion settings, leave-one-trial-out", "", selection_table(r), "",
                      "### Calibration check", "", check_table(r), "",
                      "### Gyro bias of a calibration made earlier", "", bias_table(r), "",
                      "### The node's own calibration", "", live_table(r), "",
                      "### Estimator", "", estimator_table(r), "", "### Standing", "", standing_table(r), "",
                      "### Cost", "", cost_table(r)])
    (out / "tables.md").write_text(text + "\n", encoding="utf-8")
    return text


def live_table(r: dict) -> str:
    """``imu_live``: per trial when the node calibrated and its angles' RMS vs mocap, and the mean."""
    rows = ["| trial (times: the data set's) | standing pose from | fused with its gyro biases from | node calibrated at "
            "| right thigh RMS | right shank RMS |", "|---|---|---|---|---|---|"]
    done = [x for x in r.get("live", []) if x["calibrated_at_s"] is not None]
    for x in r.get("live", []):
        if x["calibrated_at_s"] is None:
            rows.append(f"| {x['trial']} | | | never (\"{x['status']}\") | | |")
        else:
            rows.append(f"| {x['trial']} | {x['pose_s']:.1f} s | {x['biases_from_s']:.1f} s | {x['calibrated_at_s']:.1f} s "
                        f"| {x['thigh']:.2f}° | {x['shank']:.2f}° |")
    if done:
        rows.append(f"| mean of {len(done)} | | | | {np.mean([x['thigh'] for x in done]):.2f}° | "
                    f"{np.mean([x['shank'] for x in done]):.2f}° |")
    return "\n".join(rows)


def angles_table(r: dict) -> str:
    """Mean of the trials' RMS IMU - mocap (deg), per input; after the first standing also pooled."""
    rows = ["| input | right thigh, shank | without the data set's IMU faults | and after the first standing "
            "(pooled samples) |", "|---|---|---|---|"]
    for kind, name in (("raw", "raw (the node's fusion)"),
                       ("orientation", "orientation (imufusion's defaults, as a Fusion-based driver)")):
        m, p = r[f"mean_rms_{kind}"], r[f"pooled_rms_{kind}"]
        rows.append(f"| {name} | {m['thigh']:.1f}°, {m['shank']:.1f}° | {m['thigh_clean']:.1f}°, {m['shank_clean']:.1f}° | "
                    f"{m['thigh_after']:.1f}°, {m['shank_after']:.1f}° ({p['thigh']:.1f}°, {p['shank']:.1f}°) |")
    return "\n".join(rows)


def thigh_fault_table(r: dict) -> str:
    """``thigh_fault_evidence`` per trial."""
    rows = ["| trial | start s | accelerometer step m/s² (× median standing) | walking after, s | tilt − mocap "
            "before / after, deg | median \\|Δ² gyro z\\| before / after, deg/s | r(gyro y, mocap rate) before / after "
            "| r(gyro z, ·) before / after |", "|---|---|---|---|---|---|---|---|"]
    for tr in r["trials"]:
        e = tr.get("thigh_fault")
        if e is None:
            rows.append(f"| {tr['trial']} | none | | | | | | |")
            continue
        rows.append(f"| {tr['trial']} | {e['start_s']:.3f} | {e['step_mps2']:.2f} ({e['step_ratio']:.0f}×) | "
                    f"{e['walking_after_s']:.1f} | {e['tilt_minus_mocap_before_deg']:+.1f} / "
                    f"{e['tilt_minus_mocap_after_deg']:+.1f} | {e['gyro_z_second_difference_before_dps']:.2f} / "
                    f"{e['gyro_z_second_difference_after_dps']:.2f} | {e['r_gyro_y_before']:+.2f} / "
                    f"{e['r_gyro_y_after']:+.2f} | {e['r_gyro_z_before']:+.2f} / {e['r_gyro_z_after']:+.2f} |")
    return "\n".join(rows)


def selection_table(r: dict) -> str:
    """Leave-one-trial-out fusion settings per segment (``select_fusion``)."""
    sel = r["fusion_selection"]
    rows = ["| segment | held-out trial: settings chosen on the other four, RMS there | held-out mean | best on all "
            "five (in-sample) | shipped |", "|---|---|---|---|---|"]
    for seg, v in sel.items():
        held = "; ".join(f"{k.removeprefix('levelground_')}: {h['settings']}, {h['rms_deg']:.1f}°"
                         for k, h in v["held_out"].items())
        rows.append(f"| {seg} | {held} | {v['held_out_mean_deg']:.1f}° | {v['in_sample']}, "
                    f"{v['in_sample_mean_deg']:.1f}° | {v['shipped']} |")
    return "\n".join(rows)


def check_table(r: dict) -> str:
    """``calibration_checks``: verdicts, largest lateral-axis change ('knee': decided by the knee
    alone, before the axes could be learnt) and knee extension (right leg), and the walking
    (samples the data set labels as walking) before the verdict."""
    chk = r["calibration_check"]
    rows = ["| saved calibration checked on | checks | fits / does not fit / no verdict | lateral axis change, "
            "deg (largest) | right knee past straight, deg (largest) | walking before the verdict (labelled), s |",
            "|---|---|---|---|---|---|"]

    def row(name: str, runs: list[dict]) -> str:
        done = [x for x in runs if x["fits"] is not None]
        if not done:
            return f"| {name} | {len(runs)} | 0 / 0 / {len(runs)} | | | |"
        fits = sum(bool(x["fits"]) for x in done)
        changes = [x["axis_change_deg"] for x in done]
        change = ", ".join("knee" if c is None else f"{c:.0f}" for c in changes)
        return (f"| {name} | {len(runs)} | {fits} / {len(done) - fits} / {len(runs) - len(done)} | "
                f"{max((c for c in changes if c is not None), default=math.nan):.0f} ({change}) | "
                f"{max(x['knee_extension_deg'] for x in done):.0f} | "
                f"{min(x['walking_s'] for x in done):.1f}–{max(x['walking_s'] for x in done):.1f} |")

    same = chk["same_sensors"]
    rows.append(row("its own trial", [x for x in same if x["from"] == x["on"]]))
    rows.append(row("the other four trials (same sensors)", [x for x in same if x["from"] != x["on"]]))
    for seg in RIGHT:
        for deg in TURNS_DEG:
            runs = [x for x in chk["turned"] if x["segment"] == seg and x["turn_deg"] == deg]
            rows.append(row(f"its trial, right {seg} sensor turned {deg:.0f}°", runs))
    return "\n".join(rows)


INPUT_NAMES = {"mocap": "mocap", "imu_raw": "IMU (raw)"}
"""Table names of the estimator runs' angle sources."""


def estimator_table(r: dict) -> str:
    """Accuracy and mean phase error (% of a stride) per kernel source and input."""
    every, sound = r["estimator"], r["estimator_without_faults"]
    n_all, n_sound = next(iter(every.values()))["samples"], next(iter(sound.values()))["samples"]
    rows = [f"| kernels from → fed with | all samples ({n_all}): accuracy, phase error | without the shank IMU "
            f"faults ({n_sound}) |", "|---|---|---|"]
    names = INPUT_NAMES
    for key in every:
        a, b = key.split("->")
        cells = [f"{100 * v[key]['accuracy']:.1f} %, {100 * v[key]['phase_error_mean']:.2f}" for v in (every, sound)]
        rows.append(f"| {names[a]} → {names[b]} | {cells[0]} | {cells[1]} |")
    for seg, v in r.get("estimator_in_sample_fusion", {}).items():
        for key in ("imu_raw->imu_raw", "mocap->imu_raw"):
            a, b = key.split("->")
            cells = [f"{100 * w[key]['accuracy']:.1f} %, {100 * w[key]['phase_error_mean']:.2f}"
                     for w in (v["all"], v["without_faults"])]
            rows.append(f"| {names[a]} → {names[b]}; {seg}: {v['settings']} | {cells[0]} | {cells[1]} |")
    return "\n".join(rows)


def standing_table(r: dict) -> str:
    """``fit_rms_deg`` of the estimates while the wearer stands (no mode fits) and walks."""
    rows = ["| kernels from → fed with (all samples) | standing samples | fit_rms_deg standing: 5th percentile, median "
            "| walking (scored rows): median, 95th percentile |", "|---|---|---|---|"]
    names = INPUT_NAMES
    for key, v in r["estimator"].items():
        a, b = key.split("->")
        s, w = v["fit_rms_standing_p5_p50_deg"], v["fit_rms_walking_p50_p95_deg"]
        rows.append(f"| {names[a]} → {names[b]} | {v['standing_samples']} | {s[0]:.1f}°, {s[1]:.1f}° | "
                    f"{w[0]:.1f}°, {w[1]:.1f}° |")
    return "\n".join(rows)


def cost_table(r: dict) -> str:
    rows = ["| per four-sensor sample, input; per message, decoding | median µs | p99 µs |", "|---|---|---|"]
    rows += [f"| {k} | {v['median_us']:.1f} | {v['p99_us']:.1f} |"
             for k, v in (*r["cost"].items(), *r.get("decode", {}).items())]
    return "\n".join(rows)


def per_trial(r: dict) -> str:
    lines = [f"Measured {r['date']} on {r['machine']} with `{r['command']}` ({r['seconds']} s).", "",
             "| camargo_ab06 trial | input | right thigh RMS deg (r) | right shank RMS deg (r) | without the data "
             "set's IMU faults: thigh, shank (share of walking kept) | and after the first standing: thigh, shank |",
             "|---|---|---|---|---|---|"]
    for tr in r["trials"]:
        for kind in ("orientation", "raw"):
            lines.append(f"| {tr['trial']} | {kind} | {tr[kind]['thigh']:.1f} ({tr[kind + '_r']['thigh']:.3f}) | "
                         f"{tr[kind]['shank']:.1f} ({tr[kind + '_r']['shank']:.3f}) | {tr[kind]['thigh_clean']:.1f} "
                         f"({100 * tr[kind]['thigh_clean_share']:.0f} %), {tr[kind]['shank_clean']:.1f} "
                         f"({100 * tr[kind]['shank_clean_share']:.0f} %) | {tr[kind]['thigh_after']:.1f}, "
                         f"{tr[kind]['shank_after']:.1f} |")
    for kind in ("orientation", "raw"):
        m = r[f"mean_rms_{kind}"]
        lines.append(f"| **mean of 5** | {kind} | **{m['thigh']:.1f}** | **{m['shank']:.1f}** | **{m['thigh_clean']:.1f}**, "
                     f"**{m['shank_clean']:.1f}** | "
                     f"**{m['thigh_after']:.1f}**, **{m['shank_after']:.1f}** |")
    lines += ["", "| kernels from -> tested with | accuracy | phase error (mean, % of stride) | samples |", "|---|---|---|---|"]
    for key, note in (("estimator", ""), ("estimator_without_faults", ", shank IMU faults not used")):
        for k, v in r[key].items():
            lines.append(f"| {k}{note} | {100 * v['accuracy']:.1f} % | {100 * v['phase_error_mean']:.2f} | {v['samples']} |")
    s = r["synthetic"]
    lines += ["", f"Synthetic, {s['mountings']} random mountings: orientation input worst RMS "
              f"{s['orientation_worst_rms_deg']:.2g} deg; raw input (noise, 2 deg/s gyro bias) worst RMS after 10 s "
              f"{s['raw_worst_rms_after_10s_deg']:.2f} deg.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
