"""Watching a running ``estimator_node`` from another process (``gait-estimator watch``): its
``mode`` and ``phase`` topics and its diagnostics, as ``ros2 topic echo`` would show them, for
installs without the ros2 CLI (``pip install '.[ros]'``).
"""

from __future__ import annotations

from dataclasses import dataclass

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.exceptions import NameValidationException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64, String

from ..core.errors import GaitEstimatorError
from .diagnostics import DIAGNOSTICS_TOPIC
from .tool_node import TargetStatus, ToolNode


@dataclass
class Seen:
    """The latest of what the node published (None/empty: nothing yet)."""

    mode: str | None = None
    phase: float | None = None
    estimates: int = 0
    """``phase`` messages received (one per estimate once the window is full)."""
    status: TargetStatus | None = None
    """The node's last diagnostics (they come at 1 Hz)."""


class WatchClient(ToolNode):
    """A small ROS node subscribed to one ``estimator_node``'s outputs.

    Args:
        node: Fully qualified name of the estimator node (e.g. ``/estimator_node``); its
            ``mode`` and ``phase`` topics are taken in its namespace (the node's defaults; a
            remapping on the node is not followed).
        domain_id: ROS domain (None: ``ROS_DOMAIN_ID`` of the environment, else 0).
        timeout_s: How long to wait for the node to appear in the graph.

    Raises:
        GaitEstimatorError: An invalid node name, or no node of that name within ``timeout_s``
            (one line).
    """

    def __init__(self, node: str = "/estimator_node", domain_id: int | None = None, timeout_s: float = 5.0) -> None:
        super().__init__("gait_estimator_watch", node, domain_id)
        namespace = self.target.rsplit("/", 1)[0]
        self.seen = Seen()
        display = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)  # no acks to the leg's computer
        try:
            self.node.create_subscription(String, f"{namespace}/mode", self._on_mode, display)
            self.node.create_subscription(Float64, f"{namespace}/phase", self._on_phase, display)
        except NameValidationException as exc:
            self.close()
            raise GaitEstimatorError(f"--node {node}: not a valid node name ({str(exc).splitlines()[0]})") from None
        self.node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, 10)
        if not self.spin_until(lambda: self.target in self.node.get_fully_qualified_node_names(), timeout_s):
            raise self.not_found(timeout_s)

    def _on_mode(self, msg: String) -> None:
        self.seen.mode = msg.data

    def _on_phase(self, msg: Float64) -> None:
        self.seen.phase = msg.data
        self.seen.estimates += 1

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        self.seen.status = self.target_status(msg) or self.seen.status
