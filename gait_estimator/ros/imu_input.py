"""``input_type: imu`` for ``estimator_node``: four ``sensor_msgs/Imu`` topics -> segment angles.

Each message becomes its sensor's up direction (``core/imu_pairing.py``: from the orientation, or from
gyro + accelerometer when ``orientation_covariance[0] == -1``); the four streams are paired by stamp
(``imu_pairing_tolerance_s``); a paired sample becomes four angles through the mounting calibration
(``core/imu_angles.ImuAngles``, which learns or checks it on the way; this module saves and logs what
it finds) and goes to the node's estimator like any other sample. Until the calibration is complete
(saved file, configured axes, or learnt: stand still, then walk a few strides) no sample reaches the
estimator. A saved or configured calibration is checked on the first walking
(``core/imu_learn.check_calibration``): a saved one that does not fit is learnt again (the estimate
waits); configured axes that do not fit stay, reported (an error line and a diagnostics problem).
Its gyro biases are replaced by the ones measured at the stream's first standing pose (before the
check's verdict; logged), as a learnt calibration's are. After a gap in the paired stamps longer
than ``calibration_reset_gap_s``, or a restarted stream, the calibration in use is checked again
(a learnt one is then treated as a saved one) and one being learnt starts again. A sensor silent
for ``imu_timeout_s`` is named in the diagnostics and the estimate waits, since no sample pairs
without it. Bad messages are dropped, counted and logged through the node (throttled).

Services: ``~/calibrate_standing`` takes a new standing pose from the next still second (keeping
learnt sagittal axes, unless the calibration was still to be checked: then strides too); the
node's ``~/reset_calibration`` also forgets the IMU calibration (and deletes its saved file).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.qos import QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

from ..core.ahrs import warm_up
from ..core.channels import CHANNELS, N_CHANNELS
from ..core.gait_stream import StreamEvent
from ..core.imu import CalibrationError
from ..core.imu_flow import IMU_INFO, IMU_LEARNT, IMU_NOT_FIT, IMU_WRONG_AXES, ImuFlow
from ..core.imu_learn import STILL_S, WALK_S
from ..core.imu_pairing import DEFAULT_TOLERANCE_S
from ..core.rejections import MALFORMED, SampleRejected
from ..core.teach import TAUGHT_LIBRARY
from ..io.cdr import CdrError, read_imu, stamp_to_ns
from ..io.imu_bag import DEFAULT_IMU_TOPICS
from ..io.imu_stream import calibration_path_for, load_calibration, save_calibration

CALIBRATE_STANDING_SERVICE = "~/calibrate_standing"
PARAMETERS: dict[str, tuple[Any, str]] = {
    "imu_topics": (list(DEFAULT_IMU_TOPICS), "sensor_msgs/Imu topics of right_thigh, left_thigh, right_shank, left_shank."),
    "imu_pairing_tolerance_s": (DEFAULT_TOLERANCE_S, "Largest stamp spread (s) of the four messages of one sample."),
    "imu_timeout_s": (0.5, "A sensor without decodable messages for this long (s) is reported silent in the diagnostics."),
    "imu_frame_ids": ([""] * N_CHANNELS, "Per sensor, the header.frame_id its messages must carry ('' = any); "
                      "messages with another frame are dropped (wrong_frame)."),
    "imu_lateral_axes": ([""] * N_CHANNELS, "Per segment, the sensor axis pointing to the wearer's right (+x, -y, ...; "
                         "forward swing is a positive rotation about it); '' = learn from strides."),
    "imu_proximal_axes": ([""] * N_CHANNELS, "Per segment, the sensor axis pointing along the segment towards the "
                          "proximal joint; '' = learn from the standing pose."),
    "imu_standing_angles_deg": ([0.0] * N_CHANNELS, "Segment angles (deg) taken for the standing pose."),
    "imu_calibration_path": ("", "IMU calibration file (YAML), read at start and written when learnt; '' = beside a "
                             "user library (<library>.imu.yaml), or ~/.ros/gait_estimator/<library>.imu.yaml "
                             f"(<library> = {TAUGHT_LIBRARY} without one)."),
}
"""Parameters declared (read-only) when ``input_type`` is ``imu``: default and description."""


class ImuInput:
    """The node's IMU input; see the module docstring. Raises CalibrationError (one line) for
    invalid axes or an unreadable calibration file."""

    def __init__(self, node: Any, qos: QoSProfile) -> None:
        """``node``: the EstimatorNode (its stream, ``take_angles`` and ``reject`` are used)."""
        self.node = node
        values = {}
        for name, (default, text) in PARAMETERS.items():
            node.declare_parameter(name, default, ParameterDescriptor(description=text, read_only=True))
            values[name] = node.get_parameter(name).value
        topics = list(values["imu_topics"])
        if len(topics) != N_CHANNELS or not all(t.strip() for t in topics):
            raise CalibrationError(f"imu_topics: needs {N_CHANNELS} topic names ({', '.join(CHANNELS)})")
        for name in ("imu_pairing_tolerance_s", "imu_timeout_s"):
            if not (math.isfinite(values[name]) and values[name] >= 0):
                raise CalibrationError(f"{name}: must be >= 0 s, got {values[name]!r}")
        lib = node.stream.library  # None: no library yet (kernels: ''), the modes are to be taught
        self.path = Path(values["imu_calibration_path"]).expanduser() if values["imu_calibration_path"] else \
            calibration_path_for(lib.path, lib.name) if lib is not None else calibration_path_for(None, TAUGHT_LIBRARY)
        from_file = load_calibration(self.path) if self.path.is_file() else None  # raises one line if bad
        self.timeout_s = float(values["imu_timeout_s"])
        self.flow = ImuFlow.from_settings(
            values["imu_lateral_axes"], values["imu_proximal_axes"], values["imu_standing_angles_deg"], from_file,
            frames=list(values["imu_frame_ids"]), tolerance_s=float(values["imu_pairing_tolerance_s"]),
            restart_back_s=node.stream.guard.restart_back_s, path=str(self.path))
        saved = self.flow.calibrator.calibration
        warm_up()  # the raw fusion's compiled step, before the first message waits for it
        node.stream.attach_imu(self.flow)
        self.last_arrival = [math.nan] * N_CHANNELS
        self.received = [0] * N_CHANNELS
        self.started = time.monotonic()
        self.subscriptions = [
            node.create_subscription(Imu, topic, lambda msg, i=i: self._on_imu(i, msg), qos, raw=True)
            for i, topic in enumerate(topics)
        ]
        self._srv = node.create_service(Trigger, CALIBRATE_STANDING_SERVICE, self.calibrate_standing)
        log = node.get_logger()
        if saved is not None:
            log.info(f"IMU calibration from {self.path if from_file is not None else 'the configured axes'}: "
                     f"{saved.summary()}")
            if from_file is not None and self.flow.configured:
                log.warn(f"imu_lateral_axes/imu_proximal_axes are configured, but {self.path} is used; "
                         "~/reset_calibration deletes it")
        else:
            log.info(f"no IMU calibration at {self.path}: {self.flow.calibrator.status or 'learning'} "
                     f"(stand still {STILL_S:g} s, then walk {WALK_S:g} s); the estimate waits until then")

    # -----------------------------------------------------------------------------------------

    def _on_imu(self, sensor: int, msg: bytes | Imu) -> None:
        """One message, serialised (as the subscriptions deliver it: read from the CDR bytes,
        io/cdr.py, cheaper than building the message object) or not."""
        t0 = time.perf_counter()
        node = self.node
        self.received[sensor] += 1
        if isinstance(msg, bytes):
            try:
                stamp, frame_id, orientation, cov0, gyro, acc = read_imu(msg)
            except CdrError as exc:  # not plain CDR: the middleware's deserialiser reads any encoding
                try:
                    msg = deserialize_message(msg, Imu)
                except Exception:  # whatever rclpy raises for undecodable bytes
                    node.reject(SampleRejected(MALFORMED, f"{CHANNELS[sensor]}: cannot decode the Imu ({exc})"))
                    return
        if not isinstance(msg, bytes):
            o, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
            stamp, frame_id, cov0 = msg.header.stamp, msg.header.frame_id, msg.orientation_covariance[0]
            orientation, gyro, acc = (o.x, o.y, o.z, o.w), (w.x, w.y, w.z), (a.x, a.y, a.z)
        self.last_arrival[sensor] = time.monotonic()  # decodable: the sensor is talking
        stamp_ns = stamp_to_ns(stamp)
        if stamp_ns == 0:
            stamp_ns = node.get_clock().now().nanoseconds
        node.publish_outputs(node.stream.push_imu(sensor, stamp_ns, orientation, cov0, gyro, acc, frame_id), t0)

    def handle(self, events: list[StreamEvent]) -> list[StreamEvent]:
        """Log the IMU flow's events (saving a learnt calibration, deleting one that does not
        fit); the others are returned."""
        log, rest = self.node.get_logger(), []
        for event in events:
            kind, line = event.kind, event.line
            if kind == IMU_INFO:
                log.info(line)
            elif kind == IMU_WRONG_AXES:
                log.error(line)
            elif kind == IMU_LEARNT:
                self._learnt(line)
            elif kind == IMU_NOT_FIT:
                if self.flow.configured:  # the configured axes take over; the file would be read again at the next start
                    try:
                        self.path.unlink(missing_ok=True)
                        then = "the file deleted, the configured axes used (and checked)"
                    except OSError as exc:
                        then = f"the configured axes used (and checked); the file NOT deleted ({exc})"
                else:
                    then = f"learning it again: stand still {STILL_S:g} s, then walk {WALK_S:g} s (the estimate waits)"
                log.warn(f"IMU calibration from {self.path} does not fit the sensors now ({line}): {then}")
            else:
                rest.append(event)
        return rest

    def _learnt(self, summary: str) -> None:
        log = self.node.get_logger()
        cal = self.flow.calibrator.calibration
        if self.flow.configured or cal is None:
            log.info(f"IMU calibration from the configured axes: {summary}")
            return
        try:
            save_calibration(cal, self.path)
            where = f"saved to {self.path}"
        except OSError as exc:
            where = f"NOT saved ({self.path}: {exc})"
        log.info(f"IMU calibration learnt, {where}: {summary}")

    def save_beside(self, library_path: Path, library_name: str) -> str:
        """``~/save_library``: write the learnt calibration where a node started with ``kernels:
        library_path`` looks for it; what happened, for the service reply ('' when nothing was
        learnt: configured axes need no file)."""
        cal = self.flow.calibrator.calibration
        if cal is None or all(m.source == "configured" for m in cal.mounts):
            return ""
        path = calibration_path_for(library_path, library_name)
        try:
            return f"; IMU calibration written to {save_calibration(cal, path)}"
        except OSError as exc:
            return f"; IMU calibration NOT written ({path}: {' '.join(str(exc).split())})"

    # -----------------------------------------------------------------------------------------

    def calibrate_standing(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        relearn = self.flow.calibrator.checking
        self.flow.calibrator.request_standing()
        response.success = True
        response.message = (f"stand still for {STILL_S:g} s: the next still stretch becomes the standing pose"
                            + (f", then walk {WALK_S:g} s (the calibration was not checked yet)" if relearn else "")
                            + " (the estimate waits until then; with raw IMUs until you move)")
        self.node.get_logger().info(response.message)
        return response

    def reset_calibration(self) -> str:
        """Forget the IMU calibration (and its file); what happened, for the service reply."""
        self.flow.forget()
        removed = ""
        try:
            self.path.unlink()
            removed = f", {self.path} deleted"
        except FileNotFoundError:
            pass
        except OSError as exc:
            removed = f", {self.path} NOT deleted ({exc})"
        return f"; IMU calibration forgotten{removed}: {self.flow.calibrator.status} to learn it again"

    def diagnostics(self) -> tuple[dict[str, str], list[str]]:
        """Key/values and problems for the node's diagnostics status."""
        now = time.monotonic()
        silent = []
        for c, sub, last in zip(CHANNELS, self.subscriptions, self.last_arrival, strict=True):
            since = (now - self.started) if math.isnan(last) else now - last
            if since > self.timeout_s:
                silent.append((c, sub.topic_name, since))
        calibrator = self.flow.calibrator
        cal = calibrator.calibration
        values = {
            "imu_calibration": cal.summary() if cal is not None else "",
            "imu_calibration_status": calibrator.status,
            "imu_calibration_path": str(self.path),
            "imu_messages": ",".join(str(n) for n in self.received),
            "imu_silent": ", ".join(f"{c} ({since:.1f} s)" for c, _, since in silent),
        }
        problems = []
        if len(silent) == N_CHANNELS:
            problems.append(f"no IMU sample from any sensor for {min(since for *_, since in silent):.1f} s")
        elif silent:
            problems.append("no IMU sample from " + ", ".join(f"{c} ({topic}) for {since:.1f} s" for c, topic, since in silent)
                            + ": the estimate waits")
        if cal is None:
            problems.append(f"IMU calibration: {calibrator.status}")
        if self.flow.check_problem:
            problems.append("IMU calibration: " + self.flow.check_problem)
        return values, problems
