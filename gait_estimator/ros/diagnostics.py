"""``/diagnostics`` and ``~/profile`` of ``estimator_node`` (``NodeDiagnostics``,
owned by ``EstimatorNode``): the node's status once per second, and while something subscribes the
per-sample timing of the last second."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidHandle
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from ..core.imu_pairing import UNPAIRED
from .outputs import OUTPUT_QOS, QUIET, double_array
from .priority import process_priority

DIAGNOSTICS_TOPIC = "/diagnostics"
DIAGNOSTICS_PERIOD_S = 1.0
RATE_TOLERANCE = 0.2
"""Relative deviation of the input stamp rate from the library rate that raises a WARN."""
PROFILE_TOPIC = "~/profile"
PROFILE_COLUMNS = ("stamp_sec", "stamp_nanosec", "start_sec", "start_nanosec", "estimator_ns", "publish_ns")
"""``~/profile`` rows, one per accepted sample: the input stamp; when the node began handling the
message (system clock; the message was taken from DDS just before); the time spent on angle
extraction, checks and the estimator update; the time spent publishing. The layout's dim[1]
label lists the columns. (The message info with the DDS arrival time is not available to the
callback under rclpy 7.1's EventsExecutor, so the arrival itself is not recorded.)"""
MAX_PROFILE_ROWS = 20_000
"""Most ``~/profile`` rows kept per diagnostics period (later samples are not profiled)."""


class NodeDiagnostics:
    """``/diagnostics`` and ``~/profile`` of ``node`` (an EstimatorNode: its public state and its
    stream's counters); ``record`` takes each sample's timing."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.diagnostics_pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, OUTPUT_QOS, event_callbacks=QUIET)
        self.profile_pub = node.create_publisher(Float64MultiArray, PROFILE_TOPIC, OUTPUT_QOS, event_callbacks=QUIET)
        # Diagnostics describe the process (rates, processing time), so they run on the steady
        # clock: they keep coming while simulated time is paused.
        node.create_timer(DIAGNOSTICS_PERIOD_S, self.publish, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self.profile: list[tuple[int, int, int, int, int, int]] | None = None  # rows while subscribed
        self._start = time.monotonic()
        self._sum = self._max = 0.0
        self._count = 0

    def record(self, stamp: Any, t0: float, t1: float, t2: float) -> None:
        """One accepted sample's timing (perf_counter): callback start, update done, published."""
        dt = t2 - t0
        self._sum += dt
        self._count += 1
        if dt > self._max:
            self._max = dt
        profile = self.profile
        if profile is not None and len(profile) < MAX_PROFILE_ROWS:
            start_sec, start_ns = divmod(time.time_ns() - round(dt * 1e9), 1_000_000_000)  # system clock
            profile.append((stamp.sec, stamp.nanosec, start_sec, start_ns, round((t1 - t0) * 1e9), round((t2 - t1) * 1e9)))

    def status(self) -> DiagnosticStatus:
        """The node's status; rates and processing times cover the time since the previous call."""
        node, stream = self.node, self.node.stream
        now = time.monotonic()
        elapsed = max(now - self._start, 1e-9)
        period = stream.take_period()
        mean_ms = 1e3 * self._sum / self._count if self._count else 0.0
        proc_max = self._max
        self._start, self._sum, self._max, self._count = now, 0.0, 0.0, 0
        name = f"{node.get_fully_qualified_name()}: gait estimator"
        imu = node.imu.diagnostics() if node.imu is not None else None
        est = stream.estimator
        if est is None:
            return self._without_library(name, imu)
        lib = est.library
        m = est.matcher
        e = stream.last_estimate
        shown = e is not None and e.ready
        stamp_rate = math.nan
        first, last = period.first_stamp_s, period.last_stamp_s
        if period.accepted >= 2 and first is not None and last is not None and last > first:
            stamp_rate = (period.accepted - 1) / (last - first)
        values = {
            "ready": "true" if m.ready else "false",
            "window": f"{min(m.steps, m.max_window)}/{m.max_window}",
            "mode": e.mode if shown else "",
            "phase": f"{e.phase:.4f}" if shown else "",
            "confidence": f"{e.confidence:.4g}" if shown else "",
            "held": ("true" if e.held else "false") if shown else "",
            "library": lib.name,
            "library_path": lib.path,
            "modes": str(len(lib)),
            "mode_names": ",".join(lib.mode_names),
            "library_rate_hz": f"{lib.sample_rate_hz:g}",
            "estimator_options": node.parameters.options_summary(),
            "input_topic": node.input_topics,
            "input_type": node.input_type,
            "input_units": node.units,
            "state": str(e.state) if e is not None else "",
            "input_rate_hz": f"{period.received / elapsed:.1f}",
            "stamp_rate_hz": "" if math.isnan(stamp_rate) else f"{stamp_rate:.1f}",
            "processing_time_mean_ms": f"{mean_ms:.4f}",
            "processing_time_max_ms": f"{1e3 * proc_max:.4f}",
            "samples_received": str(stream.received),
            "samples_accepted": str(stream.accepted),
            "samples_rejected": str(stream.guard.rejected_total),
            **{f"rejected_{reason}": str(n) for reason, n in node.rejected.items()},
            "window_resets": str(stream.window_resets),
            "stream_restarts": str(stream.stream_restarts),
            "max_gap_s": f"{stream.config.max_gap_s:g}",
            "scheduling": process_priority(),
            "cadence_ratio": f"{e.cadence_ratio:.3f}" if shown and math.isfinite(e.cadence_ratio) else "",
            "sensor_offset_deg": ",".join(f"{v:.2f}" for v in est.sensor_offset_deg),
            "cadence_scale": f"{est.cadence_scale:.3f}" if math.isfinite(est.cadence_scale) else "",
            "adapted_strides": str(int(est.adapter.accepted.sum())) if est.adapter else "",
            **stream.teach_values(),
        }
        silent = imu is not None and bool(imu[0]["imu_silent"])  # said first; the others' messages go unpaired
        problems: list[str] = []
        if period.received == 0 and not silent:  # IMU input: no sample paired, nor message rejected
            problems.append(f"no input on {node.input_topics}" if imu is None else "no IMU sample")
        rejected, values["rejected_main"] = stream.guard.main_rejection(ignore=UNPAIRED if silent else "")
        if rejected:
            problems.append(f"{rejected} {'sample' if imu is None else 'IMU input'}(s) rejected ({values['rejected_main']})")
        if not math.isnan(stamp_rate) and est.resampler is None and abs(stamp_rate / lib.sample_rate_hz - 1.0) > RATE_TOLERANCE:
            problems.append(f"input stamp rate {stamp_rate:.0f} Hz differs from the library's {lib.sample_rate_hz:g} Hz "
                            "(set resample: on)")
        if stream.units_check.problem is not None:
            problems.append(f"input_units {node.units}: {stream.units_check.problem}")
        if imu is not None:
            values.update(imu[0])
            problems = imu[1] + problems if silent else problems + imu[1]
        if problems:
            level, message = DiagnosticStatus.WARN, "; ".join(problems)
        elif shown and e is not None:
            level, message = DiagnosticStatus.OK, f"ready: {e.mode} phase {e.phase:.2f}"
        else:
            level, message = DiagnosticStatus.OK, f"filling window {values['window']}"
        message += f"; teaching {stream.teaching.progress()}" if stream.teaching else ""
        return DiagnosticStatus(level=level, name=name, message=message, hardware_id="",
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def _without_library(self, name: str, imu: tuple[dict[str, str], list[str]] | None) -> DiagnosticStatus:
        """Diagnostics before the first mode is taught (``kernels: ''``)."""
        stream = self.node.stream
        message = ("no kernel library: teaching " + stream.teaching.progress() if stream.teaching
                   else "no kernel library: set teach_mode to teach a mode")
        values = {
            "ready": "false", "library": "", "modes": "0", "mode_names": "",
            "samples_received": str(stream.received), "samples_accepted": str(stream.accepted),
            **stream.teach_values(),
        }
        level = DiagnosticStatus.OK
        if imu is not None:
            values.update(imu[0])
            if imu[1]:
                level, message = DiagnosticStatus.WARN, "; ".join(imu[1]) + "; " + message
        return DiagnosticStatus(level=level, name=name, message=message, hardware_id="",
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def publish(self) -> None:
        """The timer's callback: ``/diagnostics``, then the period's ``~/profile`` rows."""
        try:
            msg = DiagnosticArray()
            msg.header.stamp = self.node.get_clock().now().to_msg()
            msg.status = [self.status()]
            self.diagnostics_pub.publish(msg)
            self.publish_profile()
        except (RuntimeError, InvalidHandle):
            if self.node.context.ok():
                raise  # (a timer event can still be dispatched after the context shut down)

    def publish_profile(self) -> None:
        """Publish the period's ``~/profile`` rows; record the next period's only while
        something subscribes (no cost otherwise)."""
        rows, self.profile = self.profile, [] if self.profile_pub.get_subscription_count() else None
        if rows:
            msg = Float64MultiArray()
            n, k = len(rows), len(PROFILE_COLUMNS)
            msg.layout.dim = [
                MultiArrayDimension(label="samples", size=n, stride=n * k),
                MultiArrayDimension(label=",".join(PROFILE_COLUMNS), size=k, stride=k),
            ]
            msg.data = double_array(np.array(rows, dtype=np.float64).reshape(n, k))
            self.profile_pub.publish(msg)
