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
from ..core.teach import TeachOptions
from ..io.cdr import stamp_to_ns
from .diagnostics import DIAGNOSTICS_TOPIC
from .teach import LOG_PREFIX
from .tool_node import ToolNode

DEFAULT_NODE = "/estimator_node"
MIN_STRIDES = TeachOptions().min_strides


INPUT_STOPPED_S = 5.0
"""No input sample for this long after some arrived while teaching: said once (a recording ended)."""


class InputWatch:
    """Says when a count of input samples (the node's ``samples_received``) stops growing."""

    def __init__(self) -> None:
        self._count: str | None = None
        self._since = 0.0
        self._grew = False
        self._said = False

    def stopped(self, count: str | None, now_s: float) -> bool:
        """True once when ``count`` grew before and has not for INPUT_STOPPED_S (again after it grows)."""
        if count != self._count:
            self._grew, self._said = self._count is not None, False
            self._count, self._since = count, now_s
            return False
        if self._grew and not self._said and now_s - self._since > INPUT_STOPPED_S:
            self._said = True
            return True
        return False


def progress(diag: dict[str, str]) -> str:
    """``6/10 strides; 4 not used: 2 duration, 2 shape`` from the node's diagnostics."""
    not_used = diag.get("teach_not_used", "")
    return f"{diag.get('teach_progress') or '?'} strides" + (f"; {not_used}" if not_used else "")


def fewer(diag: dict[str, str]) -> str:
    """`` (--strides 6)``: the good strides so far, when teaching could finish with them."""
    good = diag.get("teach_progress", "").split("/")[0]
    return f" (--strides {good})" if good.isdigit() and int(good) >= MIN_STRIDES else ""


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
        self.node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, 10)
        self.params = AsyncParameterClient(self.node, self.target)
        self._save_client: Any = None
        if timeout_s is not None and not self.params.wait_for_services(timeout_s):
            raise self.not_found(timeout_s, "answered")

    # -- callbacks

    def _on_log(self, msg: Log) -> None:
        stamp = stamp_to_ns(msg.stamp)
        if msg.name == self._logger_name and msg.msg.startswith(LOG_PREFIX) and stamp >= self._started:
            if self.on_log is not None:
                self.on_log(msg.msg[len(LOG_PREFIX):])

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        st = self.target_status(msg)
        if st is not None:
            self.diagnostics = st.values

    # -- calls

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
        ``max_s`` passed (then teaching is cancelled). When the input stops for INPUT_STOPPED_S
        (a recording ended, sensors off) ``on_log`` gets one line saying so and what to do."""
        before = int(self.latest_diagnostics().get("teach_completed", "0"))
        self.set(teach_strides=strides, teach_mode=mode)
        start = time.monotonic()
        input_watch = InputWatch()
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
            if input_watch.stopped(diag.get("samples_received"), time.monotonic()) and self.on_log is not None:
                self.on_log(f"{mode}: no input for {INPUT_STOPPED_S:g} s (the recording ended? sensors off?) at "
                            f"{progress(diag)}: play or walk on (the strides so far are kept), or Ctrl-C and "
                            f"teach fewer{fewer(diag)}")
            if max_s is not None and time.monotonic() - start > max_s:
                self.cancel()
                return False, (f"{mode} not taught within {max_s:g} s ({progress(diag)}): cancelled; walk steadily "
                               f"in that mode and run teach again, with a longer --max-time or fewer strides"
                               f"{fewer(diag)}")

    def cancel(self) -> None:
        self.set(teach_mode="")

    def save(self, path: str | None) -> str:
        """``~/save_library`` (to ``path`` when given: sets ``adapted_library_path`` first); returns
        the node's answer; a failure raises with it."""
        if path:
            self.set(adapted_library_path=path)
        if self._save_client is None:  # one client for the tool's life (the dashboard saves many times)
            self._save_client = self.node.create_client(Trigger, f"{self.target}/save_library")
        client = self._save_client
        if not client.wait_for_service(timeout_sec=5.0):
            raise GaitEstimatorError(f"{self.target}/save_library is not available")
        answer = self._wait(client.call_async(Trigger.Request()), "save_library", 30.0)
        if not answer.success:
            raise GaitEstimatorError(f"{self.target}/save_library: {answer.message}")
        return str(answer.message)

