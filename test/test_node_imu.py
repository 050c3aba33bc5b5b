"""estimator_node with ``input_type: imu`` over real DDS (loopback, ROS_DOMAIN_ID 58-69, 74, 85-89, 170):
four sensor_msgs/Imu topics in, estimates equal to offline processing of the same angles (raw
IMUs: of the same messages read from a bag); learning the calibration live (also without a
library, then teaching a mode), saving it (also beside a saved library) and forgetting it; checking a saved calibration
or configured axes on the walking, again after a long gap; bad messages, a silent sensor, raw
input without imufusion; the node's reading of serialised Imu messages
(io/cdr.py) against rclpy's, and undecodable bytes."""

from __future__ import annotations

import dataclasses
import math
import re
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from imu_synth import ALONG_SEGMENT, gait_angles, random_mounts, synthesize, turned
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.serialization import serialize_message
from ros_helpers import answered_indices, assert_same_trace, in_process_factory, offline, wait_all_answered
from sensor_msgs.msg import Imu
from std_srvs.srv import Trigger

from gait_estimator import load_library
from gait_estimator.analysis.strides import heel_strikes
from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.imu import FUSION_BY_CHANNEL, STANDARD_GRAVITY, ImuCalibration, SegmentMount
from gait_estimator.core.imu_learn import learn_calibration
from gait_estimator.core.imu_pairing import ImuPairer, SensorInput
from gait_estimator.io.as_node import predict_as_node
from gait_estimator.io.cdr import read_imu
from gait_estimator.io.imu_bag import read_imu_bag, write_imu_bag
from gait_estimator.io.imu_stream import load_calibration, save_calibration
from gait_estimator.io.outputs import estimate_array
from gait_estimator.io.read_options import ReadOptions
from gait_estimator.io.recording import Recording
from gait_estimator.ros.imu_input import CALIBRATE_STANDING_SERVICE
from gait_estimator.ros.node import RESET_CALIBRATION_SERVICE, SAVE_LIBRARY_SERVICE, StartupError

RATE = 200.0
BASE_NS = 1_700_000_000 * 1_000_000_000
OFFSETS_NS = (0, 200_000, 400_000, 600_000)  # four drivers, stamped a little apart
TOPICS = ("imu/right_thigh", "imu/left_thigh", "imu/right_shank", "imu/left_shank")


@pytest.fixture
def ros(monkeypatch):
    yield from in_process_factory(monkeypatch, [58, 59, *range(60, 70), 74, 86, 87, 88])


@pytest.fixture
def ros_cdr(monkeypatch):
    yield from in_process_factory(monkeypatch, [85, 89])


@pytest.fixture
def ros_silent(monkeypatch):
    yield from in_process_factory(monkeypatch, [170])


def imu_msg(stamp_ns: int, q: np.ndarray | None, gyro_dps: np.ndarray, acc_g: np.ndarray, frame: str = "") -> Imu:
    m = Imu()
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    m.header.frame_id = frame
    if q is None:
        m.orientation_covariance[0] = -1.0
    else:
        m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w = (float(v) for v in q)
    m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = (float(v) for v in np.radians(gyro_dps))
    a = acc_g * STANDARD_GRAVITY
    m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z = (float(v) for v in a)
    return m


def stream(client, pubs, msgs: list[list[Imu]], skip=lambda k, c: False, rate_hz: float = RATE) -> None:
    """Publish sample k's four messages at k / rate_hz, spinning in between."""
    spin = client.executor.spin_once
    start = time.perf_counter()
    for k, four in enumerate(msgs):
        due = start + k / rate_hz
        while (left := due - time.perf_counter()) > 0:
            spin(timeout_sec=min(left, 0.002))
        for c, m in enumerate(four):
            if not skip(k, c):
                pubs[c].publish(m)
        spin(timeout_sec=0.0)


def make_messages(s, n: int, raw: bool = False) -> list[list[Imu]]:
    return [[imu_msg(BASE_NS + round(s.time_s[k] * 1e9) + OFFSETS_NS[c], None if raw else s.quat_xyzw[c, k],
                     s.gyro_dps[c, k], s.acc_g[c, k], CHANNELS[c]) for c in range(4)] for k in range(n)]


def node_angles(msgs: list[list[Imu]], cal) -> tuple[np.ndarray, np.ndarray]:
    """What the node computes from these messages: paired stamps and angles (same code)."""
    inputs = [SensorInput() for _ in range(4)]
    pairer = ImuPairer()
    stamps, angles = [], []
    for four in msgs:
        for c, m in enumerate(four):
            o, w, a = m.orientation, m.angular_velocity, m.linear_acceleration
            ns = m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            item = inputs[c].convert(ns, (o.x, o.y, o.z, o.w), m.orientation_covariance[0], (w.x, w.y, w.z), (a.x, a.y, a.z))
            for stamp, items in pairer.push(c, ns, item):
                stamps.append(stamp)
                angles.append(cal.angles_deg([i[0] for i in items]))
    return np.array(stamps, dtype=np.int64), np.array(angles)


def publishers(client):
    """The four Imu publishers, once the node's subscriptions have matched them."""
    pubs = [client.node.create_publisher(Imu, t, 1000) for t in TOPICS]
    assert client.spin_until(lambda: all(p.get_subscription_count() for p in pubs), 10.0)
    client.spin_for(1.0)  # the node's best-effort subscriptions and our output subscriptions match too
    return pubs


def learnt_calibration(s, path: Path) -> Path:
    """The calibration learnt offline from the orientations of ``s``, saved at ``path``."""
    ups = np.stack([np.array([SensorInput().convert(1, s.quat_xyzw[c, k], 0.0, (0, 0, 0), (0, 0, 1))[0]
                              for k in range(len(s.time_s))]) for c in range(4)])
    cal, _, missing = learn_calibration(s.time_s, ups)
    assert missing == ""
    return save_calibration(cal, path)


def call(client, h, service: str) -> Trigger.Response:
    srv = client.node.create_client(Trigger, f"{h.namespace}/{h.node_name}/{service[2:]}")
    assert srv.wait_for_service(5.0)
    future = srv.call_async(Trigger.Request())
    assert client.spin_until(future.done, 5.0)
    return future.result()


def test_imu_input_with_a_saved_calibration_equals_offline_processing(ros, tmp_path):
    rng = np.random.default_rng(3)
    s = synthesize(gait_angles(RATE, walk_s=6.0), RATE, random_mounts(rng), rng)
    path = learnt_calibration(s, tmp_path / "user.imu.yaml")
    h = ros(61)
    node = h.estimator(input_type="imu", imu_calibration_path=str(path))
    client = h.client(node)
    pubs = publishers(client)
    msgs = make_messages(s, len(s.time_s))
    stream(client, pubs, msgs, rate_hz=RATE / 2)  # time comes from the stamps; half speed spares a loaded CI
    stamps, angles = node_angles(msgs, load_calibration(path))  # as saved (rounded)
    wait_all_answered(client, len(stamps))
    lib = load_library("able_bodied")
    idx = answered_indices(client.received, stamps)
    assert idx.size >= 0.9 * len(stamps), f"only {idx.size}/{len(stamps)} samples answered"
    assert_same_trace(client.received.trace(lib.mode_names), offline(angles[idx], lib, stamps[idx]))
    diag = client.latest_diagnostics(3.0)
    assert diag["imu_calibration_status"] == "calibrated, to be checked on the walking"  # 8 s of stream in all
    assert diag["imu_calibration_path"] == str(path)
    assert diag["input_type"] == "imu"
    assert all(c in diag["imu_silent"] for c in CHANNELS), "the stream ended: every sensor is silent"


def test_a_saved_calibration_that_does_not_fit_the_sensors_is_learnt_again(ros, tmp_path):
    """Yesterday's file, but the right shank's sensor was put on turned by 90 deg: the first walking
    shows it, the node stops feeding the estimator, learns the calibration again from the next
    standing pose and strides and saves it over the old file."""
    rng = np.random.default_rng(12)
    s = synthesize(gait_angles(RATE, walk_s=8.0), RATE, random_mounts(rng), rng)
    right = load_calibration(learnt_calibration(s, tmp_path / "right.imu.yaml"))
    path = save_calibration(turned(right, 2, 90.0), tmp_path / "user.imu.yaml")
    h = ros(69)
    node = h.estimator(input_type="imu", imu_calibration_path=str(path))
    client = h.client(node)
    pubs = publishers(client)
    assert node.imu.flow.calibrator.checking
    est, forgotten = node.stream.estimator, []
    for name in ("reset_calibration", "reset"):  # count the estimator's resets (still done by the estimator)
        done = getattr(est, name)
        setattr(est, name, lambda done=done, name=name: (forgotten.append(name), done())[1])
    again_s = 12.0  # the stream again from here (stamps in s): stand, walk
    msgs = make_messages(s, len(s.time_s)) + make_messages(dataclasses.replace(s, time_s=s.time_s + again_s), len(s.time_s))
    stream(client, pubs, msgs, rate_hz=RATE / 2)
    client.spin_for(0.5)
    got = (np.array(client.received.estimate_stamp_ns) - BASE_NS) * 1e-9
    assert (got < 7.5).any(), "estimates with the saved calibration until the check (8 s of stream)"
    assert not ((got > 8.6) & (got < again_s + 5.0)).any(), "none from the check until learnt again"
    assert (got > again_s + 7.0).any(), "estimates again once learnt"
    diag = client.latest_diagnostics(3.0)
    assert diag["imu_calibration_status"] == "calibrated" and "[learnt]" in diag["imu_calibration"]
    relearnt = load_calibration(path)
    assert np.dot(relearnt.mounts[2].lateral, right.mounts[2].lateral) > math.cos(math.radians(3.0))
    assert {"reset_calibration", "reset"} <= set(forgotten), "what the estimator learnt from the wrong angles is forgotten"


def test_after_a_long_gap_the_calibration_is_checked_again(ros, tmp_path, capfd):
    """Learnt live from raw sensors; then the stream stops for longer than calibration_reset_gap_s
    (the sensors taken off) and comes back with the right shank's sensor put on another way: the
    gyro biases come from the standing pose after the gap, the first walking after it shows the
    misfit, and the node learns the calibration again."""
    rng = np.random.default_rng(17)
    angles = gait_angles(RATE, walk_s=7.0)
    mounts = random_mounts(rng)
    s = synthesize(angles, RATE, mounts, rng, gyro_bias_dps=1.0)
    moved = synthesize(angles, RATE, [*mounts[:2], random_mounts(rng, 1)[0], mounts[3]], rng, gyro_bias_dps=1.0)
    gap_s = float(s.time_s[-1]) + 6.0  # > calibration_reset_gap_s (5 s)
    path = tmp_path / "user.imu.yaml"
    h = ros(88)
    node = h.estimator(input_type="imu", imu_calibration_path=str(path))
    client = h.client(node)
    pubs = publishers(client)
    stream(client, pubs, make_messages(s, len(s.time_s), raw=True), rate_hz=RATE / 2)
    learnt = client.spin_until(lambda: path.is_file() and node.imu.flow.calibrator.status == "calibrated", 30.0)
    assert learnt, "learnt live and saved"
    stream(client, pubs, make_messages(dataclasses.replace(moved, time_s=moved.time_s + gap_s), len(s.time_s), raw=True),
           rate_hz=RATE / 2)
    client.spin_for(0.5)
    logs = capfd.readouterr().err
    assert "(the sensors may have been re-donned): the IMU calibration is checked again on the next walking" in logs
    assert logs.count("IMU gyro bias measured at the standing pose") == 2, "at each standing pose: before and after the gap"
    assert f"IMU calibration from {path} does not fit the sensors now (right" in logs, logs
    assert node.imu.flow.calibrator.calibration is None, "learnt again from the next standing pose and strides"
    got = (np.array(client.received.estimate_stamp_ns) - BASE_NS) * 1e-9
    assert (got > gap_s).any() and not (got > gap_s + 8.6).any(), "estimates after the gap until the verdict"
    stream(client, pubs, make_messages(s, 400, raw=True), rate_hz=RATE / 2)  # a restarted stream: stamps from 0 again
    client.spin_for(0.5)
    assert re.search(r"IMU stamps jumped back by \d+\.\d+ s \(a restarted stream\) \(the sensors may have been "
                     r"re-donned\): the IMU calibration is learnt again", capfd.readouterr().err)


def test_configured_axes_that_do_not_fit_the_walking_are_reported(ros, tmp_path):
    rng = np.random.default_rng(13)
    s = synthesize(gait_angles(RATE, walk_s=8.0), RATE, [ALONG_SEGMENT] * 4, rng)
    h = ros(86)
    node = h.estimator(input_type="imu", imu_calibration_path=str(tmp_path / "never.imu.yaml"),
                       imu_lateral_axes=["+z", "+z", "-z", "+z"], imu_proximal_axes=["-x"] * 4, adapt_rate=0.2)
    client = h.client(node)
    stream(client, publishers(client), make_messages(s, len(s.time_s)), rate_hz=RATE / 2)
    client.spin_for(0.5)
    diag = client.latest_diagnostics(3.0)
    assert re.match(r"calibrated, does not fit the walking: right_shank: lateral axis 1(7[5-9]|80) deg from the swing axis",
                    diag["imu_calibration_status"]), diag["imu_calibration_status"]
    assert "do not fit the walking" in client.received.diagnostics_message[-1]
    got = (np.array(client.received.estimate_stamp_ns) - BASE_NS) * 1e-9
    assert got.max() > 9.5, "configured axes stay in use (the user's statement), reported"
    assert node.stream.estimator.personaliser.paused, "kernels learn nothing from angles known to be wrong"
    assert node.stream.estimator.adapter.accepted.sum() == 0


def test_a_saved_file_that_does_not_fit_gives_way_to_the_configured_axes(ros, tmp_path):
    """Configured axes and an older file (which wins at start): the file does not fit, so it is
    deleted and the configured axes are used and checked in turn; personalisation (adapt_rate)
    waits for the verdicts; samples go to the input directly."""
    rng = np.random.default_rng(14)
    s = synthesize(gait_angles(RATE, walk_s=18.0), RATE, [ALONG_SEGMENT] * 4, rng)
    h = ros(87)
    configured = {"imu_lateral_axes": ["+z"] * 4, "imu_proximal_axes": ["-x"] * 4}
    right = ImuCalibration(tuple(SegmentMount.from_axes("+z", "-x") for _ in range(4)))
    path = save_calibration(turned(right, 0, 90.0), tmp_path / "old.imu.yaml")
    node = h.estimator(input_type="imu", imu_calibration_path=str(path), adapt_rate=0.2, **configured)
    inputs = [SensorInput() for _ in range(4)]
    samples = [(BASE_NS + round(t * 1e9), k) for k, t in enumerate(s.time_s)]

    def items(stamp: int, k: int) -> list:
        return [inputs[c].convert(stamp, s.quat_xyzw[c, k], 0.0, np.radians(s.gyro_dps[c, k]),
                                  s.acc_g[c, k] * STANDARD_GRAVITY) for c in range(4)]

    imu, adapter = node.imu, node.stream.estimator.adapter
    assert imu.flow.from_file and imu.flow.calibrator.checking
    for stamp, k in samples:
        node.publish_outputs(node.stream.push_paired(stamp, items(stamp, k)), time.perf_counter())
        if k == round(9.0 * RATE):
            assert not path.exists() and not imu.flow.from_file, "the file gave way after the first check"
            assert imu.flow.calibrator.calibration == right and imu.flow.calibrator.checking
            assert set(adapter.skipped) == {"unchecked"}, "no stride of unchecked angles reached the kernels"
    assert adapter.skipped["warmup"] >= 2, "checked, the strides are personalised again"
    assert imu.flow.calibrator.status.startswith("calibrated, checked: lateral axes within") and not imu.flow.check_problem
    # ~/calibrate_standing before the file's verdict: the configured axes take over, and their
    # verdict is theirs (the file, never checked, is kept for the next start)
    path = save_calibration(turned(right, 0, 90.0), path)
    node = h.estimator(input_type="imu", imu_calibration_path=str(path), **configured)
    imu = node.imu
    inputs = [SensorInput() for _ in range(4)]
    assert "then walk 4 s" in imu.calibrate_standing(Trigger.Request(), Trigger.Response()).message
    for stamp, k in samples:
        node.publish_outputs(node.stream.push_paired(stamp, items(stamp, k)), time.perf_counter())
    assert not imu.flow.from_file and imu.flow.calibrator.calibration == right and path.exists()  # orientations: no bias
    assert imu.flow.calibrator.status.startswith("calibrated, checked: lateral axes within")


def test_configured_axes_get_the_gyro_biases_of_the_standing_pose(ros, tmp_path):
    """Raw sensors with gyro biases and configured axes (nothing to learn, so used from the first
    sample with no bias): the stream's standing pose gives the biases, fused with from then on;
    the angles after it are as good as with the true biases. With a saved file that does not fit,
    the biases measured while it was checked carry over to the configured axes that replace it.
    Samples go to the input directly."""
    rng = np.random.default_rng(16)
    s = synthesize(gait_angles(RATE, walk_s=10.0), RATE, [ALONG_SEGMENT] * 4, rng, acc_noise_g=0.01,
                   gyro_noise_dps=0.3, gyro_bias_dps=3.0)
    true_bias = s.gyro_dps[:, :round(1.9 * RATE)].mean(axis=1)  # standing: no rotation, bias + noise
    h = ros(60)
    right = ImuCalibration(tuple(SegmentMount.from_axes("+z", "-x") for _ in range(4)))
    for saved in (None, turned(right, 0, 90.0)):
        path = tmp_path / "user.imu.yaml"
        if saved is not None:
            save_calibration(saved, path)
        node = h.estimator(input_type="imu", imu_calibration_path=str(path),
                           imu_lateral_axes=["+z"] * 4, imu_proximal_axes=["-x"] * 4)
        imu = node.imu
        angles = []
        for k, t in enumerate(s.time_s):
            stamp = BASE_NS + round(t * 1e9)
            items = [imu.flow.inputs[c].convert(stamp, (0.0, 0.0, 0.0, 1.0), -1.0, np.radians(s.gyro_dps[c, k]),
                                           s.acc_g[c, k] * STANDARD_GRAVITY) for c in range(4)]
            node.publish_outputs(node.stream.push_paired(stamp, items), time.perf_counter())
            cal = imu.flow.calibrator.calibration  # None for a sample after the file's misfit verdict
            angles.append(cal.angles_deg([i[0] for i in items]) if cal else (math.nan,) * 4)
            if t < 1.5:
                assert not any(any(i.gyro_bias_dps) for i in imu.flow.inputs), "no bias before the standing"
        assert not imu.flow.from_file and not path.exists(), "the misfit file gave way" if saved else "no file"
        assert imu.flow.calibrator.calibration.mounts[0].lateral == right.mounts[0].lateral
        got = np.array([i.gyro_bias_dps for i in imu.flow.inputs])
        assert np.abs(got - true_bias).max() < 0.1, (saved, got, true_bias)
        assert got.tolist() == [list(m.gyro_bias_dps) for m in imu.flow.calibrator.calibration.mounts]
        late = s.time_s > (10.0 if saved else 6.0)  # after the misfit file gave way
        assert (np.sqrt(np.mean((np.array(angles) - s.angles_deg)[late] ** 2, axis=0)) < 1.0).all()


def test_learning_fuses_with_the_standing_biases_from_the_end_of_the_standing(ros, tmp_path):
    """Raw sensors with gyro biases, axes learnt: the node fuses with the standing pose's biases
    from the wearer's first move on, while the strides that complete the calibration are still to
    come (so they and the first angles put out are fused with them). Samples go to the input directly."""
    rng = np.random.default_rng(17)
    s = synthesize(gait_angles(RATE, walk_s=6.0), RATE, random_mounts(rng), rng, acc_noise_g=0.01,
                   gyro_noise_dps=0.3, gyro_bias_dps=3.0)
    true_bias = s.gyro_dps[:, :round(1.9 * RATE)].mean(axis=1)
    node = ros(59).estimator(input_type="imu", imu_calibration_path=str(tmp_path / "user.imu.yaml"))
    imu = node.imu
    biased_at = learnt_at = None
    for k, t in enumerate(s.time_s):
        stamp = BASE_NS + round(t * 1e9)
        items = [imu.flow.inputs[c].convert(stamp, (0.0, 0.0, 0.0, 1.0), -1.0, np.radians(s.gyro_dps[c, k]),
                                       s.acc_g[c, k] * STANDARD_GRAVITY) for c in range(4)]
        node.publish_outputs(node.stream.push_paired(stamp, items), time.perf_counter())
        if biased_at is None and any(any(i.gyro_bias_dps) for i in imu.flow.inputs):
            biased_at = t
            assert imu.flow.calibrator.calibration is None
            assert np.abs(np.array([i.gyro_bias_dps for i in imu.flow.inputs]) - true_bias).max() < 0.1
        if imu.flow.calibrator.calibration is not None:
            learnt_at = t
            break
    assert biased_at is not None and learnt_at is not None and 2.0 <= biased_at < 2.6 and learnt_at - biased_at >= 2.5
    mounts = imu.flow.calibrator.calibration.mounts
    assert [list(i.gyro_bias_dps) for i in imu.flow.inputs] == [list(m.gyro_bias_dps) for m in mounts]


def test_benchmarks_replay_of_the_live_calibration_is_the_nodes(ros, tmp_path, monkeypatch):
    """benchmarks/imu_live.py replays the node's IMU flow with its ROS-free parts to score the
    node's own calibration on camargo_ab06: a real node's ImuInput, fed the same raw right IMUs and
    virtual left sensors, passes its estimator the same samples, bit for bit."""
    import importlib.util

    from scipy.spatial.transform import Rotation

    from gait_estimator.io.recording import read_project_csv

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("imu_live", root / "benchmarks" / "imu_live.py")
    live = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(live)
    rec = read_project_csv(root / "data" / "camargo_ab06" / "levelground_cw_slow.csv")
    t, ex, mocap = rec.time_s, rec.extra, rec.angles_deg
    gyro, acc = np.zeros((4, len(t), 3)), np.zeros((4, len(t), 3))
    for seg, c in (("thigh", 0), ("shank", 2)):
        gyro[c] = np.stack([ex[f"right_{seg}_gyro_{k}_dps"] for k in "xyz"], axis=1)
        acc[c] = np.stack([ex[f"right_{seg}_acc_{k}_mps2"] for k in "xyz"], axis=1) / STANDARD_GRAVITY
    s0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # segment frame: +z lateral, +y proximal
    left = {c: (Rotation.from_euler("y", -np.radians(mocap[:, c])[:, None]) * Rotation.from_matrix(s0)).as_quat()
            for c in (1, 3)}
    want, biased_at, calibrator = live.live_angles(t, gyro, acc, left)
    rows = np.flatnonzero(np.isfinite(want[:, 0]))
    assert biased_at is not None and rows.size > 1000, "the replay calibrates on this trial"
    node = ros(58).estimator(input_type="imu", imu_calibration_path=str(tmp_path / "user.imu.yaml"),
                             **live.VIRTUAL_AXES)
    seen = []
    monkeypatch.setattr(node, "publish_outputs", lambda outputs, t0: seen.extend(
        (o[0].sec * 1_000_000_000 + o[0].nanosec, tuple(o[1])) for o in outputs if isinstance(o, tuple)))
    imu, zero = node.imu, (0.0, 0.0, 0.0)
    for k in range(len(t)):
        stamp = live.BASE_NS + round(float(t[k]) * 1e9)
        for c in range(4):
            msg = (stamp, tuple(left[c][k].tolist()), 0.0, zero, zero) if c in left else \
                (stamp, (0.0, 0.0, 0.0, 1.0), -1.0, tuple(np.radians(gyro[c, k]).tolist()),
                 tuple((acc[c, k] * STANDARD_GRAVITY).tolist()))
            for sample_ns, items in imu.flow.pairer.push(c, stamp, imu.flow.inputs[c].convert(*msg)):
                node.publish_outputs(node.stream.push_paired(sample_ns, items), time.perf_counter())
    assert [s for s, _ in seen] == [live.BASE_NS + round(float(t[k]) * 1e9) for k in rows]
    assert np.array_equal(np.array([a for _, a in seen]), want[rows])
    assert imu.flow.calibrator.standing_s == calibrator.standing_s


def test_raw_imu_input_with_a_saved_calibration_equals_reading_the_bag(ros, tmp_path):
    """Raw IMUs (no orientation) with gyro bias, the node started with the calibration learnt from
    an earlier bag (its gyro biases included) on a stream without a standing pose (so the saved
    biases stay): the estimates equal offline processing of ``read_imu_bag``'s angles with that
    calibration file. A lost message (best-effort QoS) changes the node's fusion state: then there
    is nothing exact to compare (skipped)."""
    rng = np.random.default_rng(9)
    mounts = random_mounts(rng)
    noise = {"acc_noise_g": 0.01, "gyro_noise_dps": 0.3, "gyro_bias_dps": 1.0}
    earlier = synthesize(gait_angles(RATE, walk_s=6.0), RATE, mounts, rng, **noise)
    s = synthesize(gait_angles(RATE, walk_s=6.0, stand_s=0.0), RATE, mounts, rng, stand_s=0.0, **noise)
    for name, x in (("earlier", earlier), ("raw", s)):
        stamps4 = BASE_NS + np.round(x.time_s * 1e9).astype(np.int64)[None, :] + np.array(OFFSETS_NS)[:, None]
        bag = write_imu_bag(tmp_path / name, stamps4, np.radians(x.gyro_dps), x.acc_g * STANDARD_GRAVITY)
    path = save_calibration(read_imu_bag(tmp_path / "earlier").calibration, tmp_path / "user.imu.yaml")
    assert any(any(m.gyro_bias_dps) for m in load_calibration(path).mounts)
    rec = read_imu_bag(bag, imu_calibration=path)
    assert "gyro biases from the standing pose" not in rec.calibration_note
    h = ros(68)
    node = h.estimator(input_type="imu", imu_calibration_path=str(path))
    client = h.client(node)
    pubs = publishers(client)
    msgs = make_messages(s, len(s.time_s), raw=True)
    stream(client, pubs, msgs, rate_hz=RATE / 2)
    wait_all_answered(client, len(rec))
    lib = load_library("able_bodied")
    idx = answered_indices(client.received, rec.stamp_ns)
    assert idx.size >= 0.9 * len(rec), f"only {idx.size}/{len(rec)} samples answered"
    received = [int(n) for n in client.latest_diagnostics(3.0)["imu_messages"].split(",")]
    if received != [len(msgs)] * 4:
        pytest.skip(f"Imu messages lost on the way to the node (received {received} of {len(msgs)} each)")
    assert idx.size == len(rec)
    assert_same_trace(client.received.trace(lib.mode_names), offline(rec.angles_deg, lib, rec.stamp_ns))
    as_node, _ = predict_as_node(bag, lib, options=ReadOptions(imu_calibration=path))  # the node's way offline
    np.testing.assert_array_equal(np.array(client.received.estimate_values), estimate_array(as_node.trace))


def test_imu_input_learns_saves_and_forgets_the_calibration_and_survives_bad_input(ros, tmp_path, capfd):
    rng = np.random.default_rng(4)
    s = synthesize(gait_angles(RATE, walk_s=7.0), RATE, random_mounts(rng), rng, acc_noise_g=0.01,
                   gyro_noise_dps=0.3, gyro_bias_dps=1.0)
    path = tmp_path / "learnt.imu.yaml"
    h = ros(62)
    node = h.estimator(input_type="imu", imu_calibration_path=str(path), imu_frame_ids=list(CHANNELS))
    client = h.client(node)
    pubs = publishers(client)
    msgs = make_messages(s, len(s.time_s), raw=True)
    # bad messages on top: NaN and zero quaternions, an out-of-order stamp, and a silent right shank
    bad = imu_msg(BASE_NS + 10_000_000, [math.nan, 0, 0, 1], s.gyro_dps[0, 0], s.acc_g[0, 0], "right_thigh")
    zero = imu_msg(BASE_NS + 20_000_000, [0, 0, 0, 0], s.gyro_dps[0, 0], s.acc_g[0, 0], "right_thigh")
    late = imu_msg(BASE_NS, None, s.gyro_dps[1, 0], s.acc_g[1, 0], "left_thigh")
    wrong = imu_msg(BASE_NS + 30_000_000, None, s.gyro_dps[3, 0], s.acc_g[3, 0], "right_thigh")
    for m in (bad, zero):
        pubs[0].publish(m)
    pubs[3].publish(wrong)
    stream(client, pubs, msgs[:600])
    pubs[1].publish(late)
    silent = (1000, 1400)  # 2 s without the right shank
    stream(client, pubs, msgs[600:], skip=lambda k, c: c == 2 and silent[0] - 600 <= k < silent[1] - 600)
    client.spin_for(0.5)
    assert path.is_file(), "the learnt calibration is saved"
    diag = client.latest_diagnostics(3.0)
    assert diag["imu_calibration_status"] == "calibrated" and "[learnt]" in diag["imu_calibration"]
    assert int(diag["rejected_non_finite"]) >= 1 and int(diag["rejected_zero_norm"]) >= 1
    assert int(diag["rejected_non_increasing_stamp"]) >= 1 and int(diag["rejected_unpaired"]) >= 1
    assert int(diag["rejected_wrong_frame"]) >= 1 and "rejected_missing_joint" not in diag  # JointState's only
    assert any(d.get("imu_silent", "").startswith("right_shank (") and "thigh" not in d["imu_silent"]
               for d in client.received.diagnostics), "the silent sensor is named in the diagnostics"
    assert "dropped IMU input: unpaired: no message from right_shank within the pairing tolerance" in capfd.readouterr().err
    assert client.received.estimate_stamp_ns, "estimates once calibrated"
    got = np.array(client.received.estimate_stamp_ns)
    shank_silent = (got >= BASE_NS + silent[0] * 5_000_000) & (got < BASE_NS + silent[1] * 5_000_000)
    assert not shank_silent.any(), "no estimate while the right shank was silent"
    # ~/calibrate_standing and ~/reset_calibration answer; reset deletes the learnt file
    for name in (CALIBRATE_STANDING_SERVICE, RESET_CALIBRATION_SERVICE):
        srv = client.node.create_client(Trigger, f"{h.namespace}/{h.node_name}/{name[2:]}")
        assert srv.wait_for_service(5.0)
        future = srv.call_async(Trigger.Request())
        assert client.spin_until(future.done, 5.0)
        assert future.result().success
    assert "IMU calibration forgotten" in future.result().message and not path.exists()


def test_bad_imu_parameters_and_calibration_files_stop_the_node_with_one_line(ros, tmp_path):
    h = ros(63)
    with pytest.raises(StartupError, match="right_thigh lateral axis: '\\+w' is not a sensor axis"):
        h.estimator(input_type="imu", imu_lateral_axes=["+w", "", "", ""], imu_calibration_path=str(tmp_path / "x.yaml"))
    bad = tmp_path / "bad.yaml"
    bad.write_text("segments: [1, 2]\n")
    with pytest.raises(StartupError) as err:
        h.estimator(input_type="imu", imu_calibration_path=str(bad))
    assert str(bad) in str(err.value) and "\n" not in str(err.value)


def test_configured_axes_need_no_calibration_file(ros, tmp_path):
    h = ros(64)
    path = tmp_path / "never.imu.yaml"
    node = h.estimator(input_type="imu", imu_calibration_path=str(path), imu_lateral_axes=["+z"] * 4,
                       imu_proximal_axes=["-x"] * 4, imu_standing_angles_deg=[5.0, 5.0, -6.0, -6.0])
    cal = node.imu.flow.calibrator.calibration
    assert cal is not None and all(m.source == "configured" for m in cal.mounts)
    assert [s.params for s in node.imu.flow.inputs] == list(FUSION_BY_CHANNEL)  # thighs, then shanks: their fusion
    assert cal.angles_deg([(-1.0, 0.0, 0.0)] * 4) == (5.0, 5.0, -6.0, -6.0)  # segment vertical: standing angle
    node.imu.reset_calibration()
    assert node.imu.flow.calibrator.add(0.0, [(-1.0, 0.0, 0.0)] * 4, [(0.0,) * 3] * 4, [(0.0, 0.0, 1.0)] * 4) is not None
    assert not path.exists()


def test_imu_input_without_a_library_learns_the_calibration_and_waits_for_teaching(ros, tmp_path, monkeypatch,
                                                                                    capfd):
    """``kernels: ''``: the node starts (its configuration logged), learns the calibration (saved
    under the taught library's name) and takes the angles for teaching; only diagnostics come out."""
    monkeypatch.setenv("HOME", str(tmp_path))
    rng = np.random.default_rng(5)
    s = synthesize(gait_angles(RATE, walk_s=5.0), RATE, random_mounts(rng), rng)
    h = ros(65)
    node = h.estimator(input_type="imu", kernels="")
    client = h.client(node)
    pubs = publishers(client)
    stream(client, pubs, make_messages(s, len(s.time_s)))
    client.spin_for(0.5)
    path = tmp_path / ".ros" / "gait_estimator" / "taught.imu.yaml"
    diag = client.latest_diagnostics(3.0)
    assert diag["modes"] == "0" and diag["imu_calibration_path"] == str(path)
    assert diag["imu_calibration_status"] == "calibrated" and path.is_file()
    assert int(diag["samples_accepted"]) > RATE, "calibrated angles go to teaching"
    assert client.estimate_count == 0
    assert "no kernel library (kernels: ''): diagnostics only until a mode is taught (teach_mode); input imu on " \
        f"{h.namespace}/imu/right_thigh" in capfd.readouterr().err
    answer = call(client, h, RESET_CALIBRATION_SERVICE)
    assert answer.success and "IMU calibration forgotten" in answer.message and not path.exists()


def test_save_library_writes_the_imu_calibration_where_the_next_start_reads_it(ros, tmp_path):
    rng = np.random.default_rng(6)
    s = synthesize(gait_angles(RATE, walk_s=5.0), RATE, random_mounts(rng), rng)
    learnt = learnt_calibration(s, tmp_path / "learnt.imu.yaml")
    out = tmp_path / "wearer.yaml"
    h = ros(66)
    node = h.estimator(input_type="imu", imu_calibration_path=str(learnt), adapt_rate=0.1,
                       adapted_library_path=str(out))
    client = h.client(node)
    answer = call(client, h, SAVE_LIBRARY_SERVICE)
    beside = tmp_path / "wearer.imu.yaml"
    assert answer.success and f"IMU calibration written to {beside}" in answer.message, answer.message
    for a, b in zip(load_calibration(beside).mounts, load_calibration(learnt).mounts, strict=True):
        assert np.allclose(a.lateral, b.lateral, atol=1e-6) and np.allclose(a.proximal, b.proximal, atol=1e-6)
    h.node_name = "restarted"
    again = h.estimator(input_type="imu", kernels=str(out))
    assert again.imu.path == beside and again.imu.flow.calibrator.calibration == load_calibration(beside)


def test_raw_input_needs_no_imufusion_and_bad_imu_durations_stop_the_node(ros, tmp_path, monkeypatch):
    """The raw input's fusion is the package's own (core/ahrs.py): without imufusion no raw
    message is dropped for want of one."""
    monkeypatch.setitem(sys.modules, "imufusion", None)  # `import imufusion` raises ImportError
    rng = np.random.default_rng(7)
    s = synthesize(gait_angles(RATE, walk_s=1.0), RATE, random_mounts(rng), rng)
    h = ros(67)
    for name in ("imu_pairing_tolerance_s", "imu_timeout_s"):
        with pytest.raises(StartupError, match=f"^{name}: must be >= 0 s, got -0.1$"):
            h.estimator(input_type="imu", **{name: -0.1})
    node = h.estimator(input_type="imu", imu_calibration_path=str(tmp_path / "none.imu.yaml"))
    client = h.client(node)
    pubs = publishers(client)
    stream(client, pubs, make_messages(s, 200, raw=True))  # a callback raising would raise here
    client.spin_for(0.5)
    diag = client.latest_diagnostics(3.0)
    assert sum(int(n) for n in diag["imu_messages"].split(",")) > 400
    assert not [k for k in diag if k.endswith("no_fusion")], diag
    assert "raw IMU message(s) dropped" not in client.received.diagnostics_message[-1]


def test_serialised_imu_messages_read_as_rclpy_builds_them():
    """The node reads its Imu input from the CDR bytes (io/cdr.py): the same fields as rclpy's
    message objects, for the messages of the tests above (orientation or none, NaN and zero
    quaternions, frame ids of every length, stamps before 1970)."""
    rng = np.random.default_rng(8)
    s = synthesize(gait_angles(RATE, walk_s=0.2), RATE, random_mounts(rng), rng)
    msgs = [m for four in make_messages(s, 20) + make_messages(s, 20, raw=True) for m in four]
    msgs.append(imu_msg(BASE_NS + 1, [math.nan, 0, 0, 1], s.gyro_dps[0, 0], s.acc_g[0, 0], "thigh_r_imu"))
    msgs += [imu_msg(BASE_NS + 2, [0, 0, 0, 0], s.gyro_dps[0, 0] * math.nan, s.acc_g[0, 0], "a" * k) for k in range(9)]
    msgs[-1].header.stamp.sec = -5
    for m in msgs:
        got = read_imu(serialize_message(m))
        o, w, a = m.orientation, m.angular_velocity, m.linear_acceleration
        want = ((m.header.stamp.sec, m.header.stamp.nanosec), m.header.frame_id, (o.x, o.y, o.z, o.w),
                float(m.orientation_covariance[0]), (w.x, w.y, w.z), (a.x, a.y, a.z))
        assert repr((tuple(got.stamp), *got[1:])) == repr(want)  # bit for bit, nan included


def test_undecodable_imu_bytes_are_dropped_and_counted(ros_cdr, tmp_path):
    h = ros_cdr(85)
    node = h.estimator(input_type="imu", imu_lateral_axes=["+z"] * 4, imu_proximal_axes=["-x"] * 4,
                       imu_calibration_path=str(tmp_path / "never.imu.yaml"))
    client = h.client(node)
    pubs = publishers(client)
    good = imu_msg(BASE_NS, [0.0, 0.0, 0.0, 1.0], np.zeros(3), np.array([0.0, 0.0, 1.0]))
    data = serialize_message(good)
    for raw in (b"\x00\x01\x00\x00" + b"\xff" * 40, data[:40]):  # absurd frame_id length, cut short
        pubs[1].publish(raw)
    assert client.spin_until(lambda: node.rejected["malformed"] == 2, 5.0)
    for c in range(4):
        pubs[c].publish(good)  # still taken after them
    assert client.spin_until(lambda: node.samples_received == 3, 5.0)
    diag = client.latest_diagnostics(3.0)
    assert diag["rejected_malformed"] == "2" and "imu_rejected_malformed" not in diag
    # A sensor that sends only undecodable bytes is silent: nothing usable arrives from it.
    start = time.monotonic()
    while time.monotonic() - start < 1.5:  # > imu_timeout_s (0.5 s)
        pubs[1].publish(data[:40])
        client.spin_for(0.05)
    seen = len(client.received.diagnostics)
    while len(client.received.diagnostics) == seen:  # the next report, composed while the garbage still arrives
        assert time.monotonic() - start < 10.0, "no diagnostics"
        pubs[1].publish(data[:40])
        client.spin_for(0.05)
    diag = client.received.diagnostics[-1]
    assert CHANNELS[1] in diag["imu_silent"], diag["imu_silent"]


def test_a_silent_sensor_is_the_diagnostics_main_message(ros_silent, tmp_path):
    """The right shank's topic stops while the three others keep publishing: the diagnostics say
    so first (no IMU sample from it, with its topic, for how long), not the others' messages
    dropped unpaired for want of it. Once it is back the problem goes; when the stream ends, no
    sensor sends."""
    h = ros_silent(170)
    node = h.estimator(input_type="imu", imu_lateral_axes=["+z"] * 4, imu_proximal_axes=["-x"] * 4,
                       imu_calibration_path=str(tmp_path / "never.imu.yaml"))
    client = h.client(node)
    pubs = publishers(client)
    msgs = [[imu_msg(BASE_NS + k * 5_000_000 + OFFSETS_NS[c], [0.0, 0.0, 0.0, 1.0], np.zeros(3), np.array([0.0, 0.0, 1.0]))
             for c in range(4)] for k in range(1200)]
    stream(client, pubs, msgs, skip=lambda k, c: c == 2 and 200 <= k < 900)  # 3.5 s without the right shank
    client.spin_for(1.5)
    reports = list(zip(client.received.diagnostics, client.received.diagnostics_level,
                       client.received.diagnostics_message, strict=True))
    shank = f"no IMU sample from right_shank ({h.namespace}/imu/right_shank) for "
    seen = [i for i, (_, _, m) in enumerate(reports) if m.startswith(shank)]
    assert seen, "\n".join(client.received.diagnostics_message)
    for diag, level, message in (reports[i] for i in seen):
        assert level == 1 and message.split("; ")[0].endswith("s: the estimate waits"), (level, message)
        assert "rejected" not in message and diag["imu_silent"].startswith("right_shank (")
    assert int(reports[seen[-1]][0]["rejected_unpaired"]) > 0, "the others' messages are still counted"
    assert any("no IMU sample" not in m for _, _, m in reports[seen[-1] + 1:]), "back: the problem goes"
    diag, level, message = reports[-1]  # the stream ended: every sensor silent
    assert level == 1 and message.startswith("no IMU sample from any sensor for "), message
    assert int(diag["samples_received"]) == int(diag["samples_accepted"]) + int(diag["samples_rejected"])


def test_a_wearer_with_four_raw_imus_is_taught_live(ros, tmp_path, monkeypatch):
    """The clinic hour: no library, four raw IMUs put on anyhow. The node learns their mounting
    from the standing pose and the first strides, a mode is taught on the next strides, then its
    phase follows the walking. The taught kernel is the one ``train`` builds from the true angles
    of the same strides, to the fusion's error."""
    monkeypatch.setenv("HOME", str(tmp_path))
    rng = np.random.default_rng(11)
    s = synthesize(gait_angles(RATE, walk_s=22.0), RATE, random_mounts(rng), rng,
                   acc_noise_g=0.01, gyro_noise_dps=0.3, gyro_bias_dps=1.0)
    msgs = make_messages(s, len(s.time_s), raw=True)
    h = ros(74)
    node = h.estimator(input_type="imu", kernels="", teach_strides=4)
    client = h.client(node)
    remote = AsyncParameterClient(client.node, f"{h.namespace}/{h.node_name}")
    assert remote.wait_for_services(5.0)
    pubs = publishers(client)
    split = round(9.0 * RATE)  # standing 2 s, walking 7 s
    stream(client, pubs, msgs[:split])
    diag = client.latest_diagnostics(3.0)
    assert diag["imu_calibration_status"] == "calibrated", diag["imu_calibration_status"]
    assert client.estimate_count == 0

    future = remote.set_parameters([Parameter("teach_mode", value="Walk")])
    assert client.spin_until(future.done, 5.0) and future.result().results[0].successful
    stream(client, pubs, msgs[split:])
    client.spin_for(0.3)
    assert node.library.mode_names == ["Walk"], node.stream.teach_last_event
    taught = node.stream.last_taught
    kernel = node.library.mode("Walk")

    origin_s = node.stream.epoch_sec - BASE_NS // 1_000_000_000  # node time 0: the whole second of its first sample
    starts = origin_s + np.array([st.start_s for st in taught.strides])
    ends = starts + np.array([st.duration_s for st in taught.strides])
    labels = np.where((s.time_s >= starts.min()) & (s.time_s < ends.max()), "Walk", "")
    truth = Recording(s.time_s, s.angles_deg, labels=labels, source="synthetic")
    options = TrainOptions(heel_strikes="right_shank", rate_hz=RATE)
    expected = train_library([truth], "truth", options).library.mode("Walk")
    assert starts.min() > split / RATE, "strides from after teach_mode was set"
    assert abs(kernel.length - expected.length) <= 0.02 * expected.length
    n = min(kernel.length, expected.length)
    rms = np.sqrt(np.mean((kernel.samples[:n] - expected.samples[:n]) ** 2, axis=0))
    assert (rms < 0.5).all(), rms
    assert client.latest_diagnostics(3.0)["taught_modes"] == "Walk"

    hs = heel_strikes(truth, "right_shank", RATE).times_s
    t = (np.array(client.received.estimate_stamp_ns) - BASE_NS) / 1e9
    trace = client.received.trace(["Walk"])
    inside = (t > ends.max()) & (t < hs[-1]) & trace.ready
    assert inside.sum() > 4 * RATE
    k = np.searchsorted(hs, t[inside], side="right") - 1
    phase_truth = (t[inside] - hs[k]) / (hs[k + 1] - hs[k])
    err = np.abs((trace.phase[inside] - phase_truth + 0.5) % 1.0 - 0.5)
    assert err.mean() < 0.02, err.mean()
