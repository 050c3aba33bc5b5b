"""Turning a stream of driver messages into matcher samples, ROS-free.

Shared by the live node and offline bag processing so both treat input identically:

* ``angles_from_named`` / ``angles_from_array`` extract the four angles (degrees, CHANNELS order)
  from the fields of a ``sensor_msgs/JointState`` or ``std_msgs/Float64MultiArray``, raising
  ``SampleRejected`` with a reason code for bad input (including finite but absurd angles,
  ``out_of_range``, which would otherwise swamp the matcher's running sums);
* the stamp rules and reason codes are ``core/stamps.py``'s (re-exported here).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..core.channels import CHANNELS, N_CHANNELS, Sample, sample_values
from ..core.rejections import MISSING_JOINT, NON_FINITE, OUT_OF_RANGE, WRONG_LENGTH, SampleRejected

UNITS = ("rad", "deg")
INPUT_TYPES = ("joint_state", "float64_multi_array", "imu")  # imu: four sensor_msgs/Imu (io/imu_stream.py)

MAX_ABS_ANGLE_DEG = 1.0e4
"""Largest accepted |angle| (degrees, after unit conversion). Far beyond any segment angle, far
below values whose squares would swamp the matcher's running sums (or overflow to inf)."""


def _to_degrees(values: np.ndarray, units: str) -> np.ndarray:
    if not np.isfinite(values).all():
        raise SampleRejected(NON_FINITE, f"non-finite angle(s) {values.tolist()}")
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
    return _to_degrees(np.array([positions[index[j]] for j in joint_names], dtype=np.float64), units)


def angles_from_array(data: Sequence[float], units: str = "rad") -> np.ndarray:
    """Angles (4,), degrees, from ``[right_thigh, left_thigh, right_shank, left_shank]``."""
    if len(data) != N_CHANNELS:
        raise SampleRejected(WRONG_LENGTH, f"expected {N_CHANNELS} values, got {len(data)}")
    return _to_degrees(np.array(data, dtype=np.float64), units)


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
