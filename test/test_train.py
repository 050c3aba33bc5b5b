"""Training kernels: recovering the generating kernels, outlier rejection, errors, CLI."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from synthetic import SyntheticConfig, generate

from gait_estimator.analysis.labels import read_label_ranges, with_mode, with_ranges
from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.cli.app import main
from gait_estimator.core.errors import GaitEstimatorError
from gait_estimator.core.strides import find_peaks, normalise_strides
from gait_estimator.core.training import OutlierRule, reject_outliers
from gait_estimator.io.library_io import load_library
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import write_project_csv

MODES = ("Slow", "Med", "Fast", "RA")


def _resampled(kernel: np.ndarray, length: int) -> np.ndarray:
    """Kernel (N, 4) linearly re-sampled to ``length`` samples over one periodic stride."""
    n = kernel.shape[0]
    t = np.arange(n + 1) / n
    return normalise_strides(t, np.vstack([kernel, kernel[:1]]), np.array([[0.0, 1.0]]), length)[0]


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


@pytest.fixture(scope="module")
def walk(able_bodied):
    return generate(able_bodied, [(m, 14) for m in MODES], SyntheticConfig(), seed=11)


def test_trained_kernels_recover_the_generating_kernels(able_bodied, walk):
    res = train_library([walk.recording], "syn", TrainOptions(heel_strikes="column"))
    lib = res.library
    assert lib.mode_names == list(MODES)
    assert lib.sample_rate_hz == pytest.approx(able_bodied.sample_rate_hz)
    for m in lib.modes:
        truth = able_bodied.mode(m.name)
        assert abs(m.length - truth.length) <= 0.02 * truth.length
        err = _rms(m.samples, _resampled(truth.samples, m.length))
        # much closer to its own generator than to any other kernel
        others = min(_rms(m.samples, _resampled(o.samples, m.length)) for o in able_bodied.modes if o.name != m.name)
        assert err < 1.0, (m.name, err)
        assert err < 0.3 * others
        info = m.info
        kept = [s for s in res.strides[m.name] if not s.rejected]
        assert info["strides"] == len(kept) >= 12
        assert info["strides_found"] == len(res.strides[m.name])
        durations = np.array([s.duration_s for s in kept])
        assert info["duration_mean_s"] == pytest.approx(durations.mean(), abs=1e-5)
        assert info["duration_std_s"] == pytest.approx(durations.std(ddof=1), abs=1e-5)
        assert info["sample_rate_hz"] == lib.sample_rate_hz
    assert res.skipped == []  # modes change at heel strikes: no stride spans two labels


def test_jittered_recording_with_detected_heel_strikes(able_bodied):
    syn = generate(able_bodied, [("Med", 12), ("RD", 12)], SyntheticConfig(rate_hz=267.0, jitter=0.6), seed=21)
    res = train_library([syn.recording], "jit", TrainOptions(heel_strikes="right_foot"))
    lib = res.library
    assert lib.sample_rate_hz == pytest.approx(syn.recording.median_rate_hz)
    assert "right_foot_deg peaks" in lib.provenance["heel_strikes"][syn.recording.source]
    for m in lib.modes:
        truth = able_bodied.mode(m.name)
        expected_n = truth.stride_duration_s * lib.sample_rate_hz
        assert abs(m.length - expected_n) <= 0.02 * expected_n
        assert _rms(m.samples, _resampled(truth.samples, m.length)) < 1.2


def test_rate_option_sets_library_rate(able_bodied, walk):
    lib = train_library([walk.recording], "r", TrainOptions(heel_strikes="column", rate_hz=115.0)).library
    assert lib.sample_rate_hz == 115.0
    med = lib.mode("Med")
    assert med.length == pytest.approx(able_bodied.mode("Med").stride_duration_s * 115.0, rel=0.03)


def test_outliers_by_duration_and_shape_are_rejected_and_reported(able_bodied):
    syn = generate(able_bodied, [("Med", 12)], SyntheticConfig(), seed=5, duration_scale={4: 1.35})
    rec = syn.recording
    # corrupt stride 8's shape: a 12-degree bump on the right shank
    hs = syn.heel_strikes_s
    inside = (rec.time_s >= hs[8]) & (rec.time_s < hs[9])
    angles = rec.angles_deg.copy()
    angles[inside, 2] += 12.0 * np.sin(np.pi * (rec.time_s[inside] - hs[8]) / (hs[9] - hs[8]))
    rec = replace(rec, angles_deg=angles)
    res = train_library([rec], "o", TrainOptions(heel_strikes="column"))
    infos = res.strides["Med"]
    rejected = {round(s.start_s, 6): s.rejected for s in infos if s.rejected}
    assert set(rejected) == {round(hs[4], 6), round(hs[8], 6)}
    assert rejected[round(hs[4], 6)].startswith("duration")
    assert rejected[round(hs[8], 6)].startswith("shape")
    m = res.library.mode("Med")
    assert m.info["strides"] == 10
    assert len(m.info["rejected"]) == 2
    # without the rejection the long stride would pull N up
    assert abs(m.length - able_bodied.mode("Med").length) <= 0.02 * able_bodied.mode("Med").length


def test_reject_outliers_rule_is_robust():
    d = np.array([1.00, 1.02, 0.98, 1.01, 0.99, 1.30])
    strides = np.zeros((6, 10, 4))
    reasons, dist = reject_outliers(d, strides, OutlierRule())
    assert [bool(r) for r in reasons] == [False] * 5 + [True]
    np.testing.assert_array_equal(dist, 0.0)  # identical shapes: every distance is 0
    # the floor: nothing within 10 % of the median is rejected, however tight the others are
    d2 = np.array([1.0, 1.0, 1.0, 1.0, 1.08])
    reasons2, _ = reject_outliers(d2, np.zeros((5, 10, 4)), OutlierRule())
    assert not any(reasons2)
    # two strides' length: a heel strike between was missed, and the reason says so
    d3 = np.array([1.00, 1.02, 0.98, 1.01, 0.99, 2.03, 1.30])
    reasons3, _ = reject_outliers(d3, np.zeros((7, 10, 4)), OutlierRule())
    assert reasons3[5].endswith("(about 2 strides: 1 heel strike between not found)"), reasons3[5]
    assert reasons3[6] and "heel strike" not in reasons3[6]


def test_whole_file_mode_and_label_ranges(able_bodied, tmp_path):
    syn = generate(able_bodied, [("Fast", 5), ("Slow", 5)], SyntheticConfig(), seed=2)
    rec = replace(syn.recording, labels=None)
    lib = train_library([with_mode(rec, "walk")], "w", TrainOptions(heel_strikes="column")).library
    assert lib.mode_names == ["walk"]
    assert lib.mode("walk").info["strides_found"] == 10
    hs = syn.heel_strikes_s
    ranges = tmp_path / "r.csv"
    ranges.write_text(f"# test\nstart_s,end_s,mode\n{hs[0]},{hs[5]},fast\n{hs[6]},{hs[10]},slow\n", encoding="utf-8")
    res = train_library([with_ranges(rec, read_label_ranges(ranges))], "w", TrainOptions(heel_strikes="column"))
    assert res.library.mode_names == ["fast", "slow"]
    assert res.library.mode("fast").info["strides_found"] == 5
    assert res.library.mode("slow").info["strides_found"] == 4  # stride 5 (hs[5]..hs[6]) is unlabelled


def test_stride_spanning_two_labels_is_skipped(able_bodied):
    syn = generate(able_bodied, [("Med", 8)], SyntheticConfig(), seed=3)
    hs = syn.heel_strikes_s
    labels = np.where(syn.recording.time_s < 0.5 * (hs[4] + hs[5]), "a", "b").astype(object)
    res = train_library([replace(syn.recording, labels=labels)], "s", TrainOptions(heel_strikes="column"))
    assert len(res.skipped) == 1 and "spans labels" in res.skipped[0]["reason"]
    assert res.library.mode("a").info["strides_found"] == 4


@pytest.mark.parametrize(
    ("segments", "options", "message"),
    [
        ([("Med", 2)], TrainOptions(heel_strikes="column"), "only 2 usable stride"),
        ([("Med", 5)], TrainOptions(heel_strikes="column", min_strides=6), "need at least 6"),
    ],
)
def test_too_few_strides(able_bodied, segments, options, message):
    syn = generate(able_bodied, segments, SyntheticConfig(), seed=1)
    with pytest.raises(GaitEstimatorError, match=message):
        train_library([syn.recording], "x", options)


def test_missing_inputs_are_reported(able_bodied):
    syn = generate(able_bodied, [("Med", 5)], SyntheticConfig(), seed=1)
    rec = syn.recording
    with pytest.raises(GaitEstimatorError, match="no 'mode' column"):
        train_library([replace(rec, labels=None)], "x", TrainOptions(heel_strikes="column"))
    with pytest.raises(GaitEstimatorError, match="missing column 'heel_strike'"):
        train_library([replace(rec, heel_strike=None)], "x", TrainOptions(heel_strikes="column"))
    with pytest.raises(GaitEstimatorError, match="missing column 'right_foot_deg'"):
        train_library([replace(rec, extra={})], "x", TrainOptions(heel_strikes="right_foot"))
    flat = replace(rec, extra={"right_foot_deg": np.zeros(len(rec))})
    with pytest.raises(GaitEstimatorError, match="no heel strikes found"):
        train_library([flat], "x", TrainOptions(heel_strikes="right_foot"))


def test_cli_train_writes_library_with_statistics(able_bodied, tmp_path, capsys):
    syn = generate(able_bodied, [("Slow", 6), ("SA", 6)], SyntheticConfig(rate_hz=240.0, jitter=0.3), seed=9)
    csv_path = write_project_csv(syn.recording, tmp_path / "walk.csv")
    out = tmp_path / "lib.yaml"
    assert main(["train", str(csv_path), "--out", str(out), "--heel-strikes", "column"]) == 0
    text = capsys.readouterr().out
    assert "Slow" in text and "SA" in text and f"wrote {out}" in text
    lib = load_library(out)
    assert lib.name == "lib"
    assert lib.mode_names == ["Slow", "SA"]
    assert lib.mode("SA").mode_id == 6
    assert lib.sample_rate_hz == pytest.approx(read_recording(csv_path).median_rate_hz)
    for m in lib.modes:
        for key in ("strides", "strides_found", "duration_mean_s", "duration_std_s", "rejected", "sample_rate_hz"):
            assert key in m.info
    assert "trained from" in lib.provenance["source"]
    npz = tmp_path / "lib.npz"
    assert main(["train", str(csv_path), "--out", str(npz), "--heel-strikes", "column", "--name", "mine"]) == 0
    assert load_library(npz).name == "mine"


def test_cli_train_errors_exit_2_with_one_line(able_bodied, tmp_path, capsys):
    syn = generate(able_bodied, [("Med", 2)], SyntheticConfig(), seed=1)
    csv_path = write_project_csv(syn.recording, tmp_path / "short.csv")
    assert main(["train", str(csv_path), "--out", str(tmp_path / "l.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "only 2 usable stride" in err
    nolab = write_project_csv(replace(syn.recording, labels=None), tmp_path / "nolab.csv")
    assert main(["train", str(nolab), "--out", str(tmp_path / "l.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nolab.csv" in err and "--mode" in err
    assert main(["train", str(nolab), "--out", str(tmp_path / "l.yaml"), "--mode", "x", "--heel-strikes", "right_shank",
                 "--prominence", "500"]) == 2
    assert "no heel strikes found" in capsys.readouterr().err


def test_lg2_ramp_training_from_documented_labels(swge):
    """The shared overground recording with the experiment's label ranges (README numbers)."""

    labels = swge / "recordings" / "LG_2_Ramp_AB_Sample.labels.csv"
    rec = with_ranges(read_recording(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv"), read_label_ranges(labels))
    res = train_library([rec], "lg2", TrainOptions(heel_strikes="right_foot"))
    lib = res.library
    assert sorted(lib.mode_names) == ["RA", "RD", "level"]
    assert lib.sample_rate_hz == pytest.approx(rec.median_rate_hz)
    for m in lib.modes:
        assert m.info["strides"] >= 4
        assert 1.0 < m.info["duration_mean_s"] < 1.4
        assert m.length == round(m.info["duration_mean_s"] * lib.sample_rate_hz) or abs(
            m.length - m.info["duration_mean_s"] * lib.sample_rate_hz) <= 1
    # ramp ascent flexes the thighs more than descent (kernel physiology, cf. the AB kernels)
    assert lib.mode("RA").samples[:, 0].max() > lib.mode("RD").samples[:, 0].max() + 2


def test_find_peaks_is_scipys_on_real_recordings(swge):
    """core.strides.find_peaks (numpy; the node imports no scipy) returns what scipy.signal.find_peaks
    returns, on every angle of the bundled recordings, raw and rounded to whole degrees (flat tops
    and equal heights), for several stride distances and prominences."""
    signal = pytest.importorskip("scipy.signal")
    recordings = sorted(p for p in (swge / "recordings").glob("*.csv") if not p.name.endswith(".labels.csv"))
    paths = [*recordings, *sorted((swge.parent / "camargo_ab06").glob("*.csv"))]
    checked = 0
    for path in paths:
        rec = read_recording(path)
        for x in [*rec.angles_deg.T, *rec.extra.values()]:
            for values in (x, np.round(x)):
                for distance, prominence in ((1, 0.0), (40, 5.0), (138, 20.0)):
                    expected, _ = signal.find_peaks(values, distance=distance, prominence=prominence)
                    np.testing.assert_array_equal(find_peaks(values, distance, prominence), expected)
                    checked += expected.size
    assert len(paths) == 7 and checked > 10_000
