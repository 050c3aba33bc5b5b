"""Turning a stream of driver messages into matcher samples, ROS-free.

Shared by the live node and offline bag processing so both treat input identically:

* ``angles_from_named`` / ``angles_from_array`` extract the four angles (degrees, CHANNELS order)
  from the fields of a ``sensor_msgs/JointState`` or ``std_msgs/Float64MultiArray``, raising
  ``SampleRejected`` with a reason code for bad input (including finite but absurd angles,
  ``out_of_range``, which would otherwise swamp the matcher's running sums);
* ``StreamGuard`` checks time stamps (non-increasing -> rejected; a gap longer than
  ``max_gap_s`` -> the matcher window must restart; optionally, a jump back by more than
  ``restart_back_s`` -> a restarted stream, the window must restart too) and counts rejections by
  reason.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..core.channels import CHANNELS, N_CHANNELS, Sample, sample_values
from ..core.options import EstimatorConfig

UNITS = ("rad", "deg")
INPUT_TYPES = ("joint_state", "float64_multi_array", "imu")  # imu: four sensor_msgs/Imu (io/imu_stream.py)

# Reason codes, as counted in diagnostics and summaries.
NON_FINITE = "non_finite"
MISSING_JOINT = "missing_joint"
WRONG_LENGTH = "wrong_length"
NON_INCREASING_STAMP = "non_increasing_stamp"
OUT_OF_RANGE = "out_of_range"
MALFORMED = "malformed"  # bytes that do not decode as the input message type (live streams)
REASONS = (NON_FINITE, MISSING_JOINT, WRONG_LENGTH, NON_INCREASING_STAMP, OUT_OF_RANGE, MALFORMED)
ANGLE_MESSAGE_ONLY = (MISSING_JOINT, WRONG_LENGTH)
"""Reasons only a segment-angle message gives (not the IMU input)."""

STREAM_RESTART_S = 1.0
"""Jump back (s) that restarts a live stream when ``max_gap_s`` is 0 (gap check off); see
``restart_threshold``."""

MAX_ABS_ANGLE_DEG = 1.0e4
"""Largest accepted |angle| (degrees, after unit conversion). Far beyond any segment angle, far
below values whose squares would swamp the matcher's running sums (or overflow to inf)."""


class SampleRejected(ValueError):
    """A message that cannot become a sample; ``reason`` is one of REASONS."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


def _to_degrees(values: np.ndarray, units: str) -> np.ndarray:
    if units == "rad":
        deg = np.degrees(values)
    elif units == "deg":
        deg = values
    else:
        raise ValueError(f"units must be one of {UNITS}, got {units!r}")
    if not (np.abs(deg) <= MAX_ABS_ANGLE_DEG).all():
        raise SampleRejected(OUT_OF_RANGE, f"angle(s) {values.tolist()} {units} beyond +-{MAX_ABS_ANGLE_DEG:g} deg")
    return deg


def angles_from_named(
    names: Sequence[str], positions: Sequence[float], joint_names: Sequence[str] = CHANNELS, units: str = "rad"
) -> np.ndarray:
    """Angles (4,), degrees, from JointState-style ``name``/``position`` fields.

    ``joint_names`` gives the names of right_thigh, left_thigh, right_shank, left_shank in that
    order; other joints in the message are ignored and the message order does not matter.
    """
    if len(names) != len(positions):
        raise SampleRejected(WRONG_LENGTH, f"{len(names)} names but {len(positions)} positions")
    index = {n: i for i, n in enumerate(names)}
    missing = [j for j in joint_names if j not in index]
    if missing:
        raise SampleRejected(MISSING_JOINT, f"missing joint(s) {', '.join(missing)} (got {', '.join(names) or 'none'})")
    values = np.array([positions[index[j]] for j in joint_names], dtype=np.float64)
    if not np.isfinite(values).all():
        raise SampleRejected(NON_FINITE, f"non-finite angle(s) {values.tolist()}")
    return _to_degrees(values, units)


def angles_from_array(data: Sequence[float], units: str = "rad") -> np.ndarray:
    """Angles (4,), degrees, from ``[right_thigh, left_thigh, right_shank, left_shank]``."""
    if len(data) != N_CHANNELS:
        raise SampleRejected(WRONG_LENGTH, f"expected {N_CHANNELS} values, got {len(data)}")
    values = np.array(data, dtype=np.float64)
    if not np.isfinite(values).all():
        raise SampleRejected(NON_FINITE, f"non-finite angle(s) {values.tolist()}")
    return _to_degrees(values, units)


_DEG_PER_RAD = 180.0 / math.pi


class AngleExtractor:
    """``angles_from_named`` / ``angles_from_array`` for a live stream, with the same results
    and the same rejections, in a few microseconds: the index of each joint in the message is
    kept while the message's names stay the same, and the common case (4 finite angles in range)
    takes no loop and no numpy call. Anything unusual goes through the reference functions, which
    raise the proper SampleRejected. Returns the angles as four floats, degrees, CHANNELS order
    (equal to the reference functions' array).

    Args:
        joint_names: Names of right_thigh, left_thigh, right_shank, left_shank (CHANNELS order).
        units: Input units, ``rad`` or ``deg``.
    """

    def __init__(self, joint_names: Sequence[str] = CHANNELS, units: str = "rad") -> None:
        if units not in UNITS:
            raise ValueError(f"units must be one of {UNITS}, got {units!r}")
        self.joint_names = tuple(joint_names)
        self.units = units
        # |value| limit in input units, a little inside MAX_ABS_ANGLE_DEG so that the exact check
        # (after conversion) decides every borderline value
        self._limit = MAX_ABS_ANGLE_DEG * (0.999 * math.pi / 180.0 if units == "rad" else 0.999)
        self._names: list[str] | None = None
        self._index: tuple[int, int, int, int] = (0, 1, 2, 3)

    def named(self, names: Sequence[str], positions: Sequence[float]) -> Sample:
        """Same as ``angles_from_named(names, positions, joint_names, units)``."""
        if names != self._names:
            values = sample_values(angles_from_named(names, positions, self.joint_names, self.units))  # raises if bad
            index = {n: i for i, n in enumerate(names)}
            i0, i1, i2, i3 = (index[j] for j in self.joint_names)
            self._index = (i0, i1, i2, i3)
            self._names = list(names)
            return values
        i0, i1, i2, i3 = self._index
        lim = self._limit
        if len(positions) == len(names):
            a, b, c, d = positions[i0], positions[i1], positions[i2], positions[i3]
            if -lim < a < lim and -lim < b < lim and -lim < c < lim and -lim < d < lim:  # False for nan/inf
                return self._convert(a, b, c, d)
        return sample_values(angles_from_named(names, positions, self.joint_names, self.units))  # raises if bad

    def array(self, data: Sequence[float]) -> Sample:
        """Same as ``angles_from_array(data, units)``."""
        lim = self._limit
        if len(data) == N_CHANNELS:
            a, b, c, d = data
            if -lim < a < lim and -lim < b < lim and -lim < c < lim and -lim < d < lim:
                return self._convert(a, b, c, d)
        return sample_values(angles_from_array(data, self.units))  # raises if bad

    def _convert(self, a: float, b: float, c: float, d: float) -> Sample:
        if self.units == "rad":  # bit for bit what np.degrees gives (tested)
            return a * _DEG_PER_RAD, b * _DEG_PER_RAD, c * _DEG_PER_RAD, d * _DEG_PER_RAD
        return float(a), float(b), float(c), float(d)


def restart_threshold(max_gap_s: float) -> float:
    """How far (s) stamps must jump back to count as a restarted stream rather than a reordered or
    duplicated sample: ``max_gap_s`` (the same discontinuity that restarts the window going
    forward), or STREAM_RESTART_S while the gap check is off (``max_gap_s`` 0 or inf)."""
    return max_gap_s if 0 < max_gap_s < math.inf else STREAM_RESTART_S


@dataclass
class StreamGuard:
    """Stamp checks and rejection counts for one input stream.

    Args:
        max_gap_s: A gap between accepted samples longer than this (seconds) means the window
            must restart (``accept`` returns True, counted in ``resets``); <= 0 or inf disables
            the check.
        restart_back_s: A stamp more than this (seconds) before the previous accepted one is a
            restarted stream (a publisher that restarted its clock, a clock jump back): the
            sample is accepted and the window must restart (``accept`` returns True, counted in
            ``restarts``). A smaller step back, or any step back while this is <= 0, is a
            reordered or duplicated sample: rejected (non_increasing_stamp).
    """

    max_gap_s: float = EstimatorConfig.max_gap_s
    restart_back_s: float = 0.0
    rejected: Counter = field(default_factory=Counter)
    last_detail: dict[str, str] = field(default_factory=dict)
    """The latest rejection's text, by reason."""
    _reported: Counter = field(default_factory=Counter, repr=False)
    accepted: int = 0
    resets: int = 0
    restarts: int = 0
    last_stamp: float | None = None

    def check_stamp(self, stamp_s: float) -> bool:
        """Validate the stamp of the next sample; True if the matcher must be reset first.

        Raises SampleRejected (non_increasing_stamp, non_finite) without changing state.
        """
        if not math.isfinite(stamp_s):
            raise SampleRejected(NON_FINITE, f"non-finite stamp {stamp_s}")
        last = self.last_stamp
        if last is None:
            return False
        if stamp_s <= last:
            if 0 < self.restart_back_s < last - stamp_s:
                return True
            raise SampleRejected(NON_INCREASING_STAMP, f"stamp {stamp_s:.6f} s is not after the previous {last:.6f} s")
        return 0 < self.max_gap_s < math.inf and stamp_s - last > self.max_gap_s

    def accept(self, stamp_s: float) -> bool:
        """Record an accepted sample at ``stamp_s``; True if the window must restart before it
        (a gap, counted in ``resets``, or a jump back, counted in ``restarts``)."""
        last = self.last_stamp
        reset = self.check_stamp(stamp_s)
        if reset and last is not None and stamp_s <= last:
            self.restarts += 1
        elif reset:
            self.resets += 1
        self.last_stamp = stamp_s
        self.accepted += 1
        return reset

    def reject(self, exc: SampleRejected) -> None:
        self.rejected[exc.reason] += 1
        self.last_detail[exc.reason] = str(exc)

    def main_rejection(self) -> str:
        """``reason: its latest detail`` of the most frequent rejection since the previous call
        ('' when none)."""
        new = self.rejected - self._reported
        self._reported = Counter(self.rejected)
        if not new:
            return ""
        reason = new.most_common(1)[0][0]
        return f"{reason}: {self.last_detail[reason]}"

    @property
    def rejected_total(self) -> int:
        return int(sum(self.rejected.values()))
