"""The public API (``from gait_estimator import ...``), the README's Python example, and the lean
install: the estimator and ``process`` on a CSV need numpy and PyYAML only; a command needing an
optional package says in one line which extra installs it."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np

import gait_estimator
from gait_estimator import EstimatorConfig, load_library, run_recording
from gait_estimator.io.readers import read_recording

REPO = Path(__file__).resolve().parents[1]
LG2 = REPO / "data" / "swge" / "recordings" / "LG_2_Ramp_AB_Sample.csv"
OPTIONAL = ("scipy", "matplotlib", "rosbags", "numba", "rclpy")


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(REPO)
    return env


def test_the_public_names() -> None:
    for name in ("Estimator", "EstimatorConfig", "load_library", "run_recording", "EstimateTrace", "Estimate"):
        assert name in gait_estimator.__all__ and hasattr(gait_estimator, name), name
    assert "NaiveMatcher" not in gait_estimator.__all__ and not hasattr(gait_estimator, "NaiveMatcher")


def test_run_recording_takes_a_path_or_a_recording() -> None:
    lib = load_library("able_bodied")
    rec = read_recording(LG2, rate_hz=lib.sample_rate_hz).slice(0, 1500)
    a = run_recording(rec, lib, EstimatorConfig.preset("paper"))
    b = run_recording(LG2, "able_bodied", EstimatorConfig.preset("paper"))
    assert len(a) == 1500 and len(b) == len(read_recording(LG2))
    np.testing.assert_array_equal(a.sse, b.sse[:1500])
    assert a.ready.any() and set(a.modes) <= set(lib.mode_names)


def test_the_readme_python_example_runs() -> None:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme.split("## Use it from Python", 1)[1].split("\n## ", 1)[0]
    (code,) = re.findall(r"```python\n(.*?)```", section, re.S)
    assert len(code.strip().splitlines()) <= 10
    run = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=_env(), capture_output=True, text=True,
                         timeout=300, check=False)
    assert run.returncode == 0, run.stderr
    first, second = run.stdout.splitlines()
    assert re.fullmatch(r"(\w+ at phase 0\.\d\d|stand at phase nan); \d+% ready", first), first
    assert second == "0 '' nan", second  # one sample: the window is not full, no mode, no phase


BLOCKER = f"""
import sys
BLOCKED = {OPTIONAL!r}

class Blocker:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, Blocker())
for m in list(sys.modules):
    if m.split(".")[0] in BLOCKED:
        del sys.modules[m]
from gait_estimator.cli.app import main
"""


def test_process_needs_no_optional_package(tmp_path: Path) -> None:
    """With scipy, matplotlib, rosbags, numba and rclpy unimportable, `process` on a CSV gives the
    same predictions as with them (numpy step instead of numba's); `evaluate`, a bag and
    estimator_node say in one line which extra they need, exit 2."""
    out = tmp_path / "lean.csv"
    code = BLOCKER + (
        f"assert main(['process', {str(LG2)!r}, '--out', {str(out)!r}, '-q']) == 0\n"
        f"print('evaluate', main(['evaluate', '--predictions', {str(out)!r}, '--truth', {str(LG2)!r}, "
        f"'--mode', 'RA', '--out-dir', {str(tmp_path / 'ev')!r}]))\n"
        f"print('bag', main(['process', {str(tmp_path / 'x.mcap')!r}, '-q']))\n"
        "import gait_estimator.ros as ros\n"
        "print('node', ros.node_main())\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in BLOCKED))\n"
    )
    (tmp_path / "x.mcap").write_bytes(b"\x89MCAP0\r\n")
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(), capture_output=True, text=True,
                         timeout=600, check=False)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == ["evaluate 2", "bag 2", "node 2", "[]"], run.stdout
    errors = run.stderr.strip().splitlines()
    assert errors[:2] == [
        "gait-estimator evaluate needs the 'analysis' extra (matplotlib is not installed): "
        "pip install 'gait_estimator[analysis]'",
        "gait-estimator process needs the 'bags' extra (rosbags is not installed): pip install 'gait_estimator[bags]'",
    ] and errors[2].startswith("estimator_node: error: ROS 2 Python packages not available") and errors[2].endswith(
        "pip install 'gait_estimator[ros]'") and len(errors) == 3, run.stderr
    full = tmp_path / "full.csv"
    assert subprocess.run([sys.executable, "-m", "gait_estimator.cli", "process", str(LG2), "--out", str(full), "-q"],
                          cwd=tmp_path, env=_env(), check=False).returncode == 0
    lean_rows = [line.split(",")[2] for line in out.read_text().splitlines()]
    full_rows = [line.split(",")[2] for line in full.read_text().splitlines()]
    assert len(lean_rows) == len(read_recording(LG2)) + 1 and lean_rows == full_rows
