"""``process --as-node``: a bag taken message by message as ``estimator_node`` takes it live,
through the node's ``GaitStream`` (``core/gait_stream.py``): the angle topic's messages, or four
Imu topics' messages decoded by the node's CDR reader (``io/cdr.py``) and paired, converted and
calibrated by the node's ``ImuFlow`` (the calibration learnt on the way, or ``imu_calibration``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..core.channels import sample_values
from ..core.errors import RecordingError
from ..core.estimator import EstimatorConfig, trace_from_estimates
from ..core.imu import ImuCalibration
from ..core.kernels import KernelLibrary
from ..core.rejections import MALFORMED, SampleRejected
from ..core.supervisor import Estimate
from .bag import JOINT_STATE, bag_samples, bag_topics, is_bag_path, open_bag
from .cdr import CdrError, read_imu
from .imu_bag import imu_topics_of, is_imu_bag
from .imu_stream import DEFAULT_TOLERANCE_S, load_calibration
from .outputs import Predictions
from .read_options import ReadOptions

NANO = 1_000_000_000


def predict_as_node(path: str | Path, library: KernelLibrary, config: EstimatorConfig | None = None,
                    options: ReadOptions | None = None) -> tuple[Predictions, Any]:
    """One prediction per estimate the node would publish for the bag (a stamp jumping back
    restarts the stream instead of being dropped; a Float64MultiArray, or a zero stamp, is timed
    by its log time, as the node times it on arrival); and the ``GaitStream`` with its counts
    and events. Imu bags: four Imu topics (``imu_topics``, else found as ``read_recording``
    finds them)."""
    from ..core.gait_stream import GaitStream, SampleStamp  # (core/teach: not at package import)

    o = options or ReadOptions()
    cfg = config or EstimatorConfig()
    p = Path(path)
    rows: list[tuple[int, Estimate]] = []
    stamps: list[int] = []
    if not is_bag_path(p):
        raise RecordingError(f"{p}: --as-node reads a rosbag2 bag (directory, .mcap or .db3)")
    if o.imu_topics or is_imu_bag(p):
        stream = GaitStream(library, cfg, stamped=True, units=None)
        _imu_messages(p, stream, o, rows, stamps)
    else:
        with bag_samples(p, o) as (msgtype, samples):
            stream = GaitStream(library, cfg, stamped=msgtype == JOINT_STATE, units=o.input_units)
            for i, _log_ns, stamp_ns, _zero, sample in samples:
                if sample is None or isinstance(sample, SampleRejected):
                    stream.reject(sample or SampleRejected(MALFORMED, "undecodable CDR"))
                    continue
                try:
                    estimate = stream.push(SampleStamp(*divmod(stamp_ns, NANO)), sample_values(sample))
                except SampleRejected:
                    continue
                if estimate is not None:
                    rows.append((i, estimate))
                    stamps.append(stamp_ns)
    if not rows:
        raise RecordingError(f"{p}: no estimates: no usable samples" + (
            f" (IMU calibration: {stream.imu.calibrator.status})" if stream.imu is not None else ""))
    trace = trace_from_estimates(library.mode_names, rows)
    est = stream.estimator
    adapted = est.adapted_library() if est is not None and est.adapter is not None else None
    return Predictions((np.array(stamps) - stamps[0]) * 1e-9, trace.sample, trace, adapted), stream


def _imu_messages(p: Path, stream: Any, o: ReadOptions, rows: list[tuple[int, Estimate]], stamps: list[int]) -> None:
    """The four Imu topics' messages in log order through ``stream.push_imu``; ``rows``: (index
    of the message that completed the sample, its estimate)."""
    from ..core.imu_flow import ImuFlow

    cal = o.imu_calibration
    saved = cal if isinstance(cal, ImuCalibration) else load_calibration(cal) if cal is not None else None
    axes = [""] * 4
    with open_bag(p, "imu") as reader:
        topics = bag_topics(reader)
        names = ["/" + t.lstrip("/") for t in o.imu_topics] if o.imu_topics else imu_topics_of(topics)
        if not names or len(names) != 4 or any(t not in topics for t in names):
            raise RecordingError(f"{p}: needs four sensor_msgs/Imu topics (right_thigh, left_thigh, right_shank, "
                                 "left_shank; --imu-topics)")
        flow = ImuFlow.from_settings(o.imu_lateral_axes or axes, o.imu_proximal_axes or axes,
                                     o.imu_standing_deg or [0.0] * 4, saved, frames=axes,
                                     tolerance_s=DEFAULT_TOLERANCE_S if o.imu_tolerance_s is None else o.imu_tolerance_s,
                                     restart_back_s=stream.guard.restart_back_s, path=str(cal or "imu_calibration"))
        stream.attach_imu(flow)
        index = {t: i for i, t in enumerate(names)}
        conns = [c for c in reader.connections if c.topic in index]
        for n, (conn, log_ns, raw) in enumerate(reader.messages(connections=conns)):
            try:
                stamp, frame_id, orientation, cov0, gyro, acc = read_imu(raw)
            except CdrError as exc:
                stream.reject(SampleRejected(MALFORMED, f"cannot decode the Imu ({exc})"))
                continue
            stamp_ns = stamp.sec * NANO + stamp.nanosec or int(log_ns)
            for out in stream.push_imu(index[conn.topic], stamp_ns, orientation, cov0, gyro, acc, frame_id):
                if isinstance(out, tuple) and out[2] is not None:
                    rows.append((n, out[2]))
                    stamps.append(out[0].sec * NANO + out[0].nanosec)
