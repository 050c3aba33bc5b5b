"""The estimator pipeline: defaults = the paper, supervision, resampling, gaps, options."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from gait_estimator import IncrementalMatcher, KernelLibrary
from gait_estimator.cli.app import main as cli_main
from gait_estimator.core.channels import sample_values
from gait_estimator.core.errors import GaitEstimatorError
from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.core.kernels import make_mode, resample_stride
from gait_estimator.core.resample import UniformResampler
from gait_estimator.core.supervisor import Supervisor, transitions_matrix
from gait_estimator.io.readers import read_recording


@pytest.fixture(scope="module")
def multispeed(multispeed_csv: Path):
    return read_recording(multispeed_csv)


def run(lib: KernelLibrary, time_s: np.ndarray, x: np.ndarray, **options):
    """The paper preset plus ``options`` over (time_s, x), stamped input."""
    return run_estimator(Estimator(lib, EstimatorConfig.preset("paper", **options)), time_s, x)


def circular(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    d = np.abs(a - b) % 1.0
    return np.minimum(d, 1.0 - d)


def test_defaults_reproduce_the_matcher(able_bodied, multispeed) -> None:
    x = multispeed.angles_deg[4000:5000]
    trace = run(able_bodied, multispeed.time_s[4000:5000], x)
    raw = IncrementalMatcher(able_bodied).run(x)
    np.testing.assert_array_equal(trace.mode_index, raw.mode_index)
    np.testing.assert_array_equal(trace.phase, raw.phase)
    np.testing.assert_array_equal(trace.sse, raw.sse)
    assert not trace.held.any()
    np.testing.assert_array_equal(trace.raw_mode_index, trace.mode_index)


def test_confidence_and_fit_quality(able_bodied, multispeed) -> None:
    trace = run(able_bodied, multispeed.time_s[4000:5000], multispeed.angles_deg[4000:5000])
    i = 900
    s = np.sort(trace.sse[i])
    assert trace.confidence[i] == pytest.approx((s[1] - s[0]) / s[0])
    n = able_bodied.lengths[trace.mode_index[i]]
    assert trace.fit_rms_deg[i] == pytest.approx(math.sqrt(s[0] / (n * 4)))
    assert (trace.confidence[trace.ready] >= 0).all()


def _two_mode_stream() -> tuple[KernelLibrary, np.ndarray, np.ndarray]:
    n = 50
    t = np.arange(n) / n
    a = np.stack([20 * np.sin(2 * np.pi * t), 10 * np.cos(2 * np.pi * t), 5 * t, 0 * t], axis=1)
    b = a.copy()
    b[:, 3] = 8.0
    lib = KernelLibrary("two", (make_mode("A", a, 100.0), make_mode("B", b, 100.0)))
    stream = np.concatenate([np.tile(a, (4, 1)), np.tile(b, (4, 1))])
    return lib, np.arange(len(stream)) / 100.0, stream


def test_min_dwell_delays_the_switch_by_exactly_the_dwell() -> None:
    lib, time_s, x = _two_mode_stream()
    raw = run(lib, time_s, x)
    switch = int(np.flatnonzero(np.diff(raw.mode_index[raw.ready]) != 0)[0]) + 1 + int(np.argmax(raw.ready))
    for k in (5, 10, 20):  # k samples at 100 Hz
        held = run(lib, time_s, x, min_dwell_s=k / 100.0)
        first_b = int(np.flatnonzero(held.mode_index == 1)[0])
        assert first_b == switch + k
        assert held.held[switch : first_b].all() and not held.held[first_b]


def test_low_confidence_holds_the_last_confident_mode() -> None:
    lib, time_s, x = _two_mode_stream()
    raw = run(lib, time_s, x)
    threshold = 1.0
    sup = run(lib, time_s, x, min_confidence=threshold)
    ready = raw.ready
    low = ready & (raw.confidence < threshold)
    assert low.any() and sup.held[low].all()
    # Where held, the reported mode is the last confidently reported one, with its own phase.
    for i in np.flatnonzero(low):
        prev = i - 1
        while prev >= 0 and sup.held[prev]:
            prev -= 1
        if prev >= 0 and ready[prev]:
            assert sup.mode_index[i] == sup.mode_index[prev]
            assert sup.phase[i] == raw.phases[i][sup.mode_index[i]]


def test_disallowed_transitions_are_never_reported(able_bodied, multispeed, tmp_path: Path) -> None:
    names = able_bodied.mode_names
    table = tmp_path / "t.yaml"
    table.write_text("allowed_transitions:\n  Slow: [Fast]\n  Med: [Slow]\n  Fast: [Med]\n")
    trace = run(able_bodied, multispeed.time_s[3000:9000], multispeed.angles_deg[3000:9000], transitions=str(table))
    allowed = transitions_matrix({"Slow": ["Fast"], "Med": ["Slow"], "Fast": ["Med"]}, names)
    modes = trace.mode_index[trace.ready]
    for a, b in itertools.pairwise(modes):
        assert allowed[a, b], (names[a], names[b])
    assert not allowed[0, 1] and allowed[0, 2] and allowed[3, 0]  # rows without an entry: anything


def test_bad_transitions_files(able_bodied, tmp_path: Path) -> None:
    p = tmp_path / "t.yaml"
    for text, msg in [("allowed_transitions:\n  Jog: [Slow]\n", "unknown mode 'Jog'"),
                      ("allowed_transitions:\n  Slow: [Jog]\n", "unknown mode 'Jog'"),
                      ("nothing: 1\n", "expected a mapping"), ("a: [\n", "invalid YAML")]:
        p.write_text(text)
        with pytest.raises(GaitEstimatorError, match=msg):
            Estimator(able_bodied, EstimatorConfig(transitions=str(p)))


def test_phase_rate_matches_the_stride_frequency(able_bodied) -> None:
    med = able_bodied.mode("Med")
    x = np.tile(med.samples, (6, 1))
    t = np.arange(len(x)) / 230.0
    trace = run(able_bodied, t, x)
    assert set(trace.mode_index[trace.ready]) == {1}
    assert trace.phase_rate[-1] == pytest.approx(230.0 / med.length, rel=1e-6)
    assert np.isnan(trace.phase_rate[0])


def test_gap_restarts_the_window(able_bodied, multispeed) -> None:
    t = multispeed.time_s[:1200].copy()
    t[600:] += 1.0  # a 1 s gap
    est = Estimator(able_bodied, EstimatorConfig.preset("paper", max_gap_s=0.5))
    trace = run_estimator(est, t, multispeed.angles_deg[:1200])
    assert est.resets == 1
    assert trace.ready[599] and not trace.ready[600] and not trace.ready[600 + 390] and trace.ready[600 + 391]
    fresh = run(able_bodied, t[600:], multispeed.angles_deg[600:1200])
    np.testing.assert_array_equal(trace.sse[600:], fresh.sse)
    none = run(able_bodied, t, multispeed.angles_deg[:1200], max_gap_s=0.0)
    assert none.ready[600:].all()


def test_bad_samples_leave_the_state_untouched(able_bodied, multispeed) -> None:
    est = Estimator(able_bodied)
    ref = Estimator(able_bodied)
    x, t = multispeed.angles_deg[:500], multispeed.time_s[:500]
    for i in range(500):
        if i == 300:
            with pytest.raises(ValueError):
                est.update(t[i], [np.nan, 0, 0, 0])
            with pytest.raises(ValueError):
                est.update(t[i - 1], x[i])
        a, b = est.update(t[i], x[i]), ref.update(t[i], x[i])
        np.testing.assert_array_equal(a.sse, b.sse)


def test_sample_values() -> None:
    assert sample_values(np.array([1.0, 2.0, 3.0, 4.0])) == (1.0, 2.0, 3.0, 4.0)
    assert sample_values(np.arange(4).reshape(1, 4)) == (0.0, 1.0, 2.0, 3.0)
    got = sample_values([1, np.float32(0.5), 3.0, True])
    assert got == (1.0, 0.5, 3.0, 1.0) and all(type(v) is float for v in got)
    for bad in ([1.0, 2.0, 3.0], np.zeros(5), "abcd", [1.0, 2.0, 3.0, None], 4.0):
        with pytest.raises(ValueError, match="a sample is 4 numbers"):
            sample_values(bad)


def test_tuples_and_arrays_give_the_same_estimates(able_bodied) -> None:
    """The node hands the estimator tuples of floats, the offline tools array rows: same results."""
    x = np.concatenate([m.samples for m in able_bodied.modes]) + 1.5
    t = np.arange(len(x)) / 251.0  # off the library rate: the resampler interpolates
    a, b = Estimator(able_bodied), Estimator(able_bodied)
    for i in range(len(x)):
        ea, eb = a.update(t[i], x[i]), b.update(float(t[i]), tuple(x[i].tolist()))
        fields = ("mode_index", "mode", "state", "phase", "confidence", "cadence_ratio", "phase_rate", "held")
        np.testing.assert_equal([getattr(ea, f) for f in fields], [getattr(eb, f) for f in fields])
        np.testing.assert_array_equal(ea.sse, eb.sse)


def test_resampler_interpolates_linearly() -> None:
    r = UniformResampler(10.0)
    assert [t for t, _ in r.push(0.0, np.array([0.0]))] == [0.0]
    out = r.push(0.25, np.array([2.5]))
    assert [round(t, 9) for t, _ in out] == [0.1, 0.2]
    np.testing.assert_allclose([x[0] for _, x in out], [1.0, 2.0])
    assert r.push(0.29, np.array([2.9])) == []
    out = r.push(0.31, np.array([3.1]))
    assert len(out) == 1 and out[0][1][0] == pytest.approx(3.0)


@pytest.mark.parametrize("rate", [100.0, 200.0, 500.0, "jitter"])
def test_rate_invariance(able_bodied, multispeed, rate) -> None:
    """The same walk sampled at another rate (or with +-2 ms jitter) and resampled to the
    library's 230 Hz gives the same modes and phase within 0.5 % of a stride."""
    lo, hi = 3000, 9000
    t0 = multispeed.time_s[lo:hi]
    x0 = multispeed.angles_deg[lo:hi]
    base = run(able_bodied, t0, x0)
    rng = np.random.default_rng(5)
    if rate == "jitter":
        t1 = t0 + rng.uniform(-0.002, 0.002, t0.size)
        t1[0] = t0[0]
    else:
        t1 = np.arange(t0[0], t0[-1], 1.0 / rate)
    x1 = np.stack([np.interp(t1, t0, x0[:, c]) for c in range(4)], axis=1)
    out = run(able_bodied, t1, x1, resample="on")
    assert np.array_equal(out.time_s, t1)  # one estimate per input sample, at its stamp
    idx = np.searchsorted(t0, out.time_s + 1e-9, side="right") - 1  # the last 230 Hz sample before it
    ok = (idx >= 0) & out.ready & base.ready[np.maximum(idx, 0)]
    idx = idx[ok]
    agree = out.mode_index[ok] == base.mode_index[idx]
    assert agree.mean() >= 0.99

    def runs(m: np.ndarray) -> list[int]:
        keep = np.r_[True, m[1:] != m[:-1]]
        starts = np.flatnonzero(keep)
        lengths = np.diff(np.r_[starts, m.size])
        return [int(v) for v, n in zip(m[starts], lengths, strict=True) if n >= 0.5 * rate_hz]  # runs >= 0.5 s

    rate_hz = 230.0 if rate == "jitter" else float(rate)
    assert runs(out.mode_index[ok]) == runs(base.mode_index[np.searchsorted(t0, t1[ok] + 1e-9, side="right") - 1])
    same = agree & out.ready[ok]
    err = circular(out.phase[ok][same], base.phase[idx][same])
    assert err.mean() <= 0.005


def test_config_validation() -> None:
    for kwargs, msg in [({"channels": ("right_knee",)}, "channels"),
                        ({"channels": ()}, "channels"), ({"min_confidence": -1}, "min_confidence"),
                        ({"min_dwell_s": float("nan")}, "min_dwell_s"), ({"phase_rate_tau_s": 0}, "phase_rate_tau_s"),
                        ({"channel_weights": (0, 0, 1, 1), "channels": ("right_thigh", "left_thigh")}, "not all 0")]:
        with pytest.raises(ValueError, match=msg):
            EstimatorConfig(**kwargs)
    for removed in ("window_fraction", "subsample_phase", "switch_evidence_deg2s", "min_dwell_samples"):
        with pytest.raises(ValueError, match="unknown estimator option"):
            EstimatorConfig().with_options(**{removed: 1})


def test_channel_subset_equals_zero_weights(able_bodied, multispeed) -> None:
    t, x = multispeed.time_s[4000:4800], multispeed.angles_deg[4000:4800]
    a = run(able_bodied, t, x, channels=("right_thigh", "right_shank"))
    b = run(able_bodied, t, x, channel_weights=(1.0, 0.0, 1.0, 0.0))
    np.testing.assert_array_equal(a.sse, b.sse)
    best = a.mode_index[-1]
    assert a.fit_rms_deg[-1] == pytest.approx(math.sqrt(a.sse[-1][best] / (able_bodied.lengths[best] * 2)))


def test_cli_process_with_options(tmp_path: Path, multispeed_csv: Path) -> None:
    out = tmp_path / "p.csv"
    code = cli_main(["process", str(multispeed_csv), "--start", "4000", "--stop", "5000", "-o", str(out), "-q",
                     "--min-dwell-s", "0.05", "--channels", "right_thigh", "right_shank",
                     "--offset-tolerance-deg", "inf"])
    assert code == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header[-7:] == ["confidence", "fit_rms_deg", "held", "phase_rate", "raw_mode", "cadence_ratio", "state"]
    assert cli_main(["process", str(multispeed_csv), "--min-confidence", "-1", "-q"]) == 2
    for removed in ("--window-fraction", "--subsample-phase", "--switch-evidence-deg2s", "--min-dwell-samples"):
        with pytest.raises(SystemExit) as exc:
            cli_main(["process", str(multispeed_csv), removed, "1", "-q"])
        assert exc.value.code == 2
    assert cli_main(["process", str(multispeed_csv), "--transitions", str(tmp_path / "none.yaml"), "-q"]) == 2


def test_supervisor_without_options_is_transparent() -> None:
    sup = Supervisor(["a", "b"])
    assert sup.min_confidence == 0 and sup.allowed is None


def test_transitions_table_reports_the_best_allowed_mode() -> None:
    """With min_confidence 0 (off) nothing is held: a table only narrows the candidates."""
    names = ["A", "B", "C"]
    sup = Supervisor(names, allowed=transitions_matrix({"A": ["C"]}, names))

    def result(sse):
        from gait_estimator.core.matcher import StepResult

        sse = np.array(sse, dtype=float)
        return StepResult(int(sse.argmin()), names[int(sse.argmin())], 0.0, sse, np.zeros(3), True, np.full(3, 10))

    assert sup.decide(0.0, result([1, 5, 5])).mode == "A"
    est = sup.decide(0.01, result([5, 1, 2]))
    assert est.mode == "C" and not est.held and est.raw_mode_index == 1
    assert est.confidence == pytest.approx((1 - 2) / 2)


# ---------------------------------------------------------------------------------------------
# Presets, rate handling by default, cadence ratio, personalisation


def test_presets() -> None:
    paper = EstimatorConfig.preset("paper")
    assert (paper.resample, paper.time_scales, paper.offset_tolerance_deg, paper.normalize_error) == ("off", (1.0,), 0.0, False)
    assert paper.preset_name() == "paper" and EstimatorConfig().preset_name() == "default"
    assert EstimatorConfig.preset("paper", min_dwell_s=0.5).changed_from("paper") == {"min_dwell_s": 0.5}
    assert EstimatorConfig(resample=True).resample == "on" and EstimatorConfig(resample="false").resample == "off"
    with pytest.raises(ValueError, match="preset"):
        EstimatorConfig.preset("fast")
    with pytest.raises(ValueError, match="resample"):
        EstimatorConfig(resample="sometimes")
    assert EstimatorConfig().resamples(stamped=True) and not EstimatorConfig().resamples(stamped=False)
    assert EstimatorConfig(resample="on").resamples(stamped=False) and not paper.resamples(stamped=True)


def test_paper_preset_is_the_plain_matcher(able_bodied, multispeed) -> None:
    x = multispeed.angles_deg[4000:5000]
    trace = run_estimator(Estimator(able_bodied, EstimatorConfig.preset("paper")), multispeed.time_s[4000:5000], x)
    raw = IncrementalMatcher(able_bodied).run(x)
    np.testing.assert_array_equal(trace.mode_index, raw.mode_index)
    np.testing.assert_array_equal(trace.phase, raw.phase)
    assert np.isnan(trace.cadence_ratio).all()


def test_one_estimate_per_input_at_any_rate(able_bodied, multispeed) -> None:
    """At 1 kHz (several inputs per 230 Hz grid point) every input is answered at its own time;
    between grid points the phase advances with the phase rate."""
    t0, x0 = multispeed.time_s[3000:4000], multispeed.angles_deg[3000:4000]
    t1 = np.arange(t0[0], t0[-1], 0.001)
    x1 = np.stack([np.interp(t1, t0, x0[:, c]) for c in range(4)], axis=1)
    est = Estimator(able_bodied)
    out = [est.update(float(t), x) for t, x in zip(t1, x1, strict=True)]
    assert [e.time_s for e in out] == t1.tolist()
    ready = [e for e in out if e.ready]
    assert ready and all(0.0 <= e.phase < 1.0 for e in ready)
    steps = np.diff([e.phase for e in ready])
    steps = steps[np.abs(steps) < 0.5]  # leave out heel strikes
    assert np.median(steps) == pytest.approx(0.001 * ready[-1].phase_rate, rel=0.5)


def test_cadence_ratio_reports_the_time_scale(able_bodied) -> None:
    """A wearer 6 % slower than the Med kernel (strides 1.06 x as long): Med, cadence 1/1.06."""
    from gait_estimator.core.kernels import resample_stride

    med = able_bodied.mode("Med").samples
    x = np.tile(resample_stride(med, round(1.06 * len(med))), (4, 1))
    t = np.arange(len(x)) / 230.0
    trace = run_estimator(Estimator(able_bodied, EstimatorConfig(time_scales=(0.94, 1.0, 1.06))), t, x)
    assert set(np.asarray(trace.modes)[trace.ready]) == {"Med"}
    assert trace.cadence_ratio[-1] == pytest.approx(1 / 1.06)
    paper = run(able_bodied, t, x)
    assert circular(paper.phase[-200:], trace.phase[-200:]).mean() > circular(trace.phase[-200:], trace.phase[-200:]).mean()


def _wearer(lib: KernelLibrary, offsets: np.ndarray, amplitude: float) -> KernelLibrary:
    modes = []
    for m in lib.modes:
        mean = m.samples.mean(axis=0)
        modes.append(make_mode(m.name, mean + amplitude * (m.samples - mean) + offsets, m.sample_rate_hz))
    return KernelLibrary("wearer", tuple(modes))


def test_personalisation_pulls_the_kernel_towards_the_wearer(able_bodied, tmp_path: Path) -> None:
    """Steady RA strides of a wearer whose sensors sit differently: only RA adapts, every
    adopted stride moves it by at most adapt_rate x adapt_max_step_deg, and it ends closer to the
    wearer's stride; the adapted library saves and loads with its provenance."""
    import sys

    from gait_estimator.io.library_io import load_library, save_library

    sys.path.insert(0, str(Path(__file__).parent))
    from synthetic import SyntheticConfig, generate

    wearer = _wearer(able_bodied, np.array([2.0, -1.5, 1.0, -2.0]), 1.05)
    syn = generate(wearer, [("RA", 40)], SyntheticConfig(offset_sd_deg=0.2), seed=4)
    rec = syn.recording
    config = EstimatorConfig(adapt_rate=0.2, adapt_max_step_deg=3.0)
    est = Estimator(able_bodied, config)
    before = [k.copy() for k in est.adapter.kernels]
    moves = []
    for t, x in zip(rec.time_s, rec.angles_deg, strict=True):
        prev = est.adapter.kernels[3].copy()
        est.update(float(t), x)
        moves.append(np.abs(est.adapter.kernels[3] - prev).max())
    ra = able_bodied.mode_names.index("RA")
    assert est.adapter.accepted[ra] >= 20 and est.adapter.accepted.sum() == est.adapter.accepted[ra]
    assert max(moves) <= 0.2 * 3.0 + 1e-12
    for i in range(len(able_bodied)):
        if i != ra:
            np.testing.assert_array_equal(est.adapter.kernels[i], before[i])
    target = wearer.mode("RA").samples
    dist = lambda k: float(np.sqrt(np.mean((k - target) ** 2)))  # noqa: E731
    assert dist(est.adapter.kernels[ra]) < 0.5 * dist(before[ra])
    lib = est.adapted_library()
    path = save_library(lib, tmp_path / "adapted.yaml")
    back = load_library(path)
    np.testing.assert_allclose(back.mode("RA").samples, est.adapter.kernels[ra], atol=1e-6)
    assert back.provenance["adaptation"]["accepted_strides"]["RA"] == est.adapter.accepted[ra]

    # New options (as a node parameter change): the personalised kernels carry over.
    strides = int(est.adapter.accepted.sum())
    again = Estimator(able_bodied, config.with_options(min_dwell_s=0.1))
    assert again.adopt_adaptation(est) == strides
    np.testing.assert_array_equal(again.adapter.kernels[ra], est.adapter.kernels[ra])
    assert again.adapter.accepted[ra] == est.adapter.accepted[ra]
    x = rec.angles_deg[-600:]
    fresh = Estimator(est.adapted_library(), config.with_options(min_dwell_s=0.1, adapt_rate=0.0))
    for i, d in enumerate(x):  # its matcher uses them: the same as an estimator built on them
        a, b = again.update(i / 230.0, d), fresh.update(i / 230.0, d)
        if again.adapter.accepted.sum() > strides:  # it went on adapting
            break
        assert a.mode == b.mode and a.sse == pytest.approx(b.sse, rel=1e-9, abs=1e-9)
    assert i > 450, "compared at least one full window"
    off = Estimator(able_bodied, config.with_options(adapt_rate=0.0))
    assert off.adopt_adaptation(est) == strides and off.adapter is None


def test_personalisation_never_uses_held_or_unconfident_strides(able_bodied) -> None:
    """Strides alternating between two modes: every estimate is held (dwell) or low-confidence
    around the switches; nothing alternating is adopted."""
    x = np.concatenate([able_bodied.mode("Med").samples, able_bodied.mode("Fast").samples] * 8)
    t = np.arange(len(x)) / 230.0
    est = Estimator(able_bodied, EstimatorConfig(adapt_rate=0.5, min_dwell_s=10.0))
    for ti, xi in zip(t, x, strict=True):
        est.update(float(ti), xi)
    assert est.adapter.accepted.sum() == 0
    assert est.adapter.skipped["held"] > 0


def test_personalisation_paused_adopts_nothing_then_resumes(able_bodied) -> None:
    """``pause_adaptation(True)`` (input angles not yet checked): strides that end are counted as
    'unchecked' and no kernel changes; released, the same strides are adopted again."""
    med = able_bodied.mode_names.index("Med")
    x = np.concatenate([able_bodied.mode("Med").samples] * 24)
    t = np.arange(len(x)) / 230.0
    est = Estimator(able_bodied, EstimatorConfig(adapt_rate=0.2))
    before = [k.copy() for k in est.adapter.kernels]
    est.pause_adaptation(True)
    half = len(x) // 2
    for ti, xi in zip(t[:half], x[:half], strict=True):
        est.update(float(ti), xi)
    assert est.adapter.accepted.sum() == 0 and est.adapter.skipped["unchecked"] >= 8
    for k, b in zip(est.adapter.kernels, before, strict=True):
        np.testing.assert_array_equal(k, b)
    est.pause_adaptation(False)
    for ti, xi in zip(t[half:], x[half:], strict=True):
        est.update(float(ti), xi)
    assert est.adapter.accepted[med] >= 8


def test_cli_save_adapted(tmp_path: Path, multispeed_csv: Path, capsys) -> None:
    out = tmp_path / "adapted.yaml"
    assert cli_main(["process", str(multispeed_csv), "--start", "4000", "--stop", "9000", "--adapt-rate", "0.1",
                     "--save-adapted", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"wrote {out} (personalised kernels; strides adopted:" in text
    assert out.is_file()
    assert cli_main(["process", str(multispeed_csv), "--save-adapted", str(out), "-q"]) == 2


def _med_walk_with_offsets(able_bodied) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """25 kernel strides of Med read by sensors offset by (6, 1, 0, -1) deg (the right thigh's
    far off): (offsets, times s at 230 Hz, samples deg)."""
    offsets = np.array([6.0, 1.0, 0.0, -1.0])
    x = np.tile(able_bodied.mode("Med").samples, (25, 1)) + offsets
    return offsets, np.arange(len(x)) / 230.0, x


def test_walking_calibration_finds_constant_sensor_offsets(able_bodied) -> None:
    """Level walking with sensors that read differently (re-donned; the right thigh 6 deg up):
    the default estimator learns the offsets from confident strides and keeps the mode; without
    calibration and with the paper's zero tolerance the offsets cost it the mode most of the time
    (no stride is confident: its cadence is never learnt)."""
    offsets, t, x = _med_walk_with_offsets(able_bodied)
    est = Estimator(able_bodied)
    trace = run_estimator(est, t, x)
    np.testing.assert_allclose(est.sensor_offset_deg, offsets, atol=0.3)
    tail = trace.ready & (t > t[-1] - 5.0)
    assert set(np.asarray(trace.modes)[tail]) == {"Med"}
    assert Estimator(able_bodied, EstimatorConfig.preset("paper")).config.offset_calibration_rate == 0.0
    off = run_estimator(Estimator(able_bodied, EstimatorConfig(offset_calibration_rate=0.0, offset_tolerance_deg=0.0)), t, x)
    assert np.mean(np.asarray(off.modes)[tail] == "Med") < 0.5


def test_walking_calibration_counts_near_copies_as_one_mode(able_bodied) -> None:
    """A library holding near copies of every mode: few strides are confident against the other
    copies, and the reported mode moves between them within a stride. Counted as one mode, they
    let the calibrations learn the offsets as with the bundled library, and recency weighting
    starts; counted apart (near_copy_rms_deg 0), a stride is confident only when it happens to fit
    one copy much better than its neighbours (a few of these noise-free strides), and the right
    thigh's 6 deg offset is far from learnt."""
    from synthetic import near_copies

    from gait_estimator.core.pipeline import PipelineParams

    lib = near_copies(able_bodied, 5)
    offsets, t, x = _med_walk_with_offsets(able_bodied)
    est = Estimator(lib)
    trace = run_estimator(est, t, x)
    np.testing.assert_allclose(est.sensor_offset_deg, offsets, atol=0.5)
    assert est.calibration.strides >= 3 and est.matcher.recency_half_life == est.config.recency_half_life
    tail = trace.ready & (t > t[-1] - 5.0)
    assert {name.rsplit("_", 1)[0] for name in np.asarray(trace.modes)[tail]} == {"Med"}
    apart = Estimator(lib, params=PipelineParams.from_config(EstimatorConfig(), calibration={"near_copy_rms_deg": 0.0}))
    run_estimator(apart, t, x)
    assert apart.calibration.strides < est.calibration.strides / 4
    assert abs(apart.sensor_offset_deg[0] - offsets[0]) > 2.0


def _stretched_strides(able_bodied, mode: str, strides: int, cadence: float) -> np.ndarray:
    """``strides`` kernel strides of ``mode`` stretched to last 1/cadence as long, (T, 4) deg."""
    k = able_bodied.mode(mode).samples
    return np.tile(resample_stride(k, round(len(k) / cadence)), (strides, 1))


def test_cadence_calibration_tells_speed_classes_apart_at_the_wearer_cadence(able_bodied) -> None:
    """Synthetic new wearer 1 (cadence 0.932: strides 7 % longer than the kernels'; offsets,
    amplitudes, noise, 100-500 Hz) walks ramps and stairs, then Fast. The default estimator
    learns the time scale from confident strides and reads the Fast strides as Fast; without the
    calibration they are mostly read as Med (a slower wearer's Fast lasts as long as the kernels'
    Med). reset_calibration forgets the scale and searches every scale again."""
    from synthetic import generate, new_wearer

    wearer = new_wearer(1)
    rec = generate(able_bodied, [("RA", 6), ("SA", 6), ("RD", 6), ("Fast", 12)], wearer, seed=1001).recording
    est = Estimator(able_bodied)
    trace = run_estimator(est, rec.time_s, rec.angles_deg)
    assert est.cadence_scale == pytest.approx(1 / wearer.cadence, rel=0.03) and est.calibration.cadence_strides >= 3
    band = est.matcher.scale_band
    assert band[np.abs(est.matcher.time_scales - est.cadence_scale) < 0.02].all() and not band[0]
    tail = rec.time_s > rec.time_s[-1] - 5.0
    assert np.mean(np.asarray(trace.modes)[tail] == "Fast") > 0.95
    assert np.nanmedian(trace.cadence_ratio[tail]) == pytest.approx(wearer.cadence, rel=0.04)
    off = run_estimator(Estimator(able_bodied, EstimatorConfig(cadence_calibration_rate=0.0)), rec.time_s, rec.angles_deg)
    assert np.mean(np.asarray(off.modes)[tail] == "Fast") < 0.5
    est.reset_calibration()
    assert math.isnan(est.cadence_scale) and est.matcher.searched_modes.sum() == 3  # every scale for the best 3
    assert EstimatorConfig.preset("paper").cadence_calibration_rate == 0.0


def test_calibrations_read_each_stride_once(able_bodied) -> None:
    """The calibrations read at most once per stride, however the reported phase flickers across
    the heel strike (0.99, 0.01, 0.99, ...), and still read most strides: reading at every flicker
    let a few strides of a wrong mode set the sensor offsets. They do not read the stride in which
    the mode changed: it blends two modes (one such SA stride of this wearer read a time scale of
    0.94 against the wearer's 1.07 and widened the band until Fast was read as Med)."""
    from synthetic import generate, new_wearer

    route = [("RA", 6), ("SA", 6), ("RD", 6), ("Fast", 12)]
    syn = generate(able_bodied, route, new_wearer(1), seed=1001)
    est = Estimator(able_bodied)
    reads = []
    for t, x in zip(syn.recording.time_s, syn.recording.angles_deg, strict=True):
        before = est.calibration.cadence_strides
        est.update(float(t), x)
        if est.calibration.cadence_strides > before:
            reads.append(float(t))
    strides = len(syn.stride_modes)
    assert len(reads) == est.calibration.cadence_strides
    assert strides - 3 * len(route) <= len(reads) <= strides - 1
    first = np.cumsum([n for _, n in route])[:-1]  # index of each mode's first stride after a change
    ends = syn.heel_strikes_s[first + 1]
    gap = np.abs(np.subtract.outer(ends, reads)).min(axis=1)
    assert np.all(gap > 0.1), f"read at the end of a transition stride: {ends[gap <= 0.1].round(2).tolist()}"


@pytest.mark.parametrize("mode", ["Med", "SA"])
@pytest.mark.parametrize("scale", [0.98, 1.02])
def test_cadence_is_read_between_the_time_scales(able_bodied, mode: str, scale: float) -> None:
    """Strides lasting 0.98 or 1.02 times the kernel's, halfway between two time scales (0.96,
    1.0, 1.04): the calibration reads the scale between them (the vertex of the row scores), not
    the nearest scale, which was 0.02 off at every stride."""
    x = _stretched_strides(able_bodied, mode, 10, 1.0 / scale)
    est = Estimator(able_bodied)
    run_estimator(est, np.arange(len(x)) / 230.0, x)
    assert est.calibration.cadence_strides >= 6
    assert est.cadence_scale == pytest.approx(scale, abs=0.005)


def test_new_options_keep_the_learnt_calibration(able_bodied) -> None:
    """adopt_calibration (the node calls it when options change, same kernels): the sensor
    offsets, the learnt time scale and its band carry over to an estimator with other options;
    one that does not calibrate keeps none of them."""
    offsets = np.array([3.0, -2.0, 1.0, 0.5])
    x = np.concatenate([_stretched_strides(able_bodied, m, 6, 0.93) for m in ("RA", "SA", "Med")]) + offsets
    est = Estimator(able_bodied)
    run_estimator(est, np.arange(len(x)) / 230.0, x)
    assert est.calibration.cadence_strides >= 3 and not est.matcher.scale_band.all()
    other = Estimator(able_bodied, EstimatorConfig(min_dwell_s=0.1))
    other.adopt_calibration(est)
    np.testing.assert_array_equal(other.sensor_offset_deg, est.sensor_offset_deg)
    theirs, mine = est.calibration, other.calibration
    assert (mine.cadence_scale, mine.cadence_strides, mine.cadence_spread) == (
        theirs.cadence_scale, theirs.cadence_strides, theirs.cadence_spread)
    np.testing.assert_array_equal(other.matcher.scale_band, est.matcher.scale_band)
    plain = Estimator(able_bodied, EstimatorConfig(offset_calibration_rate=0.0, cadence_calibration_rate=0.0))
    plain.adopt_calibration(est)
    assert not plain.sensor_offset_deg.any() and math.isnan(plain.cadence_scale) and plain.matcher.scale_band.all()


def test_adopting_an_early_cadence_keeps_every_scale(able_bodied) -> None:
    """An estimator that has read fewer cadence strides than it needs to narrow the time scales
    hands over a band that is still open (the best-fitting modes at every scale), and the adopting
    estimator keeps it open too (it narrows from the same stride count as the one it adopts from)."""
    x = _stretched_strides(able_bodied, "Med", 8, 0.93)
    t = np.arange(len(x)) / 230.0
    est = Estimator(able_bodied)
    for i in range(len(x)):
        est.update(float(t[i]), x[i])
        if est.calibration.cadence_strides == 1:
            break
    assert est.calibration.cadence_strides == 1 and est.matcher.searched_modes.any()
    other = Estimator(able_bodied, EstimatorConfig(min_dwell_s=0.1))
    other.adopt_calibration(est)
    assert other.calibration.cadence_strides == 1
    np.testing.assert_array_equal(other.matcher.scale_band, est.matcher.scale_band)
    assert other.matcher.searched_modes.any()


def test_cadence_calibration_stays_open_when_the_scales_spread(able_bodied) -> None:
    """Med strides alternating every 4 strides between 12 % slower and 12 % faster than the kernel
    (a wearer changing speed): the strides' scales spread, and the band is wider than the 4 %
    tolerance alone (3 scales at most) would make it."""
    x = np.concatenate([_stretched_strides(able_bodied, "Med", 4, c) for c in (0.89, 1.12) * 3])
    t = np.arange(len(x)) / 230.0
    est = Estimator(able_bodied)
    run_estimator(est, t, x)
    assert est.calibration.cadence_strides >= 6 and est.calibration.cadence_spread > 0.04
    assert est.matcher.scale_band.sum() >= 5


@pytest.mark.parametrize("bad", [{"cadence_calibration_rate": 1.5}, {"cadence_calibration_rate": -0.1},
                                 {"cadence_tolerance": -0.01}, {"cadence_tolerance": float("nan")}])
def test_cadence_options_are_checked(bad) -> None:
    with pytest.raises(ValueError, match=next(iter(bad))):
        EstimatorConfig(**bad)


def test_a_long_gap_forgets_the_calibrations(able_bodied) -> None:
    """Sensors re-donned while the stream stopped: a Med walk with one set of offsets, a gap, a
    sample with the opposite offsets. A gap longer than calibration_reset_gap_s (5 s) forgets the
    learnt offsets (as reset_calibration does), so the new ones are learnt starting from zero; a
    shorter gap only restarts the window and keeps them; 0 keeps them whatever the gap."""
    before, t1, x1 = _med_walk_with_offsets(able_bodied)
    redonned = able_bodied.mode("Med").samples[0] - before
    runs = {}
    for name, gap, config in (("long", 6.0, EstimatorConfig()), ("short", 4.0, EstimatorConfig()),
                              ("never", 60.0, EstimatorConfig(calibration_reset_gap_s=0.0))):
        est = Estimator(able_bodied, config)
        run_estimator(est, t1, x1)
        learnt = est.sensor_offset_deg.copy()
        est.update(t1[-1] + gap, redonned)
        runs[name] = (learnt, est.sensor_offset_deg.copy(), est.calibration_resets, est.resets)
    for learnt, _, _, _ in runs.values():
        np.testing.assert_allclose(learnt, before, atol=0.5)
    assert not runs["long"][1].any() and runs["long"][2:] == (1, 1)
    np.testing.assert_array_equal(runs["short"][1], runs["short"][0])
    assert runs["short"][2:] == (0, 1)
    np.testing.assert_array_equal(runs["never"][1], runs["never"][0])
    assert runs["never"][2:] == (0, 1)
    assert EstimatorConfig.preset("paper").calibration_reset_gap_s == 0.0
    with pytest.raises(ValueError, match="calibration_reset_gap_s"):
        EstimatorConfig(calibration_reset_gap_s=-1.0)


def test_recency_weighting_starts_once_the_calibrations_have_read_three_strides(able_bodied) -> None:
    """A sensor 6 deg off while walking Med: with recency weighting from the first stride the
    speed classes are not told apart confidently enough for the calibrations to start (Fast is
    reported on a quarter of the strides, the offset is never learnt), so the default estimator
    matches with uniform weights until the calibrations have read 3 strides, then with
    recency_half_life; reset_calibration goes back to uniform weights."""
    offsets, t, x = _med_walk_with_offsets(able_bodied)
    est = Estimator(able_bodied)
    weights = []
    for ti, xi in zip(t, x, strict=True):
        est.update(float(ti), xi)
        weights.append((est.calibration.strides, est.matcher.recency_half_life))
    assert {h for n, h in weights if n < 3} == {0.0}
    assert {h for n, h in weights if n >= 3} == {EstimatorConfig().recency_half_life} and est.calibration.strides > 10
    np.testing.assert_allclose(est.sensor_offset_deg, offsets, atol=0.3)
    est.reset_calibration()
    assert est.matcher.recency_half_life == 0.0 and est.calibration.strides == 0
    # without the wait (the matcher weighted from the start) this walk goes wrong
    from gait_estimator.core.pipeline import PipelineParams

    eager = Estimator(able_bodied, params=PipelineParams.from_config(EstimatorConfig(),
                                                                     calibration={"recency_after_strides": 0}))
    assert eager.matcher.recency_half_life == EstimatorConfig().recency_half_life
    trace = run_estimator(eager, t, x)
    assert np.abs(eager.sensor_offset_deg - offsets).max() > 3.0
    assert np.mean(np.asarray(trace.modes)[len(x) // 2:] == "Med") < 0.9
    # no calibrations: weighted from the start; paper: never
    assert Estimator(able_bodied, EstimatorConfig(offset_calibration_rate=0.0, cadence_calibration_rate=0.0)
                     ).matcher.recency_half_life == EstimatorConfig().recency_half_life
    assert EstimatorConfig.preset("paper").recency_half_life == 0.0


def test_recency_weighting_follows_mode_changes_sooner(able_bodied) -> None:
    """Synthetic new wearer 0 walks a route with 12 mode changes: with recency weighting (the
    default) the first correct estimate after a change comes sooner than with uniform weights,
    and more rows are right."""
    from synthetic import generate, new_wearer

    route = [("Med", 5), ("RA", 5), ("Med", 4), ("SA", 5), ("Slow", 5), ("SD", 5), ("Fast", 5), ("RD", 5), ("Med", 5)]
    syn = generate(able_bodied, route, new_wearer(0), seed=1000)
    rec = syn.recording
    truth = np.asarray(rec.labels).astype(str)
    results = {}
    for h in (0.0, EstimatorConfig().recency_half_life):
        config = EstimatorConfig(recency_half_life=h)
        trace = run_estimator(Estimator(able_bodied, config), rec.time_s, rec.angles_deg)
        right = np.asarray(trace.modes) == truth
        changes = np.flatnonzero(truth[1:] != truth[:-1]) + 1
        delays = [rec.time_s[c + np.argmax(right[c:])] - rec.time_s[c] for c in changes]
        results[h] = (float(np.mean(delays)), float(np.mean(right[trace.ready])))
    (d0, a0), (d1, a1) = results[0.0], results[EstimatorConfig().recency_half_life]
    assert d1 < 0.85 * d0, results
    assert a1 > a0, results
