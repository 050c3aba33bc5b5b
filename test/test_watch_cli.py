"""``gait-estimator watch`` against a real estimator_node process over DDS (loopback), and with
no node at all.

Domain IDs 79 and 80; LOCALHOST discovery.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from ros_helpers import BASE_NS

from gait_estimator import load_library
from gait_estimator.cli.watch_command import watch_line
from gait_estimator.io.readers import read_recording
from gait_estimator.ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command

RATE_HZ = 230.0


@pytest.fixture(autouse=True)
def _local(monkeypatch) -> None:
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)


def _cli(*args: str, domain_id: int) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "gait_estimator.cli", "watch", *args, "--domain-id", str(domain_id)],
        env=local_ros_environment(domain_id), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def test_the_line_drops_what_the_columns_already_say() -> None:
    line = watch_line(12.25, "Fast", 0.4321, "OK", "ready: Fast phase 0.43; teaching Slow: 3/10 strides",
                      {"input_rate_hz": "230.0"}, ["input_rate_hz", "absent"])
    assert line == "   12.2 s  Fast          0.432  [OK] teaching Slow: 3/10 strides  input_rate_hz=230.0  absent=?"
    assert watch_line(0.5, None, None, "", "", {}, []) == "    0.5 s  -                 -  (no diagnostics yet)"
    long = re.split(r"\s{2,}", watch_line(1.0, "a_long_mode_name", 0.5, "OK", "", {}, []).strip())
    assert long[1:3] == ["a_long_mode_name", "0.500"]


@pytest.mark.parametrize(("node", "says"), [("/nobody", "no estimator node /nobody within 1 s on ROS_DOMAIN_ID=79"),
                                            ("/a-b/x", "--node /a-b/x: not a valid node name")])
def test_no_node_exit_2_one_line(node: str, says: str) -> None:
    proc = _cli("--node", node, "--timeout", "1", domain_id=79)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], err


def test_watch_a_running_node_in_a_namespace(multispeed_csv: Path, monkeypatch) -> None:
    """Lines before, while and after a stream: '-' without estimates, then the library's modes."""
    domain, ns = 80, "/clinic"
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    rec = read_recording(multispeed_csv, rate_hz=RATE_HZ)
    modes = load_library("able_bodied").mode_names
    command = node_command(["-p", "kernels:=able_bodied", "-r", f"__ns:={ns}"])
    with NodeProcess(command, local_ros_environment(domain)) as node:
        client = EstimatorClient(domain, namespace=ns, estimator_name=f"{ns}/estimator_node", outputs=("mode",))
        try:
            deadline = time.monotonic() + 30
            while not client.wait_for_node(0.5, outputs=False, settle_s=0.5):
                assert node.poll() is None and time.monotonic() < deadline, node.output()
            watch = _cli("--node", f"{ns}/estimator_node", "--duration", "10", "--rate", "4",
                         "--keys", "samples_accepted", domain_id=domain)
            first = watch.stdout.readline()
            assert first.startswith(f"watching {ns}/estimator_node on ROS_DOMAIN_ID={domain}: "), (first, watch.stderr.read())
            time.sleep(1.0)
            stamps = BASE_NS + np.round(rec.time_s * 1e9).astype(np.int64)
            n = round(5 * RATE_HZ)
            client.stream(np.radians(rec.angles_deg[:n]), stamps[:n], RATE_HZ)
            out, err = watch.communicate(timeout=30)
        finally:
            client.close()
        assert node.poll() is None
    assert watch.returncode == 0, (out, err)
    lines = [re.split(r"\s{2,}", x.strip()) for x in out.splitlines()]
    assert 35 <= len(lines) <= 45, out  # 4 lines a second for 10 s
    estimating = [i for i, x in enumerate(lines) if x[1] != "-"]
    walking = [i for i in estimating if lines[i][1] in modes]  # the recording starts standing: stand, phase nan
    assert estimating and all(0.0 <= float(lines[i][2]) < 1.0 for i in walking), out
    assert all(lines[i][1] in {"stand", "unknown"} and lines[i][2] == "nan" for i in set(estimating) - set(walking)), out
    assert lines[-1][1] == "-" and lines[-1][2] == "-", "the stream has ended: no estimate since the previous line"
    assert all(x[3].startswith(("[OK]", "[WARN]")) for x in lines if x[3] != "(no diagnostics yet)"), out
    accepted = [int(x[-1].removeprefix("samples_accepted=")) for x in lines if x[-1].startswith("samples_accepted=")
                and x[-1] != "samples_accepted=?"]
    assert accepted and max(accepted) > RATE_HZ, out


def test_watch_says_why_samples_are_rejected(multispeed_csv: Path, monkeypatch) -> None:
    """A driver naming its joints otherwise: the WARN line names the reason and the names seen
    (issue 46; domain 103)."""
    domain = 103
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    rec = read_recording(multispeed_csv, rate_hz=RATE_HZ)
    with NodeProcess(node_command([]), local_ros_environment(domain)) as node:
        client = EstimatorClient(domain, joint_names=("rt", "lt", "rs", "ls"), outputs=())
        try:
            deadline = time.monotonic() + 30
            while not client.wait_for_node(0.5, outputs=False, settle_s=0.5):
                assert node.poll() is None and time.monotonic() < deadline, node.output()
            watch = _cli("--duration", "5", "--rate", "2", domain_id=domain)
            n = round(RATE_HZ)
            for second in range(60):  # a second at a time until watch has seen 5 s of them (however late it starts)
                if watch.poll() is not None:
                    break
                stamps = BASE_NS + np.round((rec.time_s[:n] + second) * 1e9).astype(np.int64)
                client.stream(np.radians(rec.angles_deg[:n]), stamps, RATE_HZ)
            out, err = watch.communicate(timeout=30)
        finally:
            client.close()
    assert watch.returncode == 0, (out, err)
    assert re.search(r"\[WARN\] \d+ sample\(s\) rejected \(missing_joint: missing joint\(s\) right_thigh, left_thigh, "
                     r"right_shank, left_shank \(got rt, lt, rs, ls\)\)", out), out
