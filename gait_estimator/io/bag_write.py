"""Writing rosbag2 bags (mcap or sqlite3) with the pure-Python ``rosbags`` library.

* ``write_input_bag``: a recording as the driver topic (``sensor_msgs/msg/JointState`` or
  ``std_msgs/msg/Float64MultiArray``), what ``ros2 bag record /segment_angles`` would give;
* ``write_output_bag``: the estimator outputs ``mode``, ``phase``, ``sse``, ``estimate`` with the
  types and layouts of ``outputs.py`` (what the live node publishes), stamped with the input
  stamps.

Bags are written as rosbag2 metadata version 8, the format of ROS 2 Jazzy's ``ros2 bag``, into
a temporary directory beside the target that is renamed to it when complete (``staged_writer``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import struct
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..core.channels import CHANNELS
from ..core.errors import GaitEstimatorError
from .atomic import fsync_path
from .bag import (
    DEFAULT_TOPIC,
    FLOAT64_MULTI_ARRAY,
    INPUT_MSGTYPES,
    JOINT_STATE,
    BagRecording,
    normalize_topic,
    parse_joint_names,
    typestore,
)
from .cdr import read_stamp, stamp_to_ns
from .outputs import (
    ESTIMATE_TOPIC,
    MODE_TOPIC,
    PHASE_TOPIC,
    SSE_TOPIC,
    Predictions,
    estimate_array,
    estimate_names,
    sse_label,
)
from .recording import Recording
from .stream import UNITS

STORAGES = ("mcap", "sqlite3")
"""rosbag2 storage plugins: mcap (the Jazzy default) and sqlite3."""

BAG_VERSION = 8
"""rosbag2 metadata version written (ROS 2 Jazzy)."""

STRING = "std_msgs/msg/String"
FLOAT64 = "std_msgs/msg/Float64"
OUTPUT_MSGTYPES = {
    MODE_TOPIC: STRING,
    PHASE_TOPIC: FLOAT64,
    SSE_TOPIC: FLOAT64_MULTI_ARRAY,
    ESTIMATE_TOPIC: JOINT_STATE,
}
"""Message type of every output topic (relative names, as in outputs.py)."""


def offered_qos(depth: int) -> list[Any]:
    """The offered QoS recorded for a topic: reliable, volatile, keep last ``depth``, no
    deadline/lifespan (``ros2 bag play`` publishes with it)."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    infinite = QosTime(9223372036, 854775807)  # rmw's "infinite" duration, as ros2 bag records it
    return [
        Qos(
            history=QosHistory.KEEP_LAST,
            depth=depth,
            reliability=QosReliability.RELIABLE,
            durability=QosDurability.VOLATILE,
            deadline=infinite,
            lifespan=infinite,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=infinite,
            avoid_ros_namespace_conventions=False,
        )
    ]


@contextlib.contextmanager
def staged_writer(path: str | Path, storage: str) -> Iterator[Any]:
    """An open rosbags ``Writer`` for a new bag directory ``path``, writing into a temporary
    directory beside it. On a clean exit the files are fsynced and the directory renamed to
    ``path``, so an interrupted write never leaves a half-written bag under that name; on an
    error nothing is left."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    if storage not in STORAGES:
        raise GaitEstimatorError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
    target = Path(path)
    if target.exists():
        raise GaitEstimatorError(f"{target}: already exists; rosbag2 bags are written to a new directory")
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    target.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    try:
        staged = work / target.name  # rosbags names the storage file after the directory
        with Writer(staged, version=BAG_VERSION, storage_plugin=plugin) as writer:
            yield writer
        for f in staged.iterdir():
            fsync_path(f)
        os.rename(staged, target)
        fsync_path(target.parent)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def recording_stamps(rec: Recording, start_ns: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, log times) of every sample, int64 ns since the epoch.

    A BagRecording keeps its original stamps and receive times. Other recordings get
    ``start_ns + (time_s - time_s[0])`` for both (``start_ns`` default: now, wall clock), so
    the first sample is stamped ``start_ns``.
    """
    if isinstance(rec, BagRecording) and rec.stamp_ns is not None and rec.log_time_ns is not None:
        return rec.stamp_ns, rec.log_time_ns
    start = time.time_ns() if start_ns is None else int(start_ns)
    if start <= 0:
        raise GaitEstimatorError(f"start time must be after the epoch, got {start} ns")
    rel = np.rint((rec.time_s - rec.time_s[0]) * 1e9).astype(np.int64) if len(rec) else np.zeros(0, np.int64)
    stamps = start + rel
    return stamps, stamps


def output_stamps(rec: Recording, pred: Predictions, start_ns: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, log times) of the prediction rows of ``pred`` (computed from ``rec``), int64 ns.

    Stamp = the stamp of ``rec``'s first sample (``recording_stamps``) + the row's time since
    it, i.e. exactly the input stamp of the sample the row answers;
    log time = that of the input sample that produced the row (``pred.sample``).
    """
    stamps_in, logs_in = recording_stamps(rec, start_ns)
    t = np.asarray(pred.time_s, dtype=np.float64)
    stamps = int(stamps_in[0]) + np.rint((t - rec.time_s[0]) * 1e9).astype(np.int64)
    pos = np.searchsorted(np.asarray(rec.index), np.asarray(pred.sample))
    return stamps, logs_in[np.clip(pos, 0, len(rec) - 1)]


def joint_state_msg(ts: Any, stamp_ns: int, names: list[str], values: Any) -> Any:
    t = ts.types
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    empty = np.empty(0, dtype=np.float64)
    return t[JOINT_STATE](
        header=t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec), frame_id=""),
        name=names,
        position=np.asarray(values, dtype=np.float64),
        velocity=empty,
        effort=empty,
    )


def multi_array_msg(ts: Any, label: str, values: Any) -> Any:
    t = ts.types
    data = np.asarray(values, dtype=np.float64)
    dim = t["std_msgs/msg/MultiArrayDimension"](label=label, size=len(data), stride=len(data))
    return t[FLOAT64_MULTI_ARRAY](layout=t["std_msgs/msg/MultiArrayLayout"](dim=[dim], data_offset=0), data=data)


def write_input_bag(
    rec: Recording,
    path: str | Path,
    *,
    storage: str = "mcap",
    topic: str = DEFAULT_TOPIC,
    msg_type: str = "joint_state",
    units: str = "rad",
    joint_names: Sequence[str] = CHANNELS,
    start_ns: int | None = None,
) -> Path:
    """Write ``rec`` as the driver topic of a new bag (one message per sample).

    Args:
        rec: The samples (degrees, CHANNELS order).
        path: New bag directory.
        storage: ``mcap`` or ``sqlite3``.
        topic: Topic name (made absolute).
        msg_type: ``joint_state`` (header stamp + named joints) or ``float64_multi_array``
            (``data`` = the four angles in CHANNELS order, no header; the bag's log time is the
            only time stamp).
        units: ``rad`` (REP 103, the node's default) or ``deg``.
        joint_names: JointState names of right_thigh, left_thigh, right_shank, left_shank.
        start_ns: Stamp of the first sample for recordings without absolute stamps (see
            ``recording_stamps``); ns since the epoch, default now.

    Returns:
        The bag directory. Log time = header stamp, except for a BagRecording, which keeps
        its original receive times.
    """
    stamps, logs = recording_stamps(rec, start_ns)
    data = serialize_inputs(rec, stamps, msg_type=msg_type, units=units, joint_names=joint_names)
    msgtype = INPUT_MSGTYPES[msg_type]
    with staged_writer(path, storage) as writer:
        conn = writer.add_connection(
            normalize_topic(topic), msgtype, typestore=typestore(), offered_qos_profiles=offered_qos(100)
        )
        for i, raw in enumerate(data):
            writer.write(conn, int(logs[i]), raw)
    return Path(path)


def serialize_inputs(
    rec: Recording,
    stamps_ns: np.ndarray,
    *,
    msg_type: str = "joint_state",
    units: str = "rad",
    joint_names: Sequence[str] = CHANNELS,
) -> list[memoryview]:
    """CDR-serialized driver messages, one per sample of ``rec`` (see ``write_input_bag``);
    JointState messages are stamped ``stamps_ns[i]`` (ns since the epoch)."""
    if msg_type not in INPUT_MSGTYPES:
        raise GaitEstimatorError(f"message type must be one of {', '.join(INPUT_MSGTYPES)}, got {msg_type!r}")
    if units not in UNITS:
        raise GaitEstimatorError(f"units must be rad or deg, got {units!r}")
    names = list(parse_joint_names(joint_names))
    ts = typestore()
    msgtype = INPUT_MSGTYPES[msg_type]
    values = np.radians(rec.angles_deg) if units == "rad" else np.asarray(rec.angles_deg, dtype=np.float64)
    label = ",".join(CHANNELS) + f" ({units})"
    serialize = ts.serialize_cdr
    if msgtype == JOINT_STATE:
        return [serialize(joint_state_msg(ts, int(stamps_ns[i]), names, values[i]), msgtype) for i in range(len(rec))]
    return [serialize(multi_array_msg(ts, label, values[i]), msgtype) for i in range(len(rec))]


def write_output_bag(
    pred: Predictions,
    path: str | Path,
    stamps_ns: np.ndarray,
    log_times_ns: np.ndarray | None = None,
    *,
    storage: str = "mcap",
    namespace: str = "/",
) -> dict[str, int]:
    """Write the estimator outputs for every input sample into a new bag.

    Per input sample i (stamp ``stamps_ns[i]``, logged at ``log_times_ns[i]``, default the
    stamp): ``estimate`` always; ``mode``, ``phase`` and ``sse`` only once the matcher is ready,
    as the live node publishes. Topics are ``namespace`` + the names in outputs.py.

    Returns:
        Messages written per topic.
    """
    ts = typestore()
    t = ts.types
    tr = pred.trace
    n = len(pred.time_s)
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    logs = stamps if log_times_ns is None else np.asarray(log_times_ns, dtype=np.int64)
    if stamps.shape != (n,) or logs.shape != (n,):
        raise ValueError(f"expected {n} stamps and log times, got {stamps.shape} and {logs.shape}")
    ns = normalize_topic(namespace).rstrip("/") + "/"
    label = sse_label(tr.mode_names)
    keys = estimate_names(tr.mode_names)
    values = estimate_array(tr)  # every step at once
    serialize = ts.serialize_cdr
    estimate = _ArrayTemplate(
        lambda i: serialize(joint_state_msg(ts, int(stamps[i]), keys, values[i]), JOINT_STATE), values, tail=8, stamped=True
    )
    sse = _ArrayTemplate(lambda i: serialize(multi_array_msg(ts, label, tr.sse[i]), FLOAT64_MULTI_ARRAY), tr.sse, tail=0)
    phase = _ArrayTemplate(lambda i: serialize(t[FLOAT64](data=float(tr.phase[i])), FLOAT64), tr.phase[:, None], tail=0)
    modes = {name: bytes(serialize(t[STRING](data=name), STRING)) for name in set(tr.modes)}
    counts = dict.fromkeys(OUTPUT_MSGTYPES, 0)
    with staged_writer(path, storage) as writer:
        conns = {
            name: writer.add_connection(ns + name, ty, typestore=ts, offered_qos_profiles=offered_qos(10))
            for name, ty in OUTPUT_MSGTYPES.items()
        }
        write = writer.write
        for i in range(n):
            log = int(logs[i])
            write(conns[ESTIMATE_TOPIC], log, estimate.message(i, int(stamps[i])))
            if tr.ready[i]:
                write(conns[MODE_TOPIC], log, modes[tr.mode[i]])
                write(conns[PHASE_TOPIC], log, phase.message(i))
                write(conns[SSE_TOPIC], log, sse.message(i))
        counts[ESTIMATE_TOPIC] = n
        for name in (MODE_TOPIC, PHASE_TOPIC, SSE_TOPIC):
            counts[name] = int(np.count_nonzero(tr.ready))
    return counts


class _ArrayTemplate:
    """Fast CDR for a series of messages that differ only in one float64 array (and the header
    stamp): the bytes of message 0 serialized by rosbags, with the array (``tail`` bytes before
    the end) and the stamp (bytes 4..12) replaced per message. Checked against rosbags for
    message 0; if the layout is not as expected, every message is serialized by ``slow``.

    Args:
        slow: i -> CDR of message i (rosbags, little endian).
        values: (T, K) the array of every message.
        tail: Bytes after the array (e.g. empty velocity and effort sequences of a JointState).
        stamped: The message starts with a std_msgs/Header whose stamp is patched.
    """

    def __init__(self, slow: Any, values: np.ndarray, tail: int, stamped: bool = False) -> None:
        self.slow = slow
        self.stamped = stamped
        data = np.ascontiguousarray(values, dtype="<f8")
        self.width = 8 * data.shape[1] if data.ndim == 2 and len(data) else 0
        self.data = data.tobytes()
        self.prefix = self.suffix = b""
        self.fast = False
        if not len(data):
            return
        first = bytes(slow(0))
        end = len(first) - tail
        start = end - self.width
        if start < (12 if stamped else 4) or first[1] != 1:  # 0x0001: CDR little endian
            return
        self.prefix, self.suffix = first[:start], first[end:]
        self.fast = True
        self.fast = self.message(0, stamp_to_ns(read_stamp(first)) if stamped else None) == first

    def message(self, i: int, stamp_ns: int | None = None) -> bytes:
        """CDR of message i (header stamp ``stamp_ns`` when stamped)."""
        if not self.fast:
            return bytes(self.slow(i))
        row = self.data[i * self.width : (i + 1) * self.width]
        if self.stamped:
            stamp = struct.pack("<iI", *divmod(int(stamp_ns or 0), 1_000_000_000))
            return self.prefix[:4] + stamp + self.prefix[12:] + row + self.suffix
        return self.prefix + row + self.suffix
