"""The node's optional ``~/angles`` output, for the dashboard: every accepted sample's stamp and
the four angles as the matcher saw them (degrees, the learnt sensor offsets removed), sent in
blocks about ``PERIOD_S`` apart. Rows are kept only while something subscribes (asked once a
block); otherwise a sample costs the node one clock read."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

ANGLES_TOPIC = "~/angles"
ANGLES_LABEL = "stamp_s,right_thigh,left_thigh,right_shank,left_shank"
"""``layout.dim[1].label``: per row, the input stamp (s since 1970), then the angles (deg) in CHANNELS order."""
PERIOD_S = 1.0 / 30.0
MAX_ROWS = 1000


class AnglesOutput:
    """``~/angles`` of ``node`` (std_msgs/Float64MultiArray, rows x 5, row-major), published with
    ``qos`` and QoS ``events`` those of the node's other outputs."""

    def __init__(self, node: Node, qos: QoSProfile, events: PublisherEventCallbacks) -> None:
        self._pub = node.create_publisher(Float64MultiArray, ANGLES_TOPIC, qos, event_callbacks=events)
        self._msg = Float64MultiArray()
        self._rows: list[float] = []
        self._due = 0.0
        self._listening = False  # a subscriber at the last block's end: rows are kept for the next

    def add(self, stamp: Any, angles_deg: Any, offset_deg: np.ndarray) -> None:
        """One sample (``stamp``: sec/nanosec; ``angles_deg``: 4 values, CHANNELS order)."""
        rows = self._rows
        if self._listening:
            rows.append(stamp.sec + stamp.nanosec * 1e-9)
            rows.extend(float(x) - o for x, o in zip(angles_deg, offset_deg.tolist(), strict=True))
        now = time.monotonic()
        if now >= self._due or len(rows) >= 5 * MAX_ROWS:
            self._due = now + PERIOD_S
            if rows:
                n = len(rows) // 5
                self._msg.layout.dim = [MultiArrayDimension(label="samples", size=n, stride=5 * n),
                                        MultiArrayDimension(label=ANGLES_LABEL, size=5, stride=5)]
                self._msg.data = rows
                self._pub.publish(self._msg)
                self._rows = []
            self._listening = self._pub.get_subscription_count() > 0
