"""launch/estimator.launch.xml (``launch`` itself is not installable from PyPI, so this tests what
can be): it parses, every executable it names is one this package installs, and the params file it
passes is one the node accepts (a real EstimatorNode over loopback DDS, ROS_DOMAIN_ID 112)."""

from __future__ import annotations

import configparser
import re
import xml.etree.ElementTree as ET
from importlib.metadata import distribution
from pathlib import Path

import pytest
import rclpy
from rclpy.context import Context

from gait_estimator.ros.node import EstimatorNode
from gait_estimator.ros.parameters import StartupError

REPO = Path(__file__).resolve().parents[1]
LAUNCH = REPO / "launch" / "estimator.launch.xml"
DOMAIN = 112


def _launch() -> ET.Element:
    root = ET.parse(LAUNCH).getroot()
    assert root.tag == "launch"
    return root


def test_launch_file_names_installed_executables():
    nodes = _launch().findall("node")
    assert [n.get("exec") for n in nodes] == ["estimator_node", "estimator_dashboard"]
    assert {n.get("pkg") for n in nodes} == {"gait_estimator"}
    scripts = {e.name for e in distribution("gait_estimator").entry_points if e.group == "console_scripts"}
    assert {n.get("exec") for n in nodes} <= scripts
    cfg = configparser.ConfigParser()
    cfg.read(REPO / "setup.cfg")  # colcon: console scripts go to lib/gait_estimator, where ros2 launch looks
    assert cfg["install"]["install_scripts"] == "$base/lib/gait_estimator"
    setup = (REPO / "setup.py").read_text(encoding="utf-8")
    assert '("share/" + package_name + "/launch", glob("launch/*.launch.xml"))' in setup


def test_launch_arguments_are_declared():
    root = _launch()
    declared = {a.get("name") for a in root.findall("arg")}
    used = set(re.findall(r"\$\(var (\w+)\)", LAUNCH.read_text(encoding="utf-8")))
    assert used <= declared
    default = next(a.get("default") for a in root.findall("arg") if a.get("name") == "params_file")
    assert default == "$(find-pkg-share gait_estimator)/config/estimator.yaml"


def _start_with(params_file: Path) -> None:
    context = Context()
    rclpy.init(context=context, domain_id=DOMAIN, args=["--ros-args", "--params-file", str(params_file)])
    try:
        node = EstimatorNode(context=context)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_the_params_file_is_accepted_by_the_node(tmp_path, monkeypatch):
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    params = REPO / "config" / "estimator.yaml"
    _start_with(params)
    bad = tmp_path / "bad.yaml"
    bad.write_text(params.read_text(encoding="utf-8").replace("input_units: rad", "input_units: furlongs"))
    with pytest.raises(StartupError, match="input_units"):
        _start_with(bad)


def test_the_dashboard_executable_takes_what_launch_appends():
    """launch_ros appends ``--ros-args -r __node:=NAME`` to a node's command: the dashboard ignores it."""
    import subprocess
    import sys

    exe = str(Path(sys.executable).parent / "estimator_dashboard")  # the console script beside this Python
    run = subprocess.run([exe, "--help", "--ros-args", "-r", "__node:=estimator_dashboard"],
                         capture_output=True, text=True, timeout=60, check=False)
    assert run.returncode == 0, run.stderr
    assert "gait-estimator dashboard" in run.stdout and "--read-only" in run.stdout
    bad = subprocess.run([exe, "--port", "70000", "--ros-args"], capture_output=True, text=True, timeout=60, check=False)
    assert bad.returncode == 2 and "--port" in bad.stderr
