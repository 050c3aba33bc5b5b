"""IMU angles on real IMUs (data/camargo_ab06, cw_fast: raw right thigh and shank IMUs): the
mounting learnt from a bag of sensor_msgs/Imu matches the sensor frames the data set's README
infers, and the angles follow motion capture. The figures are benchmarks/imu.py's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from fusion_reference import RawFusion

from gait_estimator.io.imu_bag import read_imu_bag, write_imu_bag
from gait_estimator.io.recording import read_project_csv

TRIAL = Path(__file__).resolve().parents[1] / "data" / "camargo_ab06" / "levelground_cw_fast.csv"
S0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def test_raw_camargo_imus_learn_the_documented_frames_and_follow_mocap(tmp_path):
    from scipy.spatial.transform import Rotation

    rec = read_project_csv(TRIAL)
    t, ex, mocap = rec.time_s, rec.extra, rec.angles_deg
    gyro = np.zeros((4, len(t), 3))
    acc = np.zeros((4, len(t), 3))
    for seg, c in (("thigh", 0), ("shank", 2)):
        gyro[c] = np.stack([ex[f"right_{seg}_gyro_{k}_dps"] for k in "xyz"], axis=1)
        acc[c] = np.stack([ex[f"right_{seg}_acc_{k}_mps2"] for k in "xyz"], axis=1)
    # no left IMUs in the data set: virtual ones carrying the mocap angles, axes configured
    left = [(Rotation.from_euler("y", -np.radians(mocap[:, c])[:, None]) * Rotation.from_matrix(S0)).as_quat() for c in (1, 3)]
    stamps = 1_700_000_000 * 10**9 + np.round(t * 1e9).astype(np.int64)
    bag = write_imu_bag(tmp_path / "cw_fast", stamps, np.radians(gyro), acc, [None, left[0], None, left[1]])
    got = read_imu_bag(bag, imu_lateral_axes=["", "+z", "", "+z"], imu_proximal_axes=["", "+y", "", "+y"])
    assert len(got) == len(t)
    thigh, shank = got.calibration.mounts[0], got.calibration.mounts[2]
    # README "IMU frames": thigh X distal, Z lateral (+gyro Z = flexion); shank X distal, sagittal gyro -Y
    assert np.dot(thigh.proximal, [-1, 0, 0]) > 0.95 and np.dot(thigh.lateral, [0, 0, 1]) > 0.9
    assert np.dot(shank.proximal, [-1, 0, 0]) > 0.95 and np.dot(shank.lateral, [0, -1, 0]) > 0.9
    assert np.array_equal(got.angles_deg[:, [1, 3]].round(6), mocap[:, [1, 3]].round(6))
    walk = rec.labels != "stand"
    for c in (0, 2):
        d = got.angles_deg[walk, c] - mocap[walk, c]
        assert np.corrcoef(got.angles_deg[walk, c], mocap[walk, c])[0, 1] > 0.9
        assert np.std(d) < 8.0


def test_compiled_fusion_gives_imufusions_angles_on_real_imus():
    """core/ahrs.CompiledFusion against imufusion (RawFusion) on the real thigh and shank IMUs,
    each with its node settings and with acceleration rejection on: the same angles to 0.001 deg."""
    from gait_estimator.core.ahrs import CompiledFusion
    from gait_estimator.core.imu import FUSION_BY_CHANNEL, FusionParams, SegmentMount

    rec = read_project_csv(TRIAL)
    t, ex = rec.time_s, rec.extra
    mounts = {"thigh": SegmentMount.from_axes("+z", "-x"), "shank": SegmentMount.from_axes("-y", "-x")}
    for seg, c in (("thigh", 0), ("shank", 2)):
        gyro = np.stack([ex[f"right_{seg}_gyro_{k}_dps"] for k in "xyz"], axis=1)
        acc = np.stack([ex[f"right_{seg}_acc_{k}_mps2"] for k in "xyz"], axis=1) / 9.80665
        for params in (FUSION_BY_CHANNEL[c], FusionParams(acceleration_rejection_deg=10.0, rejection_timeout_s=0.5)):
            ref, ours = RawFusion(200.0, (0.5, -0.5, 0.5), params), CompiledFusion(200.0, (0.5, -0.5, 0.5), params)
            ups = np.empty((2, len(t), 3))
            for k in range(len(t)):
                dt = None if k == 0 else float(t[k] - t[k - 1])
                ups[0, k], ups[1, k] = ref.update(gyro[k], acc[k], dt), ours.update(gyro[k], acc[k], dt)
            a, b = mounts[seg].angles_deg(ups[0]), mounts[seg].angles_deg(ups[1])
            assert np.abs(a - b).max() < 1e-3, (seg, params, np.abs(a - b).max())


def test_benchmark_bags_to_try_the_imu_path_run_on_their_truths_clock(tmp_path):
    """``python benchmarks/imu.py --bags DIR`` (docs/imu.md): five bags of four Imu topics and their
    recordings with the time origin of the bags' outputs, so evaluate matches every row."""
    import subprocess
    import sys

    from gait_estimator.analysis.evaluate import evaluate, read_predictions_csv
    from gait_estimator.cli.app import main

    repo = Path(__file__).resolve().parents[1]
    r = subprocess.run([sys.executable, str(repo / "benchmarks" / "imu.py"), "--bags", str(tmp_path)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert len(r.stdout.splitlines()) == 10 and len(list(tmp_path.glob("*_truth.csv"))) == 5
    truth = read_project_csv(tmp_path / "levelground_cw_fast_truth.csv")
    assert main(["process", str(tmp_path / "levelground_cw_fast"), "--out", str(tmp_path / "pred.csv")]) == 0
    pred = read_predictions_csv(tmp_path / "pred.csv")
    assert np.allclose(pred.time_s, truth.time_s, atol=1e-6) and truth.time_s[0] == 0.0
    ev = evaluate(pred, truth)
    assert ev.metrics["samples"]["matched"] == len(truth)
    # no time-base warning; the bundled kernels' names are not the data set's labels, and it says so
    assert [w.split(" (")[0] for w in ev.metrics["warnings"]] == ["truth label 'walk_fast'", "truth label 'stand'"]
