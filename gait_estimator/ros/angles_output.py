"""The node's optional ``~/angles`` output, for the dashboard: per accepted sample, its stamp and
the four angles as the matcher saw them (degrees, the learnt sensor offsets removed). Published
only while something subscribes to it (a count query per sample otherwise)."""

from __future__ import annotations

from typing import Any

import numpy as np
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

ANGLES_TOPIC = "~/angles"
ANGLES_LABEL = "stamp_s,right_thigh,left_thigh,right_shank,left_shank"
"""``layout.dim[0].label``: the input stamp (s since 1970), then the angles (deg) in CHANNELS order."""


class AnglesOutput:
    """``~/angles`` of ``node`` (std_msgs/Float64MultiArray, 5 values a message)."""

    def __init__(self, node: Node, qos: QoSProfile) -> None:
        self._pub = node.create_publisher(Float64MultiArray, ANGLES_TOPIC, qos,
                                          event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))
        self._msg = Float64MultiArray()
        self._msg.layout.dim = [MultiArrayDimension(label=ANGLES_LABEL, size=5, stride=5)]

    def publish(self, stamp: Any, angles_deg: Any, offset_deg: np.ndarray) -> None:
        """One sample (``stamp``: sec/nanosec; ``angles_deg``: 4 values, CHANNELS order), if anyone listens."""
        if self._pub.get_subscription_count():
            self._msg.data = [stamp.sec + stamp.nanosec * 1e-9,
                              *(float(x) - o for x, o in zip(angles_deg, offset_deg.tolist(), strict=True))]
            self._pub.publish(self._msg)
