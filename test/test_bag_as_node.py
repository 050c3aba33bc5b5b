"""``convert`` and ``train`` with ``--as-node`` (``cli/as_node.py``, ``io/as_node.py``): the
node's ``GaitStream`` on a bag gives the angles it feeds its estimator and the kernel its teaching
builds, a taught kernel equal to a live node's taught over real DDS (loopback, domain ID 150);
rows in bag order with unique, increasing indices and times through a restarted stream."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from imu_synth import gait_angles, random_mounts, synthesize
from ros_helpers import BASE_NS, in_process_factory, load_multispeed
from test_stream_as_node import restarted_bag

from gait_estimator import load_library
from gait_estimator.analysis.evaluate import read_predictions_csv
from gait_estimator.cli.app import main
from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.imu import STANDARD_GRAVITY
from gait_estimator.io.bag import typestore
from gait_estimator.io.bag_write import staged_writer, write_input_bag
from gait_estimator.io.cdr import write_imu
from gait_estimator.io.imu_bag import IMU
from gait_estimator.io.readers import read_recording
from gait_estimator.ros.player import playlist_from_bag

RATE = 200.0


@pytest.fixture
def ros(monkeypatch):
    yield from in_process_factory(monkeypatch, (150,))


def test_train_as_node_equals_a_node_taught_live_over_dds(ros, tmp_path: Path, multispeed_csv: Path) -> None:
    """A node without a library, ``teach_mode`` Slow from the start, fed the bag's messages one by
    one: its kernel equals ``train --as-node``'s bit for bit (the same GaitStream on the same
    decoded samples; .npz keeps every bit)."""
    rec = load_multispeed(multispeed_csv, 8 * 230, 18 * 230)  # Multispeed's slow walk
    bag = write_input_bag(rec, tmp_path / "bag", start_ns=BASE_NS)
    assert main(["train", str(bag), "--as-node", "--mode", "Slow", "--strides", "4", "-o", str(tmp_path / "o.npz")]) == 0
    offline = load_library(tmp_path / "o.npz")

    h = ros(150)
    node = h.estimator(kernels="", teach_mode="Slow", teach_strides=4)
    client = h.client(node)
    assert client.wait_for_node(10.0, settle_s=0.0)
    for i, raw in enumerate(playlist_from_bag(bag).data):
        client.publisher.publish(raw)
        assert client.spin_until(lambda i=i: node.stream.received > i, 5.0), f"message {i} not received"
    live = node.stream.library
    assert live is not None and live.mode_names == offline.mode_names == ["Slow"]
    np.testing.assert_array_equal(live.mode("Slow").samples, offline.mode("Slow").samples)
    assert offline.name == "o" and offline.mode("Slow").info == live.mode("Slow").info


def test_train_as_node_by_label_ranges_and_what_is_refused(tmp_path: Path, multispeed_csv: Path, capsys) -> None:
    rec = load_multispeed(multispeed_csv, 8 * 230, 18 * 230)
    bag = write_input_bag(rec, tmp_path / "bag", start_ns=BASE_NS)
    ranges = tmp_path / "ranges.csv"
    ranges.write_text("start_s,end_s,mode\n0.5,10,Slow\n")
    out = str(tmp_path / "o.yaml")
    assert main(["train", str(bag), "--as-node", "--labels", str(ranges), "--strides", "4", "-o", out]) == 0
    assert load_library(out).mode("Slow").info["strides"] == 4
    later = write_input_bag(load_multispeed(multispeed_csv, 20 * 230, 30 * 230), tmp_path / "later", start_ns=BASE_NS)
    for bags, name in (([bag], "one.npz"), ([bag, later], "two.npz"), ([later], "later.npz")):
        assert main(["train", *map(str, bags), "--as-node", "--mode", "Slow", "--strides", "4", "-o", str(tmp_path / name)]) == 0
    one, two, other = (load_library(tmp_path / n).mode("Slow").samples for n in ("one.npz", "two.npz", "later.npz"))
    np.testing.assert_array_equal(one, two)  # a mode is taught once: from the first bag
    assert one.shape != other.shape or not np.array_equal(one, other)
    ranges.write_text("start_s,end_s,mode\n0,3,Slow\n3,10,Med\n")  # 3 s: too short for 3 strides
    assert main(["train", str(bag), "--as-node", "--labels", str(ranges), "--strides", "3", "-o", out]) == 1
    printed = capsys.readouterr().out
    assert "Slow: cancelled at" in printed and "not taught: Slow" in printed and load_library(out).mode_names == ["Med"]
    for extra, message in ((["--rate", "100"], "--rate is not for it"), (["--heel-strikes", "right_foot"], "not right_foot"),
                           ([], "give the mode(s) to teach")):
        assert main(["train", str(bag), "--as-node", "-o", out, *(extra or []), *([] if not extra else ["--mode", "A"])]) == 2
        assert message in capsys.readouterr().err
    assert main(["train", str(bag), "--mode", "Slow", "--strides", "4", "-o", out]) == 2
    assert "--strides is for --as-node" in capsys.readouterr().err


def test_convert_as_node_angles_equal_convert_without_restarts(tmp_path: Path, multispeed_csv: Path, capsys) -> None:
    """A bag without jumps back: the node's angles are ``convert``'s CSV byte for byte; a restarted
    stream keeps every sample, its times going on from the log time (a bag written from them has
    increasing stamps)."""
    rec = load_multispeed(multispeed_csv, 4500, 5300)
    bag = write_input_bag(rec, tmp_path / "bag", start_ns=BASE_NS)
    assert main(["convert", str(bag), "-o", str(tmp_path / "plain.csv")]) == 0
    assert main(["convert", str(bag), "--as-node", "-o", str(tmp_path / "node.csv")]) == 0
    assert (tmp_path / "node.csv").read_bytes() == (tmp_path / "plain.csv").read_bytes()
    path = restarted_bag(tmp_path / "restarted", rec)
    assert main(["convert", str(path), "--as-node", "--out-bag", str(tmp_path / "again")]) == 0
    assert "800 accepted, window restarts 1 (1 jumps back)" in capsys.readouterr().out
    again = read_recording(tmp_path / "again")
    assert len(again) == 800 and np.allclose(again.angles_deg, rec.angles_deg, atol=1e-9)
    assert np.allclose(np.diff(again.time_s), 1 / 230.0, atol=1e-6)  # the log time steps over the restart


def _imu_bag(path: Path, recordings: int = 2) -> Path:
    """Four raw Imu topics: standing 2 s then walking 6 s, recorded ``recordings`` times, each time
    with the stamps from the start again (a restarted driver); log times go on."""
    rng = np.random.default_rng(5)
    s = synthesize(gait_angles(RATE, walk_s=6.0), RATE, random_mounts(rng), rng, acc_noise_g=0.01, gyro_noise_dps=0.3)
    ts = typestore()
    n = len(s.time_s)
    with staged_writer(path, "mcap") as writer:
        conns = [writer.add_connection(f"/imu/{c}", IMU, typestore=ts) for c in CHANNELS]
        for k in range(recordings * n):
            stamp = BASE_NS + round(float(s.time_s[k % n]) * 1e9)
            for c in range(4):
                raw = write_imu(stamp + 100_000 * c, CHANNELS[c], (0.0, 0.0, 0.0, 1.0), -1.0,
                                np.radians(s.gyro_dps[c, k % n]), s.acc_g[c, k % n] * STANDARD_GRAVITY)
                writer.write(conns[c], BASE_NS + round(k / RATE * 1e9) + 100_000 * c, raw)
    return path


def test_imu_bag_times_count_from_the_same_0_with_and_without_as_node(tmp_path: Path) -> None:
    """The node's angles come only once the mounting is learnt (standing), ``convert``'s from the
    first paired sample on; both count time from that sample, so label ranges (``train --labels``)
    mean the same seconds both ways."""
    bag = _imu_bag(tmp_path / "imu", recordings=1)
    assert main(["convert", str(bag), "-o", str(tmp_path / "plain.csv")]) == 0
    assert main(["convert", str(bag), "--as-node", "-o", str(tmp_path / "node.csv")]) == 0
    plain, node = read_recording(tmp_path / "plain.csv"), read_recording(tmp_path / "node.csv")
    assert plain.time_s[0] == 0.0 and node.time_s[0] > 2.0 and len(node) > 500
    np.testing.assert_allclose(node.time_s, plain.time_s[-len(node):], atol=1e-6)  # the same samples, the same times


def test_imu_bag_as_node_rows_and_calibration(tmp_path: Path, capsys) -> None:
    """Through a restarted stream ``process --as-node`` rows have unique increasing indices and
    times, one per row of ``convert --as-node`` (the same times); the calibration learnt on the way
    is saved and taken by the next run."""
    bag = _imu_bag(tmp_path / "imu")
    cal = tmp_path / "cal.imu.yaml"
    assert main(["convert", str(bag), "--as-node", "-o", str(tmp_path / "angles.csv"),
                 "--save-imu-calibration", str(cal)]) == 0
    assert f"wrote IMU calibration {cal}" in capsys.readouterr().out
    assert main(["process", str(bag), "--as-node", "-o", str(tmp_path / "pred.csv"), "--imu-calibration", str(cal)]) == 0
    assert "(1 jumps back)" in capsys.readouterr().out
    assert main(["process", str(bag), "--as-node", "-o", str(tmp_path / "first.csv")]) == 0
    angles = read_recording(tmp_path / "angles.csv")
    pred = read_predictions_csv(tmp_path / "first.csv")
    assert len(pred.time_s) == len(angles) > 2000
    np.testing.assert_array_equal(pred.sample, np.arange(len(angles)))
    np.testing.assert_allclose(pred.time_s, angles.time_s, atol=1e-6)
    assert (np.diff(pred.time_s) > 0).all()
    assert len(read_predictions_csv(tmp_path / "pred.csv").time_s) > len(angles)  # calibrated from the first sample
    joint_state_bag = write_input_bag(angles, tmp_path / "js", start_ns=BASE_NS)
    assert main(["convert", str(joint_state_bag), "--as-node", "-o", str(tmp_path / "x.csv"),
                 "--save-imu-calibration", str(cal)]) == 2
    assert "no IMU calibration to save" in capsys.readouterr().err
