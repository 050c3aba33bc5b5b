"""``gait-estimator teach`` against a real estimator_node process over DDS (loopback), and with
no node at all.

Domain IDs 72 and 73; LOCALHOST discovery.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from ros_helpers import BASE_NS

from gait_estimator import load_library
from gait_estimator.io.readers import read_recording
from gait_estimator.ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command

RATE_HZ = 230.0


def _cli(*args: str, domain_id: int, **kwargs) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "gait_estimator.cli", "teach", *args, "--domain-id", str(domain_id)],
        env=local_ros_environment(domain_id), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs,
    )


def test_no_node_answers_exit_2_one_line() -> None:
    proc = _cli("--mode", "Slow", "--timeout", "1", domain_id=72)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "no estimator node /estimator_node answered within 1 s" in lines[0], err


def test_usage_errors_exit_2() -> None:
    proc = _cli("--mode", "Slow", "--strides", "2", domain_id=72)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "teach strides must be an integer 3..100" in err
    proc = _cli(domain_id=72)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "give --mode NAME" in err


def test_teach_a_running_node_then_save(multispeed_csv: Path, tmp_path: Path, monkeypatch) -> None:
    domain = 73
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    rec = read_recording(multispeed_csv, rate_hz=RATE_HZ)
    env = local_ros_environment(domain)
    with NodeProcess(node_command(["-p", "kernels:=''", "-p", "teach_strides:=5"]), env) as node:
        client = EstimatorClient(domain, outputs=("mode",))
        try:
            deadline = time.monotonic() + 30
            while not client.wait_for_node(0.5, outputs=False, settle_s=0.5):
                assert node.poll() is None and time.monotonic() < deadline, node.output()
            teach = _cli("--mode", "Slow", "--strides", "3", domain_id=domain)
            first = teach.stdout.readline()
            assert first.startswith("teaching Slow on /estimator_node"), (first, teach.stderr.read())
            i0, i1 = np.searchsorted(rec.time_s, [8.0, 18.0])
            stamps = BASE_NS + np.round(rec.time_s * 1e9).astype(np.int64)
            client.stream(np.radians(rec.angles_deg[i0:i1]), stamps[i0:i1], RATE_HZ * 3)
            out, err = teach.communicate(timeout=30)
            assert teach.returncode == 0, (first, out, err, node.output())
            lines = out.splitlines()
            assert "Slow: 1/3 strides" in lines and "Slow: 3/3 strides" in lines, out
            assert any(x.startswith("taught: added Slow") for x in lines), out
            assert lines[-1].startswith("done: Slow: 3 strides ("), out  # (a stride hit by lost samples: rejected)
            client.spin_for(1.0)
            assert client.mode_count > 0  # estimating with the taught mode, no restart

            path = tmp_path / "wearer.yaml"
            save = _cli("--save", path.name, domain_id=domain, cwd=tmp_path)  # relative: from the CLI's directory
            out, err = save.communicate(timeout=30)
            assert save.returncode == 0, (out, err)
            assert f"wrote {path}" in out
            assert load_library(path).mode_names == ["Slow"]
        finally:
            client.close()
        assert node.poll() is None


@pytest.fixture(autouse=True)
def _local(monkeypatch) -> None:
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    monkeypatch.delenv("ROS_STATIC_PEERS", raising=False)
    assert os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST"
