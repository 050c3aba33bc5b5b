"""Synthetic IMU streams made from known segment angles (for the IMU tests).

Each segment: sagittal angle theta(t) (deg, project sign), heading psi(t) (turns); its frame S
(x forward, y proximal, z wearer's right) in a z-up world is Rz(psi) . Ry(-theta) . S0, and the
sensor sits on it rotated by an arbitrary mounting R_SB. Messages carry the exact orientation
quaternion (world <- sensor, [x, y, z, w]), gravity as the accelerometer reads it (g) and the
body rates (deg/s), with noise and gyro bias added as asked.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from gait_estimator.core.imu import ImuCalibration

S0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Columns: segment forward, proximal, right in the world (x walking direction, z up) at theta 0."""


ALONG_SEGMENT = Rotation.from_matrix(np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
"""A mounting with the sensor's axes on the segment's: x = -proximal (down the segment), y =
forward, z = right (configured lateral ``+z``, proximal ``-x``)."""


@dataclass
class SyntheticImu:
    time_s: np.ndarray  # (T,)
    angles_deg: np.ndarray  # (T, 4) truth, CHANNELS order
    quat_xyzw: np.ndarray  # (4, T, 4)
    gyro_dps: np.ndarray  # (4, T, 3)
    acc_g: np.ndarray  # (4, T, 3)
    mounts: list[Rotation]  # R_SB per sensor


def gait_angles(rate_hz: float, walk_s: float, stand_s: float = 2.0, seed: int = 0) -> np.ndarray:
    """(T, 4) angles: standing at 0, then a blend into walking taken from the bundled Multispeed
    recording (real gait), resampled to ``rate_hz``."""
    from pathlib import Path

    from gait_estimator.io.readers import read_recording

    rec = read_recording(Path(__file__).resolve().parents[1] / "data/swge/recordings/Multispeed_Walk_AB.csv", rate_hz=230.0)
    t_src = rec.time_s - rec.time_s[0]
    start = 3000 + 500 * seed
    t = np.arange(0.0, walk_s, 1.0 / rate_hz)
    walk = np.stack([np.interp(t + t_src[start], t_src, rec.angles_deg[:, c]) for c in range(4)], axis=1)
    ramp = np.clip(t / 0.6, 0, 1)[:, None]
    walk = walk * ramp
    stand = np.zeros((round(stand_s * rate_hz), 4))
    return np.concatenate([stand, walk], axis=0)


def random_mounts(rng: np.random.Generator, n: int = 4) -> list[Rotation]:
    return [Rotation.random(random_state=int(rng.integers(1 << 31))) for _ in range(n)]


def synthesize(angles_deg: np.ndarray, rate_hz: float, mounts: list[Rotation], rng: np.random.Generator,
               acc_noise_g: float = 0.0, gyro_noise_dps: float = 0.0, gyro_bias_dps: float = 0.0,
               turn_dps: float = 30.0, stand_s: float = 2.0) -> SyntheticImu:
    T = len(angles_deg)
    t = np.arange(T) / rate_hz
    walking = np.clip(t - stand_s, 0, None)
    psi = np.radians(turn_dps) * walking + 0.5 * np.sin(0.3 * walking)  # heading: turning while walking
    quat = np.empty((4, T, 4))
    gyro = np.empty((4, T, 3))
    acc = np.empty((4, T, 3))
    s0 = Rotation.from_matrix(S0)
    for c in range(4):
        r_ws = Rotation.from_euler("z", psi[:, None]) * Rotation.from_euler("y", -np.radians(angles_deg[:, c])[:, None]) * s0
        r_wb = r_ws * mounts[c]
        quat[c] = r_wb.as_quat()  # x, y, z, w
        up = r_wb.inv().apply([0.0, 0.0, 1.0])
        acc[c] = up + rng.normal(0, acc_noise_g, (T, 3))
        rel = (r_wb[:-1].inv() * r_wb[1:]).as_rotvec() * rate_hz  # body rates between samples
        w = np.empty((T, 3))
        w[1:-1] = 0.5 * (rel[:-1] + rel[1:])
        w[0], w[-1] = rel[0], rel[-1]
        bias = rng.normal(0, 1, 3)
        bias *= gyro_bias_dps / max(np.linalg.norm(bias), 1e-12)
        gyro[c] = np.degrees(w) + bias + rng.normal(0, gyro_noise_dps, (T, 3))
    return SyntheticImu(t, np.asarray(angles_deg, dtype=np.float64), quat, gyro, acc, mounts)


def turned(cal: ImuCalibration, channel: int, deg: float) -> ImuCalibration:
    """``cal`` as it fits a sensor turned by ``-deg`` about its segment's long axis."""
    m = cal.mounts[channel]
    lateral = Rotation.from_rotvec(math.radians(deg) * np.array(m.proximal)).apply(m.lateral)
    mounts = list(cal.mounts)
    mounts[channel] = dataclasses.replace(m, lateral=tuple(lateral))
    return ImuCalibration(tuple(mounts))
