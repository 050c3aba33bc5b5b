"""SerializedJointState: the node's pre-serialised ``estimate`` deserialises to what was patched in.

No DDS here (rclpy's serialisation only); test_node checks the published estimates end to end.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState

from gait_estimator import load_library
from gait_estimator.io.outputs import estimate_names
from gait_estimator.ros.serialized import SerializedJointState


@pytest.mark.parametrize(
    "names, frame_id",
    [
        ([], ""),
        (["a"], ""),
        (estimate_names(load_library("able_bodied").mode_names), ""),
        (["Rampe_hoch_ü", "x" * 37, "", "sse/Müde"], "osl/frame"),  # UTF-8, odd lengths, empty name
        ([f"sse/mode{i}" for i in range(1409)], ""),  # 700 modes
    ],
)
def test_patched_bytes_equal_a_serialised_message(names: list[str], frame_id: str) -> None:
    msg = SerializedJointState(names, frame_id=frame_id)
    rng = np.random.default_rng(len(names))
    for stamp in (Time(sec=1_763_900_000, nanosec=999_999_999), Time(sec=-5, nanosec=0), Time(sec=0, nanosec=1)):
        values = rng.normal(size=len(names)) * 1e3
        values[::5] = np.nan if len(names) > 5 else values[::5]
        if stamp.nanosec % 2:  # both ways of writing the values: the numpy view and set_values (the node's)
            msg.values[:] = values
        else:
            msg.set_values(values.tolist())
        msg.set_stamp(stamp)
        assert len(msg.data()) == len(serialize_message(_message(names, frame_id, stamp, values)))  # padding bytes differ
        got = deserialize_message(msg.data(), JointState)
        assert list(got.name) == list(names) and got.header.stamp == stamp and got.header.frame_id == frame_id
        np.testing.assert_array_equal(np.asarray(got.position), values)


def _message(names: list[str], frame_id: str, stamp: Time, values: np.ndarray) -> JointState:
    m = JointState()
    m.header.stamp, m.header.frame_id = stamp, frame_id
    m.name, m.position = list(names), values.tolist()
    return m


def test_data_is_a_snapshot() -> None:
    msg = SerializedJointState(["a", "b"])
    msg.values[:] = [1.0, 2.0]
    first = msg.data()
    msg.values[:] = [3.0, 4.0]
    assert list(deserialize_message(first, JointState).position) == [1.0, 2.0]
    assert list(deserialize_message(msg.data(), JointState).position) == [3.0, 4.0]


def test_set_values_takes_exactly_one_value_per_name() -> None:
    msg = SerializedJointState(["a", "b"])
    msg.set_values([5, True])  # ints and flags are written as doubles, as in estimate_values
    assert list(msg.values) == [5.0, 1.0]
    for wrong in ([1.0], [1.0, 2.0, 3.0]):
        with pytest.raises(struct.error):
            msg.set_values(wrong)
    assert list(msg.values) == [5.0, 1.0]
