"""What ``estimator_node`` publishes (reliable, keep last 10): the topics of ``io/outputs.py``
(docs/node.md, "Topics"); ``~/angles`` (``angles_output.py``) and ``~/profile`` (diagnostics.py
``PROFILE_COLUMNS``) only while something subscribes. Topics nobody listens to are skipped (a
count query is far cheaper than a publish).
"""

from __future__ import annotations

import array
from collections.abc import Sequence
from typing import Any

import numpy as np
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, String

from ..core.supervisor import Estimate
from ..io.outputs import ESTIMATE_TOPIC, MODE_TOPIC, PHASE_TOPIC, SSE_TOPIC, estimate_names, estimate_values, sse_label
from .angles_output import AnglesOutput
from .serialized import SerializedJointState

OUTPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=10)
QUIET = PublisherEventCallbacks(use_default_callbacks=False)
"""No QoS event handlers on the outputs: each one costs executor time on every wake-up, and a
subscriber with incompatible QoS logs the problem itself."""


def double_array(values: np.ndarray) -> array.array:
    """float64 numpy -> array('d') without a per-element Python loop (the fast message setter)."""
    out = array.array("d")
    out.frombytes(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return out


class EstimateOutputs:
    """The publishers of ``node``'s estimates; ``set_modes`` lays them out for a library."""

    def __init__(self, node: Node) -> None:
        self._mode_pub = node.create_publisher(String, MODE_TOPIC, OUTPUT_QOS, event_callbacks=QUIET)
        self._phase_pub = node.create_publisher(Float64, PHASE_TOPIC, OUTPUT_QOS, event_callbacks=QUIET)
        self._sse_pub = node.create_publisher(Float64MultiArray, SSE_TOPIC, OUTPUT_QOS, event_callbacks=QUIET)
        self._estimate_pub = node.create_publisher(JointState, ESTIMATE_TOPIC, OUTPUT_QOS, event_callbacks=QUIET)
        self.angles = AnglesOutput(node, OUTPUT_QOS, QUIET)
        self._mode_msg = String()
        self._phase_msg = Float64()
        self.set_modes([])

    def set_modes(self, names: Sequence[str]) -> None:
        """Another library (``names``: its modes)."""
        self._sse_msg = Float64MultiArray()
        self._sse_msg.layout.dim = [MultiArrayDimension(label=sse_label(names), size=len(names), stride=len(names))]
        # serialised once per library; every estimate patches its stamp and values (estimate_values)
        self._estimate_msg = SerializedJointState(estimate_names(names))

    def publish(self, e: Estimate, stamp: Any) -> None:
        """Publish one estimate. ``estimate`` goes last: once it is out, everything is."""
        if e.ready:
            if self._mode_pub.get_subscription_count():
                self._mode_msg.data = e.mode
                self._mode_pub.publish(self._mode_msg)
            if self._phase_pub.get_subscription_count():
                self._phase_msg.data = e.phase
                self._phase_pub.publish(self._phase_msg)
            if self._sse_pub.get_subscription_count():
                self._sse_msg.data = double_array(e.sse)
                self._sse_pub.publish(self._sse_msg)
        if self._estimate_pub.get_subscription_count():
            msg = self._estimate_msg
            msg.set_stamp(stamp)
            msg.set_values(estimate_values(e))
            self._estimate_pub.publish(msg.data())
