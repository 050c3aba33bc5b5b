"""The Fusion library's AHRS itself (``imufusion``, test extra): the reference that
``core/ahrs.CompiledFusion``, the package's raw-IMU fusion, is checked against to rounding.

``RawFusion`` drives imufusion's ``Ahrs`` with the settings, gain schedule, time steps and
start that ``CompiledFusion`` implements; the tests compare the two on synthetic and real IMUs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from gait_estimator.core.imu import (
    DEFAULT_FUSION,
    GYROSCOPE_RANGE_DPS,
    FusionParams,
    Vec3,
    gain_tier,
    tilt_quaternion_wxyz,
)


def _imufusion() -> Any:
    """The imufusion module, or the test using it is skipped."""
    return pytest.importorskip("imufusion")


class RawFusion:
    """Gyro + accelerometer -> ``up`` for one sensor, with imufusion's AHRS (no magnetometer):
    ``core/ahrs.CompiledFusion``'s arguments and results (to rounding).

    Args:
        rate_hz: Nominal sample rate (Hz); each ``update`` uses the actual time step when given
            (at most ``FusionParams.max_step_s``).
        gyro_bias_dps: Subtracted from every gyro sample (deg/s, sensor frame).
        params: Gains and the stillness test.
    """

    def __init__(self, rate_hz: float = 200.0, gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0),
                 params: FusionParams = DEFAULT_FUSION) -> None:
        self.params = params
        self._ahrs = _imufusion().Ahrs()
        self._set_rate(rate_hz)
        self._ahrs.set_settings(self._settings[0])
        self._limits = params.tier_limits()
        self._still = 0.0
        self._tier = 0  # settings in use: 0 moving, 1 turning slowly, 2 still
        self.gyro_bias_dps = gyro_bias_dps
        self._first = True

    @property
    def tier(self) -> int:
        """The gain tier in use: 0 moving, 1 turning slowly, 2 still."""
        return self._tier

    def _set_rate(self, rate_hz: float) -> None:
        fusion, params = _imufusion(), self.params
        self._settings = [fusion.AhrsSettings(
            sample_rate=float(rate_hz),
            convention=fusion.CONVENTION_NWU,
            gain=gain,
            gyroscope_range=GYROSCOPE_RANGE_DPS,
            acceleration_rejection=params.acceleration_rejection_deg,
            magnetic_rejection=0.0,
            rejection_timeout=params.rejection_timeout_s,
        ) for gain in params.tier_gains()]
        self._still_needed = params.still_samples(rate_hz)
        self._max_step = params.max_step_s(rate_hz)
        self._period = 1.0 / rate_hz
        self.rate_hz = rate_hz

    def set_rate(self, rate_hz: float) -> None:
        """Use ``rate_hz`` (Hz) as the nominal rate from now on (a live stream's measured rate)."""
        self._set_rate(rate_hz)
        self._ahrs.set_settings(self._settings[self._tier])
        self._ahrs.set_sample_period(self._period)

    def update(self, gyro_dps: Vec3, acc_g: Vec3, dt_s: float | None = None) -> Vec3:
        """One sample: gyro (deg/s) and accelerometer (g), sensor frame; returns ``up`` (x, y, z)."""
        g0, g1, g2 = gyro_dps
        a0, a1, a2 = acc_g
        return self.update_xyz(g0, g1, g2, a0, a1, a2, dt_s)

    def update_xyz(self, g0: float, g1: float, g2: float, ax: float, ay: float, az: float,
                   dt_s: float | None = None) -> Vec3:
        """``update`` with the six components as Python floats (deg/s, g): the per-message path,
        where numpy for a 3-vector costs more than the arithmetic."""
        b0, b1, b2 = self.gyro_bias_dps
        gx, gy, gz = g0 - b0, g1 - b1, g2 - b2
        ahrs = self._ahrs
        if dt_s is not None and dt_s > self._max_step:
            dt_s = self._max_step
        if dt_s is not None and not -1e-6 <= dt_s - self._period <= 1e-6 and dt_s > 0:
            self._period = dt_s
            ahrs.set_sample_period(dt_s)
        if self._first:  # start from the accelerometer's tilt, not from a level sensor
            self._first = False
            ahrs.set_quaternion(tilt_quaternion_wxyz(np.array([ax, ay, az], dtype=np.float64)))
            ahrs.skip_startup()
        tier, self._still = gain_tier(gx * gx + gy * gy + gz * gz, ax * ax + ay * ay + az * az - 1.0, self._still,
                                      self._limits, self._still_needed)
        if tier != self._tier:
            self._tier = tier
            ahrs.set_settings(self._settings[tier]).set_sample_period(self._period)
        x, y, z = ahrs.update_no_magnetometer((gx, gy, gz), (ax, ay, az)).get_gravity().tolist()
        return x, y, z
