"""The node's own IMU calibration on camargo_ab06, for ``benchmarks/imu.py``'s table of that name.

``live_angles`` runs estimator_node's IMU input (``ros/imu_input.py``) with no calibration file,
through its ROS-free parts built as the node builds them: ``SensorInput`` per sensor, ``ImuPairer``,
and ``ImuAngles`` with an ``ImuCalibrator`` learning the mounting from the first standing pose
(1 s still) and 4 s of walking, the raw sensors fused with the pose's gyro biases from the
wearer's first move on; the angles the node passes to its estimator, from the sample after the
calibration is complete. ``test/test_node_imu.py`` checks them against a real node's. ``live_runs``
scores them against mocap like ``trial_imu``: the walking without the data set's faults, the
node's standing angle (0) taken as mocap's mean over the node's standing pose.
"""

from __future__ import annotations

import numpy as np

from gait_estimator.core.imu import FUSION_BY_CHANNEL, STANDARD_GRAVITY, parse_axis
from gait_estimator.core.imu_angles import ImuAngles
from gait_estimator.core.imu_calibrator import ImuCalibrator
from gait_estimator.core.imu_pairing import ImuPairer, SensorInput
from gait_estimator.core.options import EstimatorConfig
from gait_estimator.core.stamps import restart_threshold

RIGHT = {"thigh": 0, "shank": 2}
VIRTUAL_AXES = {"imu_lateral_axes": ["", "+z", "", "+z"], "imu_proximal_axes": ["", "+y", "", "+y"]}
"""The left channels: virtual sensors carrying the mocap angles (``imu.virtual_quaternions``)."""
BASE_NS = 1_700_000_000 * 1_000_000_000


def live_angles(time_s: np.ndarray, gyro_dps: np.ndarray, acc_g: np.ndarray,
                quaternions: dict[int, np.ndarray]) -> tuple[np.ndarray, int | None, ImuCalibrator]:
    """Raw sensors (T,), (4, T, 3) deg/s and g, and orientation sensors {channel: (T, 4) x, y, z, w}
    -> (the angles the node puts out (T, 4), nan elsewhere; the sample from which it fused with the
    standing pose's gyro biases, or None; its calibrator, for ``status`` and ``standing_s``)."""
    axes = {k: [parse_axis(a) if a else None for a in v] for k, v in VIRTUAL_AXES.items()}
    back = restart_threshold(EstimatorConfig().max_gap_s)  # the node's default max_gap_s
    inputs = [SensorInput(None, "", FUSION_BY_CHANNEL[c], back) for c in range(4)]
    pairer, calibrator = ImuPairer(), ImuCalibrator(axes["imu_lateral_axes"], axes["imu_proximal_axes"], [0.0] * 4)
    gyro = np.radians(gyro_dps).tolist()  # Python floats, as the node reads them
    acc = (acc_g * STANDARD_GRAVITY).tolist()
    quat = {c: q.tolist() for c, q in quaternions.items()}
    out = np.full((len(time_s), 4), np.nan)
    biased_at: list[int] = []
    k = 0
    flow = ImuAngles(inputs, calibrator, on_gyro_biases=lambda _: biased_at.append(k))  # k: the sample being paired

    def emit(angles: tuple[float, ...], _: int) -> None:
        out[k] = angles

    zero, identity = (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)
    for k in range(len(time_s)):
        stamp = BASE_NS + round(float(time_s[k]) * 1e9)
        for c in range(4):
            item = (inputs[c].convert(stamp, quat[c][k], 0.0, zero, zero) if c in quat else
                    inputs[c].convert(stamp, identity, -1.0, gyro[c][k], acc[c][k]))
            for sample_ns, items in pairer.push(c, stamp, item):
                flow.sample(sample_ns, items, emit)
    return out, (biased_at[-1] if biased_at else None), calibrator


def live_runs(trials: list[dict], quaternions: dict[str, dict[int, np.ndarray]]) -> list[dict]:
    """``live_angles`` per trial (``quaternions``: trial name -> its virtual left sensors): when
    the node calibrated, and RMS of its angles vs mocap per right segment."""
    runs = []
    for tr in trials:
        rec, name = tr["rec"], tr["stats"]["trial"]
        t, mocap = rec.time_s, rec.angles_deg
        out, biased_at, calibrator = live_angles(t, tr["gyro"], tr["acc_g"], quaternions[name])
        done = np.isfinite(out[:, 0])
        if not done.any() or biased_at is None or calibrator.standing_s is None:
            runs.append({"trial": name, "calibrated_at_s": None, "status": calibrator.status})
            continue
        first_s, last_s = np.subtract(calibrator.standing_s, BASE_NS * 1e-9)  # the node's stamps -> the data set's time
        start, stop = int(np.searchsorted(t, first_s - 1e-4)), int(np.searchsorted(t, last_s + 1e-4))
        run = {"trial": name, "calibrated_at_s": float(t[np.argmax(done)]), "pose_s": float(t[start]),
               "biases_from_s": float(t[biased_at])}
        for seg, c in RIGHT.items():
            sel = done & (rec.labels != "stand") & ~tr["faults"][c]
            err = out[sel, c] + mocap[start:stop, c].mean() - mocap[sel, c]
            run[seg] = float(np.sqrt(np.mean(err ** 2)))
        runs.append(run)
    return runs
