"""``gait-estimator play``: playlists (no ROS), and real playback over DDS into estimator_node.

Every test that starts ROS uses ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a domain of its own
(47, 48): nothing leaves this machine and parallel test runs of other modules do not interfere.
No assertion depends on timing performance.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.cli.app import main
from gait_estimator.io.bag_write import write_input_bag
from gait_estimator.io.cdr import read_stamp, stamp_to_ns
from gait_estimator.io.outputs import estimate_names
from gait_estimator.io.process import predict
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording, write_project_csv
from gait_estimator.ros.player import load_playlist, playlist_from_bag

START_NS = 1_700_000_000_000_000_000
PLAY_NODE_DOMAIN = 47
PLAY_LOOP_DOMAIN = 48


@pytest.fixture(scope="module")
def ramp(swge: Path) -> Recording:
    return read_recording(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv")


# ---------------------------------------------------------------------------------------------
# Playlists (ROS-free)


def test_playlist_from_csv(ramp, tmp_path):
    csv = write_project_csv(ramp.slice(10, 60), tmp_path / "s.csv")
    pl = load_playlist(csv)
    assert pl.relative and len(pl) == 50 and [t.topic for t in pl.tracks] == ["segment_angles"]
    assert pl.tracks[0].msgtype == "sensor_msgs/msg/JointState" and pl.tracks[0].has_header
    np.testing.assert_array_equal(pl.time_ns, np.rint((ramp.time_s[10:60] - ramp.time_s[10]) * 1e9))
    assert pl.loop_period_ns == pl.time_ns[-1] + np.median(np.diff(pl.time_ns)).astype(np.int64)
    fma = load_playlist(csv, topics=["/imu/angles"], msg_type="float64_multi_array")
    assert fma.tracks[0].topic == "/imu/angles" and not fma.tracks[0].has_header


def test_playlist_from_bag_keeps_messages_and_times(ramp, tmp_path):
    bag = write_input_bag(ramp.slice(0, 40), tmp_path / "bag", start_ns=START_NS)
    pl = playlist_from_bag(bag)
    assert not pl.relative and len(pl) == 40
    assert pl.time_ns[0] == START_NS and stamp_to_ns(read_stamp(pl.data[0])) == START_NS
    assert [stamp_to_ns(read_stamp(d)) for d in pl.data] == pl.time_ns.tolist()


def test_play_errors_before_starting_ros(ramp, tmp_path, capsys):
    bag = write_input_bag(ramp.slice(0, 10), tmp_path / "bag", start_ns=START_NS)
    assert main(["play", str(bag), "--topic", "/nope"]) == 2
    err = capsys.readouterr().err
    assert "no topic /nope" in err and "/segment_angles [sensor_msgs/msg/JointState, 10 msgs]" in err
    csv = write_project_csv(ramp.slice(0, 10), tmp_path / "s.csv")
    assert main(["play", str(csv), "--topic", "a", "--topic", "b"]) == 2
    assert "one topic" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["play", str(csv), "--rate", "0"])


# ---------------------------------------------------------------------------------------------
# Real playback (rclpy, DDS on localhost)


def _ros_env(domain: int) -> dict[str, str]:
    env = dict(os.environ)
    env.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST", PYTHONUNBUFFERED="1")
    env.pop("ROS_STATIC_PEERS", None)
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


class Collector:
    """An rclpy node (private context) recording what arrives on some topics."""

    def __init__(self, domain: int, topics: dict[str, type]) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context, domain_id=domain)
        self.node = rclpy.create_node("play_test_collector", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST, depth=5000)
        self.got: dict[str, list] = {t: [] for t in topics}
        self.subs = [
            self.node.create_subscription(cls, t, lambda m, t=t: self.got[t].append(m), qos) for t, cls in topics.items()
        ]

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            if time.monotonic() > deadline:
                return False
            self.executor.spin_once(timeout_sec=0.02)
        return True

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()


def _player(args: list[str], env: dict[str, str]) -> subprocess.Popen:
    # With faulthandler (unbuffered already: _ros_env): if it ever hangs, _stop's SIGABRT shows where.
    env = {**env, "PYTHONFAULTHANDLER": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "gait_estimator.cli", "play", *args],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
    )


def _stop(proc: subprocess.Popen, sig: int = signal.SIGINT) -> int:
    """Send ``sig`` and return the exit code; a process still running 15 s later gets SIGABRT
    (a Python child started with PYTHONFAULTHANDLER=1 prints its threads' stacks), then SIGKILL."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGABRT)
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    return int(proc.returncode)


def _stamp_ns(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


@pytest.fixture
def ros_domain(monkeypatch):
    """Set the DDS environment of this process (before rclpy.init) and return a setter."""
    pytest.importorskip("rclpy")

    def use(domain: int) -> dict[str, str]:
        env = _ros_env(domain)
        for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE"):
            monkeypatch.setenv(key, env[key])
        monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)
        monkeypatch.delenv("ROS_LOCALHOST_ONLY", raising=False)
        return env

    return use


def test_play_csv_into_live_node_equals_offline(ramp, able_bodied, tmp_path, ros_domain):
    """play (CSV -> JointState, radians) -> estimator_node -> estimate == offline, sample for sample."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    env = ros_domain(PLAY_NODE_DOMAIN)
    n = 700  # 3 s at 230 Hz; the window fills after 392 samples
    csv = write_project_csv(ramp.slice(1000, 1000 + n), tmp_path / "slice.csv")
    rec = read_recording(csv)
    offline = predict(rec, able_bodied).trace

    node = subprocess.Popen(
        [sys.executable, "-m", "gait_estimator.ros.node"], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True, start_new_session=True,
    )
    collector = Collector(PLAY_NODE_DOMAIN, {"estimate": JointState, "mode": String})
    player = None
    try:
        ok = collector.spin_until(lambda: all(s.get_publisher_count() > 0 for s in collector.subs), 60)
        assert ok, "estimator_node did not come up"
        collector.spin_until(lambda: False, 0.5)  # let the node's publishers match us too
        player = _player([str(csv), "--wait-for-subscribers", "30"], env)
        collector.spin_until(lambda: player.poll() is not None, 90)
        out = player.communicate(timeout=15)[0]
        assert player.returncode == 0, out
        assert f"published {n} message(s)" in out
        collector.spin_until(lambda: len(collector.got["estimate"]) >= n, 20)
    finally:
        if player is not None:
            _stop(player)
        collector_msgs = dict(collector.got)
        collector.close()
        code = _stop(node)
    log = node.stdout.read() if node.stdout else ""
    assert code == 0, log

    est = collector_msgs["estimate"]
    stamps = np.array([_stamp_ns(m) for m in est])
    if len(est) != n:
        rel = np.rint((rec.time_s - rec.time_s[0]) * 1e9).astype(np.int64)
        got = set((stamps - stamps[0]).tolist()) if len(est) else set()
        missing = [i for i, t in enumerate(rel) if t not in got]
        pytest.fail(f"{len(est)} of {n} estimates arrived (missing, if the first arrived: {missing[:20]}); node log:\n{log}")
    # stamps: the CSV time offset to the wall clock at the start of playback
    np.testing.assert_array_equal(stamps - stamps[0], np.rint((rec.time_s - rec.time_s[0]) * 1e9))
    assert abs(stamps[0] - time.time_ns()) < 600e9
    assert list(est[0].name) == estimate_names(offline.mode_names)
    values = np.array([np.asarray(m.position) for m in est])
    m = len(offline.mode_names)
    np.testing.assert_array_equal(values[:, 0], offline.mode_index)
    # resampling interpolates at the stamps: the node's (ns since its first stamp) and the CSV's
    # (s) differ in the last bits
    np.testing.assert_allclose(values[:, 1], offline.phase, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(values[:, 2], offline.ready)
    np.testing.assert_allclose(values[:, 3 : 3 + m], offline.sse, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(values[:, 3 + m : 3 + 2 * m], offline.phases, rtol=0, atol=1e-9)
    modes = [msg.data for msg in collector_msgs["mode"]]
    assert modes == [offline.mode_names[i] for i in offline.mode_index[offline.ready]]


def test_play_bag_with_clock_and_loop(ramp, tmp_path, ros_domain):
    """Bag messages go out unchanged (then shifted by one period per loop), /clock follows the
    log times, and Ctrl-C ends playback with exit code 130, also when the player inherits SIGINT
    ignored (as a background job of a script does: the player kept playing until it was killed)."""
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState

    env = ros_domain(PLAY_LOOP_DOMAIN)
    n = 200
    bag = write_input_bag(ramp.slice(0, n), tmp_path / "bag", start_ns=START_NS)
    pl = playlist_from_bag(bag)
    collector = Collector(PLAY_LOOP_DOMAIN, {"/segment_angles": JointState, "/clock": Clock})
    ignored = signal.signal(signal.SIGINT, signal.SIG_IGN)  # inherited by the player
    try:
        player = _player([str(bag), "--clock", "--loop", "--rate", "4", "--wait-for-subscribers", "30"], env)
    finally:
        signal.signal(signal.SIGINT, ignored)
    try:
        assert collector.spin_until(lambda: len(collector.got["/segment_angles"]) >= 2 * n + 50, 60), player.poll()
    finally:
        code = _stop(player)
        out = player.communicate(timeout=15)[0]
        got = dict(collector.got)
        collector.close()
    assert code == 130, out
    told = re.search(r"interrupted after (\d+) message\(s\)", out)
    assert told and int(told[1]) >= len(got["/segment_angles"]), out  # every message it sent, counted

    stamps = np.array([_stamp_ns(m) for m in got["/segment_angles"]])
    k = len(stamps)
    expected = np.concatenate([pl.time_ns + loop * pl.loop_period_ns for loop in range(k // n + 1)])[:k]
    np.testing.assert_array_equal(stamps, expected)
    assert np.all(np.diff(stamps) > 0)
    first = got["/segment_angles"][0]
    np.testing.assert_allclose(np.degrees(first.position), ramp.angles_deg[0], rtol=0, atol=1e-9)
    clock = np.array([c.clock.sec * 1_000_000_000 + c.clock.nanosec for c in got["/clock"]])
    # /clock is published just before each message, with its log time (= its stamp here); as
    # for any clock, a late subscriber may miss a tick: check values and order, not the count
    assert len(clock) > n
    assert np.all(np.diff(clock) > 0)
    every = np.concatenate([pl.time_ns + loop * pl.loop_period_ns for loop in range(len(clock) // n + 2)])
    assert np.isin(clock, every).all()
