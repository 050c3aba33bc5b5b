"""ROS-free parts of the live input path: StreamGuard's stamp rules, AngleExtractor (the node's
fast angle extraction) against the reference functions, estimate_values against estimate_array."""

from __future__ import annotations

import array
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.estimator import Estimator
from gait_estimator.core.rejections import NON_INCREASING_STAMP, SampleRejected
from gait_estimator.core.stamps import STREAM_RESTART_S, StreamGuard, restart_threshold
from gait_estimator.io.outputs import estimate_array, estimate_names, estimate_values
from gait_estimator.io.stream import MAX_ABS_ANGLE_DEG, AngleExtractor, angles_from_array, angles_from_named


def test_stamps_going_back_small_steps_rejected_big_jumps_restart() -> None:
    g = StreamGuard(max_gap_s=0.0, restart_back_s=0.5)
    assert g.accept(10.0) is False
    assert g.accept(10.01) is False
    for stamp in (10.01, 10.0, 9.6, 9.51):  # equal, and back by up to 0.5 s: reordering
        with pytest.raises(SampleRejected) as info:
            g.accept(stamp)
        assert info.value.reason == NON_INCREASING_STAMP
    assert g.check.last_time == 10.01
    assert g.accept(9.5) is True  # back by 0.51 s: a restarted stream, accepted
    assert (g.restarts, g.resets, g.check.last_time) == (1, 0, 9.5)
    assert g.accept(9.51) is False and g.accept(100.0) is False  # gap check off (max_gap_s 0)
    assert g.accept(0.0) is True and g.restarts == 2


def test_gap_forward_and_restart_back_are_counted_apart() -> None:
    g = StreamGuard(max_gap_s=0.5, restart_back_s=0.5)
    g.accept(1.0)
    assert g.accept(2.0) is True and (g.resets, g.restarts) == (1, 0)
    assert g.accept(0.0) is True and (g.resets, g.restarts) == (1, 1)


def test_without_restart_back_every_step_back_is_rejected() -> None:
    g = StreamGuard(max_gap_s=0.5)  # offline bag reading: no restarts
    g.accept(100.0)
    with pytest.raises(SampleRejected):
        g.accept(1.0)
    assert g.restarts == 0


def test_restart_threshold() -> None:
    assert restart_threshold(0.5) == 0.5
    assert restart_threshold(0.0) == STREAM_RESTART_S
    assert restart_threshold(math.inf) == STREAM_RESTART_S


def _reference(names, positions, joint_names, units):
    try:
        return angles_from_named(names, positions, joint_names, units), None
    except SampleRejected as exc:
        return None, exc.reason


def _fast(ex, names, positions):
    try:
        return ex.named(names, positions), None
    except SampleRejected as exc:
        return None, exc.reason


special = st.sampled_from([math.nan, math.inf, -math.inf, 0.0, MAX_ABS_ANGLE_DEG, -MAX_ABS_ANGLE_DEG,
                           math.radians(MAX_ABS_ANGLE_DEG), math.radians(MAX_ABS_ANGLE_DEG) * (1 + 1e-15),
                           MAX_ABS_ANGLE_DEG * (1 + 1e-15), 1e6])
value = st.one_of(st.floats(-200.0, 200.0), special)


@settings(max_examples=300, deadline=None)
@given(
    units=st.sampled_from(["rad", "deg"]),
    messages=st.lists(
        st.tuples(
            st.permutations([*CHANNELS, "ankle"]).map(list),
            st.lists(value, min_size=5, max_size=5),
            st.sampled_from(["ok", "drop_joint", "short_positions", "rename"]),
        ),
        min_size=1,
        max_size=6,
    ),
)
def test_angle_extractor_equals_the_reference(units, messages) -> None:
    """Same values and the same rejection reasons, message after message (the names cache)."""
    ex = AngleExtractor(CHANNELS, units)
    for names, values, change in messages:
        if change == "drop_joint":
            names = names[1:]
            values = values[1:]
        elif change == "short_positions":
            values = values[:-1]
        elif change == "rename":
            names = [n.replace("left_shank", "left_shin") for n in names]
        positions = array.array("d", values)
        ref, ref_reason = _reference(names, positions, CHANNELS, units)
        got, got_reason = _fast(ex, names, positions)
        assert got_reason == ref_reason
        if ref is not None:
            assert type(got) is tuple and all(type(v) is float for v in got)
            np.testing.assert_array_equal(got, ref)  # bit for bit
        if len(values) == 4:
            try:
                ref_a = angles_from_array(positions, units)
            except SampleRejected as exc:
                with pytest.raises(SampleRejected) as info:
                    ex.array(positions)
                assert info.value.reason == exc.reason
            else:
                np.testing.assert_array_equal(ex.array(positions), ref_a)


def test_angle_extractor_other_joint_names_and_array_lengths() -> None:
    ex = AngleExtractor(["a", "b", "c", "d"], "deg")
    np.testing.assert_array_equal(ex.named(["d", "c", "b", "a"], [4.0, 3.0, 2.0, 1.0]), [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(ex.named(["d", "c", "b", "a"], [8.0, 7.0, 6.0, 5.0]), [5.0, 6.0, 7.0, 8.0])
    for data in ([1.0, 2.0, 3.0], [1.0, 2.0, 3.0, 4.0, 5.0], []):
        with pytest.raises(SampleRejected) as info:
            ex.array(data)
        assert info.value.reason == "wrong_length"
    with pytest.raises(ValueError):
        AngleExtractor(CHANNELS, "grad")


def test_estimate_values_equal_estimate_array(able_bodied) -> None:
    est = Estimator(able_bodied)
    rng = np.random.default_rng(3)
    x = able_bodied.modes[0].samples
    for i in range(int(able_bodied.lengths.max()) + 30):
        e = est.update(i / 230.0, x[i % len(x)] + rng.normal(0, 0.5, 4))
        assert len(estimate_values(e)) == len(estimate_names(able_bodied.mode_names))
        np.testing.assert_array_equal(np.array(estimate_values(e), dtype=np.float64), estimate_array(e))
