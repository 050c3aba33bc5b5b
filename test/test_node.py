"""estimator_node in-process: real rclpy publishers/subscribers over DDS on loopback (no mocks).

Domain IDs 11..20, 26 and 28, one per test; LOCALHOST discovery; a namespace unique to the run.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from ros_helpers import (
    REPO,
    as_node_sees,
    assert_same_trace,
    check_against_offline,
    in_process_factory,
    load_multispeed,
    lockstep,
    offline,
    stamps_ns,
    wait_all_answered,
)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from gait_estimator import load_library
from gait_estimator.core.estimator import Estimator, EstimatorConfig
from gait_estimator.core.options import ADVANCED
from gait_estimator.core.rejections import REASONS
from gait_estimator.ros.imu_input import PARAMETERS as IMU_PARAMETERS
from gait_estimator.ros.node import DEFAULTS, DESCRIPTIONS, EstimatorNode, StartupError
from gait_estimator.ros.parameters import yaml_defaults

PERIOD_NS = round(1e9 / 230.0)


@pytest.fixture
def ros(monkeypatch):
    """Factory: ``ros(domain_id)`` -> an InProcess harness, closed after the test."""
    yield from in_process_factory(monkeypatch, range(11, 30))


def test_joint_state_rad_at_230hz_equals_offline_process(ros, multispeed_csv: Path, able_bodied) -> None:
    """1500 Multispeed samples (fresh state at sample 4500, Slow -> Med after 3 s) as JointState
    in radians at 230 Hz from a best-effort publisher: every estimate equals offline predict."""
    h = ros(11)
    node = h.estimator()
    client = h.client(node)
    rec = load_multispeed(multispeed_csv, 4500, 6000)
    stamps = stamps_ns(rec)
    assert client.wait_for_node(10.0, settle_s=0.0)
    client.stream(np.radians(rec.angles_deg), stamps, 230.0)
    wait_all_answered(client, len(rec))
    idx = check_against_offline(client.received, stamps, rec.angles_deg, "rad", able_bodied, min_fraction=0.99)
    ref = offline(as_node_sees(rec.angles_deg[idx], "rad"), able_bodied, stamps[idx])
    assert len(set(ref.modes[400:])) >= 2, "the chosen samples should contain mode changes"
    if np.array_equal(idx, np.arange(len(rec))):
        assert np.flatnonzero(ref.ready)[0] == Estimator(able_bodied).matcher.max_window - 1
    diag = client.latest_diagnostics(3.0)
    assert diag is not None
    assert diag["ready"] == "true" and diag["library"] == "able_bodied" and diag["modes"] == "7"
    assert int(diag["samples_accepted"]) == idx.size and diag["samples_rejected"] == "0"


def test_float64_multi_array_in_degrees(ros, multispeed_csv: Path, able_bodied) -> None:
    """Float64MultiArray [rt, lt, rs, ls] in degrees at 230 Hz; stamps come from the node clock."""
    h = ros(12)
    node = h.estimator(input_type="float64_multi_array", input_units="deg")
    client = h.client(node, input_type="float64_multi_array")
    rec = load_multispeed(multispeed_csv, 5000, 5600)
    assert client.wait_for_node(10.0, settle_s=0.0)
    lockstep(client, rec.angles_deg, 230.0)
    got = client.received
    assert len(got.estimate_values) == len(rec)
    assert (np.diff(got.estimate_stamp_ns) > 0).all()
    now_ns = node.get_clock().now().nanoseconds
    assert abs(now_ns - got.estimate_stamp_ns[-1]) < 60e9  # node clock (system time here)
    ref = offline(rec.angles_deg, able_bodied)
    assert_same_trace(got.trace(able_bodied.mode_names), ref)
    assert got.modes == [ref.mode_names[i] for i in ref.mode_index[ref.ready]]


def test_best_effort_and_reliable_publishers_both_reach_the_node(ros, multispeed_csv: Path, able_bodied) -> None:
    h = ros(13)
    node = h.estimator()
    best_effort = h.client(node)
    reliable = h.client(reliable=True, outputs=())
    rec = load_multispeed(multispeed_csv, 0, 60)
    stamps = stamps_ns(rec)
    x = np.radians(rec.angles_deg)
    assert best_effort.wait_for_node(10.0, settle_s=0.0)
    assert reliable.wait_for_node(10.0, outputs=False, settle_s=0.0)
    for i in range(30):
        best_effort.publish(x[i], stamps[i])
        best_effort.spin_once(0.005)
    wait_all_answered(best_effort, 30)
    for i in range(30, 60):
        reliable.publish(x[i], stamps[i])
        best_effort.spin_once(0.005)
    wait_all_answered(best_effort, 60)
    idx = check_against_offline(best_effort.received, stamps, rec.angles_deg, "rad", able_bodied, 0.9)
    assert (idx < 30).any() and (idx >= 30).any(), "both publishers must reach the node"


def _joint_state(names: list[str], positions: list[float], stamp_ns: int) -> JointState:
    msg = JointState()
    msg.name = names
    msg.position = [float(v) for v in positions]
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return msg


def test_bad_input_is_dropped_counted_warned_and_state_stays_valid(ros, multispeed_csv: Path, able_bodied, capfd) -> None:
    h = ros(14)
    node = h.estimator()
    client = h.client(node)
    assert client.wait_for_node(10.0, settle_s=0.0)
    rec = load_multispeed(multispeed_csv, 2000, 2500)
    x = np.radians(rec.angles_deg)
    stamps = stamps_ns(rec)
    names = ["right_thigh", "left_thigh", "right_shank", "left_shank"]
    good = list(range(len(rec)))
    sent = 0

    def send(msg: JointState | bytes) -> None:
        nonlocal sent
        client.publisher.publish(msg)
        sent += 1
        assert client.spin_until(lambda: node.samples_received == sent, 2.0)

    def good_sample(i: int) -> JointState:
        # extra joints and a different order are fine
        return _joint_state(["ankle", *reversed(names)], [0.3, *reversed(x[i].tolist())], stamps[i])

    bad_stamp = stamps[200]
    bad = [
        ("non_finite", _joint_state(names, [math.nan, 0.1, 0.2, 0.3], bad_stamp + 1)),
        ("non_finite", _joint_state(names, [0.1, math.inf, 0.2, 0.3], bad_stamp + 2)),
        ("missing_joint", _joint_state(names[:3], [0.1, 0.2, 0.3], bad_stamp + 3)),
        ("wrong_length", _joint_state(names, [0.1, 0.2, 0.3], bad_stamp + 4)),
        ("non_increasing_stamp", _joint_state(names, x[0].tolist(), stamps[199])),  # equal to the last
        # earlier, by less than max_gap_s (0.5 s): a reordered sample (further back restarts the
        # window as a restarted stream, see test_faults.py)
        ("non_increasing_stamp", _joint_state(names, x[0].tolist(), stamps[150])),
        ("out_of_range", _joint_state(names, [1e6, 0.1, 0.2, 0.3], bad_stamp + 5)),
        # bytes no deserialiser reads, published as a serialised JointState
        ("malformed", b"\x00\x01\x00\x00" + b"\xff" * 40),
    ]
    for i in range(200):
        send(good_sample(i))
    for _reason, msg in bad:
        send(msg)
    for i in range(200, len(rec)):
        send(good_sample(i))
    wait_all_answered(client, len(good))

    # Only good samples were answered, and exactly as if the bad ones had never been sent.
    check_against_offline(client.received, stamps, rec.angles_deg, "rad", able_bodied, min_fraction=1.0)
    expected = {r: sum(1 for reason, _ in bad if reason == r) for r in REASONS}
    assert node.rejected == expected
    diag = client.latest_diagnostics(3.0)
    assert diag is not None
    for r in REASONS:
        assert diag[f"rejected_{r}"] == str(expected[r])
    assert diag["samples_rejected"] == str(len(bad))
    assert diag["samples_accepted"] == str(len(good))
    assert diag["samples_received"] == str(len(good) + len(bad))

    # One throttled warning per reason, naming the problem.
    err = capfd.readouterr().err
    warnings = [line for line in err.splitlines() if "dropped sample" in line]
    for r in REASONS:
        assert sum(f": {r}: " in w for w in warnings) == 1, (r, warnings)
    assert any("left_shank" in w for w in warnings if "missing_joint" in w)


def test_float64_multi_array_wrong_length_and_non_finite(ros) -> None:
    h = ros(15)
    node = h.estimator(input_type="float64_multi_array")
    client = h.client(node, input_type="float64_multi_array")
    assert client.wait_for_node(10.0, settle_s=0.0)
    for data in ([0.1, 0.2, 0.3], [0.1, 0.2, 0.3, 0.4, 0.5], [], [0.1, math.nan, 0.2, 0.3]):
        n = node.samples_received
        msg = Float64MultiArray()
        msg.data = data
        client.publisher.publish(msg)
        assert client.spin_until(lambda n=n: node.samples_received > n, 2.0)
    assert node.rejected["wrong_length"] == 3 and node.rejected["non_finite"] == 1
    assert node.samples_accepted == 0
    lockstep(client, np.full((3, 4), 0.1), 230.0)
    assert client.estimate_count == 3


def test_parameters_validated_at_set_time(ros, tmp_path: Path) -> None:
    h = ros(16)
    node = h.estimator()
    bad = [
        ("input_units", "furlong", "rad, deg"),
        ("joint_names", ["a", "b", "c"], "needs 4 names"),
        ("joint_names", ["a", "b", "c", "a"], "distinct"),
        ("joint_names", ["a", "b", "", "d"], "empty"),
        ("max_gap_s", -1.0, ">= 0"),
        ("max_gap_s", math.nan, ">= 0"),
        ("channels", ["right_thigh", "tail"], "channels"),
        ("advanced.channel_weights", [1.0, -1.0, 1.0, 1.0], "channel_weights"),
        ("advanced.time_scales", [0.1], "time_scales"),
        ("min_dwell_s", -3.0, ">= 0"),
        ("transitions", str(tmp_path / "none.yaml"), "none.yaml"),
        ("kernels", str(tmp_path / "missing.yaml"), "missing.yaml: no such file"),
        ("kernels", "", "empty"),
    ]
    for name, value, why in bad:
        before = node.get_parameter(name).value
        (result,) = node.set_parameters([Parameter(name, value=value)])
        assert not result.successful, (name, value)
        assert name in result.reason and why in result.reason, result.reason
        assert node.get_parameter(name).value == before
    (result,) = node.set_parameters([Parameter("max_gap_s", value=1)])  # wrong type
    assert not result.successful
    for name, value in (("input_type", "float64_multi_array"), ("executor", "single_threaded")):
        (result,) = node.set_parameters([Parameter(name, value=value)])
        assert not result.successful and "read-only" in result.reason.lower()
    broken = tmp_path / "broken.yaml"
    broken.write_text("format: gait_estimator/kernel_library\nformat_version: 1\nname: x\n", encoding="utf-8")
    (result,) = node.set_parameters([Parameter("kernels", value=str(broken))])
    assert not result.successful and "broken.yaml" in result.reason and "\n" not in result.reason
    assert node.library.name == "able_bodied"

    # Valid values apply.
    ok = node.set_parameters(
        [
            Parameter("input_units", value="deg"),
            Parameter("max_gap_s", value=2.0),
            Parameter("joint_names", value=["a", "b", "c", "d"]),
            Parameter("kernels", value="prosthesis"),
        ]
    )
    assert all(r.successful for r in ok)
    assert node.library.name == "prosthesis"
    client = h.client(node, joint_names=["a", "b", "c", "d"])
    assert client.wait_for_node(10.0, settle_s=0.0)
    lockstep(client, np.full((2, 4), 10.0), 230.0, stamps=[1_000_000_000, 1_010_000_000])
    assert client.received.estimate_names[3:10] == [f"sse/{m}" for m in load_library("prosthesis").mode_names]
    ref = offline(np.full((2, 4), 10.0), load_library("prosthesis"), [1_000_000_000, 1_010_000_000])  # degrees as such
    assert_same_trace(client.received.trace(ref.mode_names), ref)

    # Through the ROS parameter service too: the reason reaches the caller.
    remote = AsyncParameterClient(client.node, f"{h.namespace}/{h.node_name}")
    assert remote.wait_for_services(5.0)
    future = remote.set_parameters([Parameter("input_units", value="gradians")])
    assert client.spin_until(future.done, 5.0)
    (result,) = future.result().results
    assert not result.successful and "input_units" in result.reason and "gradians" in result.reason
    future = remote.describe_parameters(list(DEFAULTS))
    assert client.spin_until(future.done, 5.0)
    descriptors = future.result().descriptors
    assert [d.name for d in descriptors] == list(DEFAULTS)
    for d in descriptors:
        assert d.description == DESCRIPTIONS[d.name] and len(d.description) > 20
    assert "(s)" in DESCRIPTIONS["max_gap_s"] and "gap" in DESCRIPTIONS["max_gap_s"]


def test_invalid_values_at_startup_raise_one_line_errors(ros, tmp_path: Path) -> None:
    h = ros(17)
    for params, text in [
        ({"kernels": str(tmp_path / "nope.yaml")}, "nope.yaml: no such file or directory"),
        ({"input_units": "furlong"}, "input_units"),
        ({"input_type": "pose"}, "input_type"),
        ({"executor": "multi_threaded"}, "executor: must be one of events, single_threaded"),
        ({"max_gap_s": "soon"}, "max_gap_s"),
    ]:
        with pytest.raises(StartupError) as info:
            h.estimator(**params)
        assert text in str(info.value) and "\n" not in str(info.value)

    # `-p resample:=on` goes through rcl's YAML parser, which makes on/off booleans.
    for text, want in (("on", "on"), ("off", "off"), ("auto", "auto"), ("true", "on")):
        node = EstimatorNode(node_name=h.node_name, namespace=h.namespace, context=h.context,
                             cli_args=["--ros-args", "-p", f"resample:={text}"])
        assert node.config.resample == want, text
        (result,) = node.set_parameters([Parameter("resample", value=False)])
        assert result.successful and node.config.resample == "off"
        (result,) = node.set_parameters([Parameter("resample", value="sometimes")])
        assert not result.successful and "resample" in result.reason
        node.destroy_node()
    with pytest.raises(StartupError) as info:
        EstimatorNode(node_name=h.node_name, namespace=h.namespace, context=h.context,
                      cli_args=["--ros-args", "-p", "adapted_library_path:=/tmp/kernels.txt"])
    assert "adapted_library_path" in str(info.value) and ".npz" in str(info.value)


def test_max_gap_restarts_the_window(ros, multispeed_csv: Path, able_bodied) -> None:
    h = ros(18)
    node = h.estimator(max_gap_s=0.25)
    client = h.client(node)
    assert client.wait_for_node(10.0, settle_s=0.0)
    rec = load_multispeed(multispeed_csv, 3000, 3900)
    x = np.radians(rec.angles_deg)
    stamps = stamps_ns(rec)
    stamps[450:] += 300_000_000  # a 0.3 s hole before sample 450 (> max_gap_s)
    lockstep(client, x, 2000.0, stamps)
    got = client.received
    ready = got.trace(able_bodied.mode_names).ready
    window = Estimator(able_bodied).matcher.max_window
    assert ready[449] and not ready[450] and not ready[450 + window - 2] and ready[450 + window - 1]
    first = offline(as_node_sees(rec.angles_deg[:450], "rad"), able_bodied, stamps[:450])
    second = offline(as_node_sees(rec.angles_deg[450:], "rad"), able_bodied, stamps[450:])
    live = got.trace(able_bodied.mode_names)
    np.testing.assert_array_equal(live.mode_index, np.concatenate([first.mode_index, second.mode_index]))
    np.testing.assert_array_equal(live.phase, np.concatenate([first.phase, second.phase]))
    assert len(got.modes) == first.ready.sum() + second.ready.sum()
    diag = client.latest_diagnostics(3.0)
    assert diag is not None and diag["window_resets"] == "1" and diag["max_gap_s"] == "0.25"

    # 0 disables the check: the same hole no longer restarts anything.
    (result,) = node.set_parameters([Parameter("max_gap_s", value=0.0)])
    assert result.successful
    n = client.estimate_count
    lockstep(client, x[:5], 2000.0, stamps[-1] + 10**9 + PERIOD_NS * np.arange(5))
    assert client.estimate_count == n + 5 and got.estimate_values[-1][2] == 1.0


def test_use_sim_time_and_unstamped_input(ros) -> None:
    """Under use_sim_time, inputs without a stamp get the /clock time; stamped ones keep theirs."""
    h = ros(19)
    node = h.estimator(use_sim_time=True)
    client = h.client(node)
    clock_pub = client.node.create_publisher(Clock, "/clock", 10)
    assert client.wait_for_node(10.0, settle_s=0.0)
    assert client.spin_until(lambda: clock_pub.get_subscription_count() > 0, 5.0)
    for k, sim_ns in enumerate((5_000_000_000, 5_004_347_826, 5_008_695_652)):
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(sim_ns, 1_000_000_000)
        clock_pub.publish(msg)
        assert client.spin_until(lambda sim_ns=sim_ns: node.get_clock().now().nanoseconds == sim_ns, 5.0)
        lockstep(client, np.full((1, 4), 0.2), 230.0, stamps=[0])  # zero stamp = unstamped
        assert client.received.estimate_stamp_ns[k] == sim_ns
    lockstep(client, np.full((1, 4), 0.2), 230.0, stamps=[7_000_000_123])
    assert client.received.estimate_stamp_ns[-1] == 7_000_000_123


def test_config_yaml_holds_the_declared_defaults(ros, tmp_path: Path) -> None:
    doc = yaml.safe_load((REPO / "config" / "estimator.yaml").read_text(encoding="utf-8"))
    params = doc["/**"]["ros__parameters"]
    assert params == {**yaml_defaults(), **{name: default for name, (default, _) in IMU_PARAMETERS.items()}}
    assert set(DESCRIPTIONS) == set(DEFAULTS)
    assert {n for n in DEFAULTS if n.startswith("advanced.")} == {"advanced." + n for n in ADVANCED}

    # --params-file works (here through rclpy.init args, as ros2 run passes them).
    custom = tmp_path / "custom.yaml"
    params = {**params, "input_units": "deg", "max_gap_s": 1.5, "kernels": "prosthesis",
              "advanced": {**params["advanced"], "time_scales": [0.96, 1.0, 1.04]}, "window_fraction": 0.5}
    custom.write_text(yaml.safe_dump({"/**": {"ros__parameters": params}}), encoding="utf-8")
    h = ros(20)
    ctx = rclpy.context.Context()
    rclpy.init(context=ctx, domain_id=h.domain_id, args=["--ros-args", "--params-file", str(custom)])
    try:
        node = EstimatorNode(node_name="with_params", namespace=h.namespace, context=ctx)
        assert node.get_parameter("input_units").value == "deg"
        assert node.get_parameter("max_gap_s").value == 1.5
        assert node.library.name == "prosthesis"
        assert node.config.time_scales == (0.96, 1.0, 1.04)  # advanced.time_scales from the nested mapping
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)



def test_preset_services_and_new_wearer_outputs(ros, multispeed_csv: Path, able_bodied, tmp_path: Path) -> None:
    """preset: paper at start-up gives the paper's options (explicit ones still win); the
    estimate carries cadence_ratio; save_library writes the personalised kernels (or says why
    not); reset_calibration zeroes the learnt sensor offsets and forgets the learnt time scale, and
    so does a gap in the stream longer than calibration_reset_gap_s."""
    from std_srvs.srv import Trigger


    h = ros(26)
    paper = h.estimator(preset="paper", min_dwell_s=0.5)
    assert paper.config == EstimatorConfig.preset("paper", min_dwell_s=0.5)
    assert paper.get_parameter("resample").value == "off"
    assert list(paper.get_parameter("advanced.time_scales").value) == [1.0]
    (result,) = paper.set_parameters([Parameter("preset", value="default")])
    assert not result.successful and "read-only" in result.reason.lower()
    paper.destroy_node()
    h.nodes.remove(paper)

    path = tmp_path / "adapted.yaml"
    node = h.estimator(adapt_rate=0.2, adapted_library_path=str(path))
    assert node.config == EstimatorConfig(adapt_rate=0.2)
    client = h.client(node)
    assert client.wait_for_node(10.0, settle_s=0.0)
    rec = load_multispeed(multispeed_csv, 5500, 8500)  # steady slow walking
    lockstep(client, np.radians(rec.angles_deg), 2000.0, stamps_ns(rec))
    got = client.received
    assert "cadence_ratio" in got.estimate_names
    ratio = np.array(got.estimate_values)[:, got.estimate_names.index("cadence_ratio")]
    ready = np.array(got.estimate_values)[:, 2] == 1.0
    assert np.all((ratio[ready] >= 1 / 1.12 - 1e-9) & (ratio[ready] <= 1 / 0.88 + 1e-9))

    def call(name: str) -> Trigger.Response:
        cli = client.node.create_client(Trigger, f"{h.namespace}/{h.node_name}/{name}")
        assert cli.wait_for_service(timeout_sec=5.0)
        future = cli.call_async(Trigger.Request())
        assert client.spin_until(future.done, 5.0)
        return future.result()

    saved = call("save_library")
    assert saved.success and str(path) in saved.message and path.is_file(), saved.message
    lib = load_library(path)
    assert lib.mode_names == able_bodied.mode_names and sum(
        lib.provenance["adaptation"]["accepted_strides"].values()) > 0
    assert np.any(node.stream.estimator.sensor_offset_deg != 0)
    scale = node.stream.estimator.cadence_scale
    assert 0.88 <= scale <= 1.12
    diag = client.latest_diagnostics(3.0)
    assert diag is not None and diag["cadence_scale"] == f"{scale:.3f}"
    reset = call("reset_calibration")
    assert reset.success and "reset to 0" in reset.message and f"time scale {scale:.3f} forgotten" in reset.message
    assert not np.any(node.stream.estimator.sensor_offset_deg) and math.isnan(node.stream.estimator.cadence_scale)
    diag = client.latest_diagnostics(3.0)
    assert diag is not None and diag["sensor_offset_deg"] == "0.00,0.00,0.00,0.00" and int(diag["adapted_strides"]) > 0
    assert diag["cadence_scale"] == ""

    (result,) = node.set_parameters([Parameter("adapt_rate", value=0.0)])
    assert result.successful
    off = call("save_library")
    assert not off.success and "personalisation is off" in off.message

    # A gap in the stream longer than calibration_reset_gap_s forgets them too (the sensors may
    # have been re-donned); changing that threshold keeps the estimator and its window.
    est = node.stream.estimator
    (result,) = node.set_parameters([Parameter("calibration_reset_gap_s", value=4.0)])
    assert result.successful and node.stream.estimator is est and est.config.calibration_reset_gap_s == 4.0
    later = stamps_ns(rec) + (stamps_ns(rec)[-1] - stamps_ns(rec)[0]) + 10**8
    lockstep(client, np.radians(rec.angles_deg), 2000.0, later)
    assert np.any(est.sensor_offset_deg != 0) and est.calibration_resets == 0
    lockstep(client, np.radians(rec.angles_deg[:5]), 2000.0, later[-1] + 4_500_000_000 + PERIOD_NS * np.arange(5))
    assert not np.any(est.sensor_offset_deg) and est.calibration_resets == 1 and est.resets >= 1
