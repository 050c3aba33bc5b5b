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
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import InvalidHandle, ParameterException
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.qos_overriding_options import QoSOverridingOptions
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray, MultiArrayDimension, String
from std_srvs.srv import Trigger

from ..core.channels import Sample
from ..core.errors import GaitEstimatorError
from ..core.estimator import Estimator, EstimatorConfig
from ..core.kernels import KernelLibrary
from ..core.supervisor import Estimate
from ..core.units import UnitsCheck
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
from ..io.stream import ANGLE_MESSAGE_ONLY, MALFORMED, REASONS, AngleExtractor, SampleRejected, StreamGuard, restart_threshold
from .angles_output import AnglesOutput
from .diagnostics import (  # noqa: F401  (PROFILE_COLUMNS: re-exported for the bench-node client)
    DIAGNOSTICS_PERIOD_S,
    DIAGNOSTICS_TOPIC,
    MAX_PROFILE_ROWS,
    PROFILE_COLUMNS,
    PROFILE_TOPIC,
    NodeDiagnostics,
    double_array,
)
from .executors import make_executor, spin
from .parameters import DEFAULTS, DESCRIPTIONS, NodeParameters, StartupError, one_line  # noqa: F401
from .serialized import SerializedJointState

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


class EstimatorNode(NodeParameters, NodeDiagnostics, Node):
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
        self._declare_parameters()  # raises StartupError

        self._joint_names: tuple[str, ...] = tuple(self.get_parameter("joint_names").value)
        self._units: str = self.get_parameter("input_units").value
        self._input_type: str = self.get_parameter("input_type").value
        self._extract = AngleExtractor(self._joint_names, self._units)
        self._units_check = UnitsCheck()  # angles that cannot be degrees once converted (input_units wrong)
        # Stamp checks, jump-back restarts and rejection counts; gaps (forward) are the Estimator's.
        self._guard = StreamGuard(max_gap_s=0.0, restart_back_s=restart_threshold(self._config.max_gap_s))
        self._resets_before = 0  # gap restarts of estimators replaced by parameter changes
        self._epoch_sec: int | None = None

        self._received = 0
        self._warned_at: dict[str, float] = {}
        self._suppressed: Counter = Counter()
        self._proc_sum = 0.0
        self._proc_max = 0.0
        self._proc_count = 0
        self._period_received = 0
        self._period_rejected = 0
        self._period_first_stamp: float | None = None
        self._period_last_stamp: float | None = None
        self._period_accepted = 0
        self._period_start = time.monotonic()
        self.max_batch = MAX_BATCH
        """Input messages handled per callback (1 = only the executor's own; see _on_input)."""
        self._profile: list[tuple[int, int, int, int, int, int]] | None = None  # rows while subscribed

        # No QoS event handlers on the outputs: each one costs executor time on every wake-up, and a
        # subscriber with incompatible QoS logs the problem itself.
        quiet = PublisherEventCallbacks(use_default_callbacks=False)
        self._mode_pub = self.create_publisher(String, MODE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._phase_pub = self.create_publisher(Float64, PHASE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._sse_pub = self.create_publisher(Float64MultiArray, SSE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._estimate_pub = self.create_publisher(JointState, ESTIMATE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS, event_callbacks=quiet)
        self._profile_pub = self.create_publisher(Float64MultiArray, PROFILE_TOPIC, OUTPUT_QOS, event_callbacks=quiet)
        self._angles = AnglesOutput(self, OUTPUT_QOS)
        self._mode_msg = String()
        self._phase_msg = Float64()
        if self._input_type == "joint_state":
            msg_type, self._handle = JointState, self._handle_joint_state
        else:
            msg_type, self._handle = Float64MultiArray, self._handle_array
        self._imu = self._start_imu_input() if self._input_type == "imu" else None
        self._sub = self._imu.subscriptions[0] if self._imu is not None else self.create_subscription(
            msg_type,
            INPUT_TOPIC,
            self._on_input,
            INPUT_QOS,
            qos_overriding_options=QoSOverridingOptions.with_default_policies(),
            raw=msg_type is JointState,  # read from the CDR bytes (io/cdr.py): no message objects
        )
        subs = self._imu.subscriptions if self._imu is not None else [self._sub]
        self._input_topics = ", ".join(sub.topic_name for sub in subs)
        self.add_post_set_parameters_callback(self._apply_parameters)
        self._save_srv = self.create_service(Trigger, SAVE_LIBRARY_SERVICE, self._save_library)
        self._calib_srv = self.create_service(Trigger, RESET_CALIBRATION_SERVICE, self._reset_calibration)
        # Diagnostics describe the process (rates, processing time), so they run on the steady
        # clock: they keep coming while simulated time is paused.
        self._diag_timer = self.create_timer(
            DIAGNOSTICS_PERIOD_S, self._publish_diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME)
        )
        lib = self._library
        self.get_logger().info(
            ("no kernel library (kernels: ''): diagnostics only until a mode is taught (teach_mode)" if lib is None else
             f"library '{lib.name}' ({len(lib)} modes: {', '.join(lib.mode_names)}; window "
             f"{self._estimator.matcher.max_window} samples at {lib.sample_rate_hz:g} Hz) from {lib.path or '?'}")
            + f"; input {self._input_type} on {self._input_topics}" + (f" in {self._units}" if self._imu is None else "")
            + (f", joints {', '.join(self._joint_names)}" if self._input_type == "joint_state" else "")
            + f"; options: {self._options_summary()}"
        )
        priority = self.get_parameter("thread_priority").value
        if priority:
            self._set_priority(priority)

    def _start_imu_input(self) -> Any:
        """``input_type: imu``: four sensor_msgs/Imu subscriptions (ros/imu_input.py)."""
        from .imu_input import ImuInput

        try:
            return ImuInput(self, INPUT_QOS)
        except (GaitEstimatorError, ParameterException) as exc:
            self.destroy_node()
            raise StartupError(one_line(exc)) from None

    # -----------------------------------------------------------------------------------------
    # Services

    def _save_library(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/save_library``: write the library in use, with its taught modes and personalised
        kernels, to ``adapted_library_path``, and a learnt IMU calibration beside it (where the
        next start with that library looks for it)."""
        est = self._estimator
        if est is None or (est.adapter is None and not self._teacher.taught):
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
            f"; taught: {', '.join(self._teacher.taught)}" if self._teacher.taught else "") + (
            "; strides adopted: " + ", ".join(f"{m} {n}" for m, n in strides.items()) if est.adapter else "") + ")" + (
            self._imu.save_beside(out, lib.name) if self._imu is not None else "")
        self.get_logger().info(response.message)
        return response

    def _reset_calibration(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/reset_calibration``: forget the learnt sensor offsets and cadence (after
        re-donning, or for another wearer)."""
        est = self._estimator
        if est is None:  # no library yet: only the IMU input may have learnt something
            response.success = self._imu is not None
            response.message = ("no library yet" + self._imu.reset_calibration() if self._imu is not None
                                else "no library yet: nothing calibrated")
            self.get_logger().info(response.message)
            return response
        before, scale = est.sensor_offset_deg.copy(), est.cadence_scale
        est.reset_calibration()
        response.success = True
        response.message = ("sensor offsets reset to 0 (were " + ", ".join(f"{v:.2f}" for v in before) + " deg)"
                            + (f", learnt time scale {scale:.3f} forgotten" if math.isfinite(scale) else "")
                            + (self._imu.reset_calibration() if self._imu is not None else ""))
        self.get_logger().info(response.message)
        return response

    def _set_estimator(self, estimator: Estimator) -> None:
        self._estimator = estimator
        names = estimator.mode_names
        self._sse_msg = Float64MultiArray()
        self._sse_msg.layout.dim = [MultiArrayDimension(label=sse_label(names), size=len(names), stride=len(names))]
        # serialised once per library; every estimate patches its stamp and values (estimate_values)
        self._estimate_msg = SerializedJointState(estimate_names(names))
        self._last_estimate: Estimate | None = None

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
        self._received += 1
        self._period_received += 1
        if isinstance(msg, bytes):
            try:
                stamp, names, positions = read_joint_state(msg)
            except CdrError as exc:  # not plain CDR: the middleware's deserialiser reads any encoding
                try:
                    msg = deserialize_message(msg, JointState)
                except Exception:  # whatever rclpy raises for undecodable bytes
                    self._reject(SampleRejected(MALFORMED, f"cannot decode the JointState ({exc})"))
                    return
        if not isinstance(msg, bytes):
            stamp, names, positions = msg.header.stamp, msg.name, msg.position
        if stamp.sec == 0 and stamp.nanosec == 0:
            stamp = self.get_clock().now().to_msg()
        try:
            angles = self._extract.named(names, positions)
        except SampleRejected as exc:
            self._reject(exc)
            return
        self._process(angles, stamp, t0)

    def _handle_array(self, msg: Float64MultiArray) -> None:
        """One Float64MultiArray sample; stamped with the node clock on arrival."""
        t0 = time.perf_counter()
        self._received += 1
        self._period_received += 1
        stamp = self.get_clock().now().to_msg()
        try:
            angles = self._extract.array(msg.data)
        except SampleRejected as exc:
            self._reject(exc)
            return
        self._process(angles, stamp, t0)

    def _process(self, angles_deg: Sample, stamp: TimeMsg | Stamp, t0: float) -> None:
        """Stamp check, one estimator update, publish; ``t0`` = callback start (perf_counter)."""
        t = self._seconds(stamp)
        guard = self._guard
        prev = guard.last_stamp
        try:
            restart = guard.accept(t)
        except SampleRejected as exc:
            self._reject(exc)
            return
        if restart:  # stamps jumped back by more than restart_back_s: a restarted stream
            self._teacher.stream_restarted()
        est = self._estimator
        if est is None:  # no library yet (kernels: ''): the samples only teach
            self._teacher.on_sample(t, angles_deg)
            return
        if restart:
            est.reset()
            self._log_restart("back", f"input stamps jumped back by {(prev or t) - t:.3f} s (> {guard.restart_back_s:g} s)")
        units = self._units_check
        if units.problem is None and self._imu is None and units.observe(t, angles_deg) is not None:
            self.get_logger().warning(f"input_units {self._units}: {units.problem}")
        resets, recalibrations = est.resets, est.calibration_resets
        estimate = est.update(t, angles_deg)
        if est.resets != resets:
            self._log_restart(
                "gap",
                f"gap of {t - (prev if prev is not None else t):.3f} s in input stamps > max_gap_s "
                f"{est.config.max_gap_s:g} s"
            )
        if est.calibration_resets != recalibrations:  # at most one per calibration_reset_gap_s: not throttled
            self.get_logger().info(
                f"gap of {t - (prev if prev is not None else t):.3f} s in input stamps > calibration_reset_gap_s "
                f"{est.config.calibration_reset_gap_s:g} s: learnt sensor offsets and cadence forgotten "
                "(the sensors may have been re-donned)"
            )
        t1 = time.perf_counter()
        self._publish(estimate, stamp)
        self._angles.add(stamp, angles_deg, est.sensor_offset_deg)
        self._teacher.on_sample(t, angles_deg)  # may change the library and the estimator

        if self._period_first_stamp is None:
            self._period_first_stamp = t
        self._period_last_stamp = t
        self._period_accepted += 1
        t2 = time.perf_counter()
        dt = t2 - t0
        self._proc_sum += dt
        self._proc_count += 1
        if dt > self._proc_max:
            self._proc_max = dt
        profile = self._profile
        if profile is not None and len(profile) < MAX_PROFILE_ROWS:
            start_sec, start_ns = divmod(time.time_ns() - round(dt * 1e9), 1_000_000_000)  # system clock
            profile.append((stamp.sec, stamp.nanosec, start_sec, start_ns, round((t1 - t0) * 1e9), round((t2 - t1) * 1e9)))

    def _log_restart(self, kind: str, why: str) -> None:
        """One line per window restart caused by the stream (``kind``: gap or back), throttled
        per kind like the warnings."""
        key = f"restart_{kind}"
        now = time.monotonic()
        last = self._warned_at.get(key)
        if last is not None and now - last < WARN_THROTTLE_S:
            self._suppressed[key] += 1
            return
        self._warned_at[key] = now
        more = self._suppressed.pop(key, 0)
        self.get_logger().info(
            f"{why}: window restarted" + (f" ({more} more restarts since the last message)" if more else "")
        )

    def _seconds(self, stamp: TimeMsg | Stamp) -> float:
        """A stamp in seconds since the whole second of the first stamp the node saw: float64
        keeps nanoseconds there, which seconds since 1970 (~1.7e9) do not (the resampler
        interpolates at these times)."""
        if self._epoch_sec is None:
            self._epoch_sec = stamp.sec
        return (stamp.sec - self._epoch_sec) + stamp.nanosec * 1e-9

    def _publish(self, e: Estimate, stamp: TimeMsg | Stamp) -> None:
        """Publish one estimate; topics nobody listens to are skipped (a count query is far
        cheaper than a publish). ``estimate`` goes last: once it is out, everything is."""
        self._last_estimate = e
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

    def _reject(self, exc: SampleRejected) -> None:
        """Count a dropped sample; warn at most every WARN_THROTTLE_S per reason."""
        self._period_rejected += 1
        self._guard.reject(exc)
        now = time.monotonic()
        last = self._warned_at.get(exc.reason)
        if last is not None and now - last < WARN_THROTTLE_S:
            self._suppressed[exc.reason] += 1
            return
        self._warned_at[exc.reason] = now
        more = self._suppressed.pop(exc.reason, 0)
        self.get_logger().warn(
            (f"dropped sample on {self._input_topics}: " if self._imu is None else "dropped IMU input: ")
            + f"{exc.reason}: {exc}"
            + (f" ({more} more {exc.reason} dropped since the last warning)" if more else "")
        )

    # -----------------------------------------------------------------------------------------
    # State and diagnostics

    @property
    def library(self) -> KernelLibrary:
        """The kernel library in use."""
        assert self._library is not None
        return self._library

    @property
    def config(self) -> EstimatorConfig:
        """The estimator options in use."""
        return self._config

    @property
    def ready(self) -> bool:
        """True while the matcher window is full (mode/phase/sse are being published)."""
        return self._estimator is not None and self._estimator.matcher.ready

    @property
    def samples_received(self) -> int:
        """Input messages seen so far (accepted + rejected)."""
        return self._received

    @property
    def samples_accepted(self) -> int:
        """Input messages that went into the estimator."""
        return self._guard.accepted

    @property
    def rejected(self) -> dict[str, int]:
        """Dropped samples so far, by reason (every reason the input type can give listed)."""
        reasons = REASONS if self._imu is None else [r for r in REASONS if r not in ANGLE_MESSAGE_ONLY]
        return {r: int(self._guard.rejected.get(r, 0)) for r in reasons}

    @property
    def window_resets(self) -> int:
        """Window restarts caused by the input stream: gaps > max_gap_s and jumps back."""
        resets = self._estimator.resets if self._estimator is not None else 0
        return self._resets_before + resets + self._guard.restarts



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
