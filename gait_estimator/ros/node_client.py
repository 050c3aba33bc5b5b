"""Driving ``estimator_node`` from Python: start it, stream samples into it, collect its outputs.

Used by ``gait-estimator demo``, ``gait-estimator bench-node`` and the node tests, over real DDS
restricted to this machine (``node_process.py``, re-exported here, sets that up).
"""

from __future__ import annotations

import array
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.context import Context
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import Float64, Float64MultiArray, String

from ..core.channels import CHANNELS
from ..core.estimator import EstimateTrace
from ..core.kernels import KernelLibrary
from ..core.states import name_index, reported_names
from ..io.cdr import read_stamp, stamp_to_ns
from ..io.imu_bag import DEFAULT_IMU_TOPICS
from ..io.outputs import ESTIMATE_TAIL, ESTIMATE_TOPIC, INPUT_TOPIC, MODE_TOPIC, PHASE_TOPIC, SSE_TOPIC, estimate_names
from .diagnostics import DIAGNOSTICS_TOPIC
from .node_process import (  # noqa: F401 - re-exported: the node client's users start nodes too
    NODE_MODULE,
    Closes,
    NodeProcess,
    local_ros_environment,
    node_command,
    spin_executor_until,
    use_local_ros,
)
from .outputs import double_array


@dataclass
class Received:
    """What a client collected from the node.

    ``estimate_recv_ns``: ``time.perf_counter_ns()`` when the client's callback got the message;
    ``estimate_dds_ns`` / ``estimate_source_ns``: the system-clock times (``time.time_ns()``) at
    which the message reached the client's DDS reader / was written by the node (message info).
    """

    estimate_stamp_ns: list[int] = field(default_factory=list)
    estimate_values: list[np.ndarray] = field(default_factory=list)
    estimate_names: list[str] = field(default_factory=list)
    estimate_recv_ns: list[int] = field(default_factory=list)
    estimate_dds_ns: list[int] = field(default_factory=list)
    estimate_source_ns: list[int] = field(default_factory=list)
    modes: list[str] = field(default_factory=list)
    phases: list[float] = field(default_factory=list)
    sse: list[np.ndarray] = field(default_factory=list)
    sse_label: str = ""
    diagnostics: list[dict[str, str]] = field(default_factory=list)
    diagnostics_level: list[int] = field(default_factory=list)
    diagnostics_message: list[str] = field(default_factory=list)
    profile: list[np.ndarray] = field(default_factory=list)
    """``~/profile`` blocks of the node (rows x PROFILE_COLUMNS), if subscribed."""

    def clear(self) -> None:
        for name in (
            "estimate_stamp_ns", "estimate_values", "estimate_recv_ns", "estimate_dds_ns", "estimate_source_ns",
            "modes", "phases", "sse", "profile",
        ):
            getattr(self, name).clear()

    def estimates(self) -> np.ndarray:
        """Received estimate values, (K, len(estimate_names))."""
        return np.array(self.estimate_values) if self.estimate_values else np.empty((0, 0))

    def trace(self, mode_names: Sequence[str]) -> EstimateTrace:
        """The received estimates as an EstimateTrace (as offline ``run_estimator`` returns; time:
        the stamps, s; sample: the arrival order), ``mode`` from each estimate's ``state``."""
        m = len(mode_names)
        v = self.estimates().reshape(-1, len(estimate_names(mode_names)))
        tail = dict(zip(ESTIMATE_TAIL, v[:, 3 + 2 * m:].T, strict=True))
        mode_index, state = v[:, 0].astype(np.int64), tail.pop("state").astype(np.int64)
        names = np.asarray(reported_names(list(mode_names)), dtype=object)
        return EstimateTrace(
            list(mode_names), np.asarray(self.estimate_stamp_ns, dtype=np.float64) / 1e9, np.arange(len(v)),
            mode_index, v[:, 1].copy(), v[:, 2] > 0.5, v[:, 3 : 3 + m].copy(), v[:, 3 + m : 3 + 2 * m].copy(),
            tail.pop("raw_mode_index").astype(np.int64), held=tail.pop("held") > 0.5, state=state,
            mode=names[name_index(state, mode_index, len(names))], **tail,
        )


def drained_subscription(node: Node, msg_type: Any, topic: str, callback: Callable[[Any, Any], None], qos: Any,
                         raw: bool = False) -> Subscription:
    """A subscription of ``node`` whose ``callback(msg, info)`` also takes the messages queued
    behind the first one (rclpy's executor costs hundreds of microseconds per wake-up; see
    EstimatorNode._on_input). ``info`` is the message info (a SingleThreadedExecutor passes it;
    rclpy 7.1's EventsExecutor cannot)."""

    def on_message(msg: Any, info: Any) -> None:
        callback(msg, info)
        for _ in range(200):
            try:
                with sub.handle:
                    taken = sub.handle.take_message(sub.msg_type, sub.raw)
            except InvalidHandle:
                return
            if taken is None:
                return
            callback(taken[0], taken[1])

    sub = node.create_subscription(msg_type, topic, on_message, qos, raw=raw)
    return sub


class EstimatorClient(Closes):
    """A ROS node that feeds ``segment_angles`` and records the estimator's outputs.

    Args:
        domain_id: ROS domain (a private context is created with it).
        input_type: ``joint_state`` or ``float64_multi_array``; or ``imu``: four ``sensor_msgs/Imu``
            topics (the node's default ``imu_topics``), fed serialised messages (``stream``).
        reliable: Publish input reliably (default best effort, like most sensor drivers).
        joint_names: JointState names for the four channels (CHANNELS order).
        namespace: Namespace of the estimator's topics (relative names are used otherwise).
        record: Keep received messages (turn off for long runs where only counts matter). Off,
            ``estimate`` arrives serialised and only its stamp is read: the client's CPU stays
            with the node under test, whatever the number of modes (names) in the message.
        context: An initialised rclpy Context to use instead of creating one (the caller owns it).
        extra_nodes: Further nodes (e.g. an in-process EstimatorNode) to spin in the same executor.
        node_name: This client's node name.
        outputs: The estimator topics to subscribe to (the node skips topics nobody listens to).
        estimator_name: Keep only diagnostics of the estimator node with this fully qualified name
            (e.g. ``/estimator_node``; default: any).
        profile_topic: Also subscribe to the node's ``~/profile`` topic under this full name
            (e.g. ``/estimator_node/profile``), which makes the node record it.
    """

    def __init__(
        self,
        domain_id: int,
        input_type: str = "joint_state",
        reliable: bool = False,
        joint_names: Sequence[str] = CHANNELS,
        namespace: str = "",
        record: bool = True,
        context: Context | None = None,
        extra_nodes: Sequence[Node] = (),
        node_name: str = "gait_estimator_client",
        outputs: Sequence[str] = (ESTIMATE_TOPIC, MODE_TOPIC, PHASE_TOPIC, SSE_TOPIC, DIAGNOSTICS_TOPIC),
        estimator_name: str | None = None,
        profile_topic: str | None = None,
    ) -> None:
        self._own_context = context is None
        if context is None:
            context = Context()
            rclpy.init(context=context, domain_id=int(domain_id))
        self.context = context
        self.node = Node(node_name, namespace=namespace or None, context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        for n in extra_nodes:
            self.executor.add_node(n)
        self.input_type = input_type
        self._diag_prefix = f"{estimator_name}: " if estimator_name else None
        self.joint_names = list(joint_names)
        self.record = record
        self.received = Received()
        self.estimate_count = 0
        self.mode_count = 0
        self.phase_count = 0
        self.on_mode: Callable[[str], None] | None = None
        self.on_phase: Callable[[float], None] | None = None
        in_qos = QoSProfile(
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            history=HistoryPolicy.KEEP_LAST,
            depth=1000 if reliable else 10,
        )
        if input_type == "imu":
            self.input_publishers = [self.node.create_publisher(Imu, t, in_qos) for t in DEFAULT_IMU_TOPICS]
        else:
            msg_type = JointState if input_type == "joint_state" else Float64MultiArray
            self.publisher = self.node.create_publisher(msg_type, INPUT_TOPIC, in_qos)
            self.input_publishers = [self.publisher]
        out_qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=5000)
        subs = {
            ESTIMATE_TOPIC: (JointState, self._on_estimate if record else self._on_estimate_serialized, out_qos),
            MODE_TOPIC: (String, self._on_mode, out_qos),
            PHASE_TOPIC: (Float64, self._on_phase, out_qos),
            SSE_TOPIC: (Float64MultiArray, self._on_sse, out_qos),
            DIAGNOSTICS_TOPIC: (DiagnosticArray, self._on_diagnostics, 10),
        }
        unknown = set(outputs) - set(subs)
        if unknown:
            raise ValueError(f"unknown output topic(s) {sorted(unknown)}")
        if profile_topic:
            subs[profile_topic] = (Float64MultiArray, self._on_profile, 10)
            outputs = (*outputs, profile_topic)
        self._subs = []
        for topic in outputs:
            msg_type, callback, qos = subs[topic]
            raw = topic == ESTIMATE_TOPIC and not record
            self._subs.append(drained_subscription(self.node, msg_type, topic, callback, qos, raw))
        self._js = JointState()
        self._js.name = self.joint_names
        self._fma = Float64MultiArray()

    # -- callbacks

    def _estimate_arrived(self, stamp: Any, info: dict[str, Any]) -> None:
        self.estimate_count += 1
        r = self.received
        r.estimate_recv_ns.append(time.perf_counter_ns())
        r.estimate_dds_ns.append(info["received_timestamp"])
        r.estimate_source_ns.append(info["source_timestamp"])
        r.estimate_stamp_ns.append(stamp_to_ns(stamp))

    def _on_estimate(self, msg: JointState, info: dict[str, Any]) -> None:
        self._estimate_arrived(msg.header.stamp, info)
        if self.record:
            r = self.received
            r.estimate_values.append(np.frombuffer(msg.position, dtype=np.float64).copy())
            if not r.estimate_names:
                r.estimate_names = list(msg.name)

    def _on_estimate_serialized(self, data: bytes, info: dict[str, Any]) -> None:
        """``estimate`` as CDR bytes: only its stamp is read."""
        self._estimate_arrived(read_stamp(data), info)

    def _on_mode(self, msg: String, _info: Any = None) -> None:
        self.mode_count += 1
        if self.record:
            self.received.modes.append(msg.data)
        if self.on_mode is not None:
            self.on_mode(msg.data)

    def _on_phase(self, msg: Float64, _info: Any = None) -> None:
        self.phase_count += 1
        if self.record:
            self.received.phases.append(msg.data)
        if self.on_phase is not None:
            self.on_phase(msg.data)

    def _on_sse(self, msg: Float64MultiArray, _info: Any = None) -> None:
        if self.record:
            self.received.sse.append(np.frombuffer(msg.data, dtype=np.float64).copy())
            if msg.layout.dim:
                self.received.sse_label = msg.layout.dim[0].label

    def _on_profile(self, msg: Float64MultiArray, _info: Any = None) -> None:
        if len(msg.layout.dim) == 2:
            k = msg.layout.dim[1].size
            self.received.profile.append(np.frombuffer(msg.data, dtype=np.float64).reshape(-1, k).copy())

    def _on_diagnostics(self, msg: DiagnosticArray, _info: Any = None) -> None:
        for st in msg.status:
            if st.name.startswith(self._diag_prefix) if self._diag_prefix else st.name.endswith(": gait estimator"):
                self.received.diagnostics.append({kv.key: kv.value for kv in st.values})
                level = st.level
                self.received.diagnostics_level.append(level[0] if isinstance(level, (bytes, bytearray)) else int(level))
                self.received.diagnostics_message.append(st.message)

    # -- spinning

    def spin_once(self, timeout_s: float = 0.0) -> None:
        self.executor.spin_once(timeout_sec=timeout_s)

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Spin until ``predicate()`` is true (returns True) or ``timeout_s`` passes (False)."""
        return spin_executor_until(self.executor, predicate, timeout_s)

    def spin_for(self, seconds: float) -> None:
        self.spin_until(lambda: False, seconds)

    def wait_for_node(self, timeout_s: float = 20.0, outputs: bool = True, settle_s: float = 0.5) -> bool:
        """Wait until the estimator subscribes to our input (and, if ``outputs``, until our
        subscriptions are matched with its publishers), then ``settle_s`` more.

        Discovery is not symmetric: our publisher can see the node's subscription before the
        node's (best-effort) subscription has matched our publisher, and samples sent in between
        are lost. There is no way to observe the other side's match, hence the settling time.
        """

        def matched() -> bool:
            if any(p.get_subscription_count() < 1 for p in self.input_publishers):
                return False
            return not outputs or all(s.get_publisher_count() >= 1 for s in self._subs if s.topic_name != DIAGNOSTICS_TOPIC)

        if not self.spin_until(matched, timeout_s):
            return False
        self.spin_for(settle_s)
        return True

    def latest_diagnostics(self, timeout_s: float = 3.0, after: int | None = None) -> dict[str, str] | None:
        """A diagnostics report newer than report number ``after`` (default: newer than now)."""
        n = len(self.received.diagnostics) if after is None else after
        self.spin_until(lambda: len(self.received.diagnostics) > n, timeout_s)
        return self.received.diagnostics[-1] if len(self.received.diagnostics) > n else None

    # -- publishing

    def message(self, angles: np.ndarray, stamp_ns: int) -> JointState | Float64MultiArray:
        """Input message for one sample (angles in the units the node expects)."""
        if self.input_type == "imu":
            raise ValueError("input_type 'imu' takes four serialised Imu messages per sample: stream() with "
                             "analysis/imu_sagittal.py imu_samples")
        if self.input_type == "joint_state":
            msg = self._js
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
            msg.position = double_array(angles)
            return msg
        self._fma.data = double_array(angles)
        return self._fma

    def publish(self, angles: np.ndarray, stamp_ns: int = 0) -> None:
        self.publisher.publish(self.message(angles, stamp_ns))

    def stream(
        self,
        angles: np.ndarray,
        stamps_ns: Sequence[int] | np.ndarray,
        rate_hz: float | None,
        due_s: np.ndarray | None = None,
    ) -> np.ndarray:
        """Publish samples paced at ``rate_hz`` (None: as fast as possible), spinning in between.

        Args:
            angles: (T, 4) in the node's input units; for ``imu``, per sample the four sensors'
                serialised Imu messages (analysis/imu_sagittal.py ``imu_samples``, stamped already).
            stamps_ns: (T,) stamps (JointState only; ignored for Float64MultiArray and imu).
            rate_hz: Publication rate, Hz.
            due_s: (T,) publication times, seconds from the start, instead of a fixed rate.

        Returns:
            perf_counter_ns() of every publication (taken just before the publish call; for
            ``imu``, just before the sample's last message's), (T,).
        """
        imu = self.input_publishers if self.input_type == "imu" else None
        n = len(angles)
        sent = np.empty(n, dtype=np.int64)
        period_ns = 0 if not rate_hz else round(1e9 / rate_hz)
        start = time.perf_counter_ns()
        clock = time.perf_counter_ns
        spin = self.executor.spin_once
        offsets = None if due_s is None else np.round(np.asarray(due_s, dtype=np.float64) * 1e9).astype(np.int64)
        for i in range(n):
            due = start + (i * period_ns if offsets is None else int(offsets[i]))
            while True:
                left = due - clock()
                if left <= 0:
                    break
                spin(timeout_sec=min(left, 2_000_000) / 1e9 if left > 200_000 else 0.0)
            if imu is not None:
                m0, m1, m2, m3 = angles[i]
                imu[0].publish(m0), imu[1].publish(m1), imu[2].publish(m2)
                sent[i] = clock()
                imu[3].publish(m3)
            else:
                msg = self.message(angles[i], int(stamps_ns[i]))
                sent[i] = clock()  # before the call: the message may be on its way before publish() returns
                self.publisher.publish(msg)
            if not period_ns:
                spin(timeout_sec=0.0)
        return sent

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        if self._own_context:
            rclpy.try_shutdown(context=self.context)


def publishing_costs_us(lib: KernelLibrary, node: Node) -> dict[str, float]:
    """Per-sample costs in this process, µs, of the node's ways to publish ``estimate``: patching
    its pre-serialised message and publishing the bytes (what the node does), filling a
    preallocated JointState and publishing it, building a fresh one; and a subscriber-count query
    (the node's check before each publish). Published on a topic of ``node`` nobody subscribes
    to: conversion and serialisation, no delivery."""
    import timeit

    from builtin_interfaces.msg import Time as TimeMsg

    from ..analysis.bench import synthetic_walk
    from ..core.estimator import Estimator
    from ..io.outputs import estimate_array, estimate_values
    from .serialized import SerializedJointState

    est = Estimator(lib)
    e = None
    for i, row in enumerate(synthetic_walk(lib, int(lib.lengths.max()) + 20, seed=1)):
        e = est.update(i / lib.sample_rate_hz, row)
    assert e is not None
    names = estimate_names(lib.mode_names)
    stamp = TimeMsg(sec=1, nanosec=0)
    probe = node.create_publisher(JointState, "~/publish_cost_probe", 10)
    serialized = SerializedJointState(names)
    reused = JointState()
    reused.name = names
    buffer = array.array("d", bytes(8 * len(names)))
    view = np.frombuffer(buffer, dtype=np.float64)

    def patch_serialized() -> None:  # what the node does
        serialized.set_stamp(stamp)
        serialized.set_values(estimate_values(e))
        probe.publish(serialized.data())

    def fill_message() -> None:
        reused.header.stamp = stamp
        view[:] = estimate_values(e)
        reused.position = buffer
        probe.publish(reused)

    def fresh() -> None:
        m = JointState()
        m.name = list(names)
        m.header.stamp = stamp
        m.position = [float(v) for v in estimate_array(e)]
        probe.publish(m)

    n = 2000
    try:
        t = {
            "serialized_estimate_publish_us": timeit.timeit(patch_serialized, number=n) / n * 1e6,
            "preallocated_estimate_publish_us": timeit.timeit(fill_message, number=n) / n * 1e6,
            "fresh_estimate_publish_us": timeit.timeit(fresh, number=n) / n * 1e6,
            "subscription_count_query_us": timeit.timeit(probe.get_subscription_count, number=n) / n * 1e6,
        }
    finally:
        node.destroy_publisher(probe)
    return {k: float(v) for k, v in t.items()}
