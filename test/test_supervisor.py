"""Supervisor.decide_many, the bulk form of Supervisor.decide: the same decision, field by field."""

from __future__ import annotations

import itertools
import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.core.matcher import IncrementalMatcher, StepBlock, StepResult
from gait_estimator.core.supervisor import Estimate, Supervisor, SupervisorParams, carry_forward
from gait_estimator.io.readers import read_recording


def block_of(results: list[StepResult], mode_names: list[str], n_scales: int) -> StepBlock:
    """The matcher results as the compiled steps give them in bulk."""
    block = StepBlock.empty(mode_names, n_scales, len(results))
    for g, r in enumerate(results):
        b = r.mode_index
        block.sse[g], block.phases[g], block.best[g], block.ready[g] = r.sse, r.phases, b, r.ready
        block.variant[g] = 0 if r.variant is None else r.variant[b]
        block.column[g], block.window[g] = r.column[b], r.window[b]
    return block


@pytest.mark.parametrize("scales", [(1.0,), (0.9, 1.0, 1.1)], ids=["one-scale", "three-scales"])
def test_decide_many_equals_decide(multispeed_csv: Path, able_bodied, scales) -> None:
    """In runs of any length (the phase-rate state carried from one to the next), every field of
    every estimate and the state left behind equal decide's, sample by sample."""
    rec = read_recording(multispeed_csv)
    matcher = IncrementalMatcher(able_bodied, time_scales=scales)
    results = [matcher.step(rec.angles_deg[i]) for i in range(2600)]
    t = rec.time_s[:2600].astype(np.float64)
    t[1500:] += 0.3  # a longer interval: another smoothing weight
    args = (able_bodied.mode_names, SupervisorParams(), None, matcher.active_channels, False, matcher.time_scales)
    one, many = Supervisor(*args), Supervisor(*args)
    ref = [one.decide(float(t[g]), r) for g, r in enumerate(results)]
    block = block_of(results, able_bodied.mode_names, matcher.n_scales)
    cuts = [0, 1, 700, 700, 1501, 2600]
    parts = [many.decide_many(t[a:b], block.rows(a, b)) for a, b in itertools.pairwise(cuts)]
    got = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    assert np.isfinite(got["phase_rate"][-1]) and np.isfinite(got["cadence_ratio"]).all() == (len(scales) > 1)
    for f in fields(Estimate):
        if f.name == "mode":
            assert [able_bodied.mode_names[m] for m in got["mode_index"]] == [e.mode for e in ref]
            continue
        if f.name == "state":  # the state stage's (states.py; test_batch.py)
            assert {e.state for e in ref} == {1}
            continue
        want = np.array([getattr(e, f.name) for e in ref])
        np.testing.assert_array_equal(got[f.name], want, err_msg=f.name)
    assert (many._last, many._current, many._pending) == (one._last, one._current, one._pending)
    assert many._rate == one._rate


def test_carry_forward_is_estimate_at(multispeed_csv: Path, able_bodied) -> None:
    rec = read_recording(multispeed_csv)
    matcher = IncrementalMatcher(able_bodied)
    sup = Supervisor(able_bodied.mode_names, active_channels=matcher.active_channels)
    results = [matcher.step(rec.angles_deg[i]) for i in range(1200)]
    cols = sup.decide_many(rec.time_s[:1200], block_of(results, able_bodied.mode_names, 1))
    later = cols["time_s"] + np.where(np.arange(1200) % 3 == 0, 0.0, 0.004)
    got = carry_forward(cols, later)
    for g in range(0, 1200, 7):
        want = Estimate.from_columns(cols, g, able_bodied.mode_names).at(float(later[g]))
        assert (got["time_s"][g], got["phase"][g]) == (want.time_s, want.phase)


def test_decide_many_only_passes_the_matcher_choice_through(able_bodied) -> None:
    """Holds, dwell and transitions have state per sample: decide alone does them."""
    held = Supervisor(able_bodied.mode_names, SupervisorParams(min_confidence=0.1))
    assert not held.passes_through and Supervisor(able_bodied.mode_names).passes_through
    with pytest.raises(ValueError, match="min_confidence"):
        held.decide_many(np.zeros(1), StepBlock.empty(able_bodied.mode_names, 1, 1))
    assert math.isnan(held._rate)
