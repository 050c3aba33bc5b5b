"""rosbag2 recordings: reading, --out-bag, convert, bad input (no ROS needed; rosbags only).

Bags are generated in temporary directories from slices of the shared recordings.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from gait_estimator.cli.app import main
from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.errors import RecordingError
from gait_estimator.core.estimator import EstimatorConfig
from gait_estimator.io.bag import (
    FLOAT64_MULTI_ARRAY,
    JOINT_STATE,
    UNDECODABLE,
    BagRecording,
    read_bag,
    typestore,
)
from gait_estimator.io.bag_write import (
    joint_state_msg,
    offered_qos,
    recording_stamps,
    write_input_bag,
    write_output_bag,
)
from gait_estimator.io.imu_bag import read_imu_bag
from gait_estimator.io.outputs import estimate_names, mode_names_from_sse_label, sse_label
from gait_estimator.io.process import predict
from gait_estimator.io.read_options import ReadOptions
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording, read_project_csv, write_project_csv

START_NS = 1_700_000_000_123_456_789
N = 1000  # samples of the ramp recording used by most tests (window: 392 samples)


@pytest.fixture(scope="module")
def ramp(swge: Path) -> Recording:
    """The first N samples of LG_2_Ramp (jittery real time stamps), as a project CSV re-read,
    so that CSV and bag hold exactly the same values."""
    return read_recording(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv").slice(0, N)


@pytest.fixture(scope="module")
def ramp_csv(ramp: Recording, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_project_csv(ramp, tmp_path_factory.mktemp("csv") / "ramp.csv")


@pytest.fixture(scope="module")
def csv_pred(ramp_csv: Path, able_bodied):
    return predict(read_recording(ramp_csv), able_bodied)


def _same_trace(a, b) -> None:
    assert a.mode_names == b.mode_names
    np.testing.assert_array_equal(a.mode_index, b.mode_index)
    np.testing.assert_array_equal(a.ready, b.ready)
    # The default resampling interpolates at the stamps: the bag's are integer nanoseconds from
    # START_NS, the CSV's microseconds from 0, so grid weights differ in the last bits.
    np.testing.assert_allclose(a.phase, b.phase, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.phases, b.phases, rtol=0, atol=1e-9)
    # radians in the bag: deg -> rad -> deg may change the last bit of an angle; stamps as above
    np.testing.assert_allclose(a.sse, b.sse, rtol=1e-10, atol=1e-9)


def _error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith("gait-estimator: error: ")
    return err


# ---------------------------------------------------------------------------------------------
# bag vs CSV identity


@pytest.mark.parametrize(
    ("storage", "msg_type", "units"),
    [("mcap", "joint_state", "rad"), ("sqlite3", "joint_state", "deg"), ("sqlite3", "float64_multi_array", "rad")],
)
def test_bag_predictions_equal_csv(tmp_path, ramp, csv_pred, able_bodied, storage, msg_type, units):
    bag = write_input_bag(ramp, tmp_path / "bag", storage=storage, msg_type=msg_type, units=units, start_ns=START_NS)
    assert (bag / "metadata.yaml").is_file()
    assert next(bag.glob("*.mcap" if storage == "mcap" else "*.db3"))
    rec = read_recording(bag, input_units=units)
    assert isinstance(rec, BagRecording)
    assert rec.msgtype == (JOINT_STATE if msg_type == "joint_state" else FLOAT64_MULTI_ARRAY)
    assert len(rec) == N and rec.skipped == {}
    assert rec.stamp_ns[0] == START_NS
    np.testing.assert_allclose(rec.time_s, ramp.time_s - ramp.time_s[0], atol=1e-9)
    pred = predict(rec, able_bodied)
    _same_trace(pred.trace, csv_pred.trace)
    np.testing.assert_array_equal(pred.sample, np.arange(N))


def test_cli_process_bag_and_csv_write_the_same_predictions(tmp_path, ramp, ramp_csv, capsys):
    bag = write_input_bag(ramp, tmp_path / "bag", start_ns=START_NS)
    assert main(["process", str(ramp_csv), "--out", str(tmp_path / "csv.csv"), "-q"]) == 0
    assert main(["process", str(bag), "--topic", "/segment_angles", "--out", str(tmp_path / "bag.csv")]) == 0
    out = capsys.readouterr().out
    assert f"{bag}: {N} samples" in out
    assert "skipped" not in out and "note:" not in out
    assert (tmp_path / "bag.csv").read_text() == (tmp_path / "csv.csv").read_text()


def test_process_bag_slice_equals_csv_slice(tmp_path, ramp, ramp_csv):
    bag = write_input_bag(ramp, tmp_path / "bag", storage="sqlite3", start_ns=START_NS)
    args = ["--start", "100", "--stop", "700", "-q", "--out"]
    assert main(["process", str(ramp_csv), *args, str(tmp_path / "csv.csv")]) == 0
    assert main(["process", str(bag), *args, str(tmp_path / "bag.csv")]) == 0
    assert (tmp_path / "bag.csv").read_text() == (tmp_path / "csv.csv").read_text()


def test_storage_file_without_metadata_is_read(tmp_path, ramp, able_bodied, csv_pred):
    bag = write_input_bag(ramp, tmp_path / "bag", start_ns=START_NS)
    (bag / "metadata.yaml").unlink()
    rec = read_recording(next(bag.glob("*.mcap")))
    _same_trace(predict(rec, able_bodied).trace, csv_pred.trace)


def test_reference_csv_without_time_converts_at_230_hz(tmp_path, multispeed_csv, capsys):
    assert main(["convert", str(multispeed_csv), "--out-bag", str(tmp_path / "ms"), "--start-time", "1700000000"]) == 0
    rec = read_bag(tmp_path / "ms")
    assert len(rec) == 14170
    np.testing.assert_array_equal(np.diff(rec.stamp_ns[:4]), np.rint(np.diff(np.arange(4) / 230.0) * 1e9))
    assert rec.stamp_ns[0] == 1_700_000_000 * 10**9
    ref = read_recording(multispeed_csv)
    np.testing.assert_allclose(rec.angles_deg, ref.angles_deg, rtol=0, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# --out-bag


def _read_back(path: Path) -> dict[str, list[tuple[int, object]]]:
    ts = typestore()
    out: dict[str, list[tuple[int, object]]] = {}
    with Reader(path) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for conn, log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append((log_ns, ts.deserialize_cdr(raw, conn.msgtype)))
    out["__types__"] = types  # type: ignore[assignment]
    return out


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_out_bag_round_trip(tmp_path, ramp, csv_pred, storage, capsys):
    bag = write_input_bag(ramp, tmp_path / "in", start_ns=START_NS)
    out_bag = tmp_path / "out"
    assert main(["process", str(bag), "--out-bag", str(out_bag), "--storage", storage]) == 0
    assert f"wrote {out_bag} ({storage}" in capsys.readouterr().out
    assert next(out_bag.glob("*.mcap" if storage == "mcap" else "*.db3"))
    got = _read_back(out_bag)
    assert got.pop("__types__") == {
        "/mode": "std_msgs/msg/String",
        "/phase": "std_msgs/msg/Float64",
        "/sse": "std_msgs/msg/Float64MultiArray",
        "/estimate": "sensor_msgs/msg/JointState",
    }
    tr = csv_pred.trace
    stamps = read_bag(bag).stamp_ns
    ready = np.flatnonzero(tr.ready)
    assert 0 < ready.size < N
    # estimate: every input sample, stamped (and logged) with the input stamp
    est = got["/estimate"]
    assert len(est) == N
    assert [log for log, _ in est] == stamps.tolist()
    assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in est] == stamps.tolist()
    assert all(m.name == estimate_names(tr.mode_names) for _, m in est)
    values = np.array([m.position for _, m in est])
    m = len(tr.mode_names)
    np.testing.assert_array_equal(values[:, 0], tr.mode_index)
    np.testing.assert_allclose(values[:, 1], tr.phase, rtol=0, atol=1e-9)  # stamps: see _same_trace
    np.testing.assert_array_equal(values[:, 2], tr.ready.astype(float))
    np.testing.assert_allclose(values[:, 3 : 3 + m], tr.sse, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(values[:, 3 + m : 3 + 2 * m], tr.phases, rtol=0, atol=1e-9)
    tail = values[:, 3 + 2 * m :]
    np.testing.assert_allclose(tail[:, 0], tr.confidence, rtol=1e-10)
    np.testing.assert_allclose(tail[:, 1], tr.fit_rms_deg, rtol=1e-10)
    np.testing.assert_array_equal(tail[:, 2], tr.held.astype(float))
    np.testing.assert_allclose(tail[:, 3], tr.phase_rate, rtol=1e-9)  # nan until known, in both; stamps are ns
    np.testing.assert_array_equal(tail[:, 4], tr.raw_mode_index)
    np.testing.assert_array_equal(tail[:, 6], tr.state)
    # mode, phase, sse: only once ready, as the node publishes them
    for topic in ("/mode", "/phase", "/sse"):
        assert [log for log, _ in got[topic]] == stamps[ready].tolist(), topic
    assert [msg.data for _, msg in got["/mode"]] == tr.mode[ready].tolist()
    np.testing.assert_allclose([msg.data for _, msg in got["/phase"]], tr.phase[ready], rtol=0, atol=1e-9)
    sse = got["/sse"]
    assert all(mode_names_from_sse_label(msg.layout.dim[0].label) == tr.mode_names for _, msg in sse)
    assert sse[0][1].layout.dim[0].label == sse_label(tr.mode_names)
    assert (sse[0][1].layout.dim[0].size, sse[0][1].layout.dim[0].stride) == (m, m)
    np.testing.assert_allclose(np.array([msg.data for _, msg in sse]), tr.sse[ready], rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("resample", ["on", "off"])
def test_out_bag_answers_every_input_at_its_stamp(tmp_path, ramp, resample):
    """With or without resampling to the library's grid, one estimate per input sample, stamped
    and logged with that sample's stamp."""
    bag = write_input_bag(ramp, tmp_path / "in", start_ns=START_NS)
    argv = ["process", str(bag), "-q", "--resample", resample, "--out", str(tmp_path / "p.csv"), "--out-bag", str(tmp_path / "o")]
    assert main(argv) == 0
    times = np.loadtxt(tmp_path / "p.csv", delimiter=",", skiprows=1, usecols=0)
    est = _read_back(tmp_path / "o")["/estimate"]
    stamps = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for _, m in est])
    assert len(est) == len(times) == N
    np.testing.assert_array_equal(stamps, read_bag(bag).stamp_ns)
    np.testing.assert_array_equal([log for log, _ in est], stamps)


def test_fast_output_serialization_is_byte_identical_to_rosbags():
    from gait_estimator.io.bag_write import _ArrayTemplate, multi_array_msg

    ts = typestore()
    rng = np.random.default_rng(0)
    v = rng.normal(size=(6, 17)) * 1e3
    keys = [f"key{i}" for i in range(17)]
    est = _ArrayTemplate(
        lambda i: ts.serialize_cdr(joint_state_msg(ts, START_NS + i, keys, v[i]), JOINT_STATE), v, tail=8, stamped=True
    )
    arr = _ArrayTemplate(
        lambda i: ts.serialize_cdr(multi_array_msg(ts, "modes:a", v[i, :7]), FLOAT64_MULTI_ARRAY), v[:, :7], tail=0
    )
    assert est.fast and arr.fast
    for i in range(6):
        assert est.message(i, START_NS + i) == bytes(est.slow(i))
        assert arr.message(i) == bytes(arr.slow(i))


def test_out_bag_refuses_to_overwrite(tmp_path, ramp_csv, capsys):
    (tmp_path / "exists").mkdir()
    err = _error(capsys, ["process", str(ramp_csv), "-q", "--out-bag", str(tmp_path / "exists")])
    assert "already exists" in err


def test_out_bag_from_csv_is_stamped_from_csv_time(tmp_path, ramp, csv_pred):
    stamps, logs = recording_stamps(ramp, START_NS)
    assert stamps[0] == START_NS and np.array_equal(stamps, logs)
    counts = write_output_bag(csv_pred, tmp_path / "out", stamps, storage="mcap", namespace="/left_leg")
    assert counts == {"mode": int(csv_pred.trace.ready.sum()), "phase": int(csv_pred.trace.ready.sum()),
                      "sse": int(csv_pred.trace.ready.sum()), "estimate": N}
    with Reader(tmp_path / "out") as reader:
        assert sorted(reader.topics) == ["/left_leg/estimate", "/left_leg/mode", "/left_leg/phase", "/left_leg/sse"]


# ---------------------------------------------------------------------------------------------
# convert


@pytest.mark.parametrize(
    ("storage", "msg_type", "units"), [("mcap", "joint_state", "rad"), ("sqlite3", "float64_multi_array", "deg")]
)
def test_convert_csv_to_bag_and_back(tmp_path, ramp, ramp_csv, storage, msg_type, units, capsys):
    bag = tmp_path / "bag"
    argv = ["convert", str(ramp_csv), "--out-bag", str(bag), "--storage", storage, "--type", msg_type, "--units", units]
    assert main([*argv, "--topic", "imu/segment_angles"]) == 0
    with Reader(bag) as reader:
        assert {t: i.msgcount for t, i in reader.topics.items()} == {"/imu/segment_angles": N}
        conn = reader.connections[0]
        assert conn.ext.offered_qos_profiles == offered_qos(100)
    csv = tmp_path / "back.csv"
    assert main(["convert", str(bag), "--out", str(csv), "--topic", "/imu/segment_angles", "--units", units]) == 0
    back = read_recording(csv)
    np.testing.assert_allclose(back.angles_deg, ramp.angles_deg, rtol=0, atol=1e-8)
    np.testing.assert_allclose(back.time_s, ramp.time_s - ramp.time_s[0], rtol=0, atol=1e-6)
    assert back.extra == {}


def test_convert_needs_exactly_one_output(tmp_path, ramp_csv, capsys):
    assert "exactly one of" in _error(capsys, ["convert", str(ramp_csv)])
    assert "exactly one of" in _error(capsys, ["convert", str(ramp_csv), "--out", "a.csv", "--out-bag", "b"])


# ---------------------------------------------------------------------------------------------
# bad messages, zero stamps, gaps


def _write_messages(path: Path, items: list[tuple[int, bytes]], msgtype: str = JOINT_STATE, topic: str = "/segment_angles",
                    storage: StoragePlugin = StoragePlugin.MCAP) -> Path:
    with Writer(path, version=8, storage_plugin=storage) as writer:
        conn = writer.add_connection(topic, msgtype, typestore=typestore())
        for log_ns, raw in items:
            writer.write(conn, log_ns, raw)
    return path


def _js(stamp_ns: int, names: list[str], angles_deg: np.ndarray) -> bytes:
    ts = typestore()
    return bytes(ts.serialize_cdr(joint_state_msg(ts, stamp_ns, names, np.radians(angles_deg)), JOINT_STATE))


def test_bad_messages_are_skipped_and_counted(tmp_path, ramp, able_bodied, capsys):
    n = 600
    stamps = START_NS + np.rint((ramp.time_s[:n] - ramp.time_s[0]) * 1e9).astype(np.int64)
    items = []
    for i in range(n):
        names, angles, stamp = list(CHANNELS), ramp.angles_deg[i], int(stamps[i])
        if i == 100:
            angles = np.array([0.1, math.nan, 0.3, 0.4])
        if i == 200:
            names = ["r_thigh", "l_thigh", "r_shank", "l_shank"]
        if i == 300:
            stamp = 0  # -> the receive (log) time is used
        if i == 400:
            stamp = int(stamps[i - 1])  # repeated stamp
        raw = _js(stamp, names, angles)
        if i == 450:
            raw = raw[:20]  # truncated CDR
        if i == 500:  # another joint in the message, other order: still fine
            raw = _js(stamp, ["left_foot", *reversed(CHANNELS)], np.r_[5.0, angles[::-1]])
        items.append((int(stamps[i]), raw))
    bag = _write_messages(tmp_path / "bad", items)

    rec = read_bag(bag)
    assert rec.skipped == {"non_finite": 1, "missing_joint": 1, "non_increasing_stamp": 1, UNDECODABLE: 1}
    assert rec.messages == n and len(rec) == n - 4
    assert rec.stamp_fallbacks == 1 and rec.stamp_ns[rec.index == 300] == stamps[300]
    keep = np.setdiff1d(np.arange(n), [100, 200, 400, 450])
    np.testing.assert_array_equal(rec.index, keep)
    clean = Recording(time_s=ramp.time_s[keep], angles_deg=ramp.angles_deg[keep])
    _same_trace(predict(rec, able_bodied).trace, predict(clean, able_bodied).trace)

    assert main(["process", str(bag)]) == 0
    out = capsys.readouterr().out
    assert f"{bag}: {n - 4} samples" in out
    for reason in ("non_finite", "missing_joint", "non_increasing_stamp", UNDECODABLE):
        assert f"skipped 1 sample(s): {reason}" in out
    assert "1 message(s) on /segment_angles had a zero header stamp: used the bag's receive time" in out


def test_gap_restarts_the_window_like_the_node(tmp_path, ramp, able_bodied, capsys):
    n, cut = 900, 500
    rec = Recording(time_s=ramp.time_s[:n].copy(), angles_deg=ramp.angles_deg[:n])
    rec.time_s[cut:] += 1.0  # a 1 s gap > max_gap_s 0.5
    bag = write_input_bag(rec, tmp_path / "gap", units="deg", start_ns=START_NS)

    got = read_bag(bag, input_units="deg")
    assert got.resets == 1
    paper = EstimatorConfig.preset("paper")  # the window counts below are the paper's (no resampling)
    expected = [predict(rec.slice(0, cut), able_bodied, paper).trace, predict(rec.slice(cut, n), able_bodied, paper).trace]
    tr = predict(got, able_bodied, paper).trace
    for name in ("mode_index", "phase", "sse", "phases", "ready"):
        np.testing.assert_array_equal(getattr(tr, name), np.concatenate([getattr(t, name) for t in expected]))
    assert not tr.ready[cut : cut + 391].any() and tr.ready[cut + 391 :].all()

    # the CLI says so; a CSV converted from the bag gives the same predictions
    assert main(["process", str(bag), "--input-units", "deg", "--out", str(tmp_path / "bag.csv")]) == 0
    assert "1 gap(s) longer than 0.5 s on /segment_angles: the matcher window restarted" in capsys.readouterr().out
    assert main(["convert", str(bag), "--units", "deg", "--out", str(tmp_path / "conv.csv")]) == 0
    assert main(["process", str(tmp_path / "conv.csv"), "-q", "--out", str(tmp_path / "conv_pred.csv")]) == 0
    assert (tmp_path / "conv_pred.csv").read_text() == (tmp_path / "bag.csv").read_text()
    assert "note: 1 gap(s)" in capsys.readouterr().out  # convert says so too

    # the gap check can be disabled (as the node's max_gap_s = 0)
    assert read_bag(bag, input_units="deg", max_gap_s=0).resets == 0
    out = tmp_path / "nogap.csv"
    assert main(["process", str(bag), "--input-units", "deg", "--max-gap", "0", "--preset", "paper", "--out", str(out)]) == 0
    assert "gap(s)" not in capsys.readouterr().out
    ready = np.loadtxt(out, delimiter=",", skiprows=1, usecols=4)
    assert ready[391:].all()


def test_joint_names_and_units_options(tmp_path, ramp, capsys):
    names = ["hip_r", "hip_l", "knee_r", "knee_l"]
    bag = write_input_bag(ramp, tmp_path / "bag", units="deg", joint_names=names, start_ns=START_NS)
    assert "missing_joint" in _error(capsys, ["process", str(bag), "-q"])
    out = tmp_path / "p.csv"
    assert main(["process", str(bag), "-q", "--joint-names", ",".join(names), "--input-units", "deg", "--out", str(out)]) == 0
    assert len(out.read_text().splitlines()) == N + 1
    with pytest.raises(SystemExit):  # argparse: 4 names needed
        main(["process", str(bag), "-q", "--joint-names", "a,b"])
    assert "expected 4 distinct comma-separated names" in capsys.readouterr().err


def test_a_misspelt_reader_option_is_refused_by_name(tmp_path, ramp, ramp_csv):
    bag = write_input_bag(ramp, tmp_path / "bag", units="deg", start_ns=START_NS)
    for read, path in ((read_recording, bag), (read_bag, bag), (read_recording, ramp_csv), (read_project_csv, ramp_csv)):
        with pytest.raises(TypeError, match=r"unknown reading option 'input_unit' \(known: .*input_units"):
            read(path, input_unit="deg")
    with pytest.raises(TypeError, match="unknown reading options 'rate', 'topc'"):
        read_recording(bag, topc="/segment_angles", rate=100.0)
    with pytest.raises(TypeError, match="'imu_topic'"):
        read_imu_bag(bag, imu_topic=["/a"] * 4)
    # an options object and fields by name read alike; fields a format has no use for are left alone
    by_name = read_recording(bag, input_units="deg", max_gap_s=0, rate_hz=50.0)
    given = read_bag(bag, ReadOptions(input_units="deg", max_gap_s=0))
    np.testing.assert_array_equal(by_name.angles_deg, given.angles_deg)
    np.testing.assert_allclose(given.angles_deg, ramp.angles_deg, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# bad bags: one line naming bag and topic, exit code 2


def test_missing_topic_lists_the_topics(tmp_path, ramp, capsys):
    bag = write_input_bag(ramp.slice(0, 10), tmp_path / "bag", start_ns=START_NS)
    err = _error(capsys, ["process", str(bag), "--topic", "/imu/angles"])
    assert str(bag) in err and "no topic /imu/angles" in err
    assert "topics in the bag: /segment_angles [sensor_msgs/msg/JointState, 10 msgs]" in err


def test_unsupported_message_type(tmp_path, capsys):
    ts = typestore()
    raw = bytes(ts.serialize_cdr(ts.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"))
    bag = _write_messages(tmp_path / "str", [(START_NS, raw)], msgtype="std_msgs/msg/String", topic="/chatter")
    err = _error(capsys, ["process", str(bag), "--topic", "chatter"])
    assert str(bag) in err and "topic /chatter has message type std_msgs/msg/String" in err
    # without --topic: nothing to choose from
    err = _error(capsys, ["process", str(bag)])
    assert "no topic /segment_angles" in err and "choose one with --topic" in err and "/chatter" in err


def test_no_usable_samples(tmp_path, capsys):
    nan = np.full(4, np.nan)
    bag = _write_messages(tmp_path / "nan", [(START_NS + i, _js(START_NS + i, list(CHANNELS), nan)) for i in range(5)])
    err = _error(capsys, ["process", str(bag)])
    assert "topic /segment_angles: no usable samples in 5 message(s); skipped: 5 non_finite" in err


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
@pytest.mark.parametrize("damage", ["garbage", "file_missing"])
def test_damaged_bags(tmp_path, ramp, capsys, storage, damage):
    """Damage that is no cut (overwritten bytes, the storage file gone): one line, exit 2. Cut
    files and a missing or wrong metadata.yaml are read as far as they go: test_bag_recover.py."""
    bag = write_input_bag(ramp, tmp_path / "bag", storage=storage, start_ns=START_NS)
    data = next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))
    if damage == "garbage":
        raw = bytearray(data.read_bytes())
        raw[len(raw) // 3 : len(raw) // 3 + 4096] = b"\xff" * 4096
        data.write_bytes(bytes(raw))
    else:
        data.unlink()
    with pytest.raises(RecordingError):
        read_bag(bag, topic="/segment_angles")
    err = _error(capsys, ["process", str(bag), "--topic", "/segment_angles"])
    assert str(bag) in err and "/segment_angles" in err
    if damage == "file_missing":
        assert f"metadata.yaml lists {data.name}, not in the directory; no complete message could be read" in err
    assert main(["convert", str(bag), "--out", str(tmp_path / "x.csv")]) == 2
    assert "topic /segment_angles" in capsys.readouterr().err


def test_empty_directory_is_not_a_recording(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert "not a recognised recording" in _error(capsys, ["process", str(tmp_path / "empty")])


def test_bag_options_on_a_csv_are_reported(ramp_csv, capsys):
    assert main(["process", str(ramp_csv), "--topic", "/x", "--input-units", "deg", "--max-gap", "1"]) == 0
    assert f"note: --topic, --input-units apply to bags only; ignored for {ramp_csv}" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------
# benchmark command


def test_bench_bag_command(tmp_path, ramp_csv, capsys):
    report = tmp_path / "bench.json"
    assert main(["bench-bag", str(ramp_csv), "--repeat", "1", "--json", str(report)]) == 0
    out = capsys.readouterr().out
    assert "process (read + matcher)" in out and "samples/s" in out
    import json

    data = json.loads(report.read_text())
    assert data["samples"] == N and data["samples_per_s"]["process"] > 0
