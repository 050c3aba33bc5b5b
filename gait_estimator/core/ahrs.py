"""The raw-IMU fusion: the Fusion library's AHRS without magnetometer, one call per sample.

``CompiledFusion`` takes the gain tier from the gyro and accelerometer (``imu.gain_tier``,
compiled in), then does one update of xioTechnologies/Fusion's ``FusionAhrsUpdateNoMagnetometer``
(the code behind ``imufusion``: startup gain ramp, gyroscope overrange restart, acceleration
rejection and recovery), and gives the gravity direction. It computes in double precision with
exact square roots where the library uses single precision and a fast inverse square root, so
the two differ by rounding (the tests check it against imufusion on real recordings); the
heading, which the library zeroes during startup, is left alone because the gravity direction
does not depend on it. The step is compiled with numba when it is installed
(``compiled.AVAILABLE``; the ``imu`` extra), and runs as plain Python otherwise (slower, same
results).
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import AVAILABLE, njit
from .imu import DEFAULT_FUSION, GYROSCOPE_RANGE_DPS, FusionParams, Vec3, gain_tier, tilt_quaternion_wxyz

INITIAL_STARTUP_GAIN = 10.0
"""The library's gain at the start of its startup ramp (after a gyroscope overrange)."""
STARTUP_PERIOD_S = 3.0
"""The library's startup ramp (s)."""

# state: quaternion w x y z, sample period, tier, still count, recovery trigger, recovery
# threshold, startup (0/1), startup gain
_Q, _PERIOD, _TIER, _STILL, _TRIGGER, _THRESHOLD, _STARTUP, _STARTUP_GAIN = 0, 4, 5, 6, 7, 8, 9, 10
_N_STATE = 11
# params: per tier t (0 moving, 1 turning slowly, 2 still) at 4 t: gain, startup gain step,
# rejection threshold, rejection timeout (samples); then the rest
_BIAS, _OVERRANGE, _STILL_RATE2, _STILL_ACC2, _QUASI_RATE2, _QUASI_ACC2, _CALM_RATE2, _STILL_NEEDED, _MAX_STEP = \
    12, 15, 16, 17, 18, 19, 20, 21, 22
_N_PARAMS = 23
_gain_tier = njit(cache=True, nogil=True, inline="always")(gain_tier)


@njit(cache=True, nogil=True)
def _step(s, p, g0, g1, g2, ax, ay, az, dt):  # pragma: no cover - compiled
    """One sample (deg/s, g, s; dt <= 0: the period in use; at most the longest step) -> gravity
    direction, sensor frame."""
    gx, gy, gz = g0 - p[_BIAS], g1 - p[_BIAS + 1], g2 - p[_BIAS + 2]
    if dt > p[_MAX_STEP]:
        dt = p[_MAX_STEP]
    if dt > 0.0 and not -1e-6 <= dt - s[_PERIOD] <= 1e-6:
        s[_PERIOD] = dt
    n2 = ax * ax + ay * ay + az * az
    tier, s[_STILL] = _gain_tier(gx * gx + gy * gy + gz * gz, n2 - 1.0, s[_STILL], p[_STILL_RATE2:_CALM_RATE2 + 1],
                                 p[_STILL_NEEDED])
    k = 4 * tier
    timeout = p[k + 3]
    if tier != s[_TIER]:  # new settings: the library resets the recovery threshold
        s[_TIER] = tier
        s[_THRESHOLD] = timeout
    limit = p[_OVERRANGE]
    if abs(gx) > limit or abs(gy) > limit or abs(gz) > limit:  # soft restart, keeping the quaternion
        s[_STARTUP], s[_STARTUP_GAIN], s[_TRIGGER], s[_THRESHOLD] = 1.0, INITIAL_STARTUP_GAIN, 0.0, timeout
    gain = p[k]
    if s[_STARTUP] != 0.0:
        s[_STARTUP_GAIN] -= p[k + 1]
        if s[_STARTUP_GAIN] > gain:
            gain = s[_STARTUP_GAIN]
        else:
            s[_STARTUP] = 0.0
    qw, qx, qy, qz = s[_Q], s[_Q + 1], s[_Q + 2], s[_Q + 3]
    hx, hy, hz = qx * qz - qw * qy, qy * qz + qw * qx, qw * qw - 0.5 + qz * qz  # half gravity
    fx = fy = fz = 0.0
    if ax != 0.0 or ay != 0.0 or az != 0.0:
        inv = 1.0 / math.sqrt(n2)
        sx, sy, sz = ax * inv, ay * inv, az * inv
        rx, ry, rz = sy * hz - sz * hy, sz * hx - sx * hz, sx * hy - sy * hx
        if sx * hx + sy * hy + sz * hz <= 0.0:  # more than 90 degrees off: full feedback
            c2 = rx * rx + ry * ry + rz * rz
            if c2 == 0.0:
                rx = ry = rz = 0.0
            else:
                inv = 1.0 / math.sqrt(c2)
                rx, ry, rz = rx * inv, ry * inv, rz * inv
        ignored = True
        if s[_STARTUP] != 0.0 or rx * rx + ry * ry + rz * rz <= p[k + 2]:
            ignored = False
            s[_TRIGGER] -= 9.0
        else:
            s[_TRIGGER] += 1.0
        if s[_TRIGGER] > s[_THRESHOLD]:
            s[_THRESHOLD] = 0.0
            ignored = False
        else:
            s[_THRESHOLD] = timeout
        s[_TRIGGER] = min(max(s[_TRIGGER], 0.0), timeout)
        if not ignored:
            fx, fy, fz = rx, ry, rz
    half = 0.5 * math.pi / 180.0
    period = s[_PERIOD]
    wx, wy, wz = (gx * half + fx * gain) * period, (gy * half + fy * gain) * period, (gz * half + fz * gain) * period
    nw = qw - qx * wx - qy * wy - qz * wz
    nx = qx + qw * wx + qy * wz - qz * wy
    ny = qy + qw * wy - qx * wz + qz * wx
    nz = qz + qw * wz + qx * wy - qy * wx
    inv = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    nw, nx, ny, nz = nw * inv, nx * inv, ny * inv, nz * inv
    s[_Q], s[_Q + 1], s[_Q + 2], s[_Q + 3] = nw, nx, ny, nz
    return 2.0 * (nx * nz - nw * ny), 2.0 * (ny * nz + nw * nx), 2.0 * (nw * nw - 0.5 + nz * nz)


class CompiledFusion:
    """Gyro + accelerometer -> ``up`` for one sensor (module docstring).

    Args:
        rate_hz: Nominal sample rate (Hz); each ``update`` uses the actual time step when given
            (at most ``FusionParams.max_step_s``).
        gyro_bias_dps: Subtracted from every gyro sample (deg/s, sensor frame).
        params: Gains and the stillness test.
    """

    def __init__(self, rate_hz: float = 200.0, gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0),
                 params: FusionParams = DEFAULT_FUSION) -> None:
        self.params = params
        self._p = np.zeros(_N_PARAMS)
        self._s = np.zeros(_N_STATE)
        self._s[_Q] = 1.0
        self._set_rate(rate_hz)
        self._s[_THRESHOLD] = self._p[3]
        self.gyro_bias_dps = gyro_bias_dps
        self._first = True

    @property
    def gyro_bias_dps(self) -> Vec3:
        return self._bias

    @gyro_bias_dps.setter
    def gyro_bias_dps(self, bias_dps: Vec3) -> None:
        self._bias = bias_dps
        self._p[_BIAS:_BIAS + 3] = bias_dps

    def _set_rate(self, rate_hz: float) -> None:
        p, params = self._p, self.params
        period = 1.0 / rate_hz
        timeout = float(int(np.float32(rate_hz) * np.float32(params.rejection_timeout_s)))  # as the library's float32
        for t, gain in enumerate(params.tier_gains()):
            off = params.acceleration_rejection_deg == 0.0 or gain == 0.0 or params.rejection_timeout_s == 0.0
            rejection = math.inf if off else (0.5 * math.sin(math.radians(params.acceleration_rejection_deg))) ** 2
            p[4 * t:4 * t + 4] = gain, (INITIAL_STARTUP_GAIN - gain) / STARTUP_PERIOD_S * period, rejection, timeout
        p[_OVERRANGE] = 0.98 * GYROSCOPE_RANGE_DPS
        p[_STILL_RATE2:_CALM_RATE2 + 1] = params.tier_limits()
        p[_STILL_NEEDED] = params.still_samples(rate_hz)
        p[_MAX_STEP] = params.max_step_s(rate_hz)
        self._s[_PERIOD] = period
        self.rate_hz = rate_hz

    def set_rate(self, rate_hz: float) -> None:
        """Use ``rate_hz`` (Hz) as the nominal rate from now on (a live stream's measured rate)."""
        self._set_rate(rate_hz)
        self._s[_THRESHOLD] = self._p[4 * int(self._s[_TIER]) + 3]

    def update(self, gyro_dps: Vec3, acc_g: Vec3, dt_s: float | None = None) -> tuple[float, float, float]:
        """One sample: gyro (deg/s) and accelerometer (g), sensor frame; returns ``up`` (x, y, z)."""
        g0, g1, g2 = gyro_dps
        a0, a1, a2 = acc_g
        return self.update_xyz(float(g0), float(g1), float(g2), float(a0), float(a1), float(a2), dt_s)

    def update_xyz(self, g0: float, g1: float, g2: float, ax: float, ay: float, az: float,
                   dt_s: float | None = None) -> tuple[float, float, float]:
        """``update`` with the six components as Python floats (deg/s, g)."""
        if self._first:  # start from the accelerometer's tilt, not from a level sensor
            self._first = False
            self._s[_Q:_Q + 4] = tilt_quaternion_wxyz(np.array([ax, ay, az], dtype=np.float64))
        return _step(self._s, self._p, g0, g1, g2, ax, ay, az, -1.0 if dt_s is None else dt_s)


def warm_up() -> None:
    """Compile (or load from numba's cache) ``CompiledFusion``'s step now rather than at the first
    raw message, which would wait for it; nothing without numba."""
    if AVAILABLE:
        CompiledFusion().update_xyz(0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def make_fusion(rate_hz: float = 200.0, gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0),
                params: FusionParams = DEFAULT_FUSION) -> CompiledFusion:
    """The raw-input fusion of one sensor (``CompiledFusion``)."""
    return CompiledFusion(rate_hz, gyro_bias_dps, params)


def fuse_raw(time_s: np.ndarray, gyro_dps: np.ndarray, acc_g: np.ndarray,
             gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0), params: FusionParams = DEFAULT_FUSION) -> np.ndarray:
    """The raw-input fusion (``make_fusion``) over a whole stream: (T,), (T, 3), (T, 3) -> up (T, 3)."""
    t = np.asarray(time_s, dtype=np.float64)
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 200.0
    fusion = make_fusion(rate, gyro_bias_dps, params)
    out = np.empty((len(t), 3))
    prev = None
    for i in range(len(t)):
        dt = None if prev is None else t[i] - prev
        out[i] = fusion.update(gyro_dps[i], acc_g[i], dt)
        prev = t[i]
    return out


def fuse_raw_backwards(time_s: np.ndarray, gyro_dps: np.ndarray, acc_g: np.ndarray,
                       gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0), params: FusionParams = DEFAULT_FUSION) -> np.ndarray:
    """``fuse_raw`` run from the last sample to the first (time reversed: the rotation rates
    negated), started from the last sample's accelerometer; up (T, 3) in time order."""
    back = slice(None, None, -1)
    t, gyro, acc = (np.asarray(x, dtype=np.float64)[back] for x in (time_s, gyro_dps, acc_g))
    bias = (-gyro_bias_dps[0], -gyro_bias_dps[1], -gyro_bias_dps[2])
    return fuse_raw(-t, -gyro, acc, bias, params)[back]
