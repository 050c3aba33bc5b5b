"""IMU -> global sagittal segment angle, ROS-free.

Frames and sign (the project's convention, as the recordings): a segment's angle is its
inclination from vertical in its own sagittal plane, degrees, + = distal end in front of the
proximal one (thigh flexed, ankle in front of the knee), 0 = segment vertical.

A sensor on the segment sees gravity; ``up`` is the world's up direction expressed in the sensor
frame (unit vector). From an orientation quaternion (world <- sensor, world z up as in REP 103 /
REP 145, ENU or NWU) ``up`` is the quaternion's rotation matrix' third row, so the heading (yaw,
drifting without a magnetometer) never enters. Without an orientation, ``up`` is the gravity
direction of a gyro + accelerometer fusion: the Fusion library's AHRS (``imufusion``), ported
in ``core/ahrs.py`` and compiled with numba when it is installed (extra ``imu``).

The mounting (``SegmentMount``) is three orthonormal sensor-frame axes: ``lateral`` (the sagittal
rotation axis, pointing to the wearer's right, so that a forward swing is a positive rotation by
the right-hand rule), ``proximal`` (along the segment towards the proximal joint) and ``forward``
(= proximal x lateral, anterior). Then::

    angle = standing_deg + atan2(forward . up, proximal . up)

``standing_deg`` is the angle the segment is taken to have in the standing pose (0 unless
configured). Mounts are configured (sensor axes such as ``+z``) or learnt (``core/imu_learn.py``).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .channels import CHANNELS, N_CHANNELS
from .errors import GaitEstimatorError

Vec3 = tuple[float, float, float]
STANDARD_GRAVITY = 9.80665
"""m/s^2 per g (sensor_msgs/Imu linear_acceleration is m/s^2)."""
_DEG = 180.0 / math.pi

AXES: dict[str, Vec3] = {
    "+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0),
}
"""Sensor axis names accepted in configured mounts."""


class CalibrationError(GaitEstimatorError):
    """A missing, malformed or unusable IMU mounting calibration (one line)."""


def parse_axis(text: str, what: str = "axis") -> Vec3:
    """``'+y'`` / ``'-x'`` / ``'z'`` -> unit vector in the sensor frame."""
    key = text.strip().lower()
    if key in ("x", "y", "z"):
        key = "+" + key
    if key not in AXES:
        raise CalibrationError(f"{what}: {text!r} is not a sensor axis (one of {', '.join(AXES)})")
    return AXES[key]


def _unit(v: Any, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    n = float(np.linalg.norm(a)) if a.shape == (3,) else math.nan
    if not (math.isfinite(n) and n > 1e-9):
        raise CalibrationError(f"{what}: {list(np.ravel(v))} is not a non-zero 3-vector")
    return a / n


@dataclass(frozen=True)
class SegmentMount:
    """How one IMU sits on its segment: sensor-frame unit axes (see the module docstring).

    Attributes:
        lateral: The sagittal rotation axis (wearer's right), sensor frame.
        proximal: Along the segment towards the proximal joint, sensor frame.
        standing_deg: Segment angle (deg) in the pose ``proximal`` was taken from.
        gyro_bias_dps: Gyro bias (deg/s, sensor frame) measured while standing; raw input only.
        source: ``configured`` or ``learnt``.
    """

    lateral: Vec3
    proximal: Vec3
    standing_deg: float = 0.0
    gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0)
    source: str = "configured"
    forward: Vec3 = field(init=False)

    def __post_init__(self) -> None:
        lat = _unit(self.lateral, "lateral axis")
        prox = _unit(self.proximal, "proximal axis")
        prox = prox - float(prox @ lat) * lat
        if np.linalg.norm(prox) < 0.5:
            raise CalibrationError("proximal axis is (nearly) parallel to the lateral axis")
        prox /= np.linalg.norm(prox)
        if not (math.isfinite(self.standing_deg) and abs(self.standing_deg) <= 90):
            raise CalibrationError(f"standing angle {self.standing_deg!r} deg is not within +-90")
        bias = np.asarray(self.gyro_bias_dps, dtype=np.float64)
        if bias.shape != (3,) or not np.isfinite(bias).all():
            raise CalibrationError(f"gyro bias {self.gyro_bias_dps!r} is not a finite 3-vector")
        object.__setattr__(self, "lateral", tuple(float(v) for v in lat))
        object.__setattr__(self, "proximal", tuple(float(v) for v in prox))
        object.__setattr__(self, "forward", tuple(float(v) for v in np.cross(prox, lat)))
        object.__setattr__(self, "gyro_bias_dps", tuple(float(v) for v in bias))
        object.__setattr__(self, "standing_deg", float(self.standing_deg))

    @classmethod
    def from_axes(cls, lateral: str, proximal: str, standing_deg: float = 0.0) -> SegmentMount:
        """A configured mount from sensor axis names, e.g. ``from_axes('+z', '-x')``."""
        return cls(parse_axis(lateral, "lateral axis"), parse_axis(proximal, "proximal axis"), standing_deg)

    def angles_deg(self, up: np.ndarray) -> np.ndarray:
        """Segment angles (deg) for world up directions ``up`` (T, 3) in the sensor frame (any norm), (T,)."""
        return self.standing_deg + np.degrees(np.arctan2(up @ np.asarray(self.forward), up @ np.asarray(self.proximal)))

    def as_dict(self) -> dict[str, Any]:
        return {
            "lateral": [round(v, 6) for v in self.lateral],
            "proximal": [round(v, 6) for v in self.proximal],
            "standing_deg": round(self.standing_deg, 4),
            "gyro_bias_dps": [round(v, 5) for v in self.gyro_bias_dps],
            "source": self.source,
        }

    @classmethod
    def from_dict(cls, d: Any, what: str = "mount") -> SegmentMount:
        if not isinstance(d, dict) or not {"lateral", "proximal"} <= set(d):
            raise CalibrationError(f"{what}: needs 'lateral' and 'proximal' (3-vectors)")
        try:
            return cls(
                tuple(d["lateral"]), tuple(d["proximal"]), float(d.get("standing_deg", 0.0)),
                tuple(d.get("gyro_bias_dps", (0.0, 0.0, 0.0))), str(d.get("source", "configured")),
            )
        except (TypeError, ValueError, CalibrationError) as exc:
            raise CalibrationError(f"{what}: {exc}") from None


@dataclass(frozen=True)
class ImuCalibration:
    """The four mounts, CHANNELS order (right_thigh, left_thigh, right_shank, left_shank)."""

    mounts: tuple[SegmentMount, SegmentMount, SegmentMount, SegmentMount]

    def __post_init__(self) -> None:
        if len(self.mounts) != N_CHANNELS or not all(isinstance(m, SegmentMount) for m in self.mounts):
            raise CalibrationError(f"an IMU calibration needs {N_CHANNELS} segment mounts ({', '.join(CHANNELS)})")
        object.__setattr__(self, "_rows", tuple((*m.forward, *m.proximal, m.standing_deg) for m in self.mounts))

    def angles_deg(self, ups: Any) -> tuple[float, float, float, float]:
        """Four segment angles (deg) from four up vectors (sensor frames), CHANNELS order; the
        formula of each mount's ``angles_deg``."""
        # Unrolled over the four sensors: this runs for every sample of a live stream.
        (a0, a1, a2, a3, a4, a5, a6), (b0, b1, b2, b3, b4, b5, b6), (c0, c1, c2, c3, c4, c5, c6), \
            (d0, d1, d2, d3, d4, d5, d6) = self._rows  # type: ignore[attr-defined]
        (x0, y0, z0), (x1, y1, z1), (x2, y2, z2), (x3, y3, z3) = ups
        atan2, deg = math.atan2, _DEG
        return (a6 + deg * atan2(a0 * x0 + a1 * y0 + a2 * z0, a3 * x0 + a4 * y0 + a5 * z0),
                b6 + deg * atan2(b0 * x1 + b1 * y1 + b2 * z1, b3 * x1 + b4 * y1 + b5 * z1),
                c6 + deg * atan2(c0 * x2 + c1 * y2 + c2 * z2, c3 * x2 + c4 * y2 + c5 * z2),
                d6 + deg * atan2(d0 * x3 + d1 * y3 + d2 * z3, d3 * x3 + d4 * y3 + d5 * z3))

    def with_gyro_biases(self, biases_dps: Sequence[Sequence[float]]) -> ImuCalibration:
        """The same mounts (axes to the bit) with these gyro biases (deg/s, sensor frames,
        CHANNELS order)."""
        mounts = []
        for m, b in zip(self.mounts, biases_dps, strict=True):
            bias = replace(m, gyro_bias_dps=tuple(b)).gyro_bias_dps  # validated
            mount = copy.copy(m)  # not replace(): __post_init__ would normalise the axes again (last bits)
            object.__setattr__(mount, "gyro_bias_dps", bias)
            mounts.append(mount)
        return ImuCalibration(tuple(mounts))  # type: ignore[arg-type]

    def summary(self) -> str:
        """One line: each segment's lateral and proximal axes and standing angle."""
        def fmt(v: Vec3) -> str:
            return "(" + ",".join(f"{x:+.2f}" for x in v) + ")"
        return "; ".join(
            f"{name}: lateral {fmt(m.lateral)} proximal {fmt(m.proximal)} standing {m.standing_deg:+.1f} deg [{m.source}]"
            for name, m in zip(CHANNELS, self.mounts, strict=False)
        )

    def as_dict(self) -> dict[str, Any]:
        return {"format": "gait_estimator imu calibration", "version": 1,
                "segments": {name: m.as_dict() for name, m in zip(CHANNELS, self.mounts, strict=False)}}

    @classmethod
    def from_dict(cls, d: Any) -> ImuCalibration:
        if not isinstance(d, dict) or not isinstance(d.get("segments"), dict):
            raise CalibrationError("not an IMU calibration (no 'segments' mapping)")
        segs = d["segments"]
        missing = [c for c in CHANNELS if c not in segs]
        if missing:
            raise CalibrationError(f"no mount for {', '.join(missing)}")
        return cls(tuple(SegmentMount.from_dict(segs[c], c) for c in CHANNELS))  # type: ignore[arg-type]


# ---------------------------------------------------------------------------------------------
# Up vectors


def up_from_quaternion(x: float, y: float, z: float, w: float) -> Vec3 | None:
    """World up (z) in the sensor frame from an orientation quaternion (world <- sensor, any
    norm); None for a non-finite or (near) zero quaternion."""
    n = x * x + y * y + z * z + w * w
    if not (1e-12 < n < math.inf):  # False for nan
        return None
    s = 2.0 / n
    return s * (x * z - w * y), s * (y * z + w * x), 1.0 - s * (x * x + y * y)


def ups_from_quaternions(q_xyzw: np.ndarray) -> np.ndarray:
    """Vectorised ``up_from_quaternion``: (T, 4) [x, y, z, w] -> (T, 3); bad rows are nan."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    n = np.einsum("ij,ij->i", q, q)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where((n > 1e-12) & np.isfinite(n), 2.0 / n, np.nan)
    return np.stack([s * (x * z - w * y), s * (y * z + w * x), 1.0 - s * (x * x + y * y)], axis=1)


@dataclass(frozen=True)
class FusionParams:
    """Settings of the raw-IMU fusion (``core/ahrs.CompiledFusion``: imufusion's AHRS without magnetometer).

    Attributes:
        gain: AHRS gain (imufusion's default): weight of the accelerometer's tilt correction.
        acceleration_rejection_deg: imufusion acceleration rejection (deg; 0 = off). Off because
            on walking its recoveries (jumps back to the accelerometer's tilt) cost more than the
            accelerations it ignores (docs/imu.md).
        rejection_timeout_s: imufusion rejection timeout (s).
        still_gain: Gain while the sensor is still (the accelerometer then reads gravity alone):
            the tilt settles on it within a fraction of a second instead of keeping the error of
            the last movement.
        still_rate_dps, still_acc_g, still_after_s: A sensor is still after ``still_after_s`` (s)
            with |gyro - bias| < ``still_rate_dps`` (deg/s) and ||acc| - 1 g| < ``still_acc_g`` (g).
        quasi_gain: Gain while the sensor turns slowly (|gyro - bias| < ``quasi_rate_dps``) and
            ||acc| - 1 g| < ``quasi_acc_g`` without being still (a shank in mid-stance: little
            acceleration besides gravity); None = ``gain``.
        quasi_rate_dps, quasi_acc_g: The limits of ``quasi_gain`` (deg/s, g).
    """

    gain: float = 0.5
    acceleration_rejection_deg: float = 0.0
    rejection_timeout_s: float = 1.0
    still_gain: float = 5.0
    still_rate_dps: float = 10.0
    still_acc_g: float = 0.05
    still_after_s: float = 0.1
    quasi_gain: float | None = None
    quasi_rate_dps: float = 60.0
    quasi_acc_g: float = 0.1

    def tier_gains(self) -> tuple[float, float, float]:
        """The gain of each tier: moving, turning slowly, still."""
        return self.gain, self.gain if self.quasi_gain is None else self.quasi_gain, self.still_gain

    def tier_limits(self) -> tuple[float, float, float, float, float]:
        """The tier test's thresholds, squared: still rate ((deg/s)^2), still ||acc|^2 - 1|, slow-turn
        rate (-1 when that tier has the moving gain), its ||acc|^2 - 1|, and the larger rate
        (above it the sensor is moving). |acc|^2 - 1 ~ 2 (|acc| - 1) near 1 g."""
        quasi = self.quasi_gain is not None and self.quasi_gain != self.gain
        still_rate2 = self.still_rate_dps * self.still_rate_dps
        quasi_rate2 = self.quasi_rate_dps * self.quasi_rate_dps if quasi else -1.0
        return still_rate2, 2.0 * self.still_acc_g, quasi_rate2, 2.0 * self.quasi_acc_g, max(still_rate2, quasi_rate2)

    def still_samples(self, rate_hz: float) -> int:
        """Samples of stillness before the still tier, at ``rate_hz`` (>= 1)."""
        return max(1, round(self.still_after_s * rate_hz))

    @staticmethod
    def max_step_s(rate_hz: float) -> float:
        """Longest time step (s) integrated at once at ``rate_hz``: ``MAX_STEP_S``, or two nominal
        periods of a slower sensor."""
        return max(MAX_STEP_S, 2.0 / rate_hz)


GYROSCOPE_RANGE_DPS = 2000.0
"""The gyroscope range the fusion assumes: rates beyond 98 % of it restart the AHRS (imufusion's
overrange recovery)."""
MAX_STEP_S = 0.1
"""Longest time step (s) the fusion integrates at once (``FusionParams.max_step_s``: longer for
sensors slower than 20 Hz). The rotation during a longer gap is unknown; the rate of the sample
after it is integrated over this much, not over the whole gap, and the accelerometer takes up the
rest."""
DEFAULT_FUSION = FusionParams()
"""The default fusion settings (a default argument value): imufusion's gain."""
THIGH_FUSION = FusionParams(gain=0.3)
"""The thighs' fusion settings: imufusion's with a lower gain, so that the accelerations of a
swinging thigh pull its tilt less (docs/imu.md, "Measured")."""
SHANK_FUSION = FusionParams(gain=0.2, quasi_gain=2.0)
"""The shanks' fusion settings: swing accelerations of the shank are larger, its mid-stance
quieter than the thigh's, so the accelerometer weighs little except while it turns slowly."""
FUSION_BY_CHANNEL = (THIGH_FUSION, THIGH_FUSION, SHANK_FUSION, SHANK_FUSION)
"""Fusion settings per sensor, CHANNELS order (right_thigh, left_thigh, right_shank, left_shank)."""


def gain_tier(rate2: float, acc2_off: float, still: float, limits: Any, still_needed: float) -> tuple[int, float]:
    """The fusion's gain schedule for one sample: (tier, samples of stillness so far), tier 0
    moving, 1 turning slowly, 2 still; from the squared gyro rate ((deg/s)^2), |acc|^2 - 1, the
    stillness count before the sample, ``FusionParams.tier_limits()`` and ``still_samples``.
    ``core/ahrs.py`` compiles it into its step."""
    if rate2 >= limits[4]:  # faster than both tiers allow (most of a stride); still_needed >= 1
        return 0, 0.0
    acc2 = limits[1]
    still = still + 1.0 if rate2 < limits[0] and -acc2 < acc2_off < acc2 else 0.0
    if still >= still_needed:
        return 2, still
    acc2 = limits[3]
    return (1 if rate2 < limits[2] and -acc2 < acc2_off < acc2 else 0), still


def tilt_quaternion_wxyz(acc: np.ndarray) -> np.ndarray:
    """The smallest rotation (world <- sensor, [w, x, y, z]) that turns ``acc`` to world up."""
    n = float(np.linalg.norm(acc))
    if not (math.isfinite(n) and n > 0):
        return np.array([1.0, 0.0, 0.0, 0.0])
    a = acc / n
    w = 1.0 + a[2]
    if w < 1e-9:  # upside down: half a turn about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    q = np.array([w, a[1], -a[0], 0.0])  # axis a x z, angle acos(a.z)
    return q / np.linalg.norm(q)
