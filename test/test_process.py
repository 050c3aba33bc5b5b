"""Offline processing: the reference output acceptance test, CSV formats, CLI behaviour."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.cli.app import main as cli_main
from gait_estimator.core.errors import RecordingError
from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.io.library_io import load_library
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import write_project_csv


def read_predictions(path: Path) -> dict[str, np.ndarray]:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([r[k] for r in rows]) for k in rows[0]}


def assert_reproduces_reference(pred: dict[str, np.ndarray], swge: Path) -> None:
    ref = np.loadtxt(swge / "reference_output" / "trick_multispeed_4000_7000.csv", delimiter=",", skiprows=1, usecols=(0, 1))
    assert len(pred["mode"]) == len(ref) == 3000
    ids = {"Slow": 1, "Med": 2, "Fast": 3, "RA": 4, "RD": 5, "SA": 6, "SD": 7}
    mode_ok = np.array([ids[m] for m in pred["mode"]]) == ref[:, 1].astype(int)
    assert mode_ok.mean() >= 0.999
    lengths = {"Slow": 392, "Med": 313, "Fast": 280, "RA": 283, "RD": 286, "SA": 318, "SD": 309}
    n = np.array([lengths[m] for m in pred["mode"]])
    d = np.abs(pred["phase"].astype(float) - ref[:, 0])
    d = np.minimum(d, 1.0 - d)  # the reference writes 1.0 where we write 0.0
    assert np.mean(d * n <= 1.0 + 1e-4) >= 0.999
    assert np.mean(d * n <= 1e-4) >= 0.999  # the same column but for the one near-tie
    phase = pred["phase"].astype(float)
    assert phase.min() >= 0.0 and phase.max() < 1.0
    assert pred["ready"].astype(int).tolist() == [0] * 391 + [1] * (3000 - 391)


def test_reproduces_the_reference_implementation(tmp_path: Path, swge: Path, multispeed_csv: Path) -> None:
    """Multispeed 4000..6999 with the able-bodied library and the paper preset vs the reference
    C++ output."""
    out = tmp_path / "pred.csv"
    code = cli_main(["process", str(multispeed_csv), "--kernels", "able_bodied", "--start", "4000", "--stop", "7000",
                     "--preset", "paper", "--out", str(out), "--quiet"])
    assert code == 0
    pred = read_predictions(out)
    np.testing.assert_array_equal(pred["sample"].astype(int), np.arange(4000, 7000))
    assert_reproduces_reference(pred, swge)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_default_rate_handling_leaves_a_library_rate_stream_unchanged(multispeed_csv: Path, backend: str) -> None:
    """The same samples with real time stamps at 230 Hz (rounded to nanoseconds, as ROS stamps
    are): resample 'auto' is on for stamped input and passes them through exactly."""
    if backend == "numba" and os.environ.get("GAIT_ESTIMATOR_NO_NUMBA"):
        pytest.skip("GAIT_ESTIMATOR_NO_NUMBA")
    lib = load_library("able_bodied")
    rec = read_recording(multispeed_csv).slice(4000, 7000)
    stamps = np.round((1_700_000_000 + np.arange(3000) / 230.0) * 1e9) / 1e9
    paper = EstimatorConfig.preset("paper")
    plain = run_estimator(Estimator(lib, paper, stamped=False, backend=backend), stamps, rec.angles_deg)
    auto = Estimator(lib, paper.with_options(resample="auto"), stamped=True, backend=backend)
    assert auto.resampler is not None
    resampled = run_estimator(auto, stamps, rec.angles_deg)
    np.testing.assert_array_equal(resampled.mode_index, plain.mode_index)
    np.testing.assert_array_equal(resampled.phase, plain.phase)
    np.testing.assert_array_equal(resampled.sse, plain.sse)


def test_prediction_csv_columns_and_times(tmp_path: Path, multispeed_csv: Path) -> None:
    out = tmp_path / "p.csv"
    assert cli_main(["process", str(multispeed_csv), "--start", "100", "--stop", "150", "-o", str(out), "-q"]) == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header[:12] == ["time_s", "sample", "mode", "phase", "ready",
                          "sse_Slow", "sse_Med", "sse_Fast", "sse_RA", "sse_RD", "sse_SA", "sse_SD"]
    assert header[12:] == ["confidence", "fit_rms_deg", "held", "phase_rate", "raw_mode", "cadence_ratio", "state"]
    pred = read_predictions(out)
    np.testing.assert_allclose(pred["time_s"].astype(float), np.arange(100, 150) / 230.0, atol=1e-6)


def test_project_csv_in_radians_gives_the_same_predictions(tmp_path: Path, multispeed_csv: Path) -> None:
    rec = read_recording(multispeed_csv).slice(5000, 5600)
    deg_csv = write_project_csv(rec, tmp_path / "deg.csv")
    rad_csv = tmp_path / "rad.csv"
    lines = deg_csv.read_text().splitlines()
    header = lines[0].replace("_deg", "_rad")
    body = []
    for line in lines[1:]:
        v = line.split(",")
        body.append(",".join([v[0], *(f"{np.radians(float(x)):.12f}" for x in v[1:5])]))
    rad_csv.write_text("\n".join([header, *body]) + "\n")
    outs = []
    for src in (deg_csv, rad_csv):
        out = tmp_path / f"{src.stem}.pred.csv"
        assert cli_main(["process", str(src), "-o", str(out), "-q"]) == 0
        outs.append(read_predictions(out))
    assert outs[0]["mode"].tolist() == outs[1]["mode"].tolist()
    np.testing.assert_allclose(outs[0]["phase"].astype(float), outs[1]["phase"].astype(float))
    np.testing.assert_array_equal(outs[0]["sample"], np.arange(600).astype(str))  # rows of the new file


def test_project_csv_labels_heel_strikes_and_extra_columns(tmp_path: Path) -> None:
    p = tmp_path / "r.csv"
    p.write_text(
        "time_s,right_thigh_deg,left_thigh_deg,right_shank_deg,left_shank_deg,right_foot_deg,mode,heel_strike\n"
        "0.00,1,2,3,4,5,Slow,1\n0.01,1,2,3,4,6,Slow,0\n0.02,1,nan,3,4,7,Med,0\n0.03,1,2,3,4,8,Med,1\n"
    )
    rec = read_recording(p)
    assert len(rec) == 3 and rec.skipped == {"non_finite": 1}
    assert rec.labels.tolist() == ["Slow", "Slow", "Med"]
    assert rec.heel_strike.tolist() == [True, False, True]
    np.testing.assert_array_equal(rec.extra["right_foot_deg"], [5, 6, 8])
    np.testing.assert_array_equal(rec.index, [0, 1, 3])


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("time_s,a\n0,1\n", "missing angle column"),
        ("right_thigh_deg\n1\n", "not a recognised recording"),
        ("time_s,right_thigh_deg,left_thigh_deg,right_shank_deg,left_shank_deg\n0,1,2,3,x\n", ":2:"),
        ("time_s,right_thigh_deg,left_thigh_deg,right_shank_deg,left_shank_deg\n0,1,2,3,4\n0,1,2,3,4\n",
         "not strictly increasing"),
        ("time_s,right_thigh_deg,left_thigh_deg,right_shank_deg,left_shank_deg\n0,1,2,3\n", "expected 5 columns"),
        ("Dimension:4x3\nA,B,C,D\n1,2,3,4\n", "Dimension says 3 samples but the file has 1 rows"),
    ],
)
def test_bad_recordings_raise_one_line_errors(tmp_path: Path, text: str, message: str) -> None:
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(RecordingError) as err:
        read_recording(p)
    assert message in str(err.value) and str(p) in str(err.value)


def test_cli_usage_and_input_errors_exit_2(tmp_path: Path, multispeed_csv: Path) -> None:
    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "gait_estimator.cli", *args], capture_output=True, text=True)

    missing = run("process", str(tmp_path / "nope.csv"))
    assert missing.returncode == 2 and "no such file" in missing.stderr
    empty = run("process", str(multispeed_csv), "--start", "20000")
    assert empty.returncode == 2 and "no samples" in empty.stderr
    order = run("process", str(multispeed_csv), "--start", "10", "--stop", "5")
    assert order.returncode == 2 and "--stop" in order.stderr
    usage = run("process")
    assert usage.returncode == 2 and "usage" in usage.stderr
    badlib = run("process", str(multispeed_csv), "--kernels", str(tmp_path / "x.yaml"))
    assert badlib.returncode == 2 and "x.yaml" in badlib.stderr


def test_summary_lists_mode_segments(multispeed_csv: Path, capsys) -> None:
    assert cli_main(["process", str(multispeed_csv), "--start", "4000", "--stop", "7000"]) == 0
    out = capsys.readouterr().out
    assert "segments:" in out and "Slow" in out and "Med" in out
    assert "no time stamps" in out


def test_bench_command_times_every_implementation(tmp_path: Path) -> None:
    """`gait-estimator bench` (short run, no naive matcher): the paper matcher with each backend,
    the default preset's matcher, both presets' whole updates at every M with their ratio (the
    default preset also while it calibrates), at the smallest M the default preset's update
    without numba too, and the offline process throughput of both presets, in bulk with the same
    estimates as sample by sample; every median and p99 positive."""
    from gait_estimator.core import compiled

    report = tmp_path / "bench.json"
    assert cli_main(["bench", "--modes", "7,14", "--steps", "200", "--naive-max-modes", "0", "--preset-max-modes", "7",
                     "--process-max-modes", "7", "--json", str(report)]) == 0
    rows = {(r["modes"], r["impl"], r["preset"]): r for r in json.loads(report.read_text())["results"]}
    first = "numba" if compiled.AVAILABLE else "numpy"
    expected = {(7, f"estimator ({first})", "default"), (14, f"estimator ({first})", "paper"),
                (14, f"estimator ({first})", "default"), (14, f"estimator ({first}), calibrating", "default"),
                (7, f"incremental ({first})", "default")}
    if compiled.AVAILABLE:
        expected |= {(7, "estimator (numpy)", "default"), (7, "incremental (numpy)", "paper"), (7, "process", "paper"),
                     (7, "process", "default")}
        assert (14, "estimator (numpy)", "default") not in rows and (14, "process", "default") not in rows
        for preset in ("paper", "default"):
            proc = rows[(7, "process", preset)]
            assert proc["bulk"] and proc["same_estimates"] and proc["samples_per_s"] > 0
    assert expected <= set(rows) and not any(k[1] == "naive" for k in rows)
    assert (14, f"incremental ({first})", "default") not in rows
    assert rows[(14, f"estimator ({first})", "default")]["median_ratio_to_paper"] > 0
    timed = [r for r in rows.values() if "step_us_median" in r]
    assert all(r["step_us_median"] > 0 and r["step_us_p99"] >= r["step_us_median"] for r in timed)
