"""Helpers for the node tests: real rclpy over real DDS, confined to this machine.

Every test that starts ROS uses a ROS_DOMAIN_ID of its file's (11..180, named in each file's docstring) and
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, and a namespace/node name unique to this test run, so
concurrent runs (or other engineers' tests) cannot cross-talk.
"""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Callable, Container, Iterator, Sequence
from pathlib import Path

import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.parameter import Parameter

from gait_estimator.core.estimator import Estimator, EstimatorConfig, trace_from_estimates
from gait_estimator.core.kernels import KernelLibrary
from gait_estimator.core.stamps import StreamGuard, restart_threshold
from gait_estimator.io.process import predict
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording
from gait_estimator.ros.node import EstimatorNode
from gait_estimator.ros.node_client import EstimatorClient, Received

REPO = Path(__file__).resolve().parents[1]
RATE_HZ = 230.0
PERIOD_NS = round(1e9 / RATE_HZ)
BASE_NS = 1_700_000_000 * 1_000_000_000  # first stamp: a realistic wall-clock time


def unique_suffix() -> str:
    return f"{os.getpid()}_{uuid.uuid4().hex[:6]}"


def load_multispeed(path: Path, start: int, stop: int) -> Recording:
    """Samples [start, stop) of the shared Multispeed recording on a 230 Hz time base."""
    return read_recording(path, rate_hz=RATE_HZ).slice(start, stop)


def stamps_ns(rec: Recording, base_ns: int = BASE_NS) -> np.ndarray:
    return base_ns + np.round((rec.time_s - rec.time_s[0]) * 1e9).astype(np.int64)


def as_node_sees(angles_deg: np.ndarray, units: str) -> np.ndarray:
    """The degrees the node computes from what we send (rad: the deg->rad->deg round trip)."""
    return np.degrees(np.radians(angles_deg)) if units == "rad" else np.asarray(angles_deg, dtype=np.float64)


def offline(angles_deg: np.ndarray, lib: KernelLibrary, stamps: np.ndarray | None = None,
            config: EstimatorConfig | None = None):
    """Offline ``predict`` (the ``process`` command's engine) on these samples: an EstimateTrace.

    ``stamps`` (int ns) are the stamps the node saw, converted to seconds as the node does (the
    default resampling interpolates at the stamps, so skipped samples matter); None: 230 Hz.
    ``config``: the estimator options (None: the defaults).
    """
    n = len(angles_deg)
    if stamps is None:
        stamps = stamps_ns(Recording(time_s=np.arange(n) / RATE_HZ, angles_deg=np.zeros((n, 4))))
    stamps = np.asarray(stamps, dtype=np.int64)
    sec = stamps // 1_000_000_000
    time_s = (sec - sec[0]) + (stamps % 1_000_000_000) * 1e-9  # as the node: seconds since its first stamp
    return predict(Recording(time_s=time_s, angles_deg=np.asarray(angles_deg)), lib, config).trace


def offline_stream(angles_deg: np.ndarray, stamps: np.ndarray, lib: KernelLibrary):
    """What the node computes for these accepted samples: one Estimator over the whole stream,
    stamps converted as the node does, its window restarted where the node restarts it (a gap >
    max_gap_s inside ``Estimator``, a jump back > ``restart_threshold`` here). Unlike offline() on
    separate pieces, what the estimator learns across restarts (the sensor-offset calibration)
    carries over, as in the node."""
    stamps = np.asarray(stamps, dtype=np.int64)
    sec = stamps // 1_000_000_000
    time_s = (sec - sec[0]) + (stamps % 1_000_000_000) * 1e-9
    est = Estimator(lib)
    guard = StreamGuard(max_gap_s=0.0, restart_back_s=restart_threshold(est.config.max_gap_s))
    rows = []
    for i, (t, x) in enumerate(zip(time_s, np.asarray(angles_deg), strict=True)):
        if guard.accept(float(t)):
            est.reset()
        rows.append((i, est.update(float(t), x)))
    return trace_from_estimates(lib.mode_names, rows)


def assert_same_trace(live, ref) -> None:
    """Every field of every step equal (mode and ready exactly; phase, SSE to float rounding: the
    default resampling interpolates at stamps the node and the test convert to seconds
    differently)."""
    assert len(live.mode_index) == len(ref.mode_index)
    bad = np.flatnonzero(live.mode_index != ref.mode_index)
    assert bad.size == 0, f"{bad.size} mode differences, first at step {bad[:5]}"
    np.testing.assert_array_equal(live.ready, ref.ready)
    np.testing.assert_allclose(live.phase, ref.phase, rtol=0, atol=1e-9)
    np.testing.assert_allclose(live.sse, ref.sse, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(live.phases, ref.phases, rtol=0, atol=1e-9)


def answered_indices(received: Received, stamps: np.ndarray) -> np.ndarray:
    """Indices (into ``stamps``) of the received estimates, in arrival order; all must be known."""
    index = {int(s): i for i, s in enumerate(stamps)}
    idx = np.array([index.get(int(s), -1) for s in received.estimate_stamp_ns], dtype=np.int64)
    assert (idx >= 0).all(), "an estimate carries a stamp that was never sent"
    assert (np.diff(idx) > 0).all(), "estimates out of order or duplicated"
    return idx


def check_against_offline(
    received: Received, stamps: np.ndarray, angles_deg: np.ndarray, units: str, lib: KernelLibrary, min_fraction: float
) -> np.ndarray:
    """Estimates equal offline predictions on exactly the answered samples; mode/phase/sse topics
    equal the ready part. Returns the answered indices."""
    idx = answered_indices(received, stamps)
    assert idx.size >= min_fraction * len(stamps), f"only {idx.size}/{len(stamps)} samples answered"
    ref = offline(as_node_sees(angles_deg[idx], units), lib, stamps[idx])
    live = received.trace(lib.mode_names)
    assert received.estimate_names[:3] == ["mode_index", "phase", "ready"]
    assert_same_trace(live, ref)
    ready_modes = [str(m) for m in ref.mode[ref.ready]]
    assert len(received.modes) == len(ready_modes), (len(received.modes), len(ready_modes))
    assert received.modes == ready_modes
    np.testing.assert_allclose(np.array(received.phases), ref.phase[ref.ready], rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.array(received.sse).reshape(-1, len(lib)), ref.sse[ref.ready], rtol=1e-10, atol=1e-9)
    if ref.ready.any():
        assert received.sse_label == "modes:" + ",".join(lib.mode_names)
    return idx


def wait_all_answered(client: EstimatorClient, n: int, timeout_s: float = 5.0) -> None:
    """Spin until ``n`` estimates arrived, or nothing new came for 1 s (lost samples)."""
    deadline = time.monotonic() + timeout_s
    last, changed = client.estimate_count, time.monotonic()
    while client.estimate_count < n and time.monotonic() < deadline and time.monotonic() - changed < 1.0:
        client.spin_once(0.02)
        if client.estimate_count != last:
            last, changed = client.estimate_count, time.monotonic()
    client.spin_for(0.2)  # mode/phase/sse travel on other topics: let the last ones land


def lockstep(client: EstimatorClient, angles: np.ndarray, rate_hz: float, stamps: Sequence[int] | None = None) -> None:
    """Publish at ``rate_hz``, waiting for each sample's estimate (resending a lost sample), so
    inputs without stamps (Float64MultiArray) can be compared one to one."""
    period = 1.0 / rate_hz
    start = time.perf_counter()
    for i, a in enumerate(angles):
        due = start + i * period
        while (left := due - time.perf_counter()) > 0:
            client.spin_once(min(left, 0.002))
        for _attempt in range(5):
            n = client.estimate_count
            client.publish(a, 0 if stamps is None else int(stamps[i]))
            if client.spin_until(lambda n=n: client.estimate_count > n, 1.0):
                break
        else:
            raise AssertionError(f"sample {i} never answered")
    client.spin_for(0.2)  # mode/phase/sse travel on other topics: let the last ones land


class InProcess:
    """A private rclpy Context on ``domain_id`` holding an EstimatorNode and its clients."""

    def __init__(self, domain_id: int) -> None:
        self.domain_id = domain_id
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        suffix = unique_suffix()
        self.namespace = f"/gait_test_{suffix}"
        self.node_name = "estimator"
        self.nodes: list[EstimatorNode] = []
        self.clients: list[EstimatorClient] = []

    def estimator(self, **params: object) -> EstimatorNode:
        overrides = [Parameter(k, value=v) for k, v in params.items()]
        node = EstimatorNode(
            node_name=self.node_name, namespace=self.namespace, context=self.context, parameter_overrides=overrides
        )
        self.nodes.append(node)
        return node

    def client(self, node: EstimatorNode | None = None, **kwargs: object) -> EstimatorClient:
        """A client in the same context; the first one also spins ``node``."""
        extra = [node] if node is not None else []
        c = EstimatorClient(
            self.domain_id,
            context=self.context,
            extra_nodes=extra,
            namespace=self.namespace,
            estimator_name=f"{self.namespace}/{self.node_name}",
            node_name=f"client{len(self.clients)}",
            **kwargs,  # type: ignore[arg-type]
        )
        self.clients.append(c)
        return c

    def close(self) -> None:
        for c in self.clients:
            c.close()
        for n in self.nodes:
            n.destroy_node()
        rclpy.try_shutdown(context=self.context)


def in_process_factory(monkeypatch, domains: Container[int]) -> Iterator[Callable[[int], InProcess]]:
    """For a ``ros`` fixture: ``make(domain_id)`` -> an InProcess harness on that domain (one of
    the test file's ``domains``), LOCALHOST discovery; every harness is closed after the test."""
    made: list[InProcess] = []

    def make(domain_id: int) -> InProcess:
        assert domain_id in domains, f"domain {domain_id} outside this file's {domains}"
        monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        monkeypatch.setenv("ROS_DOMAIN_ID", str(domain_id))
        monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)
        h = InProcess(domain_id)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()
