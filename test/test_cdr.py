"""io/cdr.py: JointState and Imu fields read from CDR bytes equal what rosbags' serialiser wrote
(both byte orders, frame ids and names of every alignment); bad bytes raise CdrError. ROS-free;
test_node and test_node_imu check the node's serialised input paths over DDS against rclpy's."""

from __future__ import annotations

import numpy as np
import pytest

from gait_estimator.io.bag import typestore
from gait_estimator.io.bag_write import JOINT_STATE
from gait_estimator.io.cdr import CdrError, read_imu, read_joint_state, read_stamp, stamp_to_ns, with_stamp


def _cdr(frame_id: str, names: list[str], positions: list[float], velocity: list[float], little: bool,
         sec: int = 1_763_900_000, nanosec: int = 123_456_789) -> bytes:
    ts = typestore()
    t = ts.types
    msg = t[JOINT_STATE](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame_id),
        name=names,
        position=np.asarray(positions, dtype=np.float64),
        velocity=np.asarray(velocity, dtype=np.float64),
        effort=np.empty(0, dtype=np.float64),
    )
    return bytes(ts.serialize_cdr(msg, JOINT_STATE, little_endian=little))


OSL = ["right_thigh", "left_thigh", "right_shank", "left_shank"]


@pytest.mark.parametrize("little", [True, False])
@pytest.mark.parametrize("frame_id", ["", "a", "abc", "imu_link"])
@pytest.mark.parametrize("names", [[], ["x"], OSL, ["ankle", *reversed(OSL)], ["Knöchel", "ab", "abcde", "", "q" * 9]])
def test_fields_equal_the_serialised_message(little: bool, frame_id: str, names: list[str]) -> None:
    rng = np.random.default_rng(len(frame_id) * 10 + len(names))
    for positions in ([], rng.normal(size=len(names)).tolist(), rng.normal(size=len(names) + 2).tolist()):
        data = _cdr(frame_id, names, positions, [1.0, 2.0], little, sec=-7, nanosec=999_999_999)
        got = read_joint_state(data)
        assert read_stamp(data) == got.stamp
        assert got.names == names
        assert list(got.positions) == positions
        assert tuple(got.stamp) == (-7, 999_999_999) and got.stamp.sec == -7


@pytest.mark.parametrize("little", [True, False])
def test_stamp_patching_round_trip(little: bool) -> None:
    data = _cdr("imu_link", OSL, [0.1, 0.2, 0.3, 0.4], [], little)
    assert stamp_to_ns(read_stamp(data)) == 1_763_900_000_123_456_789
    patched = with_stamp(data, 1_700_000_000_000_000_123)
    assert stamp_to_ns(read_stamp(patched)) == 1_700_000_000_000_000_123
    assert len(patched) == len(data) and patched[12:] == data[12:] and patched[:4] == data[:4]


def test_bad_bytes_raise_cdr_error() -> None:
    good = _cdr("", OSL, [0.1, 0.2, 0.3, 0.4], [], True)
    assert read_joint_state(good).positions == (0.1, 0.2, 0.3, 0.4)
    bad = [
        b"",
        b"\x00\x01",
        good[:-9],  # positions cut short
        good[:30],  # inside the names
        b"\x00\x07" + good[2:],  # XCDR2: left to the middleware's deserialiser
        b"\x01\x01" + good[2:],
        good[:4] + b"\xff" * 40,  # absurd lengths
        good[:24] + b"\x00\x00\x00\x00" + good[28:],  # a name of length 0 (no NUL)
        good[:28] + b"\xff\xfe\xfd" + good[31:],  # not UTF-8
    ]
    for data in bad:
        with pytest.raises(CdrError):
            read_joint_state(data)
    for data in (b"", b"\x00\x01" + bytes(9), b"\x00\x07" + good[2:]):
        with pytest.raises(CdrError):
            read_stamp(data)


def _imu_cdr(frame_id: str, values: np.ndarray, little: bool, sec: int = 1_763_900_000, nanosec: int = 5) -> bytes:
    """An Imu whose 37 float fields (orientation x y z w, its covariance, angular velocity, its
    covariance, linear acceleration, its covariance) are ``values``."""
    ts = typestore()
    t = ts.types
    v = values.tolist()
    vec = t["geometry_msgs/msg/Vector3"]
    msg = t["sensor_msgs/msg/Imu"](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=frame_id),
        orientation=t["geometry_msgs/msg/Quaternion"](x=v[0], y=v[1], z=v[2], w=v[3]),
        orientation_covariance=values[4:13].copy(),
        angular_velocity=vec(x=v[13], y=v[14], z=v[15]),
        angular_velocity_covariance=values[16:25].copy(),
        linear_acceleration=vec(x=v[25], y=v[26], z=v[27]),
        linear_acceleration_covariance=values[28:37].copy(),
    )
    return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/Imu", little_endian=little))


@pytest.mark.parametrize("little", [True, False])
@pytest.mark.parametrize("frame_id", ["", "a", "abc", "imu_link", "right_thigh", "Oberschenkel_rechts_ä"])
def test_imu_fields_equal_the_serialised_message(little: bool, frame_id: str) -> None:
    rng = np.random.default_rng(len(frame_id))
    for k in range(3):
        v = rng.normal(size=37)
        if k == 1:  # no orientation (REP 145), non-finite values
            v[4], v[0], v[14], v[27] = -1.0, np.nan, np.inf, -np.inf
        got = read_imu(_imu_cdr(frame_id, v, little, sec=-3 + k, nanosec=999_999_999))
        assert got.stamp == (-3 + k, 999_999_999) and got.frame_id == frame_id
        assert np.array_equal((*got.orientation, got.orientation_cov0), v[0:5], equal_nan=True)
        assert np.array_equal(got.angular_velocity, v[13:16]) and np.array_equal(got.linear_acceleration, v[25:28])
        assert all(type(x) is float for x in (*got.orientation, *got.angular_velocity, *got.linear_acceleration))


def test_bad_imu_bytes_raise_cdr_error() -> None:
    good = _imu_cdr("imu", np.arange(37.0), True)
    assert read_imu(good).linear_acceleration == (25.0, 26.0, 27.0)
    bad = [b"", b"\x00\x01", good[:-1], good[:20], b"\x00\x07" + good[2:], good[:12] + b"\xff" * 40,
           good[:12] + bytes(4) + good[16:],  # a frame_id of length 0 (no NUL)
           good[:16] + b"\xff\xfe\xfd" + good[19:]]  # not UTF-8
    for data in bad:
        with pytest.raises(CdrError):
            read_imu(data)
