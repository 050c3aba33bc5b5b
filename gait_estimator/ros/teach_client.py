"""Teaching a running ``estimator_node`` from another process (``gait-estimator teach``).

``TeachClient`` finds the node by name, sets ``teach_strides`` and ``teach_mode`` through its
parameter service, follows the teaching in the node's log (``/rosout``, lines starting with
``teach:``) and diagnostics (``teach_completed``, ``teach_last_result``), and calls
``~/save_library``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import Log
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from std_srvs.srv import Trigger

from ..core.errors import GaitEstimatorError
from .node_client import spin_executor_until
from .teach import LOG_PREFIX
from .tool_node import ToolNode

DEFAULT_NODE = "/estimator_node"


class TeachClient(ToolNode):
    """A small ROS node talking to one ``estimator_node``.

    Args:
        node: Fully qualified name of the estimator node (e.g. ``/estimator_node``).
        domain_id: ROS domain (None: ``ROS_DOMAIN_ID`` of the environment, else 0).
        timeout_s: How long to wait for the node's parameter services (None: do not wait; the
            dashboard follows a node that may start later).
        name: This client's node name.

    Raises:
        GaitEstimatorError: No node of that name answered within ``timeout_s`` (one line).
    """

    def __init__(self, node: str = DEFAULT_NODE, domain_id: int | None = None, timeout_s: float | None = 5.0,
                 name: str = "gait_estimator_teach") -> None:
        super().__init__(name, node, domain_id)  # Ctrl-C reaches the command: it cancels
        self.diagnostics: dict[str, str] | None = None
        self.on_log: Callable[[str], None] | None = None
        self._started = self.node.get_clock().now().nanoseconds
        self._logger_name = self.target.lstrip("/").replace("/", ".")
        self.node.create_subscription(Log, "/rosout", self._on_log, 1000)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 10)
        self.params = AsyncParameterClient(self.node, self.target)
        if timeout_s is not None and not self.params.wait_for_services(timeout_s):
            raise self.not_found(timeout_s, "answered")

    # -- callbacks

    def _on_log(self, msg: Log) -> None:
        stamp = msg.stamp.sec * 1_000_000_000 + msg.stamp.nanosec
        if msg.name == self._logger_name and msg.msg.startswith(LOG_PREFIX) and stamp >= self._started:
            if self.on_log is not None:
                self.on_log(msg.msg[len(LOG_PREFIX):])

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        st = self.target_status(msg)
        if st is not None:
            self.diagnostics = {kv.key: kv.value for kv in st.values}

    # -- calls

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        return spin_executor_until(self.executor, predicate, timeout_s, step_s=0.1)

    def _wait(self, future: Any, what: str, timeout_s: float = 5.0) -> Any:
        if not self.spin_until(future.done, timeout_s):
            raise GaitEstimatorError(f"{self.target} did not answer {what} within {timeout_s:g} s")
        return future.result()

    def set(self, **values: Any) -> None:
        """Set parameters of the node, in the order given; a refusal raises with the node's reason."""
        params = [Parameter(k, value=v) for k, v in values.items()]
        results = self._wait(self.params.set_parameters(params), "the parameter change").results
        for p, r in zip(params, results, strict=True):
            if not r.successful:
                raise GaitEstimatorError(f"{self.target} refused {p.name}: {r.reason}")

    def get(self, name: str) -> Any:
        (value,) = self._wait(self.params.get_parameters([name]), f"for {name}").values
        return parameter_value_to_python(value)

    def latest_diagnostics(self, timeout_s: float = 3.0) -> dict[str, str]:
        """The node's next diagnostics report (they come at 1 Hz)."""
        self.diagnostics = None
        if not self.spin_until(lambda: self.diagnostics is not None, timeout_s):
            raise GaitEstimatorError(f"no diagnostics from {self.target} within {timeout_s:g} s")
        assert self.diagnostics is not None
        return self.diagnostics

    def teach(self, mode: str, strides: int, poll_s: float = 1.0, max_s: float | None = None) -> tuple[bool, str]:
        """Teach ``mode`` from ``strides`` good strides; returns (done, the new kernel's summary or
        why not). Returns False when ``teach_mode`` was cleared by someone else (cancelled) or
        ``max_s`` passed (then teaching is cancelled)."""
        before = int(self.latest_diagnostics().get("teach_completed", "0"))
        self.set(teach_strides=strides, teach_mode=mode)
        start = time.monotonic()
        while True:
            self.spin_until(lambda: False, poll_s)
            diag = self.diagnostics or {}
            if int(diag.get("teach_completed", before)) > before:
                return True, diag.get("teach_last_result", "")
            if self.get("teach_mode") != mode:
                diag = self.latest_diagnostics()
                if int(diag.get("teach_completed", before)) > before:
                    return True, diag.get("teach_last_result", "")
                return False, f"teach_mode of {self.target} was changed: teaching {mode} cancelled"
            if max_s is not None and time.monotonic() - start > max_s:
                self.cancel()
                return False, f"{mode} not taught within {max_s:g} s: cancelled"

    def cancel(self) -> None:
        self.set(teach_mode="")

    def save(self, path: str | None) -> str:
        """``~/save_library`` (to ``path`` when given: sets ``adapted_library_path`` first); returns
        the node's answer; a failure raises with it."""
        if path:
            self.set(adapted_library_path=path)
        client = self.node.create_client(Trigger, f"{self.target}/save_library")
        if not client.wait_for_service(timeout_sec=5.0):
            raise GaitEstimatorError(f"{self.target}/save_library is not available")
        answer = self._wait(client.call_async(Trigger.Request()), "save_library", 30.0)
        if not answer.success:
            raise GaitEstimatorError(f"{self.target}/save_library: {answer.message}")
        return str(answer.message)

