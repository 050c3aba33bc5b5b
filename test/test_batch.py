"""Offline processing in bulk (core/batch.py) gives what Estimator.update gives sample by sample."""

from __future__ import annotations

import os
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.core import batch, compiled
from gait_estimator.core.batch import batch_supported
from gait_estimator.core.estimator import EstimateTrace, Estimator, EstimatorConfig, run_estimator, trace_from_estimates
from gait_estimator.core.supervisor import SUPERVISED_STEPS
from gait_estimator.io.readers import read_recording

pytestmark = pytest.mark.skipif(not compiled.AVAILABLE or bool(os.environ.get("GAIT_ESTIMATOR_NO_NUMBA")),
                                reason="the bulk path needs numba")


def run_batch(est: Estimator, t: np.ndarray, x: np.ndarray, idx: np.ndarray) -> EstimateTrace | None:
    """run_estimator in bulk, or None if it would stream."""
    columns = batch.run_batch(est, t, x)
    return None if columns is None else EstimateTrace(est.mode_names, sample=np.asarray(idx, dtype=np.int64), **columns)


def streamed(est: Estimator, t: np.ndarray, x: np.ndarray, idx: np.ndarray) -> EstimateTrace:
    return trace_from_estimates(est.mode_names, [(int(idx[i]), est.update(float(t[i]), x[i])) for i in range(len(t))])


def assert_identical(a: EstimateTrace, b: EstimateTrace) -> None:
    for f in fields(EstimateTrace):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if f.name == "mode_names":
            assert va == vb
            continue
        assert va.dtype == vb.dtype and va.shape == vb.shape, f.name
        np.testing.assert_array_equal(va, vb, err_msg=f.name)  # nan == nan here


def assert_same_state(a: Estimator, b: Estimator) -> None:
    """What the next sample depends on."""
    ma, mb = a.matcher, b.matcher
    assert ma.steps == mb.steps and a.last_time == b.last_time and a.calibration._last == b.calibration._last
    np.testing.assert_array_equal(ma.running_sse(), mb.running_sse())
    np.testing.assert_array_equal(ma.scale_band, mb.scale_band)
    np.testing.assert_array_equal(a.sensor_offset_deg, b.sensor_offset_deg)
    assert (a.cadence_scale, a.calibration.strides, a.resets, a.calibration_resets) == (
        b.cadence_scale, b.calibration.strides, b.resets, b.calibration_resets) or np.isnan(a.cadence_scale)
    np.testing.assert_array_equal(np.array(a.supervisor._mem), np.array(b.supervisor._mem))


@pytest.mark.parametrize("preset", ["default", "paper"])
@pytest.mark.parametrize("stamped", [True, False], ids=["resampled", "not-resampled"])
@pytest.mark.parametrize("name", ["Multispeed_Walk_AB.csv", "LG_2_Ramp_AB_Sample.csv"])
def test_bulk_equals_streaming_on_the_bundled_recordings(swge: Path, able_bodied, preset, stamped, name) -> None:
    """Every field of every estimate, bit for bit, and the state left behind; with the default
    preset the walking calibrations act along the way (the bulk path hands them the strides)."""
    rec = read_recording(swge / "recordings" / name)
    cfg = EstimatorConfig.preset(preset)
    a, b = Estimator(able_bodied, cfg, stamped=stamped), Estimator(able_bodied, cfg, stamped=stamped)
    assert batch_supported(b)
    ref = streamed(a, rec.time_s, rec.angles_deg, rec.index)
    got = run_batch(b, rec.time_s, rec.angles_deg, rec.index)
    assert got is not None
    assert_identical(ref, got)
    assert_same_state(a, b)
    if preset == "default":
        assert b.calibration.strides >= 3 and b.matcher.recency_half_life > 0  # the calibrations acted
        assert set(ref.state.tolist()) == {0, 1, 2, 3}  # every state, decided alike (states.py)


@pytest.mark.parametrize("stamped", [True, False], ids=["resampled", "not-resampled"])
def test_bulk_equals_streaming_under_every_supervisor_option(multispeed_csv: Path, able_bodied, tmp_path: Path,
                                                              stamped) -> None:
    """Holds, dwell, switch-back margin and transitions (the walking calibrations off: paper preset, states on): the
    same decision in bulk as sample by sample."""
    table = tmp_path / "transitions.yaml"
    table.write_text("allowed_transitions:\n  Slow: [Med]\n  Fast: [Med]\n")
    cfg = EstimatorConfig.preset("paper", min_confidence=0.02, min_dwell_s=0.08, switch_back_margin=0.1,
                                 transitions=str(table), states=True,
                                 resample="auto")
    rec = read_recording(multispeed_csv)
    a, b = Estimator(able_bodied, cfg, stamped=stamped), Estimator(able_bodied, cfg, stamped=stamped)
    assert batch_supported(b)
    ref = streamed(a, rec.time_s, rec.angles_deg, rec.index)
    got = run_batch(b, rec.time_s, rec.angles_deg, rec.index)
    assert got is not None and got.held.any() and (got.mode_index != got.raw_mode_index).any()
    assert_identical(ref, got)
    assert_same_state(a, b)


TABLE = "Med: [Slow, RA]\n  RD: [Fast]"
"""Allowed transitions that change the reported mode of both recordings and leave confident strides."""
SUPERVISED = {
    "dwell": {"min_dwell_s": 0.3},
    "confidence": {"min_confidence": 0.05},
    "switch-back": {"switch_back_margin": 0.3},
    "transitions": {"transitions": TABLE},
    "all": {"min_confidence": 0.02, "min_dwell_s": 0.08, "switch_back_margin": 0.1, "transitions": TABLE},
}


@pytest.mark.parametrize("setting", SUPERVISED)
@pytest.mark.parametrize("stamped", [True, False], ids=["resampled", "not-resampled"])
@pytest.mark.parametrize("name", ["Multispeed_Walk_AB.csv", "LG_2_Ramp_AB_Sample.csv"])
def test_bulk_equals_streaming_with_the_supervisor_and_the_walking_calibrations(swge: Path, able_bodied, tmp_path: Path,
                                                                               setting, stamped, name) -> None:
    """Each supervisor option with the walking calibrations acting (default preset): the supervisor
    decides inside the compiled steps and the calibrations follow its reported mode and phase, bit
    for bit as sample by sample."""
    options = dict(SUPERVISED[setting])
    if "transitions" in options:
        table = tmp_path / "transitions.yaml"
        table.write_text(f"allowed_transitions:\n  {options['transitions']}")
        options["transitions"] = str(table)
    cfg = EstimatorConfig.preset("default", **options)
    rec = read_recording(swge / "recordings" / name)
    a, b = Estimator(able_bodied, cfg, stamped=stamped), Estimator(able_bodied, cfg, stamped=stamped)
    assert batch_supported(b) and b.calibration.active and not b.supervisor.passes_through
    ref = streamed(a, rec.time_s, rec.angles_deg, rec.index)
    got = run_batch(b, rec.time_s, rec.angles_deg, rec.index)
    assert got is not None
    assert_identical(ref, got)
    assert_same_state(a, b)
    assert b.calibration.strides >= 3  # the calibrations acted
    assert (got.mode_index != got.raw_mode_index).any()  # and the supervisor


def test_bulk_in_short_chunks_carries_the_supervisor_and_the_tracker(multispeed_csv: Path, able_bodied, tmp_path: Path,
                                                                      monkeypatch) -> None:
    """Every option on and the steps cut every 37 (``CHUNK_VALUES``): the supervisor's memory and
    the stride tracker go on from one compiled call to the next as sample by sample."""
    monkeypatch.setattr(batch, "CHUNK_VALUES", 37 * len(able_bodied))
    options = dict(SUPERVISED["all"])
    table = tmp_path / "transitions.yaml"
    table.write_text(f"allowed_transitions:\n  {options['transitions']}")
    cfg = EstimatorConfig.preset("default", **{**options, "transitions": str(table)})
    rec = read_recording(multispeed_csv)
    a, b = Estimator(able_bodied, cfg), Estimator(able_bodied, cfg)
    ref = streamed(a, rec.time_s, rec.angles_deg, rec.index)
    got = run_batch(b, rec.time_s, rec.angles_deg, rec.index)
    assert got is not None
    assert_identical(ref, got)
    assert_same_state(a, b)
    assert b.calibration.strides >= 3 and (got.mode_index != got.raw_mode_index).any()


def test_bulk_reads_the_reported_near_copy_at_stride_ends(multispeed_csv: Path, able_bodied, tmp_path: Path) -> None:
    """Transitions that allow only the near copies of the library's modes (``replicated``): the
    calibrations read strides of a reported mode that is not the matcher's best (its near copy),
    at the reported mode's kernel column, in bulk as sample by sample."""
    lib = able_bodied.replicated(2 * len(able_bodied))
    copies = [m for m in lib.mode_names if m not in able_bodied.mode_names]
    table = tmp_path / "transitions.yaml"
    table.write_text("allowed_transitions:\n" + "".join(f"  {m}: [{', '.join(copies)}]\n" for m in lib.mode_names))
    cfg = EstimatorConfig.preset("default", transitions=str(table))
    rec = read_recording(multispeed_csv)
    a, b = Estimator(lib, cfg), Estimator(lib, cfg)
    assert a.calibration.near_copies is not None
    ref = streamed(a, rec.time_s, rec.angles_deg, rec.index)
    got = run_batch(b, rec.time_s, rec.angles_deg, rec.index)
    assert got is not None
    assert_identical(ref, got)
    assert_same_state(a, b)
    assert b.calibration.strides >= 3 and (got.mode_index != got.raw_mode_index).mean() > 0.3


def test_bulk_continues_a_stream_and_restarts_at_gaps(multispeed_csv: Path, able_bodied) -> None:
    """A stream in pieces, with a gap that restarts the window (> max_gap_s) and one that also
    forgets the calibrations (> calibration_reset_gap_s), at an irregular rate: the same as
    streaming it, whichever path each piece takes."""
    rec = read_recording(multispeed_csv)
    rng = np.random.default_rng(5)
    t = rec.time_s[:9000] + np.cumsum(rng.uniform(-0.3, 0.3, 9000)) / 230.0 * 0.2
    t[4000:] += 2.0
    t[7000:] += 8.0
    x, idx = rec.angles_deg[:9000], rec.index[:9000]
    a, b = Estimator(able_bodied), Estimator(able_bodied)
    ref = streamed(a, t, x, idx)
    parts = [run_batch(b, t[:2500], x[:2500], idx[:2500]), streamed(b, t[2500:2600], x[2500:2600], idx[2500:2600]),
             run_batch(b, t[2600:], x[2600:], idx[2600:])]
    got = EstimateTrace(ref.mode_names, *(np.concatenate([getattr(p, f.name) for p in parts])
                                          for f in fields(EstimateTrace)[1:]))
    assert_identical(ref, got)
    assert b.resets == 2 and b.calibration_resets == 1
    assert_same_state(a, b)


def test_bulk_hands_back_what_it_cannot_do(multispeed_csv: Path, able_bodied) -> None:
    """Options the bulk path does not cover (personalisation) and bad input take the streaming
    path: same results, the same error at the same sample."""
    rec = read_recording(multispeed_csv)
    t, x = rec.time_s[:1500], rec.angles_deg[:1500].copy()
    adapting = EstimatorConfig.preset("default", adapt_rate=0.1)
    assert not batch_supported(Estimator(able_bodied, adapting))
    assert run_batch(Estimator(able_bodied, adapting), t, x, rec.index[:1500]) is None
    x[1200, 2] = np.nan
    assert run_batch(Estimator(able_bodied), t, x, rec.index[:1500]) is None
    est = Estimator(able_bodied)
    with pytest.raises(ValueError, match="non-finite"):
        run_estimator(est, t, x)
    assert est.matcher.steps > 1000  # streamed up to the bad sample


@pytest.mark.parametrize("options", [{}, {"min_dwell_s": 0.3}], ids=["matcher-reports", "supervisor-reports"])
def test_bulk_equals_the_threaded_float32_step_of_large_libraries(multispeed_csv: Path, able_bodied, options) -> None:
    """From PARALLEL_MIN_ROWS rows on, both paths read float32 kernels and spread the rows over
    threads (when the process has more than one CPU): the same results as on one thread, with the
    supervisor's step inside the compiled steps or after them."""
    lib = able_bodied.replicated(70)  # >= PARALLEL_MIN_ROWS rows at one time scale
    rec = read_recording(multispeed_csv)
    t, x, idx = rec.time_s[:1600], rec.angles_deg[:1600], rec.index[:1600]
    cfg = EstimatorConfig.preset("default", **options)
    a, b, one = Estimator(lib, cfg), Estimator(lib, cfg), Estimator(lib, cfg)
    assert a.matcher._kernels.dtype == np.float32
    one.matcher.parallel = False
    one.matcher.set_scale_band(one.matcher.scale_band, one.calibration.params.scale_search_modes)  # the same band,
    # and the one-thread step
    assert one.matcher._compiled_step is compiled.step_rows
    bulk = run_batch(b, t, x, idx)
    assert_identical(streamed(a, t, x, idx), bulk)
    assert_identical(run_batch(one, t, x, idx), bulk)
    if b.matcher.parallel:  # the bulk path ran the threaded steps
        assert (SUPERVISED_STEPS[1] if options else compiled.run_steps_parallel).signatures
