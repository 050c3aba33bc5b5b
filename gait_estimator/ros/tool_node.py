"""The small ROS node of a command that talks to one running ``estimator_node`` (``gait-estimator
teach``, ``watch``): its own context, node and executor, without rclpy's signal handlers (Ctrl-C
reaches the command). It uses the ROS environment it runs in (``ROS_DOMAIN_ID``, discovery range),
as the ros2 CLI would, unless given a domain ID.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import NamedTuple

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..core.errors import GaitEstimatorError
from .node_process import Closes, spin_executor_until

LEVELS = ("OK", "WARN", "ERROR", "STALE")
"""diagnostic_msgs/DiagnosticStatus levels 0..3."""


class TargetStatus(NamedTuple):
    """The target's ``DiagnosticStatus``: level name (LEVELS), message, key/values; and when it came
    (``time.monotonic()``)."""

    level: str
    message: str
    values: dict[str, str]
    at: float


class ToolNode(Closes):
    """A command's ROS node aimed at the estimator node ``target``.

    Args:
        name: This node's name.
        target: Name of the estimator node (a leading ``/`` is added if missing).
        domain_id: ROS domain (None: ``ROS_DOMAIN_ID`` of the environment, else 0).
    """

    def __init__(self, name: str, target: str, domain_id: int | None) -> None:
        self.target = target if target.startswith("/") else "/" + target
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id, signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node(name, context=self.context, start_parameter_services=False)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def target_status(self, msg: DiagnosticArray) -> TargetStatus | None:
        """The target's status in a ``/diagnostics`` message, or None."""
        st = next((st for st in msg.status if st.name.startswith(self.target + ": ")), None)
        if st is None:
            return None
        level = st.level if isinstance(st.level, int) else int.from_bytes(st.level, "little")
        return TargetStatus(LEVELS[level] if level < len(LEVELS) else str(level), st.message,
                            {kv.key: kv.value for kv in st.values}, time.monotonic())

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Take messages until ``predicate()`` is true (True) or ``timeout_s`` passes (False)."""
        return spin_executor_until(self.executor, predicate, timeout_s, step_s=0.1)

    def not_found(self, timeout_s: float, verb: str = "") -> GaitEstimatorError:
        """Close, and the one-line error for a target that did not show (``verb``, e.g.
        ``answered``) within ``timeout_s``."""
        domain = self.context.get_domain_id()
        self.close()
        what = " ".join(x for x in (f"no estimator node {self.target}", verb, f"within {timeout_s:g} s") if x)
        return GaitEstimatorError(f"{what} on ROS_DOMAIN_ID={domain} (is it running, on this domain and discovery "
                                  "range? --node NAME, --domain-id ID)")

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
