"""The stride-start reader: a mode change shows within the stride it starts in."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from synthetic import generate, new_wearer, with_stops

from gait_estimator.core import compiled, estimator, stride_reader
from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.core.kernels import KernelLibrary, resample_stride
from gait_estimator.core.stride_reader import JOIN_FRACTIONS, SUGGESTED_EVIDENCE_DEG2S, StrideStartReader

EVIDENCE = SUGGESTED_EVIDENCE_DEG2S  # deg^2 s (the reader is opt-in)
ROUTE = [("Med", 5), ("RA", 5), ("Med", 4), ("SA", 5), ("Slow", 5), ("SD", 5), ("Fast", 5), ("RD", 5), ("Med", 5)]


def _joined_stride(lib: KernelLibrary, old: str, new: str, join: float = JOIN_FRACTIONS[-1]) -> np.ndarray:
    """One stride of ``new`` from its heel strike, joined to the pose ``old`` ended in over
    ``join`` of the stride (the reader's model), without the heel-strike sample itself."""
    k = lib.mode(new).samples
    n = k.shape[0]
    phi = np.arange(n) / n
    w = np.where(phi < join, 0.5 * (1 + np.cos(np.pi * phi / join)), 0.0)
    return (k + w[:, None] * (lib.mode(old).samples[0] - k[0]))[1:]


def test_reader_reads_the_new_mode_early_in_its_stride(able_bodied) -> None:
    names = able_bodied.mode_names
    reader = StrideStartReader(able_bodied, np.ones(4), evidence_deg2s=20.0)
    med = names.index("Med")
    for new, join in itertools.product(("SA", "RD", "SD"), JOIN_FRACTIONS):
        stride = _joined_stride(able_bodied, "Med", new, join)
        reader.start(able_bodied.mode("Med").samples[0], med, np.zeros(4), np.array([1.0]))
        reads = [reader.step(x) for x in stride]
        first = next(i for i, r in enumerate(reads) if r is not None)
        assert first < 0.4 * len(stride), (new, join, first)
        assert {r[0] for r in reads[first:] if r is not None} == {names.index(new)}
        _, phase, scale = reads[len(stride) // 2]
        assert abs(phase - (len(stride) // 2 + 1) / able_bodied.mode(new).length) < 1e-9 and scale == 1.0
    # the reported mode itself, continued: nothing to report
    reader.start(able_bodied.mode("Med").samples[-1], med, np.zeros(4), np.array([0.96, 1.0, 1.04]))
    assert all(reader.step(x) is None for x in able_bodied.mode("Med").samples)


def test_reader_keeps_to_the_allowed_transitions(able_bodied) -> None:
    names = able_bodied.mode_names
    med, sa = names.index("Med"), names.index("SA")
    allowed = np.ones((len(names), len(names)), dtype=bool)
    allowed[med, sa] = False
    reader = StrideStartReader(able_bodied, np.ones(4), 20.0, allowed=allowed)
    reader.start(able_bodied.mode("Med").samples[0], med, np.zeros(4), np.array([1.0]))
    reads = [reader.step(x) for x in _joined_stride(able_bodied, "Med", "SA")]
    assert all(r is None or r[0] != sa for r in reads)


def test_reader_stops_after_one_and_a_half_strides_and_on_reset(able_bodied) -> None:
    reader = StrideStartReader(able_bodied, np.ones(4), 20.0)
    reader.start(able_bodied.mode("Med").samples[0], 0, np.zeros(4), np.array([1.0]))
    stride = _joined_stride(able_bodied, "Med", "SD")
    assert reader.step(stride[0]) is None and reader.step(stride[1]) is None  # not enough evidence yet
    reader.reset()
    assert all(reader.step(x) is None for x in stride)
    reader.start(able_bodied.mode("Med").samples[0], 0, np.zeros(4), np.array([1.0]))
    longest = int(1.5 * able_bodied.lengths.max())
    sd = able_bodied.mode("SD").samples
    reads = [reader.step(stride[i] if i < len(stride) else sd[i % len(sd)]) for i in range(longest + 5)]
    assert reads[longest - 1] is not None and reads[longest:] == [None] * 5


@pytest.mark.skipif(not compiled.AVAILABLE, reason="numba not installed")
def test_reader_numba_and_numpy_agree(able_bodied) -> None:
    rng = np.random.default_rng(3)
    xs = rng.normal(0.0, 20.0, (300, 4))
    weights = np.array([1.0, 0.5, 1.0, 0.0])
    runs = []
    for backend in ("numba", "numpy"):
        reader = StrideStartReader(able_bodied, weights, 20.0, backend=backend)
        assert reader.compiled == (backend == "numba")
        reader.start(xs[0], 2, np.array([1.0, -1.0, 0.5, 2.0]), np.array([0.92, 0.96, 1.0, 1.04]))
        runs.append(([reader.step(x) for x in xs[1:]], reader._error.copy()))
    assert runs[0][0] == runs[1][0]
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=1e-12)


def test_reader_follows_mode_changes_within_the_stride(able_bodied) -> None:
    """Synthetic new wearer 0 walks a route with 8 mode changes: with the reader the first
    correct estimate after a change comes much sooner and more rows are right; in steady walking
    (from a whole stride into a run on) nothing is lost."""
    syn = generate(able_bodied, ROUTE, new_wearer(0), seed=1000)
    rec = syn.recording
    truth = np.asarray(rec.labels).astype(str)
    changes = np.flatnonzero(truth[1:] != truth[:-1]) + 1
    starts = np.r_[0, changes]
    run_start = starts[np.searchsorted(starts, np.arange(len(truth)), side="right") - 1]
    steady = rec.time_s - rec.time_s[run_start] > 1.4  # a whole stride (up to 1.1 s) into the run
    results = {}
    for evidence in (0.0, EVIDENCE):
        est = Estimator(able_bodied, EstimatorConfig(switch_evidence_deg2s=evidence))
        assert (est.reader is None) == (evidence == 0.0)
        trace = run_estimator(est, rec.time_s, rec.angles_deg)
        right = np.asarray(trace.modes) == truth
        delays = [rec.time_s[c + np.argmax(right[c:])] - rec.time_s[c] for c in changes]
        results[evidence] = (float(np.mean(delays)), float(np.mean(right[trace.ready])),
                             float(np.mean(right[trace.ready & steady])))
    (d0, a0, s0), (d1, a1, s1) = results.values()
    assert d1 < 0.75 * d0, results
    assert a1 > a0 + 0.02, results
    assert s1 >= s0 - 0.005, results


def test_reader_changes_little_in_steady_walking(able_bodied) -> None:
    """New wearers walking Med or RA only, no mode change: with the reader the estimator reports
    another mode than without it on at most a few rows in a hundred (a stride start now and then
    fits a neighbouring mode better), and is right as often within a point."""
    changed, lost = [], []
    for mode, seed in itertools.product(("Med", "RA"), (2, 3, 4)):
        rec = generate(able_bodied, [(mode, 25)], new_wearer(seed), seed=7).recording
        traces = [run_estimator(Estimator(able_bodied, EstimatorConfig(switch_evidence_deg2s=e)), rec.time_s,
                                rec.angles_deg) for e in (0.0, EVIDENCE)]
        modes = [np.asarray(t.modes)[traces[0].ready] for t in traces]
        changed.append(np.mean(modes[0] != modes[1]))
        lost.append(np.mean(modes[0] == mode) - np.mean(modes[1] == mode))
    assert np.mean(changed) < 0.02 and max(changed) < 0.04, changed
    assert np.mean(lost) < 0.01, lost


def test_reader_option_is_checked_and_off_by_default(able_bodied) -> None:
    with pytest.raises(ValueError, match="switch_evidence_deg2s"):
        EstimatorConfig(switch_evidence_deg2s=-1.0)
    with pytest.raises(ValueError, match="evidence_deg2s"):
        StrideStartReader(able_bodied, np.ones(4), float("inf"))
    assert EstimatorConfig.preset("paper").switch_evidence_deg2s == 0.0 == EstimatorConfig().switch_evidence_deg2s
    assert Estimator(able_bodied).reader is None


def test_reader_reads_personalised_kernels(able_bodied) -> None:
    """set_kernel replaces what a mode is read against: SD made a copy of Med is not read in an
    SD stride any more."""
    names = able_bodied.mode_names
    med, sd = names.index("Med"), names.index("SD")
    stride = _joined_stride(able_bodied, "Med", "SD")
    reads = {}
    for personalised in (False, True):
        reader = StrideStartReader(able_bodied, np.ones(4), 20.0)
        if personalised:
            reader.set_kernel(sd, resample_stride(able_bodied.mode("Med").samples, able_bodied.mode("SD").length))
        reader.start(able_bodied.mode("Med").samples[0], med, np.zeros(4), np.array([1.0]))
        reads[personalised] = {r[0] for r in (reader.step(x) for x in stride) if r is not None}
    assert sd in reads[False] and sd not in reads[True]


def test_reader_reads_only_after_strides_that_fitted_as_usual(able_bodied) -> None:
    """No reading before the first confident stride has shown how well this wearer's strides fit,
    nor at a heel strike after a stride the reported mode fitted worse than that; the learnt fit
    is forgotten with the calibrations and kept across an option change."""
    rec = generate(able_bodied, [("Med", 8), ("SD", 4)], new_wearer(1), seed=3).recording
    est = Estimator(able_bodied, EstimatorConfig(switch_evidence_deg2s=EVIDENCE))
    reader = est.reader
    assert reader is not None
    starts = []
    original = reader.start
    reader.start = lambda *a, **k: (starts.append((est.fit_strides, est.last_time)), original(*a, **k))  # type: ignore[method-assign]
    for t, x in zip(rec.time_s, rec.angles_deg, strict=True):
        est.update(float(t), x)
    assert starts and min(n for n, _ in starts) >= 1 and est.fit_strides >= 1
    assert np.isfinite(est.typical_fit2) and est.typical_fit2 > 0
    other = Estimator(able_bodied, EstimatorConfig(switch_evidence_deg2s=40.0))
    other.adopt_calibration(est)
    assert (other.fit_strides, other.typical_fit2) == (est.fit_strides, est.typical_fit2)
    est.reset_calibration()
    assert est.fit_strides == 0 and np.isnan(est.typical_fit2)


def test_a_walk_that_stops_is_not_read_as_stairs(able_bodied, monkeypatch) -> None:
    """Thirteen Med strides, then the pose fades to standing from a heel strike: early on that looks
    like the start of a stair ascent, and later no kernel fits it. Neither is reported as a new
    mode: the reader reports a mode only from REPORT_FROM of its stride on and only while it fits
    as well as READER_SWITCH_FIT allows; each guard alone lets SA through for this wearer."""
    cfg = new_wearer(103)
    walk = generate(able_bodied, [("Med", 13), ("Med", 4)], cfg, seed=103).recording
    stand = able_bodied.mode("Med").samples.mean(axis=0) + np.asarray(cfg.channel_offset_deg)
    rec = with_stops(walk, {13: 4.0}, stand, seed=103)

    def stair_rows() -> int:
        est = Estimator(able_bodied, EstimatorConfig(switch_evidence_deg2s=EVIDENCE), stamped=True)
        trace = run_estimator(est, rec.time_s, rec.angles_deg)
        return int(np.isin(np.asarray(able_bodied.mode_names)[trace.mode_index], ["SA", "SD"]).sum())

    assert stair_rows() == 0
    with monkeypatch.context() as m:
        m.setattr(stride_reader, "REPORT_FROM", 0.0)
        assert stair_rows() > 10
    monkeypatch.setattr(estimator, "READER_SWITCH_FIT", math.inf)
    assert stair_rows() > 10
