"""The incremental matcher against the naive specification, and its long-run accuracy."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_estimator import IncrementalMatcher, KernelLibrary
from gait_estimator.core import compiled
from gait_estimator.core.kernels import make_mode, resample_stride
from gait_estimator.core.matcher import NaiveMatcher
from gait_estimator.core.scale_band import SEARCH_EVERY
from gait_estimator.io.readers import read_recording


def random_library(rng: np.random.Generator, lengths: list[int], scale: float = 20.0) -> KernelLibrary:
    modes = tuple(make_mode(f"m{i}", rng.normal(0, scale, (n, 4)), 100.0) for i, n in enumerate(lengths))
    return KernelLibrary("random", modes)


def brute_force(window: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """e[j] = sum_t ||d_{i-t} - k_{(j-t) mod N}||^2 over the window (newest last), written plainly."""
    n = kernel.shape[0]
    w = window[-n:]
    e = np.zeros(n)
    for j in range(n):
        for t in range(len(w)):
            diff = w[len(w) - 1 - t] - kernel[(j - t) % n]
            e[j] += diff @ diff
    return e


def assert_steps_equal(a, b, rtol: float = 1e-9) -> None:
    scale = np.maximum(np.abs(b.sse), 1.0)
    assert np.all(np.abs(a.sse - b.sse) <= rtol * scale), (a.sse, b.sse)
    assert a.ready == b.ready
    # Same argmin except where the two best candidates are tied within rounding.
    order = np.sort(b.sse)
    if len(order) < 2 or order[1] - order[0] > 1e-9 * max(order[1], 1.0):
        assert a.mode_index == b.mode_index
    best = b.mode_index
    if a.mode_index == best:
        assert a.phases[best] == pytest.approx(b.phases[best]) or abs(a.sse[best] - b.sse[best]) < 1e-6


def test_naive_matches_a_plain_loop() -> None:
    rng = np.random.default_rng(3)
    lib = random_library(rng, [5, 7])
    naive = NaiveMatcher(lib)
    data = rng.normal(0, 20, (12, 4))
    for i, d in enumerate(data):
        r = naive.step(d)
        for m, mode in enumerate(lib.modes):
            # the matchers use the kernels' float32 values (the compiled step streams float32)
            e = brute_force(data[: i + 1], mode.samples.astype(np.float32).astype(np.float64))
            assert r.sse[m] == pytest.approx(e.min(), rel=1e-12)
            j = int(e.argmin())
            assert r.phases[m] == pytest.approx(((j + 1) % mode.length) / mode.length)
        assert r.ready == (i + 1 >= 7)


def test_recency_weighting_matches_a_plain_loop() -> None:
    """recency_half_life h: the squared error of a sample t samples old counts lambda^t, with
    lambda = 2^(-1 / (h N)), and normalize divides by the window's weight sum."""
    rng = np.random.default_rng(4)
    lib = random_library(rng, [6, 9])
    inc = IncrementalMatcher(lib, recency_half_life=0.5, normalize=True, resync_period=0)
    naive = NaiveMatcher(lib, recency_half_life=0.5, normalize=True)
    data = rng.normal(0, 20, (25, 4))
    for i, d in enumerate(data):
        a, b = inc.step(d), naive.step(d)
        for m, mode in enumerate(lib.modes):
            n = mode.length
            k = mode.samples.astype(np.float32).astype(np.float64)
            lam = 2.0 ** (-1.0 / (0.5 * n))
            w = data[: i + 1][-n:]
            e = np.zeros(n)
            for j in range(n):
                for t in range(len(w)):
                    diff = w[len(w) - 1 - t] - k[(j - t) % n]
                    e[j] += lam**t * (diff @ diff)
            weight = sum(lam**t for t in range(len(w)))
            assert a.sse[m] == pytest.approx(e.min() / weight, rel=1e-9)
            assert b.sse[m] == pytest.approx(e.min() / weight, rel=1e-12)
            assert a.phases[m] == pytest.approx(((int(e.argmin()) + 1) % n) / n)


@settings(max_examples=40, deadline=None)
@given(
    lengths=st.lists(st.integers(min_value=2, max_value=40), min_size=1, max_size=6),
    steps=st.integers(min_value=1, max_value=120),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    offset=st.floats(min_value=-200, max_value=200),
)
def test_incremental_equals_naive_on_random_libraries(lengths: list[int], steps: int, seed: int, offset: float) -> None:
    rng = np.random.default_rng(seed)
    lib = random_library(rng, lengths)
    inc, naive = IncrementalMatcher(lib, resync_period=0), NaiveMatcher(lib)
    data = rng.normal(offset, 20, (steps, 4))
    for d in data:
        assert_steps_equal(inc.step(d), naive.step(d))


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(min_value=0, max_value=2**32 - 1), period=st.integers(min_value=1, max_value=50))
def test_resynchronisation_keeps_results_equal(seed: int, period: int) -> None:
    rng = np.random.default_rng(seed)
    lib = random_library(rng, [13, 4, 21])
    inc, naive = IncrementalMatcher(lib, resync_period=period, resync_block=3), NaiveMatcher(lib)
    for d in rng.normal(0, 20, (80, 4)):
        assert_steps_equal(inc.step(d), naive.step(d))


def test_incremental_equals_naive_on_the_shared_recording(multispeed_csv, able_bodied) -> None:
    rec = read_recording(multispeed_csv)
    x = rec.angles_deg[3000:3500]  # the fill phase, a full window and beyond
    inc, naive = IncrementalMatcher(able_bodied), NaiveMatcher(able_bodied)
    for d in x:
        assert_steps_equal(inc.step(d), naive.step(d))


def test_reset_starts_a_fresh_window(able_bodied) -> None:
    rng = np.random.default_rng(0)
    data = rng.normal(0, 20, (500, 4))
    a = IncrementalMatcher(able_bodied)
    a.run(data[:450])
    a.reset()
    assert a.steps == 0 and not a.ready
    fresh = IncrementalMatcher(able_bodied)
    for d in data[450:]:
        ra, rf = a.step(d), fresh.step(d)
        np.testing.assert_array_equal(ra.sse, rf.sse)


def test_non_finite_sample_is_rejected_without_touching_state(able_bodied) -> None:
    rng = np.random.default_rng(1)
    data = rng.normal(0, 20, (400, 4))
    a, b = IncrementalMatcher(able_bodied), IncrementalMatcher(able_bodied)
    for i, d in enumerate(data):
        if i == 200:
            with pytest.raises(ValueError, match="non-finite"):
                a.step(np.array([1.0, np.nan, 0.0, 0.0]))
            with pytest.raises(ValueError, match="non-finite"):
                a.step([np.inf, 0.0, 0.0, 0.0])
        ra, rb = a.step(d), b.step(d)
        np.testing.assert_array_equal(ra.sse, rb.sse)
    assert a.steps == b.steps == 400


def test_ready_after_the_longest_window(able_bodied) -> None:
    m = IncrementalMatcher(able_bodied)
    x = np.zeros((392, 4))
    ready = [m.step(d).ready for d in x]
    assert not any(ready[:391]) and ready[391]


def test_state_memory_is_linear_in_modes(able_bodied) -> None:
    small = IncrementalMatcher(able_bodied).state_bytes()
    big = IncrementalMatcher(able_bodied.replicated(700)).state_bytes()
    assert big < 110 * small  # 100x the modes: ~100x the memory, no N^2 term
    assert big <= 20e6


def test_a_million_steps_stay_exact() -> None:
    """float64 running sums with resynchronisation equal a recomputation after 10^6 steps."""
    rng = np.random.default_rng(7)
    lib = random_library(rng, [9, 14, 11], scale=30.0)
    m = IncrementalMatcher(lib)
    block = rng.normal(5.0, 30.0, (10_000, 4))
    for _ in range(100):
        for d in block:
            m.step(d)
    exact = m.full_sse()
    ok = np.isfinite(exact)
    rel = np.abs(m.running_sse()[ok] - exact[ok]) / exact[ok]
    assert m.steps == 1_000_000
    assert rel.max() <= 1e-9


def test_resynchronisation_repairs_a_corrupted_running_sum() -> None:
    rng = np.random.default_rng(8)
    lib = random_library(rng, [9, 14, 11])
    m = IncrementalMatcher(lib, resync_period=100, resync_block=4)
    data = rng.normal(0, 20, (400, 4))
    m.run(data[:200])
    m._e[m._valid] += 1e-3  # simulate accumulated rounding error
    m.run(data[200:300])  # one resync period
    exact = m.full_sse()
    ok = np.isfinite(exact)
    assert np.abs(m.running_sse()[ok] - exact[ok]).max() < 1e-9
    never = IncrementalMatcher(lib, resync_period=0)
    never.run(data[:200])
    never._e[never._valid] += 1e-3
    never.run(data[200:300])
    assert np.abs(never.running_sse()[ok] - never.full_sse()[ok]).min() > 0.5e-3


@settings(max_examples=40, deadline=None)
@given(
    lengths=st.lists(st.integers(min_value=2, max_value=30), min_size=1, max_size=5),
    weights=st.lists(st.sampled_from([0.0, 0.5, 1.0, 2.0]), min_size=4, max_size=4).filter(any),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
)
def test_options_match_the_naive_specification(lengths, weights, seed) -> None:
    rng = np.random.default_rng(seed)
    lib = random_library(rng, lengths)
    opts = {"channel_weights": weights}
    inc = IncrementalMatcher(lib, resync_period=37, resync_block=2, **opts)
    naive = NaiveMatcher(lib, **opts)
    for d in rng.normal(0, 20, (90, 4)):
        a, b = inc.step(d), naive.step(d)
        assert_steps_equal(a, b)
        if a.mode_index == b.mode_index and np.ptp(np.sort(b.sse)[:2]) > 1e-6:
            assert a.phase == pytest.approx(b.phase, abs=1e-9)


def test_zero_weight_removes_a_channel() -> None:
    rng = np.random.default_rng(12)
    lib = random_library(rng, [15, 12])
    data = rng.normal(0, 20, (60, 4))
    noisy = data.copy()
    noisy[:, 1] += rng.normal(0, 500, 60)  # garbage on left_thigh only
    w = [1.0, 0.0, 1.0, 1.0]
    a = IncrementalMatcher(lib, channel_weights=w).run(data)
    b = IncrementalMatcher(lib, channel_weights=w).run(noisy)
    np.testing.assert_allclose(a.sse, b.sse, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"channel_weights": [1, 1, 1]}, "needs 4 values"),
    ({"channel_weights": [0, 0, 0, 0]}, "not all 0"),
    ({"channel_weights": [1, -1, 1, 1]}, ">= 0"),
])
def test_invalid_options(able_bodied, kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        IncrementalMatcher(able_bodied, **kwargs)


# ---------------------------------------------------------------------------------------------
# Time-scaled variants, offset tolerance, per-sample error; the numba and numpy steps

# numba is a dependency: its step is tested unless GAIT_ESTIMATOR_NO_NUMBA turns it off (then
# test_numba_is_there_unless_turned_off says so instead of every numba test skipping quietly).
NUMBA_OFF = bool(os.environ.get("GAIT_ESTIMATOR_NO_NUMBA"))
BACKENDS = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA"))]
BACKEND_NAMES = ["numpy"] + ([] if NUMBA_OFF else ["numba"])


def test_numba_is_there_unless_turned_off() -> None:
    assert compiled.AVAILABLE != NUMBA_OFF, "numba is a dependency (setup.py); is it installed?"


@pytest.mark.parametrize("backend", BACKENDS)
@settings(max_examples=30, deadline=None)
@given(
    lengths=st.lists(st.integers(min_value=10, max_value=30), min_size=1, max_size=4),
    scales=st.sampled_from([(1.0,), (0.9, 1.0, 1.1), (0.8, 1.25)]),
    tolerance=st.sampled_from([0.0, 3.0, math.inf]),
    normalize=st.booleans(),
    recency=st.sampled_from([0.0, 0.3, 2.0]),
    seed=st.integers(min_value=0, max_value=2**32 - 1),
)
def test_new_options_match_the_naive_specification(
    backend, lengths, scales, tolerance, normalize, recency, seed
) -> None:
    rng = np.random.default_rng(seed)
    lib = random_library(rng, lengths)
    opts = {"time_scales": scales, "offset_tolerance_deg": tolerance, "normalize": normalize,
            "channel_weights": [1.0, 0.5, 2.0, 1.0], "recency_half_life": recency}
    inc = IncrementalMatcher(lib, resync_period=41, resync_block=3, backend=backend, **opts)
    naive = NaiveMatcher(lib, **opts)
    for d in rng.normal(5, 20, (80, 4)):
        a, b = inc.step(d), naive.step(d)
        assert_steps_equal(a, b, rtol=1e-8)
        if b.variant is not None and np.ptp(np.sort(b.sse)[:2]) > 1e-6:
            assert a.variant[a.mode_index] == b.variant[b.mode_index]


@pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA")
def test_numba_and_numpy_steps_agree_on_the_recording(multispeed_csv, able_bodied) -> None:
    x = read_recording(multispeed_csv).angles_deg[2000:4000]
    for opts in ({}, {"time_scales": (0.88, 0.94, 1.0, 1.06, 1.12), "offset_tolerance_deg": 4.0, "normalize": True},
                 {"recency_half_life": 0.3, "offset_tolerance_deg": 2.0, "time_scales": (0.95, 1.05)}):
        a = IncrementalMatcher(able_bodied, backend="numba", **opts).run(x)
        b = IncrementalMatcher(able_bodied, backend="numpy", **opts).run(x)
        np.testing.assert_array_equal(a.mode_index, b.mode_index)
        np.testing.assert_allclose(a.phase, b.phase, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.sse, b.sse, rtol=1e-10)


@pytest.mark.parametrize("backend", BACKENDS)
def test_scale_band_limits_the_time_scales_a_mode_is_read_at(able_bodied, backend) -> None:
    """A Med stride stretched by 6 %: read at 1.06 with every scale allowed, at the nearest allowed
    scale when the band excludes 1.06; best_scale_index still names 1.06; the running sums do not
    depend on the band (switching it back gives the unbanded result, to rounding)."""
    med = able_bodied.mode("Med").samples
    stride = resample_stride(med, round(1.06 * len(med)))
    scales = (0.94, 1.0, 1.06)
    free = IncrementalMatcher(able_bodied, time_scales=scales, normalize=True, backend=backend)
    banded = IncrementalMatcher(able_bodied, time_scales=scales, normalize=True, backend=backend)
    banded.set_scale_band([True, True, False])
    med_index = able_bodied.mode_names.index("Med")
    for d in np.tile(stride, (3, 1)):
        a, b = free.step(d), banded.step(d)
    assert scales[a.variant[med_index]] == 1.06 and scales[b.variant[med_index]] == 1.0
    assert b.sse[med_index] > a.sse[med_index] + 1e-6
    assert banded.best_scale_index(med_index) == 2 and banded.scale_band.tolist() == [True, True, False]
    banded.set_scale_band(None)
    a, b = free.step(stride[0]), banded.step(stride[0])
    assert a.mode_index == b.mode_index and np.array_equal(a.variant, b.variant)
    np.testing.assert_allclose(a.sse, b.sse, rtol=1e-12, atol=1e-9)  # rows rebuilt from the window (numba)
    for bad in ([False, False, False], [True, True]):
        with pytest.raises(ValueError, match="scale band"):
            banded.set_scale_band(bad)


@pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA")
@pytest.mark.parametrize("half_life", [0.0, 0.3])
def test_numba_and_numpy_agree_with_a_scale_band(multispeed_csv, able_bodied, half_life) -> None:
    """Both steps read out only the rows in the band (with recency weighting: their per-shift
    offset penalty); the results and every mode's row scores agree."""
    x = read_recording(multispeed_csv).angles_deg[2000:3500]
    scales = (0.88, 0.94, 1.0, 1.06, 1.12)
    out, matchers = [], []
    for backend in ("numba", "numpy"):
        m = IncrementalMatcher(able_bodied, backend=backend, time_scales=scales, offset_tolerance_deg=2.0, normalize=True,
                               recency_half_life=half_life)
        rows = []
        for i, d in enumerate(x):
            if i == 600:
                m.set_scale_band([False, True, True, False, False])
            rows.append(m.step(d))
        out.append(rows)
        matchers.append(m)
    for a, b in zip(*out, strict=True):
        assert a.mode_index == b.mode_index and np.array_equal(a.variant, b.variant)
        np.testing.assert_allclose(a.sse, b.sse, rtol=1e-10)
    assert {int(v) for r in out[0][700:] for v in r.variant} <= {1, 2}
    # The steps read out only the band's rows; the calibrations' row scores cover all.
    for mode in range(len(able_bodied)):
        np.testing.assert_allclose(matchers[0].mode_row_scores(mode), matchers[1].mode_row_scores(mode), rtol=1e-10)
        assert np.isfinite(matchers[0].mode_row_scores(mode)).all()


def test_a_stretched_stride_is_matched_by_its_time_scale(able_bodied) -> None:
    med = able_bodied.mode("Med").samples
    n = round(1.06 * len(med))
    stride = resample_stride(med, n)
    m = IncrementalMatcher(able_bodied, time_scales=(0.94, 1.0, 1.06), normalize=True)
    r = None
    for d in np.tile(stride, (3, 1)):
        r = m.step(d)
    assert r.mode == "Med" and m.time_scales[r.variant[r.mode_index]] == 1.06
    assert r.sse[r.mode_index] == pytest.approx(0.0, abs=1e-9)
    assert r.phase == pytest.approx(0.0)  # the stream ends with a whole stride


@pytest.mark.parametrize("backend", BACKENDS)
def test_shape_only_matching_ignores_constant_offsets(able_bodied, multispeed_csv, backend) -> None:
    x = read_recording(multispeed_csv).angles_deg[3000:4200]
    offsets = np.array([7.5, -6.0, 4.0, -8.0])
    a = IncrementalMatcher(able_bodied, offset_tolerance_deg=math.inf, backend=backend).run(x)
    b = IncrementalMatcher(able_bodied, offset_tolerance_deg=math.inf, backend=backend).run(x + offsets)
    r = a.ready  # while windows fill, nothing is removed
    np.testing.assert_array_equal(a.mode_index[r], b.mode_index[r])
    np.testing.assert_array_equal(a.phase[r], b.phase[r])
    np.testing.assert_allclose(a.sse[r], b.sse[r], rtol=1e-7, atol=1e-6)
    paper = IncrementalMatcher(able_bodied, backend=backend).run(x + offsets)
    assert (paper.sse[r] > a.sse[r]).all()  # the paper pays for the offsets


def test_shape_only_matching_with_a_dropped_channel(able_bodied, multispeed_csv) -> None:
    """Infinite tolerance and a channel weighted 0: finite scores, the same on every backend
    and for the naive matcher (the dropped channel's tolerance is 0, not inf * 0)."""
    x = read_recording(multispeed_csv).angles_deg[3000:3700] + np.array([7.5, -6.0, 4.0, -8.0])
    opts = {"offset_tolerance_deg": math.inf, "channel_weights": [1.0, 0.0, 1.0, 0.0]}
    runs = [IncrementalMatcher(able_bodied, backend=b, **opts).run(x) for b in BACKEND_NAMES]
    runs.append(NaiveMatcher(able_bodied, **opts).run(x))
    r = runs[0].ready
    for run in runs:
        assert np.isfinite(run.sse[r]).all()
        np.testing.assert_array_equal(run.mode_index[r], runs[0].mode_index[r])
        np.testing.assert_allclose(run.sse[r], runs[0].sse[r], rtol=1e-7, atol=1e-6)


def test_offset_penalty_is_the_excess_over_the_tolerance() -> None:
    """One mode, a constant kernel: window mean - kernel mean = x per channel, so the score is
    W sum_c max(|x_c| - tau, 0)^2 (per sample with normalize)."""
    k = np.zeros((10, 4))
    lib = KernelLibrary("flat", (make_mode("flat", k, 100.0),))
    shift = np.array([1.0, -3.0, 5.0, 0.0])
    for tau, expected in [(0.0, 35.0), (2.0, 1.0 + 9.0), (4.0, 1.0), (math.inf, 0.0)]:
        r = None
        m = IncrementalMatcher(lib, offset_tolerance_deg=tau, normalize=True)
        for _ in range(12):
            r = m.step(shift)
        assert r.sse[0] == pytest.approx(expected), tau


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("window", [{}, {"recency_half_life": 0.3}])
def test_set_kernel_continues_as_if_the_kernel_had_always_been_this_one(able_bodied, multispeed_csv, backend, window) -> None:
    x = read_recording(multispeed_csv).angles_deg[3000:4000]
    opts = {"time_scales": (0.9, 1.0, 1.1), "offset_tolerance_deg": 3.0, "normalize": True, **window}
    new = able_bodied.mode("Fast").samples + np.random.default_rng(0).normal(0, 2.0, (280, 4))
    modes = list(able_bodied.modes)
    modes[2] = make_mode("Fast", new, 230.0)
    changed = KernelLibrary("changed", tuple(modes))
    a = IncrementalMatcher(able_bodied, backend=backend, **opts)
    a.run(x[:600])
    a.set_kernel(2, new)
    ra = a.run(x[600:])
    b = IncrementalMatcher(changed, backend=backend, **opts)
    b.run(x[:600])
    rb = b.run(x[600:])
    np.testing.assert_array_equal(ra.mode_index, rb.mode_index)
    np.testing.assert_allclose(ra.sse, rb.sse, rtol=1e-9)
    with pytest.raises(ValueError, match="shape"):
        a.set_kernel(2, new[:10])


@pytest.mark.parametrize("backend", BACKENDS)
def test_recency_weights_can_change_at_any_sample(able_bodied, multispeed_csv, backend) -> None:
    """set_recency_half_life recomputes the running sums from the window: the matcher continues as
    if it had always had the new weights (0 = uniform: as a matcher made without them)."""
    x = read_recording(multispeed_csv).angles_deg[3000:4200]
    opts = {"time_scales": (0.9, 1.0, 1.1), "offset_tolerance_deg": 2.0, "normalize": True, "backend": backend}
    switched = IncrementalMatcher(able_bodied, recency_half_life=0.3, **opts)
    switched.set_recency_half_life(0.0)
    uniform = IncrementalMatcher(able_bodied, **opts)
    np.testing.assert_allclose(switched.run(x[:500]).sse, uniform.run(x[:500]).sse, rtol=1e-9)
    switched.set_recency_half_life(0.3)
    weighted = IncrementalMatcher(able_bodied, recency_half_life=0.3, **opts)
    weighted.run(x[:500])
    a, b = switched.run(x[500:]), weighted.run(x[500:])
    np.testing.assert_array_equal(a.mode_index, b.mode_index)
    np.testing.assert_allclose(a.sse, b.sse, rtol=1e-9)
    assert not np.allclose(a.sse, uniform.run(x[500:]).sse)
    with pytest.raises(ValueError, match="recency_half_life > 0"):
        uniform.set_recency_half_life(0.3)


@pytest.mark.parametrize("backend", BACKENDS)
def test_start_uniform_matches_uniformly_until_the_weights_are_set_again(able_bodied, multispeed_csv, backend) -> None:
    """start_uniform: the matcher matches with uniform weights (as one made without recency
    weighting) until set_recency_half_life sets its age weights again, which rebuilds the weighted
    sums from the window: from then on it equals a matcher that was weighted all along (to
    rounding); reset keeps it uniform."""
    x = read_recording(multispeed_csv).angles_deg[3000:4300]
    opts = {"time_scales": (0.9, 1.0, 1.1), "offset_tolerance_deg": 2.0, "normalize": True, "backend": backend}
    deferred = IncrementalMatcher(able_bodied, recency_half_life=0.3, **opts)
    deferred.start_uniform()
    assert deferred.recency_half_life == 0.0
    uniform = IncrementalMatcher(able_bodied, **opts)
    weighted = IncrementalMatcher(able_bodied, recency_half_life=0.3, **opts)
    a, u = deferred.run(x[:600]), uniform.run(x[:600])
    np.testing.assert_array_equal(a.mode_index, u.mode_index)
    np.testing.assert_allclose(a.sse, u.sse, rtol=1e-12)
    weighted.run(x[:600])
    deferred.set_recency_half_life(0.3)
    a, w = deferred.run(x[600:]), weighted.run(x[600:])
    np.testing.assert_array_equal(a.mode_index, w.mode_index)
    np.testing.assert_allclose(a.sse, w.sse, rtol=1e-9)
    uniform.run(x[600:])
    deferred.start_uniform()  # from the weighted state: the uniform sums are recomputed once
    np.testing.assert_allclose(deferred.step(x[0]).sse, uniform.step(x[0]).sse, rtol=1e-9)
    deferred.reset()
    uniform.reset()
    np.testing.assert_allclose(deferred.run(x[:300]).sse, uniform.run(x[:300]).sse, rtol=1e-12)
    other = IncrementalMatcher(able_bodied, recency_half_life=0.3, **opts)  # to other weights than its own
    other.start_uniform()
    other.run(x[:400])
    other.set_recency_half_life(0.5)
    ref = IncrementalMatcher(able_bodied, recency_half_life=0.5, **opts)
    ref.run(x[:400])
    np.testing.assert_allclose(other.run(x[400:600]).sse, ref.run(x[400:600]).sse, rtol=1e-9)
    with pytest.raises(ValueError, match="start_uniform"):
        IncrementalMatcher(able_bodied, **opts).start_uniform()


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"time_scales": []}, "time_scales"),
    ({"time_scales": [0.3]}, "time_scales"),
    ({"time_scales": [1.0, 1.0]}, "distinct"),
    ({"offset_tolerance_deg": -1.0}, "offset_tolerance_deg"),
    ({"recency_half_life": -0.1}, "recency_half_life"),
    ({"recency_half_life": math.inf}, "recency_half_life"),
    ({"recency_half_life": math.nan}, "recency_half_life"),
    ({"backend": "cuda"}, "backend"),
])
def test_invalid_new_options(able_bodied, kwargs, message) -> None:
    with pytest.raises(ValueError, match=message):
        IncrementalMatcher(able_bodied, **kwargs)


@pytest.mark.parametrize("recency", [0.0, 0.3])
def test_mean_offset_and_sensor_offset(able_bodied, recency) -> None:
    """A kernel walked with constant sensor offsets: mean_offset reads them back, and assuming
    them (set_sensor_offset) makes the paper's score what it is without the offsets."""
    offsets = np.array([3.0, -2.0, 1.0, 5.0])
    x = np.tile(able_bodied.mode("Med").samples, (2, 1))
    opts = {"recency_half_life": recency}
    m = IncrementalMatcher(able_bodied, **opts)
    r = m.run(x + offsets)
    assert r.modes[-1] == "Med"
    np.testing.assert_allclose(m.mean_offset(1, int(m.step(x[0] + offsets).column[1])), offsets, atol=1e-6)  # float32 kernels
    # Every mode walked as itself, the longest window (its prefix sum shares a ring slot) included.
    for mode in range(len(able_bodied)):
        walk = np.tile(able_bodied.modes[mode].samples, (2, 1)) + offsets
        mm = IncrementalMatcher(able_bodied, **opts)
        mm.run(walk)
        got = mm.mean_offset(mode, int(mm.lengths[mode]) - 1)  # the aligned column: the walk ends a stride
        np.testing.assert_allclose(got, offsets, atol=1e-6, err_msg=able_bodied.modes[mode].name)
    assert int(np.argmax(mm.windows)) in range(len(able_bodied))
    clean = IncrementalMatcher(able_bodied, **opts).run(x)
    shifted = IncrementalMatcher(able_bodied, **opts)
    shifted.set_sensor_offset(offsets)
    np.testing.assert_allclose(shifted.sensor_offset_deg, offsets)
    s = shifted.run(x + offsets)
    np.testing.assert_allclose(s.sse[s.ready], clean.sse[clean.ready], rtol=1e-9, atol=1e-6)


@pytest.mark.skipif(not compiled.AVAILABLE, reason="numba not installed")
def test_per_shift_means_are_the_weighted_kernel_means_and_one_table(able_bodied) -> None:
    """With recency weighting the offset penalty compares the window's weighted mean with the
    kernel part's weighted mean at each shift: sum_t a_t k_{(j-t) mod n} / W_a, written plainly
    here. The compiled step keeps only every SHIFT_BLOCK-th of them and derives the others as
    the numpy step's full table holds them, bit for bit."""
    opts = {"recency_half_life": 0.3, "offset_tolerance_deg": 2.0, "time_scales": (0.92, 1.0, 1.08)}
    numba = IncrementalMatcher(able_bodied, backend="numba", **opts)
    table = IncrementalMatcher(able_bodied, backend="numpy", **opts)
    assert numba._mu_seg.size == 0 and table._mu_seg.shape[2] == table.max_length
    rows = np.arange(numba.n_rows)
    derived, kept = numba._row_shift_means(rows), table._row_shift_means(rows)
    for r in rows:
        n = int(numba.lengths[r])
        np.testing.assert_array_equal(derived[r, :, :n], kept[r, :, :n])
        k = numba._kernels[r, :, :n].astype(np.float64)  # (4, n)
        a = numba._lam[r] ** np.arange(n)
        plain = np.array([[(a * k[c, (j - np.arange(n)) % n]).sum() for j in range(n)] for c in range(4)]) / a.sum()
        np.testing.assert_allclose(derived[r, :, :n], plain, rtol=0, atol=1e-9)


@pytest.mark.skipif(not compiled.AVAILABLE, reason="numba not installed")
def test_the_compiled_steps_state_follows_every_replaced_array(able_bodied, multispeed_csv) -> None:
    """The compiled steps take the matcher's state as one structure, kept between steps: after
    whatever replaces one of its arrays or flags (a scale band that repacks the row tables, new
    age weights, a sensor offset) it holds the matcher's current ones."""
    x = read_recording(multispeed_csv).angles_deg[:900]
    m = IncrementalMatcher(able_bodied.replicated(14), time_scales=(0.92, 1.0, 1.08), recency_half_life=0.3,
                           offset_tolerance_deg=2.0, normalize=True, backend="numba")

    def fresh() -> tuple:
        m._state = None
        return m._step_state()

    def check() -> None:
        kept = m._step_state()
        assert all(a is b for a, b in zip(kept, fresh(), strict=True))
    m.run(x[:300])
    check()
    for change in (lambda: m.set_scale_band([False, True, False], search=2), lambda: m.set_recency_half_life(0.5),
                   lambda: m.set_sensor_offset([1.0, 0.0, 0.0, 0.0]), lambda: m.set_scale_band(None), m.start_uniform):
        kept = m._step_state()
        change()
        m.run(x[300:400])
        assert m._step_state() is not kept or all(a is b for a, b in zip(kept, fresh(), strict=True))
        check()


def test_without_numba_the_numpy_step_runs(tmp_path) -> None:
    """GAIT_ESTIMATOR_NO_NUMBA=1 (or numba missing): the numpy step, same results."""
    import os
    import subprocess
    import sys

    code = (
        "import numpy as np\n"
        "from gait_estimator import load_library\n"
        "from gait_estimator.core import compiled\n"
        "from gait_estimator.core.estimator import Estimator\n"
        "lib = load_library('able_bodied')\n"
        "est = Estimator(lib)\n"
        "x = np.tile(lib.mode('Med').samples, (3, 1))\n"
        "out = [est.update(i / 230.0, d) for i, d in enumerate(x)]\n"
        "print(compiled.AVAILABLE, est.matcher.backend, out[-1].mode, repr(out[-1].phase))\n"
    )
    env = {**os.environ, "GAIT_ESTIMATOR_NO_NUMBA": "1"}
    plain = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout.split()
    assert plain[:3] == ["False", "numpy", "Med"]
    if compiled.AVAILABLE:
        fast = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
        assert fast[:3] == ["True", "numba", "Med"]
        assert float(fast[3]) == pytest.approx(float(plain[3]), abs=1e-12)


@pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA")
def test_large_libraries_use_the_threaded_float32_step_with_the_same_results(able_bodied, multispeed_csv) -> None:
    """From PARALLEL_MIN_ROWS rows on, the compiled step reads float32 kernels and spreads rows
    over threads (given two CPUs): the same kernel values, so the numpy step's results."""
    from gait_estimator.core.matcher import PARALLEL_MIN_ROWS

    lib = able_bodied.replicated(70)
    opts = {"time_scales": (0.94, 1.0, 1.06, 1.12), "offset_tolerance_deg": 2.0, "normalize": True}
    fast = IncrementalMatcher(lib, backend="numba", **opts)
    assert fast.n_rows >= PARALLEL_MIN_ROWS and fast._kernels.dtype == np.float32
    x = read_recording(multispeed_csv).angles_deg[2000:2600]
    a, b = fast.run(x), IncrementalMatcher(lib, backend="numpy", **opts).run(x)
    np.testing.assert_array_equal(a.mode_index, b.mode_index)
    np.testing.assert_allclose(a.sse, b.sse, rtol=1e-10)
    np.testing.assert_allclose(a.phase, b.phase, rtol=0, atol=1e-12)


@pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA")
def test_searched_modes_are_read_at_every_scale(multispeed_csv, able_bodied) -> None:
    """set_scale_band(band, search=k): every mode at the band's scale, the k best-fitting ones at
    every scale, chosen again every SEARCH_EVERY steps. Both steps agree at every step, also with
    sensor offsets (the compiled per-shift read-out skips shifts that cannot win: same result);
    searching every mode equals the open band."""
    x = read_recording(multispeed_csv).angles_deg[2000:3600]
    opts = {"time_scales": (0.88, 0.94, 1.0, 1.06, 1.12), "offset_tolerance_deg": 2.0, "normalize": True,
            "recency_half_life": 0.3}
    centre = [False, False, True, False, False]
    out, searched = [], []
    for backend, search in (("numba", 2), ("numpy", 2), ("numba", len(able_bodied)), ("numba", 0)):
        m = IncrementalMatcher(able_bodied, backend=backend, **opts)
        m.set_scale_band(centre if search else None, search=search)
        rows, sets = [], []
        for i, d in enumerate(x):
            if i == 900:
                m.set_sensor_offset([3.0, -2.0, 1.0, 0.5])
            sets.append(m.searched_modes)  # the modes this step reads at every scale
            rows.append(m.step(d))
        out.append(rows)
        searched.append(np.array(sets))
    np.testing.assert_array_equal(searched[0], searched[1])
    assert 0 < np.count_nonzero(np.diff(searched[0], axis=0).any(axis=1)) < len(x) // SEARCH_EVERY
    for i, (a, b) in enumerate(zip(out[0], out[1], strict=True)):
        assert a.mode_index == b.mode_index and np.array_equal(a.variant, b.variant)
        np.testing.assert_allclose(a.sse, b.sse, rtol=1e-9)
        assert np.all(a.variant[~searched[0][i]] == 2) and searched[0][i].sum() == 2
    for a, b in zip(out[2], out[3], strict=True):  # every mode searched: the open band
        assert a.mode_index == b.mode_index and np.array_equal(a.variant, b.variant)
        np.testing.assert_allclose(a.sse, b.sse, rtol=1e-9)
    with pytest.raises(ValueError, match="search"):
        m.set_scale_band(centre, search=-1)


@pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA")
def test_the_row_tables_hold_only_the_rows_in_use(multispeed_csv, able_bodied) -> None:
    """With a scale band the compiled step's matcher keeps kernels and sums for the band's rows
    (and one mode's rows besides), every row again with the whole band; its row scores and steps
    are those of a matcher with a wider band (to the rounding of rows rebuilt from the window)."""
    x = read_recording(multispeed_csv).angles_deg[2000:2900]
    opts = {"time_scales": (0.88, 0.94, 1.0, 1.06, 1.12), "offset_tolerance_deg": 2.0, "recency_half_life": 0.3}
    pooled, kept = IncrementalMatcher(able_bodied, **opts), IncrementalMatcher(able_bodied, **opts)
    full = pooled.state_bytes()
    bands = {0: [False, False, True, False, False], 300: [False, False, False, True, False], 600: None}
    wide = {0: [False, True, True, True, False], 300: [False, True, True, True, False], 600: None}
    for i, d in enumerate(x):
        if i in bands:
            pooled.set_scale_band(bands[i])
            kept.set_scale_band(wide[i])  # its rows stay in the tables: the pooled ones are rebuilt
        if i == 10:
            assert pooled.state_bytes() < 0.5 * full
        if i < 600 and i % 100 == 50:
            np.testing.assert_allclose(pooled.mode_row_scores(3), kept.mode_row_scores(3), rtol=1e-12)
        a, b = pooled.step(d), kept.step(d)
        if i >= 600:
            assert a.mode_index == b.mode_index
            np.testing.assert_allclose(a.sse, b.sse, rtol=1e-9)
    assert pooled.state_bytes() == full


@pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA")
def test_rows_outside_the_band_are_rebuilt_when_they_are_needed(multispeed_csv, able_bodied) -> None:
    """The compiled step updates only the band's rows; a row outside it is rebuilt from the window
    when it re-enters the band or is read (mode_row_scores), also across the switch from the
    uniform to the weighted sums kept alongside and a kernel change: every step equals the numpy
    step, which updates every row."""
    x = read_recording(multispeed_csv).angles_deg[2000:4200]
    opts = {"time_scales": (0.88, 0.94, 1.0, 1.06, 1.12), "offset_tolerance_deg": 2.0, "normalize": True,
            "recency_half_life": 0.3}
    bands = {400: [False, True, True, False, False], 700: [False, False, True, True, True], 900: None,
             1100: [True, False, False, False, False], 1500: [False, False, False, True, False]}
    new = able_bodied.mode("Fast").samples + 1.5
    out = []
    for backend in ("numba", "numpy"):
        m = IncrementalMatcher(able_bodied, backend=backend, **opts)
        m.start_uniform()
        rows, scores = [], []
        for i, d in enumerate(x):
            if i in bands:
                m.set_scale_band(bands[i])
            if i == 1000:
                m.set_recency_half_life(0.3)  # the sums kept alongside, outside the band too
            if i == 1300:
                m.set_kernel(2, new)
            rows.append(m.step(d))
            if i % 97 == 0:
                scores.append(np.concatenate([m.mode_row_scores(k) for k in range(len(able_bodied))]))
        out.append((rows, scores))
    for a, b in zip(out[0][0], out[1][0], strict=True):
        assert a.mode_index == b.mode_index and np.array_equal(a.variant, b.variant)
        np.testing.assert_allclose(a.sse, b.sse, rtol=1e-9)
        np.testing.assert_allclose(a.phases, b.phases, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(out[0][1]), np.array(out[1][1]), rtol=1e-9)


@pytest.mark.skipif(NUMBA_OFF, reason="GAIT_ESTIMATOR_NO_NUMBA")
def test_many_rows_over_threads_give_the_one_thread_results(able_bodied, multispeed_csv) -> None:
    """From PARALLEL_MIN_ROWS updated rows on, the compiled step spreads the rows (per-shift
    offset penalty, age weights) over threads: bit for bit what one thread gives, and the numpy
    step's results."""
    from gait_estimator.core import compiled
    from gait_estimator.core.matcher import PARALLEL_MIN_ROWS

    lib = able_bodied.replicated(40)
    opts = {"time_scales": (0.88, 0.92, 0.96, 1.0, 1.04, 1.08, 1.12), "offset_tolerance_deg": 2.0, "normalize": True,
            "recency_half_life": 0.3}
    x = read_recording(multispeed_csv).angles_deg[2000:2700] + np.array([3.0, -1.0, 0.5, 2.0])
    many = IncrementalMatcher(lib, backend="numba", **opts)
    one = IncrementalMatcher(lib, backend="numba", **opts)
    assert many.n_rows >= PARALLEL_MIN_ROWS
    one._compiled_step = compiled.step_rows
    a, b, c = many.run(x), one.run(x), IncrementalMatcher(lib, backend="numpy", **opts).run(x)
    np.testing.assert_array_equal(a.sse, b.sse)
    np.testing.assert_array_equal(a.phase, b.phase)
    np.testing.assert_array_equal(a.mode_index, c.mode_index)
    np.testing.assert_allclose(a.sse, c.sse, rtol=1e-10)
