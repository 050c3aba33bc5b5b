"""``process --as-node`` is the live node: a JointState bag played to ``estimator_node`` over real
DDS (loopback) gives, message for message, bit for bit, the estimates that the node's stream
object (``GaitStream``) gives offline on the same bag. Domain ID 140."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from ros_helpers import BASE_NS, in_process_factory, load_multispeed

from gait_estimator.cli.app import main
from gait_estimator.io.as_node import predict_as_node
from gait_estimator.io.bag_write import write_input_bag
from gait_estimator.io.outputs import estimate_array
from gait_estimator.ros.player import playlist_from_bag


@pytest.fixture
def ros(monkeypatch):
    yield from in_process_factory(monkeypatch, (140,))


def test_a_bag_played_to_the_node_equals_process_as_node(ros, tmp_path: Path, multispeed_csv: Path,
                                                         able_bodied) -> None:
    rec = load_multispeed(multispeed_csv, 4500, 5700)
    time_s, angles = rec.time_s.copy(), rec.angles_deg.copy()
    time_s[700:] += 2.0  # a gap longer than max_gap_s: the window restarts
    angles[300, 1] = np.nan  # dropped (non_finite)
    bag = write_input_bag(replace(rec, time_s=time_s, angles_deg=angles), tmp_path / "bag", start_ns=BASE_NS)
    pred, stream = predict_as_node(bag, able_bodied)
    assert stream.window_resets == 1 and stream.guard.rejected["non_finite"] == 1 and len(pred.sample) == len(rec) - 1

    h = ros(140)
    node = h.estimator()
    client = h.client(node)
    assert client.wait_for_node(10.0, settle_s=0.0)
    accepted = set(pred.sample.tolist())
    for i, raw in enumerate(playlist_from_bag(bag).data):  # the bag's bytes, one at a time
        n = client.estimate_count
        client.publisher.publish(raw)
        if i in accepted:
            assert client.spin_until(lambda n=n: client.estimate_count > n, 5.0), f"message {i} not answered"
        else:
            client.spin_for(0.05)
    np.testing.assert_array_equal(np.array(client.received.estimate_values), estimate_array(pred.trace))
    assert node.window_resets == 1 and node.rejected["non_finite"] == 1 and node.samples_accepted == len(accepted)


def test_process_as_node_on_the_command_line(tmp_path: Path, multispeed_csv: Path, capsys) -> None:
    """Without a jump back the node's way gives ``process``'s CSV; a restarted publisher (stamps
    jumping back, the bag's log times going on) is a window restart for it, not dropped samples."""
    rec = load_multispeed(multispeed_csv, 4500, 5300)
    bag = write_input_bag(rec, tmp_path / "bag", start_ns=BASE_NS)
    assert main(["process", str(bag), "--out", str(tmp_path / "plain.csv"), "-q"]) == 0
    assert main(["process", str(bag), "--as-node", "--out", str(tmp_path / "node.csv")]) == 0
    assert "as the node: 800 received, 800 accepted, window restarts 0" in capsys.readouterr().out
    assert (tmp_path / "node.csv").read_bytes() == (tmp_path / "plain.csv").read_bytes()
    assert main(["process", str(bag), "--as-node", "--start", "3"]) == 2

    path = restarted_bag(tmp_path / "restarted", rec)  # second half: stamps from BASE_NS again
    assert main(["process", str(path), "--as-node"]) == 0
    assert "as the node: 800 received, 800 accepted, window restarts 1 (1 jumps back)" in capsys.readouterr().out
    assert main(["process", str(path)]) == 0
    assert "skipped 400 sample(s): non_increasing_stamp" in capsys.readouterr().out


def restarted_bag(path: Path, rec) -> Path:
    """``rec`` as a bag whose header stamps restart halfway (log times keep increasing)."""
    from gait_estimator.io.bag import typestore
    from gait_estimator.io.bag_write import joint_state_msg, staged_writer

    ts = typestore()
    half = len(rec) // 2
    with staged_writer(path, "mcap") as writer:
        conn = writer.add_connection("/segment_angles", "sensor_msgs/msg/JointState", typestore=ts)
        for i, a in enumerate(np.radians(rec.angles_deg)):
            stamp = BASE_NS + round(float(rec.time_s[i % half if i >= half else i] - rec.time_s[0]) * 1e9)
            msg = joint_state_msg(ts, stamp, ["right_thigh", "left_thigh", "right_shank", "left_shank"], a)
            writer.write(conn, BASE_NS + round(float(rec.time_s[i] - rec.time_s[0]) * 1e9),
                         ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
    return path


def test_every_imu_input_is_counted_once_with_its_reason() -> None:
    """Four IMUs through the node's stream object: each input is received once and either accepted
    (a paired sample, with or without angles yet) or rejected with a reason (a bad message, one
    without partners, undecodable bytes): received = accepted + rejected."""
    from imu_synth import gait_angles, random_mounts, synthesize

    from gait_estimator.core.estimator import EstimatorConfig
    from gait_estimator.core.gait_stream import GaitStream
    from gait_estimator.core.imu_flow import ImuFlow
    from gait_estimator.core.rejections import MALFORMED, SampleRejected

    rng = np.random.default_rng(5)
    s = synthesize(gait_angles(200.0, walk_s=1.0, stand_s=0.5), 200.0, random_mounts(rng), rng)
    stream = GaitStream(None, EstimatorConfig(), units=None)
    stream.attach_imu(ImuFlow.from_settings([""] * 4, [""] * 4, [0.0] * 4, None, frames=[""] * 4, tolerance_s=0.004,
                                            restart_back_s=1.0, path="x"))
    for k in range(len(s.time_s)):
        for c in range(4):
            if c == 2 and 50 <= k < 60:  # the right shank silent: the others' messages go unpaired
                continue
            q = (0.0, 0.0, 0.0, 0.0) if (c, k) == (1, 70) else tuple(s.quat_xyzw[c, k])
            stream.push_imu(c, BASE_NS + k * 5_000_000, q, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 9.8), "")
    stream.push_imu(0, BASE_NS, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 9.8), "")  # stamp back
    stream.reject(SampleRejected(MALFORMED, "undecodable"))
    rejected = stream.rejected()
    assert rejected == {"malformed": 1, "non_increasing_stamp": 1, "unpaired": 30 + 3, "zero_norm": 1}
    assert stream.accepted == len(s.time_s) - 10 - 1 and stream.received == stream.accepted + sum(rejected.values())
