"""ROS 2 node ``estimator_node``: locomotion mode and gait phase from streamed segment angles.

Subscribes ``segment_angles`` (sensor-data QoS: best effort, keep last; receives from best-effort
and reliable publishers) as ``sensor_msgs/JointState`` (angles by name) or
``std_msgs/Float64MultiArray`` (``[right_thigh, left_thigh, right_shank, left_shank]``; a
JointState is taken serialised and read by ``io/cdr.py``), feeds
every message to the shared estimator pipeline (``estimator.Estimator``: gap check, optional
resampling, incremental matcher, supervisor; the same code as ``gait-estimator process``) and
publishes (reliable, keep last 10):

* ``mode`` (std_msgs/String: a library mode, ``stand`` or ``unknown``) and ``phase``
  (std_msgs/Float64, [0, 1), NaN unless walking) once the window is full (docs/controller.md);
* ``sse`` (std_msgs/Float64MultiArray, per-mode minimum SSE in deg^2, the layout names the
  modes) once the window is full;
* ``estimate`` (sensor_msgs/JointState as stamped key/values, see ``outputs.py``) for every
  estimate, ``header.stamp`` = the input stamp, ``ready`` = 0 while the window fills;
* ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) at 1 Hz;
* ``~/angles`` (std_msgs/Float64MultiArray), only while something subscribes: each sample as the
  matcher saw it, in blocks ~30 a second, for the dashboard (``angles_output.py``);
* ``~/profile`` (std_msgs/Float64MultiArray) at 1 Hz, only while something subscribes to it: the
  per-sample timing of the last second (see ``PROFILE_COLUMNS``; ``gait-estimator bench-node
  --profile``).

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

import gc
import math
import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import InvalidHandle, ParameterException
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, String
from std_srvs.srv import Trigger

from ..core.channels import Sample
from ..core.errors import GaitEstimatorError
from ..core.estimator import EstimatorConfig
from ..core.gait_stream import RESTART_BACK, RESTART_GAP, TEACH, TEACH_DONE, GaitStream
from ..core.kernels import KernelLibrary
from ..core.supervisor import Estimate
from ..io.cdr import CdrError, Stamp, read_joint_state
from ..io.library_io import save_library
from ..io.outputs import (
    ESTIMATE_TOPIC,
    INPUT_TOPIC,
    MODE_TOPIC,
    PHASE_TOPIC,
    SSE_TOPIC,
    estimate_names,
    estimate_values,
    sse_label,
)
from ..io.stream import ANGLE_MESSAGE_ONLY, MALFORMED, REASONS, AngleExtractor, SampleRejected
from .angles_output import AnglesOutput
from .diagnostics import (  # noqa: F401  (PROFILE_COLUMNS: re-exported for the bench-node client)
    DIAGNOSTICS_PERIOD_S,
    DIAGNOSTICS_TOPIC,
    PROFILE_COLUMNS,
    PROFILE_TOPIC,
    NodeDiagnostics,
    double_array,
)
from .executors import make_executor, spin
from .parameters import DEFAULTS, DESCRIPTIONS, NodeParameters, StartupError, one_line, set_priority, stamped_input  # noqa: F401
from .serialized import SerializedJointState
from .teach import LOG_PREFIX, TeachParameters

NODE_NAME = "estimator_node"
SAVE_LIBRARY_SERVICE = "~/save_library"
RESET_CALIBRATION_SERVICE = "~/reset_calibration"
WARN_THROTTLE_S = 2.0
"""Minimum wall time (s) between two warnings about dropped samples of the same reason."""
MAX_BATCH = 50
"""Most input messages handled per executor wake-up (see ``EstimatorNode._on_input``) under a
wait-set executor; ``main`` sets ``EstimatorNode.max_batch`` to 1 under the EventsExecutor."""
INPUT_QOS = QoSProfile(
    reliability=ReliabilityPolicy.BEST_EFFORT,
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    durability=DurabilityPolicy.VOLATILE,
)
"""Sensor-data QoS (best effort, keep last; matches best-effort and reliable publishers). The
depth is 100 rather than 5 because the matcher needs every sample: a short stall of the node
(0.43 s at 230 Hz) is caught up on instead of dropping samples."""
OUTPUT_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=10)
DIAGNOSTICS_QOS = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=10)


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
        try:
            library, config = self.parameters.declare(self._parameter_overrides)
            get = self.get_parameter
            self.input_type: str = get("input_type").value
            self.units: str = get("input_units").value
            self.stream = GaitStream(library, config, stamped=stamped_input(self.input_type),
                                     units=None if self.input_type == "imu" else self.units)
            self.imu: Any = None
            self._extract = AngleExtractor(tuple(get("joint_names").value), self.units)
            self._warned_at: dict[str, float] = {}
            self._suppressed: Counter = Counter()
            self.add_post_set_parameters_callback(self._parameters_set)  # called after those added below
            self.parameters.attach(self.stream)
            TeachParameters(self, self.stream)
        except (GaitEstimatorError, ValueError) as exc:
            self.destroy_node()
            raise StartupError(one_line(exc)) from None
        self.max_batch = MAX_BATCH
        """Input messages handled per callback (1 = only the executor's own; see _on_input)."""

        # No QoS event handlers on the outputs: each one costs executor time on every wake-up, and a
        # subscriber with incompatible QoS logs the problem itself.
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self._mode_pub = self.create_publisher(String, MODE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._phase_pub = self.create_publisher(Float64, PHASE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._sse_pub = self.create_publisher(Float64MultiArray, SSE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._estimate_pub = self.create_publisher(JointState, ESTIMATE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS, event_callbacks=quiet)
        self.diagnostics = NodeDiagnostics(self, self.create_publisher(
            Float64MultiArray, PROFILE_TOPIC, OUTPUT_QOS, event_callbacks=quiet))
        self._angles = AnglesOutput(self, OUTPUT_QOS)
        self._mode_msg = String()
        self._phase_msg = Float64()
        self.library_changed()
        self._handle = self._handle_joint_state if self.input_type == "joint_state" else self._handle_array
        self.imu = self._start_imu_input() if self.input_type == "imu" else None
        msg_type = JointState if self.input_type == "joint_state" else Float64MultiArray
        self._sub = self.imu.subscriptions[0] if self.imu is not None else self.create_subscription(
            msg_type, INPUT_TOPIC, self._on_input, INPUT_QOS,
            qos_overriding_options=QoSOverridingOptions.with_default_policies(),
            raw=msg_type is JointState,  # read from the CDR bytes (io/cdr.py): no message objects
        )
        self.input_topics = ", ".join(sub.topic_name for sub in (self.imu.subscriptions if self.imu else [self._sub]))
        self.create_service(Trigger, SAVE_LIBRARY_SERVICE, self._save_library)
        self.create_service(Trigger, RESET_CALIBRATION_SERVICE, self._reset_calibration)
        # Diagnostics describe the process (rates, processing time), so they run on the steady
        # clock: they keep coming while simulated time is paused.
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME))
        lib = self.stream.library
        self.get_logger().info(
            ("no kernel library (kernels: ''): diagnostics only until a mode is taught (teach_mode)" if lib is None else
             f"library '{lib.name}' ({len(lib)} modes: {', '.join(lib.mode_names)}; window "
             f"{self.stream.estimator.matcher.max_window} samples at {lib.sample_rate_hz:g} Hz) from {lib.path or '?'}")
            + f"; input {self.input_type} on {self.input_topics}" + (f" in {self.units}" if self.imu is None else "")
            + (f", joints {', '.join(self._extract.joint_names)}" if self.input_type == "joint_state" else "")
            + f"; options: {self.parameters.options_summary()}"
        )
        self.log_events()
        priority = get("thread_priority").value
        if priority:
            set_priority(self, priority)

    def _start_imu_input(self) -> Any:
        """``input_type: imu``: four sensor_msgs/Imu subscriptions (ros/imu_input.py)."""
        from .imu_input import ImuInput

        try:
            return ImuInput(self, INPUT_QOS)
        except (GaitEstimatorError, ParameterException) as exc:
            self.destroy_node()
            raise StartupError(one_line(exc)) from None

    def _parameters_set(self, params: list[Parameter]) -> None:
        if {p.name for p in params} & {"joint_names", "input_units"}:
            self.units = self.get_parameter("input_units").value
            self._extract = AngleExtractor(tuple(self.get_parameter("joint_names").value), self.units)
            self.stream.set_units(None if self.imu is not None else self.units)
        if self.imu is not None:  # a sensor restarts where the stream does
            self.imu.set_restart_back(self.stream.guard.restart_back_s)
        self.log_events()  # what a teach or library parameter did

    # -----------------------------------------------------------------------------------------
    # Services

    def _save_library(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/save_library``: write the library in use, with its taught modes and personalised
        kernels, to ``adapted_library_path``, and a learnt IMU calibration beside it (where the
        next start with that library looks for it)."""
        est, taught = self.stream.estimator, self.stream.taught
        if est is None or (est.adapter is None and not taught):
            response.success = False
            response.message = ("no library yet: teach a mode first (teach_mode)" if est is None else
                                "no taught modes, and personalisation is off (adapt_rate is 0): nothing to save")
            return response
        path = self.get_parameter("adapted_library_path").value or str(
            Path.home() / ".ros" / "gait_estimator" / f"{self.library.name}_adapted.yaml")
        try:
            Path(path).expanduser().parent.mkdir(parents=True, exist_ok=True)
            lib = est.adapted_library()
            out = save_library(lib, Path(path).expanduser())
        except (GaitEstimatorError, OSError, ValueError) as exc:
            response.success, response.message = False, f"{path}: {one_line(exc)}"
            return response
        strides = lib.provenance.get("adaptation", {}).get("accepted_strides", {})
        response.success = True
        response.message = f"wrote {out} ({len(lib)} modes: {', '.join(lib.mode_names)}" + (
            f"; taught: {', '.join(taught)}" if taught else "") + (
            "; strides adopted: " + ", ".join(f"{m} {n}" for m, n in strides.items()) if est.adapter else "") + ")" + (
            self.imu.save_beside(out, lib.name) if self.imu is not None else "")
        self.get_logger().info(response.message)
        return response

    def _reset_calibration(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/reset_calibration``: forget the learnt sensor offsets and cadence (after
        re-donning, or for another wearer)."""
        est, imu = self.stream.estimator, self.imu
        if est is None:  # no library yet: only the IMU input may have learnt something
            response.success = imu is not None
            response.message = "no library yet" + imu.reset_calibration() if imu else "no library yet: nothing calibrated"
        else:
            before, scale = est.sensor_offset_deg.copy(), est.cadence_scale
            est.reset_calibration()
            response.success = True
            response.message = ("sensor offsets reset to 0 (were " + ", ".join(f"{v:.2f}" for v in before) + " deg)"
                                + (f", learnt time scale {scale:.3f} forgotten" if math.isfinite(scale) else "")
                                + (imu.reset_calibration() if imu is not None else ""))
        self.get_logger().info(response.message)
        return response

    def library_changed(self) -> None:
        """The stream uses another estimator (library, options): outputs laid out for its modes."""
        est = self.stream.estimator
        names = est.mode_names if est is not None else []
        self._sse_msg = Float64MultiArray()
        self._sse_msg.layout.dim = [MultiArrayDimension(label=sse_label(names), size=len(names), stride=len(names))]
        # serialised once per library; every estimate patches its stamp and values (estimate_values)
        self._estimate_msg = SerializedJointState(estimate_names(names))

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

    def take_angles(self, angles_deg: Sample, stamp: TimeMsg | Stamp, t0: float, counted: bool = False) -> None:
        """A decoded sample to the stream, its estimate published; ``t0`` = callback start
        (perf_counter); ``counted``: already counted as received (``GaitStream.push``)."""
        stream = self.stream
        est = stream.estimator
        try:
            estimate = stream.push(stamp, angles_deg, counted)
        except SampleRejected as exc:
            self._warn(exc)
            return
        if estimate is not None:
            t1 = time.perf_counter()
            self._publish(estimate, stamp)
            self._angles.add(stamp, angles_deg, est.sensor_offset_deg)
            if stream.events:
                self.log_events()
            self.diagnostics.record(stamp, t0, t1, time.perf_counter())
        elif stream.events:
            self.log_events()

    def log_events(self) -> None:
        """Log what the stream reports: window restarts throttled per kind, like the warnings."""
        log = self.get_logger()
        for event in self.stream.take_events():
            kind, line = event.kind, event.line
            if kind in (RESTART_BACK, RESTART_GAP):
                more = self._throttled(kind)
                if more >= 0:
                    log.info(f"{line}: window restarted" + (f" ({more} more restarts since the last message)" if more else ""))
            elif kind in (TEACH, TEACH_DONE):
                if event.warn:  # rclpy fixes a call site's severity at its first call: one site per severity
                    log.warning(LOG_PREFIX + line)
                else:
                    log.info(LOG_PREFIX + line)
                if kind == TEACH_DONE:
                    self.library_changed()
                    self.set_parameters([Parameter("teach_mode", value="")])
            elif event.warn:
                log.warning(line)
            else:
                log.info(line)

    def _throttled(self, key: str) -> int:
        """-1: suppressed (the last line of ``key`` is less than WARN_THROTTLE_S old), else how
        many were suppressed since that line."""
        now = time.monotonic()
        last = self._warned_at.get(key)
        if last is not None and now - last < WARN_THROTTLE_S:
            self._suppressed[key] += 1
            return -1
        self._warned_at[key] = now
        return self._suppressed.pop(key, 0)

    def _publish(self, e: Estimate, stamp: TimeMsg | Stamp) -> None:
        """Publish one estimate; topics nobody listens to are skipped (a count query is far
        cheaper than a publish). ``estimate`` goes last: once it is out, everything is."""
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

    def reject(self, exc: SampleRejected, received: bool = True) -> None:
        """Count a dropped input (``received``: as a received one too) and warn (throttled)."""
        self.stream.reject(exc, received)
        self._warn(exc)

    def _warn(self, exc: SampleRejected) -> None:
        more = self._throttled(exc.reason)
        if more >= 0:
            self.get_logger().warn(
                (f"dropped sample on {self.input_topics}: " if self.imu is None else "dropped IMU input: ")
                + f"{exc.reason}: {exc}" + (f" ({more} more {exc.reason} dropped since the last warning)" if more else ""))

    # -----------------------------------------------------------------------------------------
    # State and diagnostics

    def diagnostics_status(self) -> DiagnosticStatus:
        """The node's status; rates and processing times cover the time since the previous call."""
        return self.diagnostics.status()

    def _publish_diagnostics(self) -> None:
        try:
            msg = DiagnosticArray()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.status = [self.diagnostics.status()]
            self._diag_pub.publish(msg)
            self.diagnostics.publish_profile()
        except (RuntimeError, InvalidHandle):
            if self.context.ok():
                raise  # (a timer event can still be dispatched after the context shut down)

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
        """Input messages seen so far (accepted + rejected)."""
        return self.stream.received

    @property
    def samples_accepted(self) -> int:
        """Input messages that went into the estimator."""
        return self.stream.accepted

    @property
    def rejected(self) -> dict[str, int]:
        """Dropped samples so far, by reason (every reason the input type can give listed)."""
        return self.stream.rejected(REASONS if self.imu is None else [r for r in REASONS if r not in ANGLE_MESSAGE_ONLY])

    @property
    def window_resets(self) -> int:
        """Window restarts caused by the input stream: gaps > max_gap_s and jumps back."""
        return self.stream.window_resets


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of ``estimator_node`` (``ros2 run gait_estimator estimator_node``).

    Returns 0 after SIGINT/SIGTERM or an external shutdown, 2 if it cannot start (an invalid
    parameter or an unreadable library: usage/input errors, as for the CLI).
    """
    # SIGINT/SIGTERM only ask the spin loop to stop: rclpy's own handler raises KeyboardInterrupt
    # inside whatever callback runs, which the EventsExecutor then logs as a fatal error. A second
    # signal gets the default action (a hung shutdown still ends).
    stop = threading.Event()

    def on_signal(signum: int, _frame: Any) -> None:
        stop.set()
        signal.signal(signum, signal.SIG_DFL)

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, on_signal)
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node: EstimatorNode | None = None
    executor: Executor | None = None
    code = 0
    try:
        node = EstimatorNode()
        kind = node.get_parameter("executor").value
        executor = make_executor(kind, node.context)
        if kind == "events":
            node.max_batch = 1  # one event per message already; see EstimatorNode._on_input
        gc.collect()
        gc.freeze()  # start-up objects stay out of later collections: shorter GC pauses
        spin(node, executor, stop)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except StartupError as exc:
        print(f"{NODE_NAME}: error: {exc}", file=sys.stderr)
        code = 2
    finally:
        if executor is not None:
            executor.shutdown(timeout_sec=1.0)
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
