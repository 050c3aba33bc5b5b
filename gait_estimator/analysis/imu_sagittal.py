"""``sensor_msgs/Imu`` fields and serialised messages from segment angles: each sensor turns only
about its segment's lateral axis (a pure sagittal rotation), ROS-free; the input of
``bench-node --input imu``.

A sensor's mounting is the node's configured one (docs/imu.md): sensor axes ``lateral`` (the
wearer's right) and ``proximal``, forward = proximal x lateral. At angle 0 forward, proximal and
lateral point to the world's x, z (up) and -y; at angle theta the sensor is turned by theta
about its lateral axis, so that the world's up in the sensor frame is
``proximal cos(theta) + forward sin(theta)`` and the node's conversion returns theta exactly.

* orientation: world <- sensor quaternion (x, y, z, w), exact;
* gyro: rad/s about the lateral axis, the backward difference of the angles (the rate over the
  step that ends at the sample, which the fusion integrates back to the angles);
* accelerometer: gravity in the sensor frame, m/s^2 (no linear acceleration).

``imu_samples`` serialises them as CDR bytes (io/cdr.py ``write_imu``, the inverse of the node's
``read_imu``), so that the bench publishes each message in a few microseconds, not the tens rclpy
needs to fill and convert an Imu object.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..core.channels import CHANNELS, N_CHANNELS
from ..core.imu import STANDARD_GRAVITY, parse_axis
from ..io.cdr import write_imu

BENCH_LATERAL_AXES = ("+z", "-z", "+z", "-z")
"""Configured lateral axes of the bench's sensors, CHANNELS order: z out of the leg's outer side."""
BENCH_PROXIMAL_AXES = ("-x", "-x", "-x", "-x")
"""Configured proximal axes of the bench's sensors: x along the segment, pointing down."""


@dataclass
class SagittalImu:
    """Per sample and sensor (CHANNELS order): orientation (T, 4, 4: x, y, z, w), gyro (T, 4, 3,
    rad/s), accelerometer (T, 4, 3, m/s^2)."""

    quat_xyzw: np.ndarray
    gyro_rps: np.ndarray
    acc_mps2: np.ndarray


def _quat_from_matrix(m: np.ndarray) -> np.ndarray:
    """Rotation matrix -> unit quaternion (x, y, z, w) (Shepperd's method)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, s / 4
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4, (m[1, 0] - m[0, 1]) / s
    out = np.array(q, dtype=np.float64)
    return out / np.linalg.norm(out)


def _mount_axes(lateral: str, proximal: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sensor-frame lateral, proximal and forward unit axes of a configured mounting."""
    lat = np.array(parse_axis(lateral, "lateral axis"))
    prox = np.array(parse_axis(proximal, "proximal axis"))
    if abs(float(lat @ prox)) > 1e-9:
        raise ValueError(f"lateral {lateral!r} and proximal {proximal!r} must be perpendicular sensor axes")
    return lat, prox, np.cross(prox, lat)


def sagittal_imu(
    angles_deg: np.ndarray,
    period_s: float,
    lateral: Sequence[str] = BENCH_LATERAL_AXES,
    proximal: Sequence[str] = BENCH_PROXIMAL_AXES,
    previous_deg: np.ndarray | None = None,
) -> SagittalImu:
    """The four sensors' Imu fields for segment angles ``angles_deg`` (T, 4), degrees, spaced
    ``period_s`` seconds; ``lateral``/``proximal``: configured sensor axes per segment (the
    node's ``imu_lateral_axes``/``imu_proximal_axes``); ``previous_deg`` (4,): the angles one
    period before the first row (for its gyro; default: the first row, i.e. at rest)."""
    theta = np.radians(np.asarray(angles_deg, dtype=np.float64).reshape(-1, N_CHANNELS))
    before = theta[:1] if previous_deg is None else np.radians(np.asarray(previous_deg, dtype=np.float64))[None, :]
    rate = np.diff(np.concatenate([before, theta]), axis=0) / period_s  # (T, 4) rad/s
    t = len(theta)
    quat = np.empty((t, N_CHANNELS, 4))
    gyro = np.empty((t, N_CHANNELS, 3))
    acc = np.empty((t, N_CHANNELS, 3))
    for c in range(N_CHANNELS):
        lat, prox, fwd = _mount_axes(lateral[c], proximal[c])
        rest = np.outer([1.0, 0.0, 0.0], fwd) + np.outer([0.0, 0.0, 1.0], prox) - np.outer([0.0, 1.0, 0.0], lat)
        q0 = _quat_from_matrix(rest)  # world <- sensor at angle 0
        half = 0.5 * theta[:, c]
        v2, w2 = lat[None, :] * np.sin(half)[:, None], np.cos(half)  # the turn about the lateral axis
        v1, w1 = q0[:3], q0[3]
        quat[:, c, :3] = w1 * v2 + w2[:, None] * v1[None, :] + np.cross(v1[None, :], v2)  # q0 * q_turn
        quat[:, c, 3] = w1 * w2 - v2 @ v1
        gyro[:, c] = rate[:, c, None] * lat[None, :]
        acc[:, c] = STANDARD_GRAVITY * (np.cos(theta[:, c])[:, None] * prox + np.sin(theta[:, c])[:, None] * fwd)
    return SagittalImu(quat, gyro, acc)


def imu_samples(
    angles_deg: np.ndarray,
    stamps_ns: Sequence[int] | np.ndarray,
    period_s: float,
    raw: bool,
    previous_deg: np.ndarray | None = None,
    lateral: Sequence[str] = BENCH_LATERAL_AXES,
    proximal: Sequence[str] = BENCH_PROXIMAL_AXES,
) -> list[tuple[bytes, ...]]:
    """Per sample of ``angles_deg`` (T, 4), degrees, stamped ``stamps_ns``: the four sensors'
    serialised Imu messages (CHANNELS order, frame_id = the channel's name). ``raw``: no
    orientation (``orientation_covariance[0] = -1``), gyro and accelerometer only; otherwise the
    orientation with the same gyro and accelerometer (as an orientation filter passes them on).
    ``period_s``, ``previous_deg``, ``lateral``, ``proximal``: see ``sagittal_imu``."""
    f = sagittal_imu(angles_deg, period_s, lateral, proximal, previous_deg)
    cov0 = -1.0 if raw else 0.0
    no_orientation = (0.0, 0.0, 0.0, 0.0)
    q, g, a = f.quat_xyzw.tolist(), f.gyro_rps.tolist(), f.acc_mps2.tolist()
    return [
        tuple(write_imu(int(st), CHANNELS[c], no_orientation if raw else q[k][c], cov0, g[k][c], a[k][c])
              for c in range(N_CHANNELS))
        for k, st in enumerate(stamps_ns)
    ]
