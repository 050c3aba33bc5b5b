"""Publishing a recording into the live ROS 2 graph with its recorded timing (``play``).

For machines without ``ros2 bag``. rclpy is imported only inside ``play``; loading a playlist is
ROS-free. The domain and discovery range come from the environment, as for any ROS 2 process.
Timing, stamps, ``/clock`` and ``loop``: docs/bags.md, "``play``" (a bag's messages go out
unchanged at their log times; a CSV's are stamped from the wall clock at the start; each loop
shifts stamps and ``/clock`` by the duration plus one median interval, so they keep increasing).
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..core.channels import CHANNELS
from ..core.errors import GaitEstimatorError, RecordingError
from ..io.bag import format_topics, is_bag_path, normalize_topic, open_bag, typestore
from ..io.bag_write import serialize_inputs
from ..io.cdr import CdrError, read_stamp, stamp_to_ns, with_stamp
from ..io.outputs import ESTIMATE_TOPIC, INPUT_TOPIC, OUTPUT_TOPICS
from ..io.recording import Recording

HEADER_TYPE = "std_msgs/msg/Header"
LINGER_S = 0.5
"""Wall seconds the publishers stay up after the last message (rmw_fastrtps publishes
asynchronously: destroying the node at once can lose the last messages to best-effort readers)."""
SETTLE_S = 0.5
"""Wall seconds waited after every topic has a subscriber (``wait_for_subscribers_s``)."""
CLOCK_TOPIC = "/clock"
DEFAULT_QOS_DEPTH = 1000
"""Publisher history depth (reliable, volatile): deep enough that a subscriber that stalls for a
few seconds at 230 Hz still gets every sample."""


@dataclass(frozen=True)
class Track:
    """One published topic: name, ROS message type, whether messages start with a Header."""

    topic: str
    msgtype: str
    has_header: bool


@dataclass
class Playlist:
    """Serialized messages in publishing order.

    Attributes:
        tracks: The topics.
        time_ns: Recorded time of every message (timeline), int64 ns: log time (bag) or
            CSV time since the first sample (``relative``).
        track: Index into ``tracks`` of every message.
        data: CDR-serialized messages.
        relative: True when the timeline and stamps start at 0 and are offset to the wall
            clock at playback (CSV), False for absolute bag times.
        source: Where the messages came from (for messages).
    """

    tracks: list[Track]
    time_ns: np.ndarray
    track: np.ndarray
    data: list[bytes]
    relative: bool
    source: str

    def __len__(self) -> int:
        return len(self.data)

    @property
    def loop_period_ns(self) -> int:
        """Shift between loop repetitions: duration + one median message interval (>= 1 ns)."""
        if len(self) < 2:
            return 1_000_000_000
        dt = np.diff(self.time_ns)
        step = int(np.median(dt[dt > 0])) if np.any(dt > 0) else 1_000_000
        return int(self.time_ns[-1] - self.time_ns[0]) + max(step, 1)


def _has_header(msgtype: str) -> bool:
    try:
        fields = typestore().get_msgdef(msgtype).fields
    except Exception:  # a type rosbags does not know: publish verbatim, never patch
        return False
    return bool(fields) and fields[0][0] == "header" and fields[0][1][1] == HEADER_TYPE


def playlist_from_bag(path: str | Path, topics: Sequence[str] | None = None) -> Playlist:
    """All messages of ``topics`` (default: every topic) of a bag, in log-time order."""
    p = Path(path)
    wanted = [normalize_topic(t) for t in topics] if topics else None
    with open_bag(p, ", ".join(wanted) if wanted else None) as reader:
        infos = {name: info.msgtype for name, info in reader.topics.items()}
        if wanted:
            missing = [t for t in wanted if t not in infos]
            if missing:
                from ..io.bag import bag_topics

                raise GaitEstimatorError(f"{p}: no topic {', '.join(missing)}; {format_topics(bag_topics(reader))}")
        names = wanted or sorted(infos)
        spaces = {n.rsplit("/", 1)[0] for n in names if n.rsplit("/", 1)[-1] == ESTIMATE_TOPIC}  # an estimator's
        outputs = [n for n in names if n.rsplit("/", 1)[-1] in OUTPUT_TOPICS and n.rsplit("/", 1)[0] in spaces]
        if outputs and not wanted:  # RecordingError: open_bag passes it on as it is
            raise RecordingError(
                f"{p}: holds estimator output ({', '.join(outputs)}): not played unless chosen, as it would "
                "reach the running graph's controllers; name the topics to play with --topic (repeat it)"
            )
        for name in names:
            if infos[name] is None:
                raise GaitEstimatorError(f"{p}: topic {name} has several message types; cannot play it")
        tracks = [Track(name, infos[name], _has_header(infos[name])) for name in names]
        index = {t.topic: i for i, t in enumerate(tracks)}
        conns = [c for c in reader.connections if c.topic in index]
        times: list[int] = []
        track: list[int] = []
        data: list[bytes] = []
        for conn, log_ns, raw in reader.messages(connections=conns):
            times.append(int(log_ns))
            track.append(index[conn.topic])
            data.append(bytes(raw))
    t = np.array(times, dtype=np.int64)
    order = np.argsort(t, kind="stable")
    return Playlist(tracks, t[order], np.array(track, dtype=np.int64)[order], [data[i] for i in order], False, str(p))


def playlist_from_recording(
    rec: Recording,
    topic: str = INPUT_TOPIC,
    msg_type: str = "joint_state",
    units: str = "rad",
    joint_names: Sequence[str] = CHANNELS,
) -> Playlist:
    """One driver message per sample of ``rec``, timeline = ``time_s`` since the first sample.

    ``topic`` may be relative (resolved in the player node's namespace, like the node's input).
    """
    from ..io.bag import INPUT_MSGTYPES

    if len(rec) == 0:
        raise GaitEstimatorError(f"{rec.source}: no samples to play")
    rel = np.rint((rec.time_s - rec.time_s[0]) * 1e9).astype(np.int64)
    data = [bytes(m) for m in serialize_inputs(rec, rel, msg_type=msg_type, units=units, joint_names=joint_names)]
    msgtype = INPUT_MSGTYPES[msg_type]
    track = Track(topic, msgtype, _has_header(msgtype))
    return Playlist([track], rel, np.zeros(len(rel), dtype=np.int64), data, True, rec.source)


def load_playlist(
    path: str | Path,
    topics: Sequence[str] | None = None,
    msg_type: str = "joint_state",
    units: str = "rad",
    joint_names: Sequence[str] = CHANNELS,
    **reader_options: Any,
) -> Playlist:
    """A bag (every topic, or ``topics``) or any other recording (one topic: ``topics[0]``,
    default ``segment_angles``) as a Playlist."""
    p = Path(path)
    if is_bag_path(p):
        return playlist_from_bag(p, topics)
    from ..io.readers import read_recording

    if topics and len(topics) > 1:
        raise GaitEstimatorError(f"{p}: a recording is played on one topic, got {len(topics)} --topic options")
    rec = read_recording(p, **reader_options)
    return playlist_from_recording(rec, topics[0] if topics else INPUT_TOPIC, msg_type, units, joint_names)


def _ros_message_class(msgtype: str) -> Any:
    pkg, _, name = msgtype.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError):
        return None


def play(
    playlist: Playlist,
    *,
    rate: float = 1.0,
    loop: bool = False,
    clock: bool = False,
    wait_for_subscribers_s: float = 0.0,
    qos_depth: int = DEFAULT_QOS_DEPTH,
    node_name: str = "gait_estimator_player",
    log: Callable[[str], None] = print,
) -> int:
    """Publish ``playlist`` with its recorded timing; returns the number of messages published.

    Args:
        playlist: What to publish.
        rate: Playback speed factor (> 0): 2.0 = twice as fast.
        loop: Repeat until interrupted (stamps keep increasing, see the module docstring).
        clock: Also publish rosgraph_msgs/Clock on /clock (for nodes with use_sim_time).
        wait_for_subscribers_s: If > 0, first wait up to this long (seconds, wall clock) until
            every topic has a subscriber; GaitEstimatorError if one is still missing.
        qos_depth: Publisher history depth (reliable, volatile).

    Raises:
        GaitEstimatorError: bad arguments, a message type without Python bindings, no
            subscriber in time. KeyboardInterrupt propagates after a clean shutdown.
    """
    if not (rate > 0 and np.isfinite(rate)):
        raise GaitEstimatorError(f"--rate must be a positive number, got {rate}")
    if len(playlist) == 0:
        raise GaitEstimatorError(f"{playlist.source}: no messages to play")
    classes = {}
    for tr in playlist.tracks:
        cls = _ros_message_class(tr.msgtype)
        if cls is None:
            raise GaitEstimatorError(
                f"{playlist.source}: cannot play {tr.topic}: message type {tr.msgtype} has no Python bindings "
                "in this ROS environment (select other topics with --topic)"
            )
        classes[tr.topic] = cls

    import rclpy
    from rclpy.duration import Duration
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from rosgraph_msgs.msg import Clock

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    published = [0]  # counted by _publish_loop, also when Ctrl-C interrupts it
    node = None
    try:
        node = rclpy.create_node(node_name, context=context, start_parameter_services=False)
        qos = QoSProfile(
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE,
            history=HistoryPolicy.KEEP_LAST,
            depth=max(1, int(qos_depth)),
        )
        pubs = [node.create_publisher(classes[tr.topic], tr.topic, qos) for tr in playlist.tracks]
        clock_pub = node.create_publisher(Clock, CLOCK_TOPIC, QoSProfile(depth=100)) if clock else None
        if wait_for_subscribers_s > 0:
            _wait_for_subscribers(pubs, playlist.source, wait_for_subscribers_s)
        _publish_loop(playlist, pubs, clock_pub, Clock, rate, loop, published)
        for pub in pubs:  # reliable subscribers: until they have everything
            pub.wait_for_all_acked(Duration(seconds=2))
        time.sleep(LINGER_S)  # best-effort subscribers: the last messages may still be in flight
        log(
            f"published {published[0]} message(s) from {playlist.source} on "
            + ", ".join(p.topic_name for p in pubs)
            + (" and /clock" if clock_pub else "")
        )
    except KeyboardInterrupt:
        log(f"interrupted after {published[0]} message(s)")
        raise
    finally:
        if node is not None:
            node.destroy_node()
        context.try_shutdown()
    return published[0]


def _wait_for_subscribers(pubs: list[Any], source: str, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        missing = [p.topic_name for p in pubs if p.get_subscription_count() == 0]
        if not missing:
            # Discovery is not symmetric: a subscriber we see may not have matched us yet, and
            # what we send before it has is lost. Nothing observable tells; give it a moment.
            time.sleep(SETTLE_S)
            return
        if time.monotonic() >= deadline:
            raise GaitEstimatorError(f"{source}: no subscriber on {', '.join(missing)} after {timeout_s:g} s")
        time.sleep(0.05)


def _publish_loop(playlist: Playlist, pubs: list[Any], clock_pub: Any, clock_cls: Any, rate: float, loop: bool,
                  published: list[int]) -> None:
    """Publish every message at wall time start + (t_i - t_0 + k * period) / rate, counting them in
    ``published[0]``."""
    times = playlist.time_ns
    t0 = int(times[0])
    offsets = (times - t0).astype(np.float64) / (rate * 1e9)  # seconds after the start, wall clock
    period = playlist.loop_period_ns
    stamp_shift0 = time.time_ns() if playlist.relative else 0
    has_header = [tr.has_header for tr in playlist.tracks]
    start = time.monotonic()
    k = 0
    clock_msg = clock_cls() if clock_pub is not None else None
    while True:
        shift = stamp_shift0 + k * period  # added to header stamps and to the timeline for /clock
        loop_start = start + k * period / (rate * 1e9)
        for i, raw in enumerate(playlist.data):
            delay = loop_start + offsets[i] - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            tr = int(playlist.track[i])
            if clock_msg is not None:
                sec, nanosec = divmod(int(times[i]) + shift, 1_000_000_000)
                clock_msg.clock.sec, clock_msg.clock.nanosec = sec, nanosec
                clock_pub.publish(clock_msg)
            if shift and has_header[tr]:
                try:
                    raw = with_stamp(raw, stamp_to_ns(read_stamp(raw)) + shift)
                except CdrError:  # not plain CDR (e.g. XCDR2): looped with its recorded stamp
                    pass
            published[0] += 1  # counted first: a Ctrl-C inside publish() still counts this message
            pubs[tr].publish(raw)
        if not loop:
            return
        k += 1

