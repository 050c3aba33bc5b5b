"""io/cdr.py: JointState fields read from CDR bytes equal what rosbags' serialiser wrote
(both byte orders, frame ids and names of every alignment); bad bytes raise CdrError. ROS-free;
test_node checks the node's serialised input path over DDS against rclpy's serialiser."""

from __future__ import annotations

import numpy as np
import pytest

from gait_estimator.io.bag import typestore
from gait_estimator.io.bag_write import JOINT_STATE
from gait_estimator.io.cdr import CdrError, read_joint_state, read_stamp


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
