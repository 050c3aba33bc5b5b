"""The stamp rule (core/gaps.py): the bulk form equals the per-stamp one; stamps in nanoseconds;
a restart confirmed by a second message."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gait_estimator.core.gaps import JUMPED_BACK, NO_GAP, GapCheck, GapParams
from gait_estimator.core.rejections import NON_FINITE, NON_INCREASING_STAMP, SampleRejected


@pytest.mark.parametrize("seed", range(20))
def test_admit_many_equals_admit_stamp_on_random_stamps(seed: int) -> None:
    rng = np.random.default_rng(seed)
    params = GapParams(*(float(v) if rng.random() < 0.8 else 0.0 for v in rng.uniform(0.01, 0.5, 2)))
    steps = np.where(rng.random(300) < 0.05, rng.uniform(0.0, 1.0, 300), rng.uniform(1e-4, 0.02, 300))
    t = np.cumsum(steps) + rng.uniform(-5.0, 5.0)
    one, many = GapCheck(params), GapCheck(params)
    if seed % 2:  # a stream that went on before
        one.admit_stamp(t[0] - steps[0])
        many.admit_stamp(t[0] - steps[0])
    verdicts = [one.admit_stamp(float(s)) for s in t]
    restart, reset = many.admit_many(t)
    assert restart.tolist() == [v.restart_window for v in verdicts]
    assert reset.tolist() == [v.reset_calibration for v in verdicts]
    assert (restart | reset).any() and (NO_GAP in verdicts)
    assert many.last_time == one.last_time


def test_stamps_in_nanoseconds_are_compared_exactly() -> None:
    check = GapCheck(GapParams(0.5, 0.0, 1.0), per_second=1e9)
    base = 1_700_000_000 * 1_000_000_000
    assert check.admit_stamp(base) is NO_GAP and check.admit_stamp(base + 1) is NO_GAP  # 1 ns apart
    assert check.admit_stamp(base + 500_000_002).restart_window  # more than 0.5 s
    with pytest.raises(SampleRejected, match="is not after the previous"):
        check.admit_stamp(base + 500_000_002)
    assert check.admit_stamp(base - 600_000_000) is JUMPED_BACK  # more than 1 s back
    with pytest.raises(SampleRejected) as err:
        check.admit_stamp(math.nan)
    assert err.value.reason == NON_FINITE


def test_a_restart_needs_a_second_stamp_after_the_first_when_confirmed() -> None:
    check = GapCheck(GapParams(0.0, 0.0, 1.0), confirm_restart=True)
    check.admit_stamp(50.0)
    for stray in (10.0, 9.0):  # far back, but not after the one before: still stray
        with pytest.raises(SampleRejected, match="a restart"):
            check.admit_stamp(stray)
    assert check.admit_stamp(9.005) is JUMPED_BACK and check.last_time == 9.005
    check.admit_stamp(9.01)
    with pytest.raises(SampleRejected):
        check.admit_stamp(1.0)
    check.admit_stamp(9.02)  # a later stamp forgets the candidate
    with pytest.raises(SampleRejected) as err:
        check.admit_stamp(1.5)
    assert err.value.reason == NON_INCREASING_STAMP and check.last_time == 9.02
