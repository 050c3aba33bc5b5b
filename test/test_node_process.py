"""estimator_node as a separate process through its installed entry point, and the demo and
bench-node commands: real DDS on loopback (domain IDs 21..28, 37, 38 and 49, LOCALHOST discovery)."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from ros_helpers import (
    REPO,
    as_node_sees,
    assert_same_trace,
    check_against_offline,
    load_multispeed,
    lockstep,
    offline,
    stamps_ns,
    unique_suffix,
    wait_all_answered,
)
from sensor_msgs.msg import JointState

from gait_estimator.core.rejections import REASONS
from gait_estimator.ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command


@pytest.fixture(scope="module")
def entry_point() -> str:
    """The ``estimator_node`` console script installed beside this interpreter (pip install)."""
    exe = shutil.which("estimator_node", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.fail(f"no estimator_node script in {Path(sys.executable).parent}: pip install -e . first")
    return exe


@pytest.fixture
def local_ros(monkeypatch):
    """Confine this process's ROS traffic to localhost (clients are created in-process)."""
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)


class Running:
    """estimator_node in a child process under a unique namespace, plus a client for it."""

    def __init__(self, domain_id: int, exe: str | None, ros_args: list[str], **client_kwargs: object) -> None:
        self.namespace = f"/gait_proc_{unique_suffix()}"
        args = ["-r", f"__ns:={self.namespace}", "-r", "__node:=estimator", *ros_args]
        self.node = NodeProcess(node_command(args, exe), local_ros_environment(domain_id))
        self.client = EstimatorClient(
            domain_id, namespace=self.namespace, estimator_name=f"{self.namespace}/estimator", **client_kwargs
        )
        ok = self.client.wait_for_node(timeout_s=30.0, settle_s=0.5)
        if not ok:
            self.close()
            pytest.fail(f"estimator_node did not come up; its output:\n{self.node.output()}")

    def stop(self, sig: int) -> tuple[int, str]:
        code = self.node.stop(sig)
        return code, self.node.output()

    def close(self) -> None:
        self.client.close()
        self.node.close()


def _clean_exit(code: int, log: str) -> None:
    assert code == 0, log
    assert "Traceback" not in log and "Error" not in log, log


def test_entry_point_joint_state_equals_offline_then_bad_input_and_sigint(
    entry_point, local_ros, multispeed_csv: Path, able_bodied
) -> None:
    """The installed entry point, 1500 Multispeed samples as JointState (rad) at 230 Hz from a
    best-effort publisher: every estimate equals offline predict on the samples it answered."""
    run = Running(21, entry_point, [])
    try:
        client = run.client
        rec = load_multispeed(multispeed_csv, 1500, 3000)
        stamps = stamps_ns(rec)
        client.stream(np.radians(rec.angles_deg), stamps, 230.0)
        wait_all_answered(client, len(rec))
        idx = check_against_offline(client.received, stamps, rec.angles_deg, "rad", able_bodied, min_fraction=0.98)
        ref = offline(as_node_sees(rec.angles_deg[idx], "rad"), able_bodied, stamps[idx])
        assert len(set(ref.modes)) >= 2  # Med -> Slow at ~9.9 s

        # Bad input: dropped, counted, one throttled warning per reason naming it.
        names = ["right_thigh", "left_thigh", "right_shank", "left_shank"]
        for k in range(20):
            msg = JointState(name=names, position=[math.nan, 0.0, 0.0, 0.0])
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamps[-1]) + (k + 1) * 1000, 10**9)
            client.publisher.publish(msg)
            msg = JointState(name=names[1:], position=[0.0, 0.0, 0.0])
            client.publisher.publish(msg)
            client.spin_once(0.005)
        before = len(client.received.diagnostics)
        assert client.spin_until(
            lambda: len(client.received.diagnostics) > before
            and client.received.diagnostics[-1]["rejected_missing_joint"] != "0"
            and int(client.received.diagnostics[-1]["samples_rejected"]) >= 38,
            5.0,
        ), client.received.diagnostics[-1:]
        diag = client.received.diagnostics[-1]
        assert diag["samples_accepted"] == str(idx.size)
        assert int(diag["rejected_non_finite"]) >= 19 and int(diag["rejected_missing_joint"]) >= 19
        assert set(REASONS) <= {k[len("rejected_") :] for k in diag if k.startswith("rejected_")}
        code, log = run.stop(signal.SIGINT)
    finally:
        run.close()
    _clean_exit(code, log)
    warnings = [line for line in log.splitlines() if "dropped sample" in line]
    assert sum(": non_finite: " in w for w in warnings) == 1, warnings
    assert sum(": missing_joint: " in w for w in warnings) == 1, warnings


def test_params_file_float64_multi_array_degrees_and_sigterm(
    entry_point, local_ros, multispeed_csv: Path, able_bodied, tmp_path: Path
) -> None:
    params = yaml.safe_load((REPO / "config" / "estimator.yaml").read_text(encoding="utf-8"))
    # also the SingleThreadedExecutor (the other tests run the default EventsExecutor)
    params["/**"]["ros__parameters"].update(input_type="float64_multi_array", input_units="deg",
                                            executor="single_threaded")
    # a removed option and an advanced one by its bare name: ignored, each with a warning
    params["/**"]["ros__parameters"].update(window_fraction=0.75, time_scales=[1.0])
    file = tmp_path / "params.yaml"
    file.write_text(yaml.safe_dump(params), encoding="utf-8")
    run = Running(22, entry_point, ["--params-file", str(file)], input_type="float64_multi_array")
    try:
        rec = load_multispeed(multispeed_csv, 9000, 9450)
        lockstep(run.client, rec.angles_deg, 230.0)
        got = run.client.received
        ref = offline(rec.angles_deg, able_bodied)
        assert_same_trace(got.trace(able_bodied.mode_names), ref)
        assert got.modes == [ref.mode_names[i] for i in ref.mode_index[ref.ready]] and got.modes
        code, log = run.stop(signal.SIGTERM)
    finally:
        run.close()
    _clean_exit(code, log)
    assert "parameter window_fraction ignored: the option was removed (docs/options.md)" in log, log
    assert "parameter time_scales ignored: it is advanced.time_scales now" in log, log


@pytest.mark.parametrize(("sig", "domain_id"), [(signal.SIGINT, 23), (signal.SIGTERM, 24)])
def test_idle_node_shuts_down_cleanly(entry_point, local_ros, sig: int, domain_id: int) -> None:
    run = Running(domain_id, entry_point, [])
    try:
        diag = run.client.latest_diagnostics(3.0)
        assert diag is not None and diag["ready"] == "false" and diag["library"] == "able_bodied"
        assert run.client.received.diagnostics_message[-1].startswith("no input")
        code, log = run.stop(sig)
    finally:
        run.close()
    _clean_exit(code, log)


def _policies(pid: int) -> set[tuple[int, int]]:
    """(policy, priority) of every thread of process ``pid``."""
    out = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            out.add((os.sched_getscheduler(int(tid)), os.sched_getparam(int(tid)).sched_priority))
        except ProcessLookupError:  # a thread that just ended
            pass
    return out


def _rt_permitted() -> bool:
    """Whether a process started from here may use SCHED_FIFO."""
    probe = [sys.executable, "-c", "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(3))"]
    return subprocess.run(probe, capture_output=True).returncode == 0


def test_thread_priority_runs_every_thread_under_sched_fifo(entry_point, local_ros) -> None:
    """``-p thread_priority:=3`` puts every thread of the node's process under SCHED_FIFO 3 (what
    ``chrt -f 3`` does); setting it to 0 at run time returns them to the normal scheduler. Where
    the system refuses real-time scheduling the node warns, reports ``normal`` and runs on."""
    permitted = _rt_permitted()
    run = Running(49, entry_point, ["-p", "thread_priority:=3"])
    try:
        diag = run.client.latest_diagnostics(3.0)
        assert diag is not None
        if not permitted:
            assert diag["scheduling"] == "normal"
            assert {p for p, _ in _policies(run.node.pid)} == {os.SCHED_OTHER}
            code, log = run.stop(signal.SIGINT)
            assert code == 0 and "thread_priority 3: not permitted" in log, log
            return
        assert diag["scheduling"] == "SCHED_FIFO 3"
        threads = _policies(run.node.pid)
        assert threads == {(os.SCHED_FIFO, 3)}, threads
        remote = AsyncParameterClient(run.client.node, f"{run.namespace}/estimator")
        assert remote.wait_for_services(10.0)
        future = remote.set_parameters([Parameter("thread_priority", value=0)])
        assert run.client.spin_until(future.done, 10.0)
        assert future.result().results[0].successful
        assert {p for p, _ in _policies(run.node.pid)} == {os.SCHED_OTHER}
        future = remote.set_parameters([Parameter("thread_priority", value=100)])
        assert run.client.spin_until(future.done, 10.0)
        (result,) = future.result().results
        assert not result.successful and "0..99" in result.reason
        code, log = run.stop(signal.SIGINT)
        assert "SCHED_FIFO 3 for" in log and "normal scheduling for" in log, log
    finally:
        run.close()
    _clean_exit(code, log)


def test_thread_priority_refused_is_a_warning(entry_point, local_ros) -> None:
    """Without CAP_SYS_NICE (dropped with setpriv) the node warns once, reports ``normal`` and
    runs on. As a non-root user the test above takes this path itself."""
    setpriv = shutil.which("setpriv")
    if os.geteuid() != 0 or setpriv is None:
        pytest.skip("needs root and setpriv to drop CAP_SYS_NICE (the test above covers this case when not root)")
    namespace = f"/gait_proc_{unique_suffix()}"
    cmd = node_command(["-r", f"__ns:={namespace}", "-r", "__node:=estimator", "-p", "thread_priority:=3"], entry_point)
    node = NodeProcess([setpriv, "--bounding-set=-sys_nice", "--inh-caps=-sys_nice", *cmd], local_ros_environment(49))
    client = EstimatorClient(49, namespace=namespace, estimator_name=f"{namespace}/estimator")
    try:
        assert client.wait_for_node(timeout_s=30.0, settle_s=0.5), node.output()
        diag = client.latest_diagnostics(3.0)
        assert diag is not None and diag["scheduling"] == "normal"
        assert {p for p, _ in _policies(node.pid)} == {os.SCHED_OTHER}
        code = node.stop(signal.SIGINT)
        log = node.output()
    finally:
        client.close()
        node.close()
    assert code == 0 and log.count("thread_priority 3: not permitted to set SCHED_FIFO 3") == 1, log


def test_unusable_parameters_exit_nonzero_with_one_line(entry_point, tmp_path: Path) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text("format: gait_estimator/kernel_library\nformat_version: 1\nname: [\n", encoding="utf-8")
    env = local_ros_environment(25)
    cases = [
        (["-p", f"kernels:={tmp_path / 'missing.yaml'}"], "missing.yaml: no such file or directory"),
        (["-p", f"kernels:={broken}"], "broken.yaml: invalid YAML"),
        (["-p", "input_units:=furlong"], "input_units"),
        (["-p", "max_gap_s:=abc"], "max_gap_s"),
        (["-p", "executor:=multi_threaded"], "executor: must be one of events, single_threaded"),
    ]
    for ros_args, text in cases:
        proc = subprocess.run(
            node_command(ros_args, entry_point), env=env, capture_output=True, text=True, timeout=60, check=False
        )
        lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
        assert proc.returncode == 2, (ros_args, proc.stdout, proc.stderr)
        assert len(lines) == 1 and lines[0].startswith("estimator_node: error: ") and text in lines[0], lines


def _bench_node(report: Path, *args: str) -> tuple[subprocess.CompletedProcess, dict]:
    """``gait-estimator bench-node ... --json report`` and its report; run a second time when the
    latency probe (best effort) lost more than a tenth of its samples, as a loaded machine can."""
    for _ in range(2):
        proc = _gait_estimator("bench-node", *args, "--json", str(report))
        if proc.returncode != 0:
            break
        data = json.loads(report.read_text(encoding="utf-8"))
        if data["latency"]["answered"] >= 0.9 * data["latency"]["samples"]:
            break
    return proc, (data if proc.returncode == 0 else {})


def _gait_estimator(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "gait_estimator.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        env=local_ros_environment(0),  # the commands set their own domain and LOCALHOST discovery
    )


def test_demo_command_streams_the_bundled_recording() -> None:
    """Samples 4500-5300: walking (the recording starts standing, which reads stand)."""
    proc = _gait_estimator("demo", "--start", "4500", "--stop", "5300", "--speed", "4", "--domain-id", "27",
                           "--echo-every", "40")
    out = proc.stdout
    assert proc.returncode == 0, out + proc.stderr
    assert "Multispeed_Walk_AB.csv" in out
    assert re.search(r"^mode: data: (Slow|Med|Fast|RA|RD|SA|SD)\b", out, re.M) and "phase: data: 0." in out
    assert "summary of what the node published" in out and "segments:" in out
    line = next(line for line in out.splitlines() if line.startswith("same mode as offline"))
    same, total = line.rsplit(" ", 1)[1].split("/")
    assert same == total and int(total) >= 780
    assert "exit code 0" in out


def test_bench_node_command(tmp_path: Path) -> None:
    report = tmp_path / "bench.json"
    proc, data = _bench_node(report, "--samples", "200", "--rates", "400", "--seconds", "0.5", "--executor", "events",
                             "--outputs", "estimate,all", "--profile", "--domain-id", "28")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "latency at 230 Hz" in proc.stdout and "highest input rate sustained without drops" in proc.stdout
    lat = data["latency"]
    assert lat["samples"] == 200 and lat["answered"] >= 180 and 0 < lat["p50_ms"] <= lat["p99_ms"]
    assert 0 < lat["dds_p50_ms"] <= lat["p50_ms"]
    assert data["modes"] == 7 and data["node_exit_code"] == 0
    assert data["throughput"]["steps"][0]["rate_hz"] == 400
    assert [(v["executor"], v["outputs"]) for v in data["variants"]] == [("events", "estimate"), ("events", "all")]
    assert data["executor"] == "events" and data["variants"][0]["latency"] == lat
    assert "throughput" not in data["variants"][1]  # latency only when subscribing to all outputs
    for v in data["variants"]:
        prof = v["latency"]["profile"]
        assert prof["samples"] >= 150, prof
        stages = prof["stages"]
        assert set(stages) >= {"dds_in_and_executor", "estimator", "publish", "dds_out", "bench_callback"}
        assert 0 < stages["estimator"]["p50_ms"] < stages["total_to_callback"]["p99_ms"]
        assert v["micro_us"]["serialized_estimate_publish_us"] > 0


def test_bench_node_with_more_modes(tmp_path: Path) -> None:
    """--modes: the node runs the library cycled to M modes; every estimate (2M + 9 values) reaches the bench.
    With --thread-priority (where permitted) the node and the bench run under SCHED_FIFO."""
    report = tmp_path / "bench.json"
    priority = 2 if _rt_permitted() else 0
    proc, data = _bench_node(report, "--modes", "14", "--preset", "paper", "--samples", "150", "--rates", "300",
                             "--seconds", "0.5", "--executor", "events", "--outputs", "estimate",
                             "--thread-priority", str(priority), "--domain-id", "37")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert data["modes"] == 14 and data["preset"] == "paper" and data["node_exit_code"] == 0
    assert data["thread_priority"] == priority
    assert data["latency"]["answered"] >= 135
    assert "(14 modes)" in proc.stdout
    bad = _gait_estimator("bench-node", "--modes", "0")
    assert bad.returncode == 2 and "--modes" in bad.stderr
    bad = _gait_estimator("bench-node", "--thread-priority", "100")
    assert bad.returncode == 2 and "--thread-priority" in bad.stderr


def test_bench_node_with_raw_imu_input(tmp_path: Path) -> None:
    """--input imu-raw: the node runs input_type imu with configured mounting, four Imu messages
    (gyro + accelerometer only) per sample after a standing second; the samples are answered."""
    report = tmp_path / "bench.json"
    proc, data = _bench_node(report, "--input", "imu-raw", "--samples", "150", "--rates", "300", "--seconds", "0.5",
                             "--executor", "events", "--outputs", "estimate", "--domain-id", "38")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "input imu-raw" in proc.stdout
    assert data["input"] == "imu-raw" and data["node_exit_code"] == 0
    assert data["latency"]["samples"] == 150 and data["latency"]["answered"] >= 135
    assert data["throughput"]["steps"][0]["rate_hz"] == 300 and data["throughput"]["steps"][0]["answered"] > 0
