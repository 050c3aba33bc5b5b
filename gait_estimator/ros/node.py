"""ROS 2 node ``estimator_node``: locomotion mode and gait phase from streamed segment angles.

Subscribes ``segment_angles`` (sensor-data QoS: best effort, keep last; receives from best-effort
and reliable publishers) as ``sensor_msgs/JointState`` (angles by name; taken serialised and read
by ``io/cdr.py``) or ``std_msgs/Float64MultiArray`` (``[right_thigh, left_thigh, right_shank,
left_shank]``), or four ``sensor_msgs/Imu`` topics (``imu_input.py``). The node decodes each
message, hands it to its ``GaitStream`` (``core/gait_stream.py``: stamp checks, the estimator,
teaching; the same object as ``gait-estimator process --as-node``) and publishes its estimates
(``outputs.py``), ``/diagnostics`` at 1 Hz and, while subscribed, ``~/profile``
(``diagnostics.py``).

Time comes from the input stamps (JointState ``header.stamp``); inputs without a stamp
(Float64MultiArray, or a zero JointState stamp) are stamped with the node clock on arrival, which
follows ``/clock`` under ``use_sim_time``. A stamp that is not after the previous one is a
reordered or duplicated sample (dropped), unless it jumps back by more than ``max_gap_s`` (1 s
while the gap check is off): then the publisher or its clock restarted, and the window restarts
with that sample (``stream_restarts`` in the diagnostics). Bad input is dropped, counted and
reported (throttled warning naming the problem) without touching the estimator state.
``main`` spins the node with the ``executor`` parameter's executor. Needs rclpy at import time.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from typing import Any

from builtin_interfaces.msg import Time as TimeMsg
from rclpy.exceptions import InvalidHandle, ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ..core.channels import Sample
from ..core.errors import GaitEstimatorError
from ..core.estimator import EstimatorConfig
from ..core.gait_stream import GaitStream, Output
from ..core.imu_pairing import IMU_REASONS
from ..core.kernels import KernelLibrary
from ..core.rejections import MALFORMED, REASONS, SampleRejected
from ..core.supervisor import Estimate
from ..io.cdr import CdrError, Stamp, read_joint_state
from ..io.outputs import INPUT_TOPIC
from ..io.stream import AngleExtractor
from .diagnostics import PROFILE_COLUMNS, NodeDiagnostics
from .executors import run
from .outputs import EstimateOutputs
from .parameters import DEFAULTS, DESCRIPTIONS, NodeParameters, StartupError, set_priority, stamped_input, startup_error
from .services import RESET_CALIBRATION_SERVICE, SAVE_LIBRARY_SERVICE, NodeServices
from .stream_log import StreamLog
from .teach import TeachParameters

__all__ = ["DEFAULTS", "DESCRIPTIONS", "NODE_NAME", "PROFILE_COLUMNS", "RESET_CALIBRATION_SERVICE",
           "SAVE_LIBRARY_SERVICE", "EstimatorNode", "StartupError", "main"]
NODE_NAME = "estimator_node"
MAX_BATCH = 50
"""Most input messages handled per executor wake-up (see ``EstimatorNode._on_input``) under a
wait-set executor; ``main`` sets ``EstimatorNode.max_batch`` to 1 under the EventsExecutor."""
INPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST, depth=100,
                       durability=DurabilityPolicy.VOLATILE)
"""Sensor-data QoS (best effort, keep last; matches best-effort and reliable publishers). The
depth is 100 rather than 5 because the matcher needs every sample: a short stall of the node
(0.43 s at 230 Hz) is caught up on instead of dropping samples."""


class EstimatorNode(Node):
    """The estimator pipeline on a stream of segment angles; see the module docstring.

    Args:
        node_name: ROS node name.
        **kwargs: Passed to ``rclpy.node.Node`` (``context``, ``namespace``,
            ``parameter_overrides``, ...).

    Raises:
        StartupError: An invalid parameter value (override or params file) or an unreadable
            kernel library; the message is one line.
    """

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.parameters = NodeParameters(self)
        get = self.get_parameter
        try:
            library, config = self.parameters.declare(self._parameter_overrides)
            self.input_type: str = get("input_type").value
            self.units: str = get("input_units").value
            self.stream = GaitStream(library, config, stamped=stamped_input(self.input_type),
                                     units=None if self.input_type == "imu" else self.units)
            self.imu: Any = None
            self._extract = AngleExtractor(tuple(get("joint_names").value), self.units)
            self._log = StreamLog(self.get_logger(), "dropped IMU input: ")
            self.add_post_set_parameters_callback(self._parameters_set)  # called after those added below
            self.parameters.attach(self.stream)
            TeachParameters(self, self.stream)
            if self.input_type == "imu":  # four sensor_msgs/Imu subscriptions (ros/imu_input.py)
                from .imu_input import ImuInput

                self.imu = ImuInput(self, INPUT_QOS)
        except (GaitEstimatorError, ParameterException, ValueError) as exc:
            self.destroy_node()
            raise startup_error(exc) from None
        self.max_batch = MAX_BATCH
        """Input messages handled per callback (1 = only the executor's own; see _on_input)."""
        self.outputs = EstimateOutputs(self)
        self.diagnostics = NodeDiagnostics(self)
        self.library_changed()
        if self.imu is None:
            msg_type = JointState if self.input_type == "joint_state" else Float64MultiArray
            self._handle = self._handle_joint_state if msg_type is JointState else self._handle_array
            self._sub = self.create_subscription(
                msg_type, INPUT_TOPIC, self._on_input, INPUT_QOS,
                qos_overriding_options=QoSOverridingOptions.with_default_policies(),
                raw=msg_type is JointState)  # read from the CDR bytes (io/cdr.py): no message objects
        self.input_topics = ", ".join(sub.topic_name for sub in (self.imu.subscriptions if self.imu else [self._sub]))
        self._log.source = "dropped IMU input: " if self.imu else f"dropped sample on {self.input_topics}: "
        NodeServices(self)
        lib = self.stream.library
        self.get_logger().info(
            ("no kernel library (kernels: ''): diagnostics only until a mode is taught (teach_mode)" if lib is None else
             f"library '{lib.name}' ({len(lib)} modes: {', '.join(lib.mode_names)}; window "
             f"{self.stream.estimator.matcher.max_window} samples at {lib.sample_rate_hz:g} Hz) from {lib.path or '?'}")
            + f"; input {self.input_type} on {self.input_topics}" + (f" in {self.units}" if self.imu is None else "")
            + (f", joints {', '.join(self._extract.joint_names)}" if self.input_type == "joint_state" else "")
            + f"; options: {self.parameters.options_summary()}")
        self.log_events()
        if get("thread_priority").value:
            set_priority(self, get("thread_priority").value)

    def _parameters_set(self, params: list[Parameter]) -> None:
        if {p.name for p in params} & {"joint_names", "input_units"}:
            self.units = self.get_parameter("input_units").value
            self._extract = AngleExtractor(tuple(self.get_parameter("joint_names").value), self.units)
            self.stream.set_units(None if self.imu is not None else self.units)
        self.log_events()  # what a teach or library parameter did

    def library_changed(self) -> None:
        """The stream uses another estimator (library, options): outputs laid out for its modes."""
        est = self.stream.estimator
        self.outputs.set_modes(est.mode_names if est is not None else [])

    # -----------------------------------------------------------------------------------------
    # Input

    def _on_input(self, msg: JointState | Float64MultiArray) -> None:
        """Subscription callback: handle ``msg``, then the messages already queued behind it.

        Taking the queued messages here, up to ``max_batch`` per wake-up, instead of returning to
        the executor for each one keeps a wait-set executor's per-wake-up cost (hundreds of
        microseconds in rclpy's SingleThreadedExecutor) from limiting the input rate; in order,
        one estimator update each. Not under the EventsExecutor (``max_batch`` 1): it queues one
        event per message, and the events of messages taken here would pile up in its queue
        (native memory growing with the input rate) and then each cost a take that finds nothing.
        """
        try:
            handle = self._handle
            handle(msg)
            sub = self._sub
            for _ in range(self.max_batch - 1):
                with sub.handle:
                    taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is None:
                    return
                handle(taken[0])
        except (RuntimeError, InvalidHandle):
            if self.context.ok():
                raise
            # an external shutdown (rclpy.shutdown) invalidated the context while we were
            # publishing or taking: nothing left to do.

    def _handle_joint_state(self, msg: bytes | JointState) -> None:
        """One JointState sample, serialised (as the subscription delivers it) or not: angles by
        name, time from ``header.stamp``."""
        t0 = time.perf_counter()
        if isinstance(msg, bytes):
            try:
                stamp, names, positions = read_joint_state(msg)
            except CdrError as exc:  # not plain CDR: the middleware's deserialiser reads any encoding
                try:
                    msg = deserialize_message(msg, JointState)
                except Exception:  # whatever rclpy raises for undecodable bytes
                    self.reject(SampleRejected(MALFORMED, f"cannot decode the JointState ({exc})"))
                    return
        if not isinstance(msg, bytes):
            stamp, names, positions = msg.header.stamp, msg.name, msg.position
        if stamp.sec == 0 and stamp.nanosec == 0:
            stamp = self.get_clock().now().to_msg()
        try:
            angles = self._extract.named(names, positions)
        except SampleRejected as exc:
            self.reject(exc)
            return
        self.take_angles(angles, stamp, t0)

    def _handle_array(self, msg: Float64MultiArray) -> None:
        """One Float64MultiArray sample; stamped with the node clock on arrival."""
        t0 = time.perf_counter()
        stamp = self.get_clock().now().to_msg()
        try:
            angles = self._extract.array(msg.data)
        except SampleRejected as exc:
            self.reject(exc)
            return
        self.take_angles(angles, stamp, t0)

    def take_angles(self, angles_deg: Sample, stamp: TimeMsg | Stamp, t0: float) -> None:
        """A decoded sample to the stream, its estimate published; ``t0`` = callback start."""
        try:
            estimate = self.stream.push(stamp, angles_deg)
        except SampleRejected as exc:
            self._log.rejected(exc)
            return
        self._publish(stamp, angles_deg, estimate, t0)

    def publish_outputs(self, outputs: list[Output], t0: float) -> None:
        """What ``GaitStream.push_imu`` gave: dropped inputs logged, estimates published."""
        for out in outputs:
            if isinstance(out, SampleRejected):
                self._log.rejected(out)
            else:
                self._publish(*out, t0)
        if self.stream.events:
            self.log_events()

    def _publish(self, stamp: Any, angles_deg: Sample, estimate: Estimate | None, t0: float) -> None:
        if estimate is not None:
            t1 = time.perf_counter()
            self.outputs.publish(estimate, stamp)
            self.outputs.angles.add(stamp, angles_deg, self.stream.estimator.sensor_offset_deg)
            self.diagnostics.record(stamp, t0, t1, time.perf_counter())
        if self.stream.events:
            self.log_events()

    def reject(self, exc: SampleRejected) -> None:
        """Count a dropped input and warn (throttled)."""
        self.stream.reject(exc)
        self._log.rejected(exc)

    def log_events(self) -> None:
        """Log what the stream reports; when teaching ended, lay the outputs out for the new
        library and set ``teach_mode`` back to ''."""
        events = self.stream.take_events()
        if self._log.events(self.imu.handle(events) if self.imu is not None else events):
            self.library_changed()
            self.set_parameters([Parameter("teach_mode", value="")])

    # -----------------------------------------------------------------------------------------
    # State and diagnostics

    @property
    def library(self) -> KernelLibrary:
        """The kernel library in use."""
        lib = self.stream.library
        assert lib is not None
        return lib

    @property
    def config(self) -> EstimatorConfig:
        """The estimator options in use."""
        return self.stream.config

    @property
    def ready(self) -> bool:
        """True while the matcher window is full (mode/phase/sse are being published)."""
        return self.stream.estimator is not None and self.stream.estimator.matcher.ready

    @property
    def samples_received(self) -> int:
        """Inputs seen so far, accepted + rejected (IMU input: paired samples and dropped messages)."""
        return self.stream.received

    @property
    def samples_accepted(self) -> int:
        """Inputs that went into the estimator (IMU input: paired samples, the calibration's too)."""
        return self.stream.accepted

    @property
    def rejected(self) -> dict[str, int]:
        """Dropped samples so far, by reason (every reason the input type can give listed)."""
        return self.stream.rejected(REASONS if self.imu is None else IMU_REASONS)

    @property
    def window_resets(self) -> int:
        """Window restarts caused by the input stream: gaps > max_gap_s and jumps back."""
        return self.stream.window_resets


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``estimator_node`` (``ros2 run gait_estimator estimator_node``): 0 after
    SIGINT/SIGTERM or an external shutdown, 2 if it cannot start (an invalid parameter or an
    unreadable library: usage/input errors, as for the CLI)."""
    return run(EstimatorNode, NODE_NAME, args)


if __name__ == "__main__":
    sys.exit(main())
