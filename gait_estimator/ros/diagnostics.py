"""``/diagnostics`` and ``~/profile`` of ``estimator_node`` (``NodeDiagnostics``, a mixin of
``EstimatorNode``): the node's status once per second, and while something subscribes the
per-sample timing of the last second."""

from __future__ import annotations

import array
import math
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.exceptions import InvalidHandle
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from ..core.kernels import KernelLibrary
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


def double_array(values: np.ndarray) -> array.array:
    """float64 numpy -> array('d') without a per-element Python loop (the fast message setter)."""
    out = array.array("d")
    out.frombytes(np.ascontiguousarray(values, dtype=np.float64).tobytes())
    return out


class NodeDiagnostics:
    """Diagnostics of EstimatorNode (a mixin of it: reads the node's counters and estimator)."""

    def diagnostics_status(self) -> DiagnosticStatus:
        """The node's status; rates and processing times cover the time since the previous call."""
        now = time.monotonic()
        if self._estimator is None:
            self._period_start, self._period_received, self._period_rejected = now, 0, 0
            return self._teacher.status_without_library(f"{self.get_fully_qualified_name()}: gait estimator",
                                                        self._received, self._guard.accepted,
                                                        self._imu.diagnostics() if self._imu is not None else None)
        elapsed = max(now - self._period_start, 1e-9)
        lib = self.library
        m = self._estimator.matcher
        e = self._last_estimate
        shown = e is not None and e.ready
        input_rate = self._period_received / elapsed
        stamp_rate = math.nan
        first, last = self._period_first_stamp, self._period_last_stamp
        if self._period_accepted >= 2 and first is not None and last is not None and last > first:
            stamp_rate = (self._period_accepted - 1) / (last - first)
        mean_ms = 1e3 * self._proc_sum / self._proc_count if self._proc_count else 0.0
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
            "estimator_options": self._options_summary(),
            "input_topic": self._input_topics,
            "input_type": self._input_type,
            "input_units": self._units,
            "state": str(e.state) if e is not None else "",
            "input_rate_hz": f"{input_rate:.1f}",
            "stamp_rate_hz": "" if math.isnan(stamp_rate) else f"{stamp_rate:.1f}",
            "processing_time_mean_ms": f"{mean_ms:.4f}",
            "processing_time_max_ms": f"{1e3 * self._proc_max:.4f}",
            "samples_received": str(self._received),
            "samples_accepted": str(self._guard.accepted),
            "samples_rejected": str(self._guard.rejected_total),
            **{f"rejected_{reason}": str(n) for reason, n in self.rejected.items()},
            "window_resets": str(self.window_resets),
            "stream_restarts": str(self._guard.restarts),
            "max_gap_s": f"{self._config.max_gap_s:g}",
            "scheduling": process_priority(),
            "cadence_ratio": f"{e.cadence_ratio:.3f}" if shown and math.isfinite(e.cadence_ratio) else "",
            "sensor_offset_deg": ",".join(f"{v:.2f}" for v in self._estimator.sensor_offset_deg),
            "cadence_scale": f"{self._estimator.cadence_scale:.3f}" if math.isfinite(self._estimator.cadence_scale) else "",
            "adapted_strides": str(int(self._estimator.adapter.accepted.sum())) if self._estimator.adapter else "",
            **self._teacher.diagnostic_values(),
        }
        problems = self._problems(stamp_rate, lib, values)
        if problems:
            level, message = DiagnosticStatus.WARN, "; ".join(problems)
        elif shown and e is not None:
            level, message = DiagnosticStatus.OK, f"ready: {e.mode} phase {e.phase:.2f}"
        else:
            level, message = DiagnosticStatus.OK, f"filling window {values['window']}"
        message += self._teacher.message_suffix()
        self._start_period(now)
        return DiagnosticStatus(
            level=level,
            name=f"{self.get_fully_qualified_name()}: gait estimator",
            message=message,
            hardware_id="",
            values=[KeyValue(key=k, value=v) for k, v in values.items()],
        )

    def _problems(self, stamp_rate: float, lib: KernelLibrary, values: dict[str, str]) -> list[str]:
        """What the status warns about this period; adds the IMU input's values to ``values``."""
        problems: list[str] = []
        if self._period_received == 0:  # IMU input: no sample paired, nor message rejected
            problems.append(f"no input on {self._input_topics}" if self._imu is None else "no IMU sample")
        values["rejected_main"] = self._guard.main_rejection()
        if self._period_rejected:
            problems.append(f"{self._period_rejected} {'sample' if self._imu is None else 'IMU input'}(s) rejected"
                            + (f" ({values['rejected_main']})" if values["rejected_main"] else ""))
        if (
            not math.isnan(stamp_rate)
            and self._estimator.resampler is None
            and abs(stamp_rate / lib.sample_rate_hz - 1.0) > RATE_TOLERANCE
        ):
            problems.append(
                f"input stamp rate {stamp_rate:.0f} Hz differs from the library's {lib.sample_rate_hz:g} Hz "
                "(set resample: on)"
            )
        if self._units_check.problem is not None:
            problems.append(f"input_units {self._units}: {self._units_check.problem}")
        if self._imu is not None:
            imu_values, imu_problems = self._imu.diagnostics()
            values.update(imu_values)
            problems += imu_problems
        return problems

    def _start_period(self, now: float) -> None:
        self._period_start = now
        self._period_received = self._period_rejected = self._period_accepted = 0
        self._period_first_stamp = self._period_last_stamp = None
        self._proc_sum = self._proc_max = 0.0
        self._proc_count = 0

    def _publish_diagnostics(self) -> None:
        try:
            msg = DiagnosticArray()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.status = [self.diagnostics_status()]
            self._diag_pub.publish(msg)
            self._publish_profile()
        except (RuntimeError, InvalidHandle):
            if self.context.ok():
                raise  # (a timer event can still be dispatched after the context shut down)

    def _publish_profile(self) -> None:
        """Publish the period's ``~/profile`` rows; record the next period's only while
        something subscribes (no cost otherwise)."""
        rows, self._profile = self._profile, [] if self._profile_pub.get_subscription_count() else None
        if rows:
            msg = Float64MultiArray()
            n, k = len(rows), len(PROFILE_COLUMNS)
            msg.layout.dim = [
                MultiArrayDimension(label="samples", size=n, stride=n * k),
                MultiArrayDimension(label=",".join(PROFILE_COLUMNS), size=k, stride=k),
            ]
            msg.data = double_array(np.array(rows, dtype=np.float64).reshape(n, k))
            self._profile_pub.publish(msg)
