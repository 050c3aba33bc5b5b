"""Fault and soak suite: estimator_node as a child process over real DDS on loopback
(LOCALHOST discovery, domain IDs 31..36; one in-process test), under a 10x rate burst and an
unpaced flood, a publisher that dies and restarts, stamp jumps forward and back (also of a
simulated /clock), interleaved bad messages, and a long run at 1 kHz stamps replayed faster than
real time.

Nothing here is timed: the checks are counts (every accepted sample answered, diagnostics counts
exact), equality with offline processing, memory (the node's VmRSS) and exit codes. Where counts
must be exact, the node's input is made reliable with the standard QoS override parameter and the
feeder keeps at most WINDOW samples unanswered, so the input queue (depth 100) never overflows;
the flood test uses the default best-effort input and checks only what holds under overload.

The long run sends GAIT_SOAK_SAMPLES samples (default SOAK_SAMPLES_CI); ``make soak`` runs
1,800,000 (30 minutes of 1 kHz stamps).
"""

from __future__ import annotations

import os
import selectors
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from ros_helpers import (
    BASE_NS,
    PERIOD_NS,
    InProcess,
    answered_indices,
    as_node_sees,
    assert_same_trace,
    load_multispeed,
    lockstep,
    offline_stream,
    unique_suffix,
)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.rejections import REASONS
from gait_estimator.io.outputs import ESTIMATE_TOPIC
from gait_estimator.ros.node_client import (
    DIAGNOSTICS_TOPIC,
    EstimatorClient,
    NodeProcess,
    local_ros_environment,
    node_command,
)

HERE = Path(__file__).resolve().parent
WINDOW = 60
"""Most unanswered samples in flight (the node's input queue holds 100)."""
STALL_S = 60.0
"""Liveness only: give up when the node has answered nothing for this long."""
SOAK_SAMPLES_CI = 150_000
"""Samples of the long run in CI (2.5 minutes of 1 kHz stamps); GAIT_SOAK_SAMPLES overrides."""
SOAK_PERIOD_NS = 1_000_000
SOAK_GAP_EVERY = 50_000
SOAK_BAD_EVERY = 100
RSS_GROWTH_LIMIT_KB = 5 * 1024


@pytest.fixture(autouse=True)
def local_ros(monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)


def rss_kb(pid: int) -> int:
    """Resident set size of a process, kB (/proc/<pid>/status VmRSS)."""
    for line in Path(f"/proc/{pid}/status").read_text(encoding="utf-8").splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError(f"no VmRSS for pid {pid}")


def bad_message(kind: str, stamp_ns: int) -> JointState:
    """A JointState the node must drop with reason ``kind``."""
    names, pos = list(CHANNELS), [0.1, 0.2, 0.3, 0.4]
    if kind == "non_finite":
        pos[1] = float("nan")
    elif kind == "missing_joint":
        names[3] = "left_shin"
    elif kind == "wrong_length":
        pos = pos[:3]
    else:
        raise ValueError(kind)
    msg = JointState(name=names, position=pos)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return msg


BAD_KINDS = ("non_finite", "missing_joint", "wrong_length")


class Session:
    """estimator_node in a child process under its own namespace, and a client that feeds it
    (reliably, at most WINDOW samples unanswered) and collects its ``estimate`` messages."""

    def __init__(self, domain_id: int, ros_args: tuple[str, ...] = (), reliable_input: bool = True,
                 record: bool = True) -> None:
        self.namespace = ns = f"/gait_fault_{unique_suffix()}"
        args = ["-r", f"__ns:={ns}", "-r", "__node:=estimator"]
        if reliable_input:
            args += ["-p", f"qos_overrides.{ns}/segment_angles.subscription.reliability:=reliable"]
        self.node = NodeProcess(node_command([*args, *ros_args]), local_ros_environment(domain_id))
        self.client = EstimatorClient(
            domain_id, namespace=ns, estimator_name=f"{ns}/estimator", reliable=True, record=record,
            outputs=(ESTIMATE_TOPIC, DIAGNOSTICS_TOPIC),
        )
        self.good = 0  # samples sent that the node must accept
        self.bad = 0  # messages sent that it must reject
        self._progress = (0, time.monotonic())
        if not self.client.wait_for_node(timeout_s=30.0, settle_s=0.5):
            self.close()
            pytest.fail(f"estimator_node did not come up; its output:\n{self.node.output()}")

    # -- liveness (not a performance check: only fails when nothing happens for STALL_S)

    def spin(self, timeout_s: float = 0.005) -> None:
        self.client.spin_once(timeout_s)
        count = self.client.estimate_count
        if count != self._progress[0]:
            self._progress = (count, time.monotonic())
        elif time.monotonic() - self._progress[1] > STALL_S:
            pytest.fail(f"estimator_node answered nothing for {STALL_S:g} s; its output:\n{self.node.output()[-3000:]}")
        if self.node.poll() is not None:
            pytest.fail(f"estimator_node exited with code {self.node.poll()}:\n{self.node.output()[-3000:]}")

    # -- feeding

    def send(self, msg: JointState, good: bool = True, window: bool = True) -> None:
        while window and self.good - self.client.estimate_count >= WINDOW:
            self.spin()
        self.client.publisher.publish(msg)
        if good:
            self.good += 1
        else:
            self.bad += 1
        if (self.good + self.bad) % 16 == 0:
            self.client.spin_once(0.0)

    def sample(self, angles_rad: np.ndarray, stamp_ns: int) -> None:
        self.send(self.client.message(angles_rad, int(stamp_ns)))

    def paced(self, angles_rad: np.ndarray, stamps: np.ndarray, rate_hz: float) -> None:
        start = time.perf_counter()
        for i in range(len(angles_rad)):
            due = start + i / rate_hz
            while (left := due - time.perf_counter()) > 0:
                self.client.spin_once(min(left, 0.002) if left > 0.0002 else 0.0)
            self.sample(angles_rad[i], stamps[i])

    def wait_answered(self, n: int) -> None:
        while self.client.estimate_count < n:
            self.spin(0.01)

    def settled_diagnostics(self, received: int) -> dict[str, str]:
        """The first diagnostics report counting ``received`` input messages."""
        self.wait_answered(self.good)
        while True:
            d = self.client.latest_diagnostics(timeout_s=2.0)
            self.spin(0.0)
            if d is not None and int(d["samples_received"]) >= received:
                return d

    def quiescent_diagnostics(self) -> dict[str, str]:
        """A diagnostics report once input has stopped arriving (two reports in a row with the
        same count) and every accepted sample has been answered, for unknown input counts."""
        last = None
        while True:
            d = self.client.latest_diagnostics(timeout_s=2.0)
            self.spin(0.0)
            if d is None:
                continue
            if d["samples_received"] == last and self.client.estimate_count == int(d["samples_accepted"]):
                return d
            last = d["samples_received"]

    def stop(self) -> str:
        code = self.node.stop(signal.SIGINT)
        out = self.node.output()
        assert code == 0, out[-3000:]
        assert "Traceback" not in out, out[-3000:]
        return out

    def close(self) -> None:
        self.client.close()
        self.node.close()


@pytest.fixture
def session():
    made: list[Session] = []

    def make(*args, **kwargs) -> Session:
        s = Session(*args, **kwargs)
        made.append(s)
        return s

    yield make
    for s in made:
        s.close()


def check_counts(d: dict[str, str], accepted: int, rejected: dict[str, int], resets: int = 0, restarts: int = 0) -> None:
    """Diagnostics totals exactly as expected."""
    assert int(d["samples_accepted"]) == accepted, d
    for r in REASONS:
        assert int(d[f"rejected_{r}"]) == rejected.get(r, 0), (r, d)
    assert int(d["samples_rejected"]) == sum(rejected.values()), d
    assert int(d["samples_received"]) == accepted + sum(rejected.values()), d
    assert int(d["window_resets"]) == resets, d
    assert int(d["stream_restarts"]) == restarts, d


def test_rate_burst_then_unpaced_flood(session, multispeed_csv: Path, able_bodied) -> None:
    """230 Hz, a 10x burst (2300 Hz), 230 Hz again: every sample answered, equal to offline.
    Then an unpaced flood into the default best-effort input: whatever the node drops, every
    sample it accepted is answered, equal to offline on those samples, and the counts add up."""
    s = session(31)
    rec = load_multispeed(multispeed_csv, 0, 3000)
    x = np.radians(rec.angles_deg)
    stamps = BASE_NS + PERIOD_NS * np.arange(len(rec), dtype=np.int64)
    s.paced(x[:500], stamps[:500], 230.0)
    s.paced(x[500:2500], stamps[500:2500], 2300.0)
    s.paced(x[2500:], stamps[2500:], 230.0)
    d = s.settled_diagnostics(len(rec))
    check_counts(d, accepted=len(rec), rejected={})
    got = s.client.received
    idx = answered_indices(got, stamps)
    assert idx.size == len(rec)
    assert_same_trace(got.trace(able_bodied.mode_names), offline_stream(as_node_sees(rec.angles_deg, "rad"), stamps, able_bodied))
    s.stop()

    f = session(31, reliable_input=False)
    rec = load_multispeed(multispeed_csv, 6000, 10000)
    x = np.radians(rec.angles_deg)
    stamps = BASE_NS + PERIOD_NS * np.arange(len(rec), dtype=np.int64)
    for i in range(len(rec)):
        f.send(f.client.message(x[i], int(stamps[i])), window=False)
    d = f.quiescent_diagnostics()
    received = int(d["samples_received"])
    assert 0 < received <= len(rec)
    got = f.client.received
    idx = answered_indices(got, stamps)
    assert idx.size == received
    # Samples the node dropped leave holes in its stamps; a hole > max_gap_s restarts the window.
    expected = offline_stream(as_node_sees(rec.angles_deg[idx], "rad"), stamps[idx], able_bodied)
    holes = int(np.count_nonzero(np.diff(stamps[idx]) > 500_000_000))
    check_counts(d, accepted=received, rejected={}, resets=holes)
    assert_same_trace(got.trace(able_bodied.mode_names), expected)
    f.stop()


def _publisher(domain_id: int, namespace: str, start: int, stop: int, base_ns: int) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, str(HERE / "fault_publisher.py"), str(domain_id), namespace, str(start), str(stop), str(base_ns)],
        env=local_ros_environment(domain_id), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        start_new_session=True,
    )


def _read_until(proc: subprocess.Popen, s: Session, prefix: str) -> str:
    """Lines of ``proc`` until one starts with ``prefix`` (spinning the session meanwhile)."""
    sel = selectors.DefaultSelector()
    assert proc.stdout is not None
    sel.register(proc.stdout, selectors.EVENT_READ)
    seen = []
    deadline = time.monotonic() + STALL_S
    while time.monotonic() < deadline:
        if sel.select(timeout=0.05):
            line = proc.stdout.readline()
            if not line:
                break
            seen.append(line)
            deadline = time.monotonic() + STALL_S
            if line.startswith(prefix):
                return line
        s.client.spin_once(0.0)
    pytest.fail(f"publisher never printed {prefix!r}; it printed:\n{''.join(seen)}")


def test_publisher_dies_and_restarts_with_its_stamps_back_at_zero(session, multispeed_csv: Path, able_bodied) -> None:
    """A publisher process streams, is killed (SIGKILL) mid-stream, and a new one streams from
    the same first stamp: the node restarts its window once and answers every sample."""
    s = session(32)
    first = _publisher(32, s.namespace, 0, 3000, BASE_NS)
    try:
        _read_until(first, s, "sent 800")
        first.kill()
        first.wait(timeout=30)
    finally:
        if first.poll() is None:
            first.kill()
    # Everything the dead publisher got into the node is answered before the next one starts.
    d = s.quiescent_diagnostics()
    before = int(d["samples_accepted"])
    assert s.client.estimate_count == before and 800 <= before <= 3000
    second = _publisher(32, s.namespace, 0, 1000, BASE_NS)
    try:
        _read_until(second, s, "done")
        assert second.wait(timeout=30) == 0
    finally:
        if second.poll() is None:
            second.kill()
    s.good = before + 1000
    d = s.settled_diagnostics(before + 1000)
    check_counts(d, accepted=before + 1000, rejected={}, resets=1, restarts=1)
    got = s.client.received
    stamps = np.array(got.estimate_stamp_ns)
    np.testing.assert_array_equal(stamps[:before], BASE_NS + PERIOD_NS * np.arange(before))
    np.testing.assert_array_equal(stamps[before:], BASE_NS + PERIOD_NS * np.arange(1000))
    deg = as_node_sees(load_multispeed(multispeed_csv, 0, max(before, 1000)).angles_deg, "rad")
    expected = offline_stream(np.concatenate([deg[:before], deg[:1000]]), stamps, able_bodied)
    assert_same_trace(got.trace(able_bodied.mode_names), expected)
    out = s.stop()
    assert sum("jumped back" in line and "window restarted" in line for line in out.splitlines()) == 1, out


def test_stamp_jumps_forward_and_back(session, multispeed_csv: Path, able_bodied) -> None:
    """Forward by 10 s (> max_gap_s): window restart. A duplicate, a step back of 2 ms, and 30
    samples 0.3 s back (< max_gap_s: reordering, not a restart): dropped. Back by 100 s (a
    restarted clock): window restart, the sample accepted."""
    s = session(33)
    rec = load_multispeed(multispeed_csv, 2000, 4100)
    x = np.radians(rec.angles_deg)
    a = BASE_NS + PERIOD_NS * np.arange(600)
    b = a[-1] + 10 * 10**9 + PERIOD_NS * np.arange(500)
    c = b[-1] + PERIOD_NS * np.arange(1, 401)
    d_ = c[-1] - 100 * 10**9 + PERIOD_NS * np.arange(600)
    for i in range(600):
        s.sample(x[i], a[i])
    for i in range(500):
        s.sample(x[600 + i], b[i])
    rejected = [b[-1], b[-1] - 2_000_000, *(b[-1] - 300_000_000 + PERIOD_NS * np.arange(30))]
    for k, stamp in enumerate(rejected):
        s.send(s.client.message(x[k], int(stamp)), good=False)
    for i in range(400):
        s.sample(x[1100 + i], c[i])
    for i in range(600):
        s.sample(x[1500 + i], d_[i])
    d = s.settled_diagnostics(2100 + len(rejected))
    check_counts(d, accepted=2100, rejected={"non_increasing_stamp": len(rejected)}, resets=2, restarts=1)
    got = s.client.received
    np.testing.assert_array_equal(got.estimate_stamp_ns, np.concatenate([a, b, c, d_]))
    deg = as_node_sees(rec.angles_deg, "rad")
    expected = offline_stream(deg[:2100], np.concatenate([a, b, c, d_]), able_bodied)
    assert_same_trace(got.trace(able_bodied.mode_names), expected)
    out = s.stop()
    restarts = [line for line in out.splitlines() if "window restarted" in line]
    assert len(restarts) == 2 and "gap of 10.000 s" in restarts[0] and "jumped back by 100." in restarts[1], restarts


def test_sim_clock_jumps_back_with_unstamped_input(monkeypatch) -> None:
    """Under use_sim_time, unstamped input takes the /clock time: when /clock jumps back (a bag
    replayed in a loop) the window restarts; a small step back drops the sample."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "34")
    h = InProcess(34)
    try:
        node = h.estimator(use_sim_time=True, input_type="float64_multi_array")
        client = h.client(node, input_type="float64_multi_array")
        clock_pub = client.node.create_publisher(Clock, "/clock", 10)
        assert client.wait_for_node(10.0, settle_s=0.0)
        assert client.spin_until(lambda: clock_pub.get_subscription_count() > 0, 10.0)

        def at(sim_ns: int) -> None:
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(sim_ns, 1_000_000_000)
            clock_pub.publish(msg)
            assert client.spin_until(lambda: node.get_clock().now().nanoseconds == sim_ns, 10.0)

        times = [100 * 10**9 + k * PERIOD_NS for k in range(5)] + [10 * 10**9 + k * PERIOD_NS for k in range(5)]
        for t in times:
            at(t)
            lockstep(client, np.full((1, 4), 0.2), 230.0)
        assert client.received.estimate_stamp_ns == times
        assert node.window_resets == 1 and node.rejected["non_increasing_stamp"] == 0
        at(times[-1] - 200_000_000)  # 0.2 s back: < max_gap_s, a reordering
        n = node.samples_received
        msg = Float64MultiArray()
        msg.data = [0.2, 0.2, 0.2, 0.2]
        client.publisher.publish(msg)
        assert client.spin_until(lambda: node.samples_received > n, 10.0)
        assert node.rejected["non_increasing_stamp"] == 1 and node.window_resets == 1
        diag = client.latest_diagnostics(3.0)
        assert diag is not None and diag["stream_restarts"] == "1" and diag["window_resets"] == "1"
    finally:
        h.close()


def test_interleaved_bad_messages_at_ten_percent(session, multispeed_csv: Path, able_bodied) -> None:
    """NaN, a wrong joint name and a wrong length, interleaved at random (10 %): all dropped and
    counted exactly; the estimates equal offline on the good samples alone."""
    s = session(35)
    rec = load_multispeed(multispeed_csv, 4000, 5500)
    x = np.radians(rec.angles_deg)
    stamps = BASE_NS + PERIOD_NS * np.arange(len(rec), dtype=np.int64)
    rng = np.random.default_rng(7)
    rejected = dict.fromkeys(BAD_KINDS, 0)
    for i in range(len(rec)):
        if rng.random() < 0.1:
            kind = BAD_KINDS[rng.integers(len(BAD_KINDS))]
            rejected[kind] += 1
            s.send(bad_message(kind, stamps[i] - 1), good=False)
        s.sample(x[i], stamps[i])
    assert 120 <= sum(rejected.values()) <= 180 and min(rejected.values()) > 0
    d = s.settled_diagnostics(len(rec) + sum(rejected.values()))
    check_counts(d, accepted=len(rec), rejected=rejected)
    got = s.client.received
    np.testing.assert_array_equal(got.estimate_stamp_ns, stamps)
    assert_same_trace(got.trace(able_bodied.mode_names), offline_stream(as_node_sees(rec.angles_deg, "rad"), stamps, able_bodied))
    out = s.stop()
    for kind in BAD_KINDS:  # throttled: a few warnings, not one per message
        assert 1 <= sum(f": {kind}: " in line for line in out.splitlines()) <= 10


def test_soak_at_1khz_faster_than_real_time(session, multispeed_csv: Path) -> None:
    """GAIT_SOAK_SAMPLES samples with 1 kHz stamps (the recording repeated), 1 % bad messages and
    a 2-s gap every SOAK_GAP_EVERY samples, as fast as the node answers: no crash, every
    accepted sample answered with its stamp, exact counts, RSS growth < 5 MB after warm-up."""
    n = int(os.environ.get("GAIT_SOAK_SAMPLES", SOAK_SAMPLES_CI))
    s = session(36, record=False)
    rec = load_multispeed(multispeed_csv, 0, 14170)
    x = np.radians(rec.angles_deg)
    stamp = BASE_NS
    rejected = dict.fromkeys(BAD_KINDS, 0)
    gaps = 0
    chunk: list[int] = []
    warm = min(20_000, n // 4)
    rss_warm = None
    got = s.client.received

    def verify_chunk() -> None:
        s.wait_answered(s.good)
        np.testing.assert_array_equal(got.estimate_stamp_ns, chunk)
        got.clear()
        chunk.clear()

    started = time.monotonic()
    for i in range(n):
        if i and i % SOAK_GAP_EVERY == 0:
            stamp += 2 * 10**9
            gaps += 1
        if i % SOAK_BAD_EVERY == SOAK_BAD_EVERY - 1:
            kind = BAD_KINDS[(i // SOAK_BAD_EVERY) % len(BAD_KINDS)]
            rejected[kind] += 1
            s.send(bad_message(kind, stamp), good=False)
        stamp += SOAK_PERIOD_NS
        s.sample(x[i % len(x)], stamp)
        chunk.append(stamp)
        if len(chunk) == 10_000 or i == warm:
            verify_chunk()
            if i == warm:
                rss_warm = rss_kb(s.node.pid)
    verify_chunk()
    d = s.settled_diagnostics(n + sum(rejected.values()))
    check_counts(d, accepted=n, rejected=rejected, resets=gaps)
    rss_end = rss_kb(s.node.pid)
    elapsed = time.monotonic() - started
    assert rss_warm is not None
    print(f"soak: {n} samples ({n / 1000 / 60:.1f} min of 1 kHz stamps) in {elapsed:.0f} s "
          f"({n / elapsed:.0f} samples/s); node RSS {rss_warm} kB after warm-up, {rss_end} kB at the end")
    assert rss_end - rss_warm < RSS_GROWTH_LIMIT_KB, (rss_warm, rss_end)
    s.stop()
