"""``colcon build`` of the package in a temporary workspace, then ``ros2 run gait_estimator
estimator_node`` the way ros2 run resolves it (ament index package prefix +
``lib/gait_estimator/estimator_node``), started with the bundled default library (domain 29)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from ros_helpers import REPO, lockstep, unique_suffix

from gait_estimator import load_library
from gait_estimator.core.estimator import Estimator
from gait_estimator.ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command

DOMAIN_ID = 29
FIND_DEMO_RECORDING = "from gait_estimator.io.resources import DEMO_RECORDING, data_path; print(data_path(DEMO_RECORDING))"
IGNORED = shutil.ignore_patterns(
    ".git", ".venv*", "build", "install", "log", "out", "test", "benchmarks", "__pycache__", "*.egg-info",
    ".ruff_cache", ".pytest_cache", ".hypothesis", "*.pyc",
)


def _colcon(ws: Path, *args: str) -> subprocess.CompletedProcess:
    colcon = Path(sys.executable).parent / "colcon"
    if not colcon.exists():
        pytest.fail(f"colcon not found beside {sys.executable}: pip install -e '.[colcon]'")
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.pop("AMENT_PREFIX_PATH", None)
    env.pop("COLCON_PREFIX_PATH", None)
    return subprocess.run(
        [str(colcon), "--log-base", str(ws / "log"), *args],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    ws = tmp_path_factory.mktemp("colcon_ws")
    shutil.copytree(REPO, ws / "src" / "gait_estimator", ignore=IGNORED)
    return ws


def test_colcon_list_and_build_then_run_like_ros2_run(workspace: Path, monkeypatch) -> None:
    ws = workspace
    listed = _colcon(ws, "list", "--base-paths", "src")
    assert listed.returncode == 0, listed.stderr
    assert "gait_estimator" in listed.stdout and "(ros.ament_python)" in listed.stdout, listed.stdout

    built = _colcon(ws, "build", "--base-paths", "src", "--build-base", "build", "--install-base", "install")
    assert built.returncode == 0, built.stdout + built.stderr
    prefix_dir = ws / "install" / "gait_estimator"
    site = next(prefix_dir.glob("lib/python3*/site-packages"))

    # What `source install/setup.bash` + `ros2 run gait_estimator estimator_node` do.
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix_dir))
    monkeypatch.setenv("PYTHONPATH", str(site))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from ament_index_python.packages import get_package_prefix, get_package_share_directory

    prefix = Path(get_package_prefix("gait_estimator"))
    assert prefix == prefix_dir
    exe = prefix / "lib" / "gait_estimator" / "estimator_node"
    assert exe.is_file() and os.access(exe, os.X_OK)
    dashboard = prefix / "lib" / "gait_estimator" / "estimator_dashboard"  # named by the launch file
    assert dashboard.is_file() and os.access(dashboard, os.X_OK)
    share = Path(get_package_share_directory("gait_estimator"))
    assert (share / "launch" / "estimator.launch.xml").is_file()
    assert (share / "config" / "estimator.yaml").is_file()
    assert (share / "config" / "kernels" / "able_bodied.yaml").is_file()
    assert (share / "data" / "swge" / "LICENSE").is_file()
    demo_rec = share / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv"
    assert demo_rec.is_file()

    env = local_ros_environment(DOMAIN_ID)
    where = subprocess.run(
        [sys.executable, "-c", "import gait_estimator.ros.node as n; print(n.__file__)"],
        env=env, cwd=ws, capture_output=True, text=True, timeout=60, check=True,
    )
    assert where.stdout.strip().startswith(str(site)), where.stdout
    found = subprocess.run(
        [sys.executable, "-c", FIND_DEMO_RECORDING],
        env=env, cwd=ws, capture_output=True, text=True, timeout=60, check=True,
    )
    assert Path(found.stdout.strip()) == demo_rec, found.stdout  # what `gait-estimator demo` streams by default

    ns = f"/gait_colcon_{unique_suffix()}"
    node = NodeProcess(node_command(["-r", f"__ns:={ns}", "-r", "__node:=estimator"], str(exe)), env)
    client = EstimatorClient(DOMAIN_ID, namespace=ns, estimator_name=f"{ns}/estimator")
    try:
        assert client.wait_for_node(30.0, settle_s=0.5), node.output()
        diag = client.latest_diagnostics(3.0)
        assert diag is not None
        assert diag["library"] == "able_bodied" and diag["modes"] == "7"
        assert Path(diag["library_path"]) == share / "config" / "kernels" / "able_bodied.yaml"
        n, window = 460, Estimator(load_library("able_bodied")).matcher.max_window
        x = np.radians(np.tile([[20.0, -5.0, 10.0, -20.0]], (n, 1)) + np.linspace(0, 1, n)[:, None])
        lockstep(client, x, 2000.0, stamps=10**18 + 4_347_826 * np.arange(n))
        assert client.estimate_count == n
        assert len(client.received.modes) == len(client.received.phases) == n - window + 1 > 0
        code = node.stop(signal.SIGINT)
        log = node.output()
    finally:
        client.close()
        node.close()
    assert code == 0, log
    assert "Traceback" not in log
