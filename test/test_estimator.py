"""The estimator pipeline: defaults = the paper, supervision, resampling, gaps, options."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from gait_estimator import IncrementalMatcher, KernelLibrary
from gait_estimator.cli.app import main as cli_main
from gait_estimator.core.errors import GaitEstimatorError
from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.core.kernels import make_mode
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


def test_min_dwell_delays_the_switch_by_exactly_k_samples() -> None:
    lib, time_s, x = _two_mode_stream()
    raw = run(lib, time_s, x)
    switch = int(np.flatnonzero(np.diff(raw.mode_index[raw.ready]) != 0)[0]) + 1 + int(np.argmax(raw.ready))
    for k in (5, 20):
        held = run(lib, time_s, x, min_dwell_samples=k)
        first_b = int(np.flatnonzero(held.mode_index == 1)[0])
        assert first_b == switch + k - 1
        assert held.held[switch : first_b].all() and not held.held[first_b]
    timed = run(lib, time_s, x, min_dwell_s=0.1)
    assert int(np.flatnonzero(timed.mode_index == 1)[0]) == switch + 10  # 0.1 s at 100 Hz


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
    for kwargs, msg in [({"window_fraction": 0}, "window_fraction"), ({"channels": ("right_knee",)}, "channels"),
                        ({"channels": ()}, "channels"), ({"min_confidence": -1}, "min_confidence"),
                        ({"min_dwell_samples": 1.5}, "min_dwell_samples"), ({"phase_rate_tau_s": 0}, "phase_rate_tau_s"),
                        ({"channel_weights": (0, 0, 1, 1), "channels": ("right_thigh", "left_thigh")}, "not all 0")]:
        with pytest.raises(ValueError, match=msg):
            EstimatorConfig(**kwargs)


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
                     "--window-fraction", "0.5", "--min-dwell-samples", "10", "--subsample-phase",
                     "--channels", "right_thigh", "right_shank"])
    assert code == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header[-6:] == ["confidence", "fit_rms_deg", "held", "phase_rate", "raw_mode", "cadence_ratio"]
    assert cli_main(["process", str(multispeed_csv), "--window-fraction", "2", "-q"]) == 2
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

    assert sup.update(0.0, result([1, 5, 5])).mode == "A"
    est = sup.update(0.01, result([5, 1, 2]))
    assert est.mode == "C" and not est.held and est.raw_mode_index == 1
    assert est.confidence == pytest.approx((1 - 2) / 2)
