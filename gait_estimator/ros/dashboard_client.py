"""The dashboard's ROS side (``gait-estimator dashboard``): one thread that follows a running
``estimator_node`` and teaches it on request.

``DashboardLink`` owns a ``TeachClient`` (parameters, ``/rosout`` teach lines, diagnostics,
``~/save_library``) in a thread of its own, adds the node's ``estimate`` and ``~/angles`` topics
(best effort: no acks to the leg's computer), and hands the web server thread-safe snapshots
(``Snapshot``) and a command queue. It copes with a node that starts late, restarts or stops: it
keeps looking for the node by name and reloads the kernel library (the node's ``kernels``
parameter) whenever the node's modes change.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass, field, fields
from itertools import islice
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ..core.errors import GaitEstimatorError
from ..core.kernels import KernelLibrary
from ..io.cdr import CdrError, read_joint_state
from ..io.library_io import load_library
from ..io.outputs import ESTIMATE_TOPIC
from .angles_output import ANGLES_TOPIC
from .diagnostics import DIAGNOSTICS_TOPIC
from .node_client import drained_subscription
from .teach_client import TeachClient

DISPLAY_QOS = QoSProfile(reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST, depth=100)
WAKE_PERIOD_S = 0.01
"""The ROS thread wakes at most this often and then takes everything queued (the page needs no
more than 30 frames a second; fewer wake-ups leave the leg's computer to the node)."""
KEPT_ANGLES = 4000
"""``~/angles`` rows kept for the pages (17 s at 230 Hz; a page takes the new ones every frame)."""
KEPT_LOG = 200
LOOK_PERIOD_S = 1.0
"""How often the node's presence in the graph is checked."""


@dataclass
class NodeState:
    """What the dashboard knows of the node besides its estimate, angles and log lines."""

    present: bool = False
    ever_seen: bool = False
    estimates: int = 0
    estimate_source_ns: int = 0
    estimate_at: float = math.nan
    diagnostics: dict[str, str] = field(default_factory=dict)
    level: str = ""
    message: str = ""
    diagnostics_at: float = math.nan
    library: KernelLibrary | None = None
    library_version: int = 0
    library_note: str = ""


@dataclass
class Snapshot(NodeState):
    """NodeState copied out for one page frame, with the last estimate's keys and values;
    ``angles``/``log`` hold only the rows after the cursors given to ``DashboardLink.snapshot``,
    ``angles_cursor``/``log_cursor`` are the cursors for the next call."""

    names: list[str] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    angles: list[list[float]] = field(default_factory=list)
    angles_cursor: int = 0
    log: list[str] = field(default_factory=list)
    log_cursor: int = 0


@dataclass
class _Shared(NodeState):
    """State written by the ROS thread, read under ``DashboardLink.lock``."""

    estimate: bytes = b""
    angles: deque = field(default_factory=lambda: deque(maxlen=KEPT_ANGLES))
    angles_total: int = 0
    log: deque = field(default_factory=lambda: deque(maxlen=KEPT_LOG))
    log_total: int = 0


def parse_estimate(data: bytes) -> tuple[list[str], list[float]]:
    """Keys and values of a serialised ``estimate`` (empty: none yet, or undecodable)."""
    if not data:
        return [], []
    try:
        _, names, values = read_joint_state(data)
    except CdrError:
        return [], []
    return list(names), list(values)


def _tail(rows: deque, total: int, cursor: int) -> list:
    """The rows of ``rows`` (the last of ``total`` appended) after ``cursor`` appended ones."""
    new = min(total - cursor, len(rows))
    return list(islice(rows, len(rows) - new, None)) if new > 0 else []


class DashboardLink:
    """Follows ``node`` on ``domain_id`` from a background thread; see the module docstring.

    Args:
        node: The estimator node's fully qualified name.
        domain_id: ROS domain (None: the environment's ``ROS_DOMAIN_ID``, else 0).
    """

    def __init__(self, node: str = "/estimator_node", domain_id: int | None = None) -> None:
        self.client = TeachClient(node, domain_id, timeout_s=None, name="gait_estimator_dashboard")
        self.target = self.client.target
        self.lock = threading.Lock()
        self._shared = _Shared()
        self._commands: queue.Queue[tuple[Callable[[], str], Future]] = queue.Queue()
        self._stop = threading.Event()
        self._refreshed_for: tuple[str, ...] = ()
        """The node's modes when its library was last loaded here (a change loads it again)."""
        n = self.client.node
        namespace = self.target.rsplit("/", 1)[0]  # the node's relative topics (a remapping is not followed)
        for msg_type, topic, callback in ((JointState, f"{namespace}/{ESTIMATE_TOPIC}", self._on_estimate),
                                          (Float64MultiArray, self.target + ANGLES_TOPIC[1:], self._on_angles)):
            # serialised estimate: parsed only for a frame (io/cdr.py)
            drained_subscription(n, msg_type, topic, callback, DISPLAY_QOS, raw=msg_type is JointState)
        n.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, self._on_diagnostics, 10)
        self.client.on_log = self._on_log
        self._thread = threading.Thread(target=self._run, name="dashboard-ros", daemon=True)

    # -- ROS thread

    def start(self) -> None:
        self._thread.start()

    def _run(self) -> None:
        looked = -math.inf
        while not self._stop.is_set():
            woke = time.monotonic()
            self.client.executor.spin_once(timeout_sec=0.02)
            time.sleep(max(0.0, WAKE_PERIOD_S - (time.monotonic() - woke)))
            now = time.monotonic()
            if now - looked >= LOOK_PERIOD_S:
                looked = now
                self._look()
            try:
                work, future = self._commands.get_nowait()
            except queue.Empty:
                continue
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(work())
                except Exception as exc:  # the page gets the reason; the dashboard goes on
                    future.set_exception(exc)

    def _look(self) -> None:
        present = self.target in self.client.node.get_fully_qualified_node_names()
        with self.lock:
            came = present and not self._shared.present
            self._shared.present = present
            self._shared.ever_seen |= present
            data = self._shared.estimate
        names, _ = parse_estimate(data)
        key = tuple(k[4:] for k in names if k.startswith("sse/"))
        if came or (present and key and key != self._refreshed_for):
            self._refreshed_for = key
            self._refresh_library(key)

    def _refresh_library(self, key: tuple[str, ...]) -> None:
        """Load the node's library (its ``kernels`` parameter) for the kernel overlay."""
        try:
            source = str(self.client.get("kernels"))
        except GaitEstimatorError as exc:
            self._set_library(None, f"kernels of {self.target} not read: {exc}")
            return
        if not source:
            self._set_library(None, "the node started without a library (kernels: ''): no kernel to show")
            return
        try:
            lib = load_library(source)
        except (GaitEstimatorError, OSError, ValueError) as exc:
            self._set_library(None, f"kernels {source!r} not readable here: {exc}")
            return
        missing = [m for m in key if m not in lib.mode_names]
        self._set_library(lib, f"no kernel here for {', '.join(missing)} (taught on the node)" if missing else "")

    def _set_library(self, lib: KernelLibrary | None, note: str) -> None:
        with self.lock:
            self._shared.library = lib
            self._shared.library_note = note
            self._shared.library_version += 1

    def _on_estimate(self, data: bytes, info: Any) -> None:
        with self.lock:
            s = self._shared
            s.estimate = data
            s.estimates += 1
            s.estimate_source_ns = int(info["source_timestamp"])
            s.estimate_at = time.monotonic()

    def _on_angles(self, msg: Float64MultiArray, _info: Any = None) -> None:
        values = msg.data.tolist()
        if not values or len(values) % 5:
            return
        rows = [values[i:i + 5] for i in range(0, len(values), 5)]
        with self.lock:
            self._shared.angles.extend(rows)
            self._shared.angles_total += len(rows)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        st = self.client.target_status(msg)
        if st is not None:
            with self.lock:
                s = self._shared
                s.level, s.message, s.diagnostics, s.diagnostics_at = st

    def _on_log(self, line: str) -> None:
        with self.lock:
            self._shared.log.append(line)
            self._shared.log_total += 1

    # -- any thread

    def snapshot(self, angles_cursor: int, log_cursor: int) -> Snapshot:
        """The node's latest state, with the angle rows and log lines after the cursors."""
        with self.lock:
            s = self._shared
            snap = Snapshot(**{f.name: getattr(s, f.name) for f in fields(NodeState)},
                            angles=_tail(s.angles, s.angles_total, angles_cursor), angles_cursor=s.angles_total,
                            log=_tail(s.log, s.log_total, log_cursor), log_cursor=s.log_total)
            data = s.estimate
        snap.names, snap.values = parse_estimate(data)  # outside the lock: the ROS thread goes on meanwhile
        return snap

    def submit(self, work: Callable[[TeachClient], str]) -> Future:
        """Run ``work(client)`` in the ROS thread (where the client is spun); its result or
        exception arrives in the returned Future."""
        future: Future = Future()
        self._commands.put((lambda: work(self.client), future))
        return future

    def teach(self, mode: str, strides: int) -> Future:
        """Start teaching ``mode`` from ``strides`` strides (the node's ``teach_strides``, ``teach_mode``)."""

        def work(c: TeachClient) -> str:
            c.set(teach_strides=strides, teach_mode=mode)
            return f"teaching {mode}: walk steadily in that mode ({strides} good strides)"

        return self.submit(work)

    def cancel(self) -> Future:
        def work(c: TeachClient) -> str:
            c.cancel()
            return "teaching cancelled"

        return self.submit(work)

    def save(self) -> Future:
        """``~/save_library`` to the node's ``adapted_library_path``."""
        return self.submit(lambda c: c.save(None))

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)
        self.client.close()
