"""A bag taken message by message as ``estimator_node`` takes it live, through the node's
``GaitStream`` (``core/gait_stream.py``): the angle topic's messages, or four Imu topics' messages
decoded by the node's CDR reader (``io/cdr.py``) and paired, converted and calibrated by the
node's ``ImuFlow`` (the calibration learnt on the way, or ``imu_calibration``). ``process``,
``convert`` and ``train`` with ``--as-node`` all read a bag through ``bag_as_node``.

Samples keep bag order. Their time (``NodeSample.time_ns``, from the bag's time 0 as without
``--as-node``: ``bag.since_time_zero``) follows the node's stamps; where these jump back (a restarted
stream: a window restart for the node) it goes on from the sample before by the log-time step
between the two, so it increases through the bag."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..core.channels import Sample, sample_values
from ..core.errors import RecordingError
from ..core.estimator import EstimatorConfig, trace_from_estimates
from ..core.imu import ImuCalibration
from ..core.imu_pairing import DEFAULT_TOLERANCE_S
from ..core.kernels import KernelLibrary
from ..core.rejections import MALFORMED, SampleRejected
from ..core.supervisor import Estimate
from .bag import JOINT_STATE, BagRecording, bag_samples, bag_topics, is_bag_path, open_bag, since_time_zero
from .cdr import CdrError, read_imu, stamp_to_ns
from .imu_bag import ImuBagRecording, imu_topics_of, is_imu_bag
from .imu_stream import load_calibration
from .outputs import Predictions
from .read_options import ReadOptions

NANO = 1_000_000_000


class NodeSample(NamedTuple):
    """A sample the node's stream accepted: ``index`` of its message on the angle topic, or (Imu
    topics) among the accepted samples; ``time_ns`` (module docstring); ``estimate`` (None: no library)."""

    index: int
    log_ns: int
    stamp_ns: int
    time_ns: int
    angles_deg: Sample
    estimate: Estimate | None


@contextmanager
def bag_as_node(path: str | Path, library: KernelLibrary | None, config: EstimatorConfig | None = None,
                options: ReadOptions | None = None) -> Iterator[tuple[Any, Iterator[NodeSample]]]:
    """(the node's ``GaitStream`` for the bag, its accepted samples in bag order); a caller may
    change the stream (teaching) between samples. A stamp jumping back restarts the stream instead
    of being dropped; a Float64MultiArray, or a zero stamp, is timed by its log time, as the node
    times it on arrival. Imu bags: four Imu topics (``imu_topics``, else found as
    ``read_recording`` finds them)."""
    from ..core.gait_stream import GaitStream  # (core/teach: not at package import)

    o = options or ReadOptions()
    cfg = config or EstimatorConfig()
    p = Path(path)
    if not is_bag_path(p):
        raise RecordingError(f"{p}: --as-node reads a rosbag2 bag (directory, .mcap or .db3)")
    if o.imu_topics or is_imu_bag(p):
        with open_bag(p, "imu") as reader:
            stream = GaitStream(library, cfg, stamped=True, units=None)
            yield stream, _in_bag_order(_imu_samples(p, reader, stream, o), stream)
    else:
        with bag_samples(p, o) as (msgtype, samples):
            stream = GaitStream(library, cfg, stamped=msgtype == JOINT_STATE, units=o.input_units)
            yield stream, _in_bag_order(_angle_samples(samples, stream), stream)


def predict_as_node(path: str | Path, library: KernelLibrary, config: EstimatorConfig | None = None,
                    options: ReadOptions | None = None) -> tuple[Predictions, Any]:
    """One prediction per estimate the node would publish for the bag (``time_s``: ``time_ns``;
    ``sample``: ``index``), and the ``GaitStream`` with its counts and events."""
    rows, stream = _accepted(path, library, config, options)
    trace = trace_from_estimates(library.mode_names, [(s.index, s.estimate) for s in rows])
    est = stream.estimator
    adapted = est.adapted_library() if est is not None and est.adapter is not None else None
    return Predictions(np.array([s.time_ns for s in rows]) * 1e-9, trace.sample, trace, adapted), stream


def read_as_node(path: str | Path, config: EstimatorConfig | None = None,
                 options: ReadOptions | None = None) -> tuple[BagRecording, Any]:
    """The angles the node's stream feeds its estimator (degrees, CHANNELS order) as a recording
    (``time_s``: ``time_ns``, stamped from the first sample's stamp; ``index``; Imu topics: with
    the calibration in use at the end), and the stream."""
    rows, stream = _accepted(path, None, config, options)
    index, logs, stamps, times, angles, _ = (np.array(c) for c in zip(*rows, strict=True))
    imu = {} if stream.imu is None else {"calibration": stream.imu.calibrator.calibration}
    return (ImuBagRecording if imu else BagRecording)(times * 1e-9, angles.astype(np.float64), source=str(path),
                                                      index=index, stamp_ns=stamps[0] - times[0] + times, log_time_ns=logs,
                                                      **imu), stream


def _accepted(path: str | Path, library: KernelLibrary | None, config: EstimatorConfig | None,
              options: ReadOptions | None) -> tuple[list[NodeSample], Any]:
    with bag_as_node(path, library, config, options) as (stream, samples):
        rows = list(samples)
    if not rows:
        imu = f" (IMU calibration: {stream.imu.calibrator.status})" if stream.imu is not None else ""
        raise RecordingError(f"{path}: no usable samples{imu}")
    return rows, stream


def _in_bag_order(samples: Iterator[NodeSample], stream: Any) -> Iterator[NodeSample]:
    """``samples`` with ``time_ns`` set (module docstring)."""
    prev: NodeSample | None = None
    first = shift = 0
    for s in samples:
        if prev is None:  # (Imu: paired samples the calibration took came before)
            first = s.stamp_ns if stream.first_stamp_ns is None else min(stream.first_stamp_ns, s.stamp_ns)
        elif s.stamp_ns < prev.stamp_ns:  # accepted going back: a restarted stream
            shift += prev.stamp_ns - s.stamp_ns + max(s.log_ns - prev.log_ns, 1)
        prev = s
        yield NodeSample(s.index, s.log_ns, s.stamp_ns, since_time_zero(s.stamp_ns + shift, first), s.angles_deg,
                         s.estimate)


def _angle_samples(samples: Iterator[tuple[int, int, int, bool, Any]], stream: Any) -> Iterator[NodeSample]:
    from ..core.gait_stream import SampleStamp

    for i, log_ns, stamp_ns, _zero, sample in samples:
        if sample is None or isinstance(sample, SampleRejected):
            stream.reject(sample or SampleRejected(MALFORMED, "undecodable CDR"))
            continue
        angles = sample_values(sample)
        try:
            estimate = stream.push(SampleStamp(*divmod(stamp_ns, NANO)), angles)
        except SampleRejected:
            continue
        yield NodeSample(i, log_ns, stamp_ns, stamp_ns, angles, estimate)


def _imu_samples(p: Path, reader: Any, stream: Any, o: ReadOptions) -> Iterator[NodeSample]:
    """The four Imu topics' messages in log order through ``stream.push_imu``."""
    from ..core.imu_flow import ImuFlow

    cal = o.imu_calibration
    saved = cal if isinstance(cal, ImuCalibration) else load_calibration(cal) if cal is not None else None
    axes = [""] * 4
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
    n = 0
    for conn, log_ns, raw in reader.messages(connections=[c for c in reader.connections if c.topic in index]):
        try:
            stamp, frame_id, orientation, cov0, gyro, acc = read_imu(raw)
        except CdrError as exc:
            stream.reject(SampleRejected(MALFORMED, f"cannot decode the Imu ({exc})"))
            continue
        stamp_ns = stamp_to_ns(stamp) or int(log_ns)
        for out in stream.push_imu(index[conn.topic], stamp_ns, orientation, cov0, gyro, acc, frame_id):
            if isinstance(out, tuple):
                ns = stamp_to_ns(out[0])
                yield NodeSample(n, int(log_ns), ns, ns, out[1], out[2])
                n += 1
