"""Supervisor.decide, Supervisor.decide_many and Supervisor.step_hook (supervise_step on Python floats, compiled,
and inside the compiled matcher steps): the same decision, field by field, under every option."""

from __future__ import annotations

import itertools
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.core import compiled
from gait_estimator.core.matcher import IncrementalMatcher, StepBlock, StepResult
from gait_estimator.core.supervisor import (
    Estimate,
    Supervisor,
    SupervisorParams,
    carry_forward,
    second_smallest,
    switch_candidate,
    transitions_matrix,
)
from gait_estimator.io.readers import read_recording


def block_of(results: list[StepResult], mode_names: list[str], n_scales: int) -> StepBlock:
    """The matcher results as the compiled steps give them in bulk."""
    block = StepBlock.empty(mode_names, n_scales, len(results))
    for g, r in enumerate(results):
        b = r.mode_index
        block.sse[g], block.phases[g], block.best[g], block.ready[g] = r.sse, r.phases, b, r.ready
        block.variant[g] = 0 if r.variant is None else r.variant
        block.column[g], block.window[g] = r.column[b], r.window
    return block


SETTINGS = {
    "off": {},
    "confidence": {"min_confidence": 0.05},
    "dwell": {"min_dwell_s": 0.15},
    "switch-back": {"switch_back_margin": 0.3},
    "all": {"min_confidence": 0.02, "min_dwell_s": 0.08, "switch_back_margin": 0.1,
            "transitions": {"Slow": ["Med"], "Fast": ["Med"]}},
}


def decided_inside_steps(sup: Supervisor, matcher: IncrementalMatcher, t: np.ndarray, x: np.ndarray,
                         cuts: list[int]) -> tuple[list[dict[str, np.ndarray]], np.ndarray]:
    """``sup``'s columns decided inside the compiled matcher steps (``Supervisor.step_hook``), in
    runs between ``cuts``; and the kernel column the steps kept per step."""
    d, sq = matcher.weighted_samples(x)
    block = StepBlock.empty(matcher.mode_names, matcher.n_scales, t.size)
    hook, parts = sup.step_hook(t), []
    for a, b in itertools.pairwise(cuts):
        g = a
        while g < b:  # the steps stop at resynchronisations
            g, _ = matcher.run_steps(d, sq, g, b, block, hook=hook)
        parts.append(sup.columns(hook, a, b, block.rows(a, b)))
    return parts, block.column


@pytest.mark.parametrize("where", ["after", "inside"], ids=["after-the-steps", "inside-the-steps"])
@pytest.mark.parametrize("setting", SETTINGS)
@pytest.mark.parametrize("scales", [(1.0,), (0.9, 1.0, 1.1)], ids=["one-scale", "three-scales"])
def test_decide_many_equals_decide(multispeed_csv: Path, able_bodied, scales, setting, where) -> None:
    """In runs of any length (the state carried from one to the next), every field of every
    estimate and the state left behind equal decide's, sample by sample, under each option:
    decided after the compiled matcher steps (``decide_many``) or inside them (``step_hook``)."""
    if where == "inside" and not compiled.AVAILABLE:
        pytest.skip("the compiled steps need numba")
    rec = read_recording(multispeed_csv)
    matcher = IncrementalMatcher(able_bodied, time_scales=scales)
    results = [matcher.step(rec.angles_deg[i]) for i in range(5200)]
    t = rec.time_s[:5200].astype(np.float64)
    t[1500:] += 0.3  # a longer interval: another smoothing weight
    options = dict(SETTINGS[setting])
    table = options.pop("transitions", None)
    allowed = None if table is None else transitions_matrix(table, able_bodied.mode_names)
    args = (able_bodied.mode_names, SupervisorParams(**options), allowed, matcher.active_channels, False,
            matcher.time_scales)
    one, many = Supervisor(*args), Supervisor(*args)
    ref = [one.decide(float(t[g]), r) for g, r in enumerate(results)]
    block = block_of(results, able_bodied.mode_names, matcher.n_scales)
    cuts = [0, 1, 700, 700, 1501, 3333, 5200]
    if where == "inside":
        parts, kept = decided_inside_steps(many, IncrementalMatcher(able_bodied, time_scales=scales), t, rec.angles_deg[:5200],
                                           cuts)
    else:
        parts = [many.decide_many(t[a:b], block.rows(a, b)) for a, b in itertools.pairwise(cuts)]
    got = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    assert np.isfinite(got["phase_rate"][-1]) and np.isfinite(got["cadence_ratio"]).all() == (len(scales) > 1)
    supervised = got["mode_index"] != got["raw_mode_index"]
    assert supervised.any() == (setting != "off") and got["held"].any() == (setting != "off")
    for f in fields(Estimate):
        if f.name == "mode":
            assert [able_bodied.mode_names[m] for m in got["mode_index"]] == [e.mode for e in ref]
            continue
        if f.name == "state":  # the state stage's (states.py; test_batch.py)
            assert {e.state for e in ref} == {1}
            continue
        want = np.array([getattr(e, f.name) for e in ref])
        np.testing.assert_array_equal(got[f.name], want, err_msg=f.name)
    np.testing.assert_array_equal(np.array(many._mem), np.array(one._mem))  # nan == nan here
    if where == "inside":  # the column kept is the reported mode's: the one the walking calibrations read
        np.testing.assert_array_equal(kept, [r.column[m] for r, m in zip(results, got["mode_index"], strict=True)])


def test_second_smallest_is_what_a_partition_finds() -> None:
    rng = np.random.default_rng(3)
    cases = [rng.integers(0, 4, 7).astype(float) for _ in range(50)] + [
        np.array(v) for v in ([np.inf, np.inf], [np.nan, 1.0, 2.0], [1.0, np.nan], [np.nan, np.nan, 3.0], [-0.0, 0.0, 2.0])]
    for v in cases:
        np.testing.assert_array_equal(second_smallest(v), np.partition(v, 1)[1], err_msg=str(v))
    assert second_smallest(np.array([2.0])) == np.inf


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


def test_switch_candidate_needs_the_margin_only_to_go_back() -> None:
    errors = [10.0, 9.5, 7.5]  # current 0, previous 1
    assert switch_candidate(errors, 0, 1, 1, 0.1) == 0  # back to 1: 9.5 is not below 0.9 x 10
    assert switch_candidate(errors, 0, 1, 1, 0.04) == 1
    assert switch_candidate(errors, 0, 1, 2, 0.3) == 2  # a third mode: no margin
    assert switch_candidate(errors, 0, -1, 1, 0.3) == 1


def step(errors: list[float], ready: bool = True) -> StepResult:
    sse = np.asarray(errors)
    best = int(sse.argmin())
    return StepResult(best, str(best), 0.5, sse, np.full(sse.size, 0.5), ready, np.full(sse.size, 100))


def test_switch_back_margin_stops_two_close_modes_taking_turns() -> None:
    """Modes 0 and 1 within 5 % of each other, alternately best: off, every turn is reported;
    with a 0.1 margin the first change only, the kept mode flagged held. A change to mode 2 comes
    at the same sample either way, and a clear return (error 20 % lower) is not held back."""
    flicker = [[10.0, 10.5, 30.0], [10.5, 10.0, 30.0]] * 4
    seq = [step([10.0, 10.5, 30.0], ready=False)] + [step(e) for e in flicker]
    seq += [step(e) for e in ([10.0, 9.8, 9.0], [10.0, 9.8, 9.0], [12.0, 8.0, 10.0])]
    off, on = (Supervisor(["a", "b", "c"], SupervisorParams(switch_back_margin=m)) for m in (0.0, 0.1))
    got = {name: [sup.decide(0.01 * g, r) for g, r in enumerate(seq)] for name, sup in (("off", off), ("on", on))}
    modes = {name: [e.mode_index for e in ests] for name, ests in got.items()}
    assert modes["off"] == [0, 0, 1] + [0, 1] * 3 + [2, 2, 1]
    assert modes["on"] == [0, 0, 1, 1, 1, 1, 1, 1, 1, 2, 2, 1]
    assert [e.held for e in got["on"]] == [False] * 3 + [True, False] * 3 + [False] * 3
    assert not any(e.held for e in got["off"])
