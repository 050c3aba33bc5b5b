"""Reading the driver topic of a rosbag2 recording (mcap or sqlite3) into a Recording.

Pure Python (the ``rosbags`` library, imported lazily): no ROS install needed. Messages become
samples as the live node takes them (``stream.py``); which topic, which time and which messages
are skipped: docs/bags.md, "``process`` on a bag". Sample times are kept as integer stamps
(``BagRecording.stamp_ns``, for ``--out-bag``) and as ``time_s`` from the first accepted sample;
gaps longer than ``max_gap_s`` are counted (``process.predict`` restarts the window there).

A bag path is a rosbag2 directory or a single ``.mcap`` / ``.db3`` storage file (read on its own).
A cut or damaged bag is read as far as it goes (``bag_recover.py``, through ``open_bag``);
``bag_records`` gives any topic's raw CDR records, for readers of other message types.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from ..core.channels import CHANNELS, N_CHANNELS
from ..core.errors import RecordingError
from ..core.rejections import SampleRejected
from ..core.stamps import StreamGuard
from . import bag_recover
from .bag_recover import STORAGE_SUFFIXES, RawRecord
from .cdr import stamp_to_ns
from .read_options import DEFAULT_MAX_GAP_S, ReadOptions
from .recording import Recording
from .stream import UNITS, angles_from_array, angles_from_named

JOINT_STATE = "sensor_msgs/msg/JointState"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
INPUT_MSGTYPES = {"joint_state": JOINT_STATE, "float64_multi_array": FLOAT64_MULTI_ARRAY}
"""``--type`` / ``input_type`` names of the supported input message types."""

DEFAULT_TOPIC = "/segment_angles"

UNDECODABLE = "undecodable"
"""Skip reason for a message whose serialized data cannot be decoded as its declared type."""


@lru_cache(maxsize=1)
def typestore() -> Any:
    """The rosbags type store for ROS 2 Jazzy message definitions."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def normalize_topic(topic: str) -> str:
    """Absolute topic name as stored in bags: ``segment_angles`` -> ``/segment_angles``."""
    topic = topic.strip()
    return topic if topic.startswith("/") else "/" + topic


def since_time_zero(stamp_ns: np.ndarray | int, first_ns: int | None = None) -> np.ndarray | int:
    """Stamps (int ns) -> ns since a bag's time 0: the stamp of its first sample taken (``first_ns``,
    default the first of ``stamp_ns``): an angle message, or four Imu messages paired, also while the
    IMU calibration is learnt (``--as-node``: ``GaitStream.first_stamp_ns``). ``time_s`` is this * 1e-9."""
    return stamp_ns - (stamp_ns[0] if first_ns is None else first_ns)


# ---------------------------------------------------------------------------------------------
# The recording


@dataclass
class BagRecording(Recording):
    """A Recording read from one topic of a bag; keeps the original time stamps.

    ``time_s`` is seconds since the first accepted sample's stamp (so summaries and CSVs start
    at 0); the integer stamps below are what ``--out-bag`` stamps its outputs with.

    Attributes:
        stamp_ns: Sample time stamps used, ns since the epoch (header stamp, or the log time
            when the stamp was zero or the type has no header), int64 (T,).
        log_time_ns: The bag's receive (log) time of every sample, ns since the epoch, int64 (T,).
        bag: The bag path.
        topic: The topic read.
        msgtype: Its message type, e.g. ``sensor_msgs/msg/JointState``.
        messages: Messages on the topic (accepted + skipped).
        stamp_fallbacks: Accepted samples whose time is the log time because their header stamp
            was zero.
        resets: Gaps longer than ``max_gap_s`` (the matcher window restarts there).
        max_gap_s: The gap threshold used, seconds.
    """

    stamp_ns: np.ndarray | None = None
    log_time_ns: np.ndarray | None = None
    bag: str = ""
    topic: str = ""
    msgtype: str = ""
    messages: int = 0
    stamp_fallbacks: int = 0
    resets: int = 0
    max_gap_s: float = DEFAULT_MAX_GAP_S
    recovered: str = ""
    """One line on what was recovered from a damaged bag ('' for an intact bag)."""
    PER_SAMPLE: ClassVar[tuple[str, ...]] = (*Recording.PER_SAMPLE, "stamp_ns", "log_time_ns")

    @property
    def notes(self) -> list[str]:
        """One-line remarks for the user: time-stamp fallbacks and window restarts."""
        out = []
        if self.msgtype == FLOAT64_MULTI_ARRAY:
            out.append(f"{self.topic} is {FLOAT64_MULTI_ARRAY} (no header): sample times are the bag's receive times")
        elif self.stamp_fallbacks:
            out.append(
                f"{self.stamp_fallbacks} message(s) on {self.topic} had a zero header stamp: "
                "used the bag's receive time for them"
            )
        if self.resets:
            out.append(
                f"{self.resets} gap(s) longer than {self.max_gap_s:g} s on {self.topic}: "
                "the matcher window restarted there (as in the live node)"
            )
        return out


# ---------------------------------------------------------------------------------------------
# Opening bags, with one-line errors


def is_bag_path(p: Path) -> bool:
    """True for what looks like a bag: a directory with metadata.yaml or .mcap/.db3 files, or
    such a storage file itself."""
    if p.is_dir():
        return (p / "metadata.yaml").is_file() or any(f.suffix in STORAGE_SUFFIXES for f in p.iterdir())
    return p.is_file() and p.suffix.lower() in STORAGE_SUFFIXES


@contextmanager
def open_bag(path: str | Path, topic: str | None = None, all_topics: bool = False, quiet: bool = False) -> Iterator[Any]:
    """Open a bag with rosbags; every failure (while opening or reading inside the ``with``
    block) becomes a one-line RecordingError naming the bag and the topic asked for.

    A damaged bag (``bag_recover.damage``: an mcap file cut before its summary, a .db3 with an
    unfinished transaction, a directory whose metadata.yaml is missing or disagrees with its
    files) yields a ``bag_recover.RecoveredBag`` instead, with the same reader interface, after
    one warning line on stderr saying what was recovered; RecordingError if nothing was.
    ``all_topics``: errors name the bag only (for readers of every topic, e.g. ``repair``);
    ``quiet``: no warning line (for a look at the topics before the bag is read)."""
    from rosbags.rosbag2 import Reader

    p = Path(path)
    where = str(p) if all_topics else f"{p} (topic {topic or DEFAULT_TOPIC + ' by default'})"
    reader: Any = None
    try:
        if reason := bag_recover.damage(p):
            reader = bag_recover.open_recovered(p, reason)
        else:
            reader = Reader(p)
            reader.open()
            if reason := bag_recover.count_disagreement(reader):
                reader.close()
                reader = bag_recover.open_recovered(p, reason)
    except RecordingError as exc:
        raise RecordingError(f"{where}: {str(exc).removeprefix(f'{p}: ')}") from None
    except Exception as exc:  # rosbags raises many kinds for damaged files
        raise RecordingError(f"{where}: cannot open bag, truncated or corrupt? ({_one_line(exc)})") from None
    if isinstance(reader, bag_recover.RecoveredBag) and not quiet:
        print(f"warning: {reader.recovery.line()}", file=sys.stderr, flush=True)
    try:
        yield reader
    except (RecordingError, KeyboardInterrupt):
        raise
    except Exception as exc:
        raise RecordingError(f"{where}: cannot read bag, truncated or corrupt? ({_one_line(exc)})") from None
    finally:
        with suppress(Exception):  # closing a damaged bag may fail again; reported above
            reader.close()


def bag_records(path: str | Path, topics: Sequence[str] | None = None) -> Iterator[RawRecord]:
    """Every message on ``topics`` (default: all topics) of an intact or damaged bag as
    ``RawRecord(topic, msgtype, log_time_ns, data)``, CDR bytes undecoded, in the bag's order
    (a damaged bag: file order, after the one warning line of ``open_bag``).

    Raises:
        RecordingError: one line (a topic missing, nothing readable, a corrupt bag).
    """
    wanted = [normalize_topic(t) for t in topics] if topics else []
    with open_bag(path, ", ".join(wanted) or None, all_topics=not wanted) as reader:
        conns = [c for c in reader.connections if not wanted or c.topic in wanted]
        missing = sorted(set(wanted) - {c.topic for c in conns})
        if missing:
            raise RecordingError(f"{path}: no topic {', '.join(missing)}; {format_topics(bag_topics(reader))}")
        for conn, log_ns, data in reader.messages(connections=conns):
            yield RawRecord(conn.topic, conn.msgtype, int(log_ns), bytes(data))


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 300 else text[:297] + "..."


def bag_topics(reader: Any) -> dict[str, tuple[str, int]]:
    """{topic: (message type, message count)} of an open reader."""
    return {name: (info.msgtype or "(several types)", int(info.msgcount)) for name, info in reader.topics.items()}


def format_topics(topics: dict[str, tuple[str, int]]) -> str:
    if not topics:
        return "the bag has no topics"
    return "topics in the bag: " + ", ".join(f"{t} [{ty}, {n} msgs]" for t, (ty, n) in sorted(topics.items()))


def choose_topic(bag: Path, topics: dict[str, tuple[str, int]], topic: str | None) -> str:
    """The topic to read: ``topic`` if given (must exist); otherwise DEFAULT_TOPIC if present,
    else the only topic of a supported input type."""
    if topic:
        name = normalize_topic(topic)
        if name not in topics:
            raise RecordingError(f"{bag}: no topic {name}; {format_topics(topics)}")
        return name
    if DEFAULT_TOPIC in topics:
        return DEFAULT_TOPIC
    supported = [t for t, (ty, _) in topics.items() if ty in INPUT_MSGTYPES.values()]
    if len(supported) == 1:
        return supported[0]
    raise RecordingError(
        f"{bag}: no topic {DEFAULT_TOPIC} and {'several' if supported else 'no'} topics of type "
        f"{JOINT_STATE} or {FLOAT64_MULTI_ARRAY}: choose one with --topic; {format_topics(topics)}"
    )


# ---------------------------------------------------------------------------------------------
# Reading samples


def parse_joint_names(joint_names: Sequence[str] | str | None) -> tuple[str, ...]:
    """JointState names of the CHANNELS (default: theirs; or comma-separated); four distinct ones."""
    if joint_names is None:
        return CHANNELS
    if isinstance(joint_names, str):
        joint_names = [j.strip() for j in joint_names.split(",")]
    names = tuple(joint_names)
    if len(names) != N_CHANNELS or not all(names) or len(set(names)) != N_CHANNELS:
        raise RecordingError(f"joint names must be {N_CHANNELS} distinct names ({', '.join(CHANNELS)}), got {names}")
    return names


def read_bag(path: str | Path, options: ReadOptions | None = None, /, **values: Any) -> BagRecording:
    """Read the driver topic of a bag into a BagRecording (angles in degrees, CHANNELS order).

    Args:
        path: rosbag2 directory or .mcap/.db3 file.
        options, values: ReadOptions, then fields by name; ``topic``, ``joint_names``,
            ``input_units`` and ``max_gap_s`` concern a bag of angles.

    Raises:
        RecordingError: one line naming the bag and topic (missing topic, unsupported type,
            damaged bag, no usable samples).
    """
    p = Path(path)
    o = ReadOptions.of(options, values)
    max_gap = float(o.max_gap_s)
    if math.isnan(max_gap):
        raise RecordingError(f"max_gap_s must be a number of seconds, got {o.max_gap_s!r}")
    with _angle_topic(p, o) as (reader, name, msgtype, samples):
        try:
            rec = _read_samples(p, name, msgtype, samples, max_gap)
            recovery = getattr(reader, "recovery", None)
            rec.recovered = recovery.line() if recovery else ""
            return rec
        except (RecordingError, KeyboardInterrupt):
            raise
        except Exception as exc:
            raise RecordingError(f"{p} (topic {name}): cannot read bag, truncated or corrupt? ({_one_line(exc)})") from None


def decoded_samples(messages: Iterator[tuple[Any, int, bytes]], msgtype: str, joint_names: tuple[str, ...],
                    units: str) -> Iterator[tuple[int, int, int, bool, np.ndarray | SampleRejected | None]]:
    """Per message of an angle topic: (index, log time ns, stamp ns, the JointState's stamp was
    zero, angles in degrees or why the message is dropped; None: undecodable CDR). The stamp is
    the header's, or the log time when it is zero or the type has no header."""
    deserialize = typestore().deserialize_cdr
    is_joint_state = msgtype == JOINT_STATE
    for i, (_conn, log_ns, raw) in enumerate(messages):
        try:
            msg = deserialize(raw, msgtype)
        except Exception:  # corrupt CDR: skip the message, like a node that never received it
            yield i, int(log_ns), 0, False, None
            continue
        try:
            if is_joint_state:
                sample = angles_from_named(msg.name, msg.position, joint_names, units)
                stamp_ns = stamp_to_ns(msg.header.stamp)
                fallback = stamp_ns == 0
                if fallback:
                    stamp_ns = int(log_ns)
            else:
                sample = angles_from_array(msg.data, units)
                stamp_ns, fallback = int(log_ns), False
        except SampleRejected as exc:
            yield i, int(log_ns), 0, False, exc
            continue
        yield i, int(log_ns), stamp_ns, fallback, sample


@contextmanager
def _angle_topic(p: Path, o: ReadOptions) -> Iterator[tuple[Any, str, str, Iterator[tuple[int, int, int, bool, Any]]]]:
    """The open bag, its angle topic (``choose_topic``), that topic's message type and its
    ``decoded_samples``."""
    names = parse_joint_names(o.joint_names)
    if o.input_units not in UNITS:
        raise RecordingError(f"input units must be one of {', '.join(UNITS)}, got {o.input_units!r}")
    with open_bag(p, o.topic and normalize_topic(o.topic)) as reader:
        topics = bag_topics(reader)
        name = choose_topic(p, topics, o.topic)
        msgtype = topics[name][0]
        if msgtype not in INPUT_MSGTYPES.values():
            raise RecordingError(f"{p}: topic {name} has message type {msgtype}; expected {JOINT_STATE} or "
                                 f"{FLOAT64_MULTI_ARRAY}")
        conns = [c for c in reader.connections if c.topic == name]
        yield reader, name, msgtype, decoded_samples(reader.messages(connections=conns), msgtype, names, o.input_units)


@contextmanager
def bag_samples(path: str | Path, options: ReadOptions | None = None, /,
                **values: Any) -> Iterator[tuple[str, Iterator[tuple[int, int, int, bool, Any]]]]:
    """The angle topic of a bag as ``read_bag`` chooses it: (its message type, ``decoded_samples``
    of all its messages), for a caller that takes each message as a live node would."""
    with _angle_topic(Path(path), ReadOptions.of(options, values)) as (_, _, msgtype, samples):
        yield msgtype, samples


def _read_samples(bag: Path, topic: str, msgtype: str, samples: Iterator[tuple[int, int, int, bool, Any]],
                  max_gap_s: float) -> BagRecording:
    guard = StreamGuard(max_gap_s=max_gap_s)
    angles: list[np.ndarray] = []
    stamps: list[int] = []
    logs: list[int] = []
    index: list[int] = []
    undecodable = 0
    fallbacks = 0
    n = 0
    for i, log_ns, stamp_ns, fallback, sample in samples:
        n = i + 1
        if sample is None:
            undecodable += 1
            continue
        try:
            if isinstance(sample, SampleRejected):
                raise sample
            guard.accept(stamp_ns * 1e-9)  # counts gaps > max_gap_s in guard.resets
        except SampleRejected as exc:
            guard.reject(exc)
            continue
        fallbacks += fallback
        angles.append(sample)
        stamps.append(stamp_ns)
        logs.append(log_ns)
        index.append(i)
    skipped = {reason: int(c) for reason, c in guard.rejected.items() if c}
    if undecodable:
        skipped[UNDECODABLE] = undecodable
    if not angles:
        why = "; skipped: " + ", ".join(f"{c} {r}" for r, c in skipped.items()) if skipped else ""
        raise RecordingError(f"{bag}: topic {topic}: no usable samples in {n} message(s){why}")
    stamp_arr = np.array(stamps, dtype=np.int64)
    return BagRecording(
        time_s=since_time_zero(stamp_arr) * 1e-9,
        angles_deg=np.array(angles, dtype=np.float64).reshape(-1, N_CHANNELS),
        source=f"{bag} {topic}",
        index=np.array(index, dtype=np.int64),
        skipped=skipped,
        stamp_ns=stamp_arr,
        log_time_ns=np.array(logs, dtype=np.int64),
        bag=str(bag),
        topic=topic,
        msgtype=msgtype,
        messages=n,
        stamp_fallbacks=fallbacks,
        resets=guard.resets,
        max_gap_s=max_gap_s,
    )
