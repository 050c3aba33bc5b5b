"""What a new user runs first, from README and docs (issue 46): the demo's domain, the bundled
LG_2_Ramp labels, error lines, playing an output bag. ROS traffic on domains 100..104, LOCALHOST."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

from gait_estimator.ros.node_client import local_ros_environment

REPO = Path(__file__).resolve().parents[1]


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


def _one_error_line(proc: subprocess.CompletedProcess) -> str:
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, (proc.returncode, lines)
    return lines[0]


def test_error_lines_say_what_was_found_and_what_is_expected(tmp_path: Path, swge: Path) -> None:
    csv = tmp_path / "walk.csv"
    csv.write_text("t,rt,lt,rs,ls\n0,1,2,3,4\n", encoding="utf-8")
    line = _one_error_line(_gait_estimator("process", str(csv)))
    assert "columns t, rt, lt, rs, ls; expected time_s, right_thigh_deg" in line, line

    ramp = str(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv")
    line = _one_error_line(_gait_estimator("process", ramp, "--kernels", "ableBodied"))
    assert "ableBodied" in line and "able_bodied, prosthesis" in line, line

    line = _one_error_line(_gait_estimator("process", ramp, "--preset", "fast"))
    assert line.startswith("gait-estimator process: error: argument --preset: invalid choice: 'fast'"), line
    assert line.endswith("(usage: gait-estimator process -h)"), line


def test_node_names_a_parameter_of_the_wrong_type() -> None:
    node = shutil.which("estimator_node", path=str(Path(sys.executable).parent))
    assert node is not None
    proc = subprocess.run([node, "--ros-args", "-p", "teach_strides:=ten"], capture_output=True, text=True,
                          timeout=60, check=False, env=local_ros_environment(101))
    line = _one_error_line(proc)
    assert line.startswith("estimator_node: error: invalid parameter teach_strides: "), line
    assert "'ten'" in line and "INTEGER" in line, line


def test_play_refuses_an_output_bag_unless_topics_are_chosen(tmp_path: Path, swge: Path) -> None:
    ramp = str(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv")
    made = _gait_estimator("process", ramp, "--stop", "500", "--out-bag", str(tmp_path / "est"), "-q")
    assert made.returncode == 0, made.stderr
    env = local_ros_environment(102)
    line = _one_error_line(_gait_estimator("play", str(tmp_path / "est"), env=env))
    assert "holds estimator output (/estimate, /mode, /phase, /sse)" in line and "--topic" in line, line
    chosen = _gait_estimator("play", str(tmp_path / "est"), "--topic", "/estimate", "--rate", "20", env=env)
    assert chosen.returncode == 0, chosen.stderr
    assert "published 500 message(s)" in chosen.stdout and "on /estimate" in chosen.stdout, chosen.stdout


def test_readme_command_reproduces_the_lg2_ramp_row(tmp_path: Path) -> None:
    """README's command for its LG_2_Ramp row, run as written (from a clone: data/ and .venv/), gives
    the row's figures; docs/training.md shows the same command."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    command = readme.split("The LG_2_Ramp row", 1)[1].split("```bash\n", 1)[1].split("```", 1)[0]
    training = (REPO / "docs" / "training.md").read_text(encoding="utf-8")
    assert command.replace(".venv/bin/", "") in training
    (tmp_path / "data").symlink_to(REPO / "data")
    (tmp_path / ".venv").symlink_to(Path(sys.executable).parent.parent)
    proc = subprocess.run(["bash", "-c", command], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "labels: data/swge/recordings/LG_2_Ramp_AB_Sample.labels.csv (beside the recording" in proc.stdout
    got = re.search(r"^accuracy ([\d.]+) %; phase error \(correct rows\) mean ([\d.]+) %", proc.stdout, re.M)
    steady = re.search(r"^steady .*accuracy ([\d.]+) %", proc.stdout, re.M)
    assert got and steady, proc.stdout
    row = next(line for line in readme.splitlines() if line.startswith("| mode accuracy on another session: LG_2_Ramp"))
    want = re.search(r"\| ([\d.]+) % \(steady rows ([\d.]+) %\); phase error ([\d.]+) % of a stride \|", row)
    assert want, row
    assert f"{float(got[1]):.1f}" == want[1] and f"{float(steady[1]):.1f}" == want[2], (proc.stdout, row)
    assert f"{float(got[2]):.2f}" == want[3], (proc.stdout, row)


def test_readme_results_keep_three_headline_rows() -> None:
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    block = readme.split("<!-- BEGIN accuracy#Results -->", 1)[1].split("<!-- END accuracy#Results -->", 1)[0]
    rows = [line.split(" | ", 1)[0] for line in block.strip().splitlines()[2:]]
    assert len(rows) == 3, rows
    assert "reference C++ implementation" in rows[0] and "another session" in rows[1] and "time per sample" in rows[2]
    after = readme.split("<!-- END accuracy#Results -->", 1)[1].split("## ", 1)[0]
    assert "(docs/results.md)" in after and "(docs/performance.md" in after
    assert len(readme.encode("utf-8")) <= 15_000


def test_docs_sample_output_is_what_the_command_prints_now() -> None:
    """docs/bags.md's `process` sample is generated (make docs) and docs-check reruns it."""
    bags = (REPO / "docs" / "bags.md").read_text(encoding="utf-8")
    block = bags.split("<!-- BEGIN samples#bags process -->\n", 1)[1].split("<!-- END samples#bags process -->", 1)[0]
    assert block.startswith("```text\n$ gait-estimator process out/ramp_bag --out-bag out/ramp_est\n"), block
    check = subprocess.run([sys.executable, "-m", "benchmarks.common", "--check-docs"], cwd=REPO, capture_output=True,
                           text=True, timeout=120, check=False)
    assert check.returncode == 0, check.stderr
    tables = (REPO / "benchmarks" / "results" / "samples" / "tables.md").read_text(encoding="utf-8")
    assert block.strip() in tables


def test_demo_summary_counts_the_states() -> None:
    """Multispeed's first 4 s are standing: the demo's summary says ``stand``, as the node published."""
    proc = _gait_estimator("demo", "--stop", "900", "--speed", "4", "--echo-every", "1000", "--reliable",
                           env=local_ros_environment(180))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = proc.stdout.splitlines()
    assert "predicted modes (ready samples): stand 100.0%" in lines, proc.stdout
    assert any(re.fullmatch(r" +[\d.]+ s - +[\d.]+ s  stand +\(\d+ samples\)", line) for line in lines), proc.stdout
