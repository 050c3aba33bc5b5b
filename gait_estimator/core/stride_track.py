"""The walking calibrations' stride tracker rule, written once: ``WalkingCalibration`` runs it on
Python floats sample by sample, the compiled bulk steps (``compiled.run_steps``) compiled."""

from __future__ import annotations


def stride_step(same: bool, last_phase: float, last_passed_mid: bool, last_began_in_mode: bool, phase: float,
                mid_stride: tuple[float, float]) -> tuple[bool, bool, bool]:
    """One reported ``phase`` of the stride tracker, ``same``: the previous sample was known and
    reported the same mode (or a near copy) at ``last_phase``. Returns (ends, passed_mid,
    began_in_mode): whether this sample is a heel strike (the phase wrapped) that ends a stride
    of that mode from the previous heel strike on whose phase passed mid-stride (``mid_stride``
    = [lo, hi)), and the tracker's flags after it. A phase that flickers across the wrap (0.99,
    0.01, 0.99, ...) ends one stride, not one per flicker."""
    wrapped = same and phase < last_phase - 0.5
    passed_mid = same and last_passed_mid
    whole = same and last_began_in_mode
    lo, hi = mid_stride
    midway = lo <= phase < hi or (passed_mid and not wrapped)
    return wrapped and whole and passed_mid, midway, wrapped or whole
