"""What a new user runs first, from README and docs (issue 46): the demo's domain, the bundled
LG_2_Ramp labels, error lines, playing an output bag. ROS traffic on domains 100..104, LOCALHOST."""

from __future__ import annotations

import subprocess
import sys

from gait_estimator.ros.node_client import local_ros_environment


def _gait_estimator(*args: str, env: dict[str, str] | None = None, timeout: float = 120,
                    cwd: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gait_estimator.cli", *args], capture_output=True, text=True,
                          timeout=timeout, check=False, env=env, cwd=cwd)


def test_demo_uses_the_environments_domain() -> None:
    env = local_ros_environment(100)  # as `ROS_DOMAIN_ID=100 make demo`
    proc = _gait_estimator("demo", "--stop", "400", "--speed", "4", "--echo-every", "100", env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "ROS_DOMAIN_ID=100 (from the environment)" in proc.stdout.splitlines()[0], proc.stdout
    line = next(line for line in proc.stdout.splitlines() if line.startswith("same mode as offline"))
    same, total = line.rsplit(" ", 1)[1].split("/")
    assert same == total and int(total) >= 390
