"""bench-node's IMU messages (analysis/imu_sagittal.py): segment angles ->
serialised sensor_msgs/Imu -> the node's own reading and conversion (io/cdr.py read_imu,
core/imu_pairing.py SensorInput, the configured mounting) give the angles back."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu

from gait_estimator import load_library
from gait_estimator.analysis.bench import synthetic_walk
from gait_estimator.analysis.imu_sagittal import BENCH_LATERAL_AXES, BENCH_PROXIMAL_AXES, imu_samples, sagittal_imu
from gait_estimator.cli.bench_node import node_imu_arguments
from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.imu import FUSION_BY_CHANNEL, ImuCalibration, SegmentMount
from gait_estimator.core.imu_pairing import SensorInput
from gait_estimator.io.cdr import read_imu, write_imu


def _angles(rate_hz: float) -> np.ndarray:
    """1 s standing, then 5 s of the bench's synthetic walk (0.5 deg noise), blended in over 0.25 s."""
    walk = synthetic_walk(load_library("able_bodied"), round(5 * rate_hz), seed=3)
    k = round(0.25 * rate_hz)
    walk[:k] = walk[k - 1] * (np.arange(1, k + 1) / k)[:, None]
    return np.concatenate([np.zeros((round(rate_hz), 4)), walk])


def _node_angles(samples: list[tuple[bytes, ...]], lateral=BENCH_LATERAL_AXES, proximal=BENCH_PROXIMAL_AXES):
    cal = ImuCalibration(tuple(SegmentMount.from_axes(a, p) for a, p in zip(lateral, proximal, strict=True)))
    inputs = [SensorInput(None, "", fusion) for fusion in FUSION_BY_CHANNEL]
    out = []
    for four in samples:
        ups = []
        for c, data in enumerate(four):
            stamp, frame, q, cov0, gyro, acc = read_imu(data)
            assert frame == CHANNELS[c]
            ups.append(inputs[c].convert(stamp.sec * 1_000_000_000 + stamp.nanosec, q, cov0, gyro, acc, frame)[0])
        out.append(cal.angles_deg(ups))
    return np.array(out)


@pytest.mark.parametrize("raw", [False, True])
def test_imu_messages_give_the_angles_back(raw: bool) -> None:
    rate = 230.0
    angles = _angles(rate)
    stamps = 1_700_000_000 * 10**9 + np.arange(len(angles)) * round(1e9 / rate)
    got = _node_angles(imu_samples(angles, stamps, 1 / rate, raw))
    if raw:  # gyro + gravity, fused (core/ahrs.py): tracks the angles
        assert np.abs(got - angles)[round(2 * rate):].max() < 1.0
    else:
        np.testing.assert_allclose(got, angles, rtol=0, atol=1e-9)


def test_other_configured_mountings_and_gyro_about_the_lateral_axis() -> None:
    lateral, proximal = ("-y", "+x", "+z", "-x"), ("+z", "-z", "+y", "+y")
    angles = np.column_stack([np.linspace(-30, 60, 50)] * 4)
    f = sagittal_imu(angles, 0.01, lateral, proximal)
    for c, axis in enumerate(lateral):  # rates about the lateral axis only, the angle's derivative
        k = "xyz".index(axis[1])
        assert np.allclose(np.delete(f.gyro_rps[:, c], k, axis=1), 0)
        np.testing.assert_allclose(f.gyro_rps[1:, c, k] * (1 if axis[0] == "+" else -1), np.radians(90 / 49) / 0.01)
    np.testing.assert_allclose(np.linalg.norm(f.acc_mps2, axis=2), 9.80665)
    np.testing.assert_allclose(np.linalg.norm(f.quat_xyzw, axis=2), 1.0)
    got = _node_angles(imu_samples(angles, np.arange(1, 51) * 10_000_000, 0.01, False, None, lateral, proximal),
                       lateral, proximal)
    np.testing.assert_allclose(got, angles, rtol=0, atol=1e-9)
    args = node_imu_arguments("/tmp/x.imu.yaml", lateral, proximal)
    assert "imu_lateral_axes:=['-y','+x','+z','-x']" in args and "input_type:=imu" in args


@pytest.mark.parametrize("raw", [False, True])
def test_serialised_imu_is_what_rclpy_serialises(raw: bool) -> None:
    m = Imu()
    m.header.stamp.sec, m.header.stamp.nanosec = 1_700_000_123, 456_789
    m.header.frame_id = "left_shank"
    q = (0.0, 0.0, 0.0, 0.0) if raw else (0.1, -0.2, 0.3, 0.9)
    m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = q
    m.orientation_covariance[0] = -1.0 if raw else 0.0
    m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = 0.5, -1.5, 2.5
    m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = 1.0, -9.0, 3.0
    ours = write_imu(1_700_000_123 * 10**9 + 456_789, "left_shank", q, m.orientation_covariance[0],
                     (0.5, -1.5, 2.5), (1.0, -9.0, 3.0))
    theirs = serialize_message(m)
    # Byte for byte but the alignment padding after frame_id, which rclpy leaves uninitialised.
    end = 4 + 8 + 4 + len("left_shank") + 1  # encapsulation, stamp, length, string and its NUL
    pad = slice(end, end + (-(end - 4)) % 8)
    assert len(ours) == len(theirs) and pad.stop > pad.start
    assert ours[: pad.start] + ours[pad.stop :] == theirs[: pad.start] + theirs[pad.stop :]
    assert deserialize_message(ours, Imu) == m
