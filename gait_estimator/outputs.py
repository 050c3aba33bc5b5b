"""Names and layouts of the estimator's outputs, ROS-free.

The live node (rclpy messages) and the bag writer (rosbags messages) both build their messages
from these, so a recorded result is identical to what the node publishes.

Topics (relative names, so namespaces and remapping apply):

``mode``, ``phase`` and ``sse`` are published once the matcher is ready, ``estimate`` for every
estimate (with ``ready`` = 0 while the window fills):

* ``mode``  std_msgs/String: name of the estimated mode;
* ``phase`` std_msgs/Float64: gait phase in [0, 1), 0 = right heel strike;
* ``sse``   std_msgs/Float64MultiArray: per-mode minimum SSE (deg^2), in library order;
  ``layout.dim[0]`` = {label: ``SSE_LABEL_PREFIX`` + comma-separated mode names, size: M, stride: M};
* ``estimate`` sensor_msgs/JointState used as stamped named values: ``header.stamp`` = the input
  sample's stamp, ``name[k]``/``position[k]`` = key/value (see ``estimate_values``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .matcher import StepResult

INPUT_TOPIC = "segment_angles"
MODE_TOPIC = "mode"
PHASE_TOPIC = "phase"
SSE_TOPIC = "sse"
ESTIMATE_TOPIC = "estimate"
SSE_LABEL_PREFIX = "modes:"


def sse_label(mode_names: Sequence[str]) -> str:
    """``layout.dim[0].label`` of the ``sse`` message: ``modes:Slow,Med,...``."""
    return SSE_LABEL_PREFIX + ",".join(mode_names)


def mode_names_from_sse_label(label: str) -> list[str]:
    if not label.startswith(SSE_LABEL_PREFIX):
        raise ValueError(f"not an sse layout label: {label!r}")
    return label[len(SSE_LABEL_PREFIX) :].split(",")


def estimate_names(mode_names: Sequence[str]) -> list[str]:
    """Keys of the ``estimate`` message (JointState ``name``), fixed for a library.

    In order: ``mode_index`` (index into the library's modes), ``phase`` ([0, 1)), ``ready``
    (1.0 or 0.0), then ``sse/<mode>`` (deg^2) and ``phase/<mode>`` for every mode in library order.
    """
    return ["mode_index", "phase", "ready", *(f"sse/{m}" for m in mode_names), *(f"phase/{m}" for m in mode_names)]


def estimate_array(result: StepResult) -> np.ndarray:
    """Values of the ``estimate`` message (JointState ``position``), float64 (3 + 2M,), in the
    order of ``estimate_names``; built without a Python loop over modes (the node's hot path)."""
    head = np.array([result.mode_index, result.phase, 1.0 if result.ready else 0.0], dtype=np.float64)
    return np.concatenate((head, np.asarray(result.sse, dtype=np.float64), np.asarray(result.phases, dtype=np.float64)))


def estimate_values(result: StepResult, mode_names: Sequence[str]) -> tuple[list[str], list[float]]:
    """Key/value pairs of the ``estimate`` message (JointState ``name``/``position``).

    Keys, in order: ``mode_index`` (index into the library's modes), ``phase`` ([0, 1)),
    ``ready`` (1.0 or 0.0), then ``sse/<mode>`` (deg^2) and ``phase/<mode>`` for every mode in
    library order.
    """
    return estimate_names(mode_names), estimate_array(result).tolist()
