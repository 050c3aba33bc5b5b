"""The IMU mounting learnt live, and a calibration made earlier checked on the first walking
(ROS-free; the node's IMU input and the Imu bag reader run it).

``ImuCalibrator``: while no calibration is complete, keeps the paired samples and learns the
mounts from them (``imu_learn.py``); the standing pose can be asked for again. A calibration made
earlier (a file, configured axes) is checked on the first walking while in use (``check``;
``check_stream`` over a whole recording), and takes the raw sensors' gyro biases of a standing
pose that ends before the verdict (``gyro_biases``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from .channels import N_CHANNELS
from .imu import CalibrationError, ImuCalibration, Vec3
from .imu_learn import (
    DEFAULT_LEARN,
    STILL_S,
    CalibrationCheck,
    ImuLearnParams,
    Standing,
    check_calibration,
    find_standing,
    learn_calibration,
    quiet_runs,
)

TO_BE_CHECKED = "calibrated, to be checked on the walking"


class ImuCalibrator:
    """Learns the mounts from paired samples while no calibration is complete; checks one made
    earlier on the first walking.

    Args:
        lateral, proximal: Configured sensor axes per segment (None = learn).
        standing_deg: Angle each segment is taken to have while standing (deg).
        calibration: A complete calibration to start with (saved or configured), or None.
        params: Learning thresholds and how often to try.
        check: Check ``calibration`` on the first walking (``check``; ``checking`` until then).
            One that ``add`` builds from configured axes alone is always checked.
    """

    def __init__(self, lateral: list[Vec3 | None], proximal: list[Vec3 | None], standing_deg: list[float],
                 calibration: ImuCalibration | None = None, params: ImuLearnParams = DEFAULT_LEARN,
                 check: bool = False) -> None:
        self.params = params
        self.lateral, self.proximal, self.standing_deg = list(lateral), list(proximal), list(standing_deg)
        self.calibration = calibration
        self.checking = check and calibration is not None
        """``calibration`` is in use but not checked yet: pass every sample to ``check``."""
        self.bias_measured = not self.checking
        """``calibration``'s gyro biases are this stream's: learnt at its standing pose, or (while
        checking) measured at it once it ended; ``check`` replaces ``calibration`` then."""
        self.gyro_biases: tuple[Vec3, ...] | None = None
        """The raw sensors' gyro biases (deg/s) last measured at a standing pose of this stream;
        kept through ``reset`` (a property of the sensors, not of their mounting)."""
        self.standing_s: tuple[float, float] | None = None
        """Stream times (s) of the first and last sample of the standing pose ``add`` learns from."""
        self.missing = "no whole window of stream yet"
        """Why the last check attempt gave no verdict."""
        self.status = "calibrated" if calibration is not None else "waiting for samples"
        if self.checking:
            self.status = TO_BE_CHECKED
        self._keep_lateral: list[Vec3 | None] | None = None
        self._standing: Standing | None = None
        self._requested = False  # a standing pose was asked for: wait for one even with configured axes
        self._clear()

    def _clear(self) -> None:
        self._t = np.empty(1024)
        self._rows = np.empty((1024, N_CHANNELS, 9))  # per sensor: up, gyro, acc
        self._n = 0
        self._next_try = -math.inf
        self._quiet_examined = -math.inf  # end (s) of the last quiet stretch looked at for a standing pose

    def request_standing(self) -> None:
        """Take a new standing pose from the next still stretch (the calibration waits for it,
        also with every axis configured), keeping learnt lateral axes; a calibration still to be
        checked is learnt again in full (its axes are not trusted yet)."""
        if self.calibration is not None and not self.checking:
            self._keep_lateral = [m.lateral for m in self.calibration.mounts]
        self.checking = False
        self.calibration = None
        self._standing = None
        self._requested = True
        self.status = "stand still"
        self._clear()

    def recheck(self) -> None:
        """Forget the stream so far (the sensors may have been taken off and put on again): a
        calibration in use is checked again on the next walking, its gyro biases from the next
        standing pose; one being learnt starts again from the next standing pose."""
        if self.calibration is not None:
            self.checking = True
            self.bias_measured = False
            self.status = TO_BE_CHECKED
        self._standing = None
        self._keep_lateral = None
        self._clear()

    def reset(self) -> None:
        """Forget everything learnt (but ``gyro_biases``): back to the configured axes."""
        self.calibration = None
        self.checking = False
        self._keep_lateral = None
        self._standing = None
        self._requested = False
        self.status = "waiting for samples"
        self._clear()

    def _append(self, t: float, ups: Sequence[Sequence[float]], gyro: Sequence[Vec3], acc: Sequence[Vec3]) -> int:
        """Append one sample to the buffer; its new length."""
        if self._n and t <= self._t[self._n - 1]:  # a restarted stream: what was kept has the old stamps
            self._standing = None
            self._clear()
        n = self._n
        if n == len(self._t):
            if t - self._t[0] > self.params.max_buffer_s:  # bounded: drop the oldest half (no standing found)
                half = n // 2
                self._t[:n - half], self._rows[:n - half] = self._t[half:n], self._rows[half:n]
                n -= half
                self._standing = None
            else:
                self._t = np.concatenate([self._t, np.empty_like(self._t)])
                self._rows = np.concatenate([self._rows, np.empty_like(self._rows)])
        self._t[n] = t
        row = self._rows[n]
        row[:, 0:3], row[:, 3:6], row[:, 6:9] = ups, gyro, acc
        self._n = n + 1
        return n + 1

    def check(self, t: float, ups: Sequence[Sequence[float]], gyro: Sequence[Vec3],
              acc: Sequence[Vec3]) -> CalibrationCheck | None:
        """While ``checking``: one paired sample (t in s); returns the check of ``calibration``
        on the last ``check_window_s`` of stream once it has enough walking (then ``checking``
        ends; the caller decides what a calibration that does not fit means). Until then, once a
        standing pose has ended, ``calibration`` is replaced by one with its gyro biases."""
        assert self.calibration is not None
        n = self._append(t, ups, gyro, acc)
        if t < self._next_try:
            return None
        params = self.params
        self._next_try = t + params.learn_every_s
        if not self.bias_measured:
            self._measure_bias(n)
        if t - self._t[0] < params.check_window_s:  # a whole window of stream first
            return None
        first = int(np.searchsorted(self._t[:n], t - params.check_window_s, side="right"))
        if first > n // 2:  # keep the buffer to about the window
            self._t[:n - first], self._rows[:n - first] = self._t[first:n], self._rows[first:n]
            n = self._n = n - first
            first = 0
        ups, gyro_a, _ = self._columns(first, n)
        found, missing = check_calibration(self._t[first:n], ups, self.calibration,
                                           gyro_a if np.isfinite(gyro_a).any() else None, params)
        if found is None:
            self.missing = missing
            self.status = f"{TO_BE_CHECKED}: {missing}"
            return None
        self.checking = False
        self.status = ("calibrated, checked: " if found.fits else "calibrated, does not fit the walking: ") + found.summary()
        self._clear()
        return found

    def _measure_bias(self, n: int) -> None:
        """Once the stream's first standing pose has ended: ``calibration`` with its gyro biases.
        The standing pose is looked for only when a new stretch of quiet gyros, long enough for
        one, has ended (a cheap necessary condition: this runs in the subscription callback)."""
        ups, gyro, acc = self._columns(0, n)
        if not np.isfinite(acc).any():
            self.bias_measured = True  # no raw sensor (they always carry an acceleration): no bias in use
            return
        t = self._t[:n]
        runs = [b for _, b in quiet_runs(t, gyro, STILL_S, self.params) if b < n and t[b - 1] > self._quiet_examined]
        if not runs:  # no quiet stretch has ended since the last look
            return
        self._quiet_examined = float(t[runs[-1] - 1])
        standing = find_standing(t, ups, gyro, acc, params=self.params)
        if standing is not None and standing.ended:
            assert self.calibration is not None
            self.gyro_biases = standing.gyro_bias_dps
            self.calibration = self.calibration.with_gyro_biases(standing.gyro_bias_dps)
            self.bias_measured = True

    def add(self, t: float, ups: Sequence[Sequence[float]], gyro: Sequence[Vec3], acc: Sequence[Vec3]) -> ImuCalibration | None:
        """One paired sample (t in s); returns the calibration when it has just been learnt. With
        raw sensors, ``gyro_biases`` are the standing pose's as soon as it has ended."""
        n = self._append(t, ups, gyro, acc)
        if t < self._next_try:
            return None
        self._next_try = t + self.params.learn_every_s
        time_s = self._t[:n]
        ups_a, gyro_a, acc_a = self._columns(0, n)
        have_rates = bool(np.isfinite(gyro_a).any())
        have_acc = bool(np.isfinite(acc_a).any())
        lateral = self.lateral
        if self._keep_lateral is not None:
            lateral = [a if a is not None else k for a, k in zip(self.lateral, self._keep_lateral, strict=False)]
        need_stand = any(p is None for p in self.proximal)
        if (self._standing is None or not self._standing.ended) and (need_stand or have_acc or self._requested):
            # until the wearer moves, each try lengthens the still stretch the gyro bias averages
            self._standing = find_standing(time_s, ups_a, gyro_a if have_rates else None, acc_a if have_acc else None,
                                           params=self.params)
        try:
            cal, standing, missing = learn_calibration(
                time_s, ups_a, lateral=lateral, proximal=self.proximal, standing_deg=self.standing_deg,
                standing=self._standing, gyro_dps=gyro_a if have_rates else None, acc_g=acc_a if have_acc else None,
                params=self.params, search=False)
        except CalibrationError as exc:
            cal, standing, missing = None, self._standing, str(exc)
        self._standing = standing
        if standing is not None:
            self.standing_s = (float(time_s[standing.start]), float(time_s[standing.stop - 1]))
        if have_acc and standing is not None and standing.ended and self.gyro_biases is not standing.gyro_bias_dps:
            self.gyro_biases = standing.gyro_bias_dps  # the fusion's from now on, before the strides are in
        if cal is not None and self._requested and standing is None:  # configured axes: the pose asked for
            cal, missing = None, f"stand still for {STILL_S:g} s"
        if cal is not None and have_acc and standing is not None and not standing.ended:
            cal, missing = None, "standing: the gyro bias is measured until you move"
        if cal is None:
            self.status = missing
            return None
        if not (have_acc and standing is not None) and self.gyro_biases is not None:
            # configured axes and no standing pose yet: the last measured
            cal = cal.with_gyro_biases(self.gyro_biases)
        if self._keep_lateral is not None:  # kept lateral axes were learnt, whatever else is configured
            cal = ImuCalibration(tuple(replace(m, source="learnt") if a is None else m  # type: ignore[arg-type]
                                       for m, a in zip(cal.mounts, self.lateral, strict=True)))
        self.calibration = cal
        self.checking = all(m.source == "configured" for m in cal.mounts)
        self.bias_measured = not self.checking
        self.status = TO_BE_CHECKED if self.checking else "calibrated"
        self._keep_lateral = None
        self._requested = False
        self._clear()
        return cal

    def _columns(self, first: int, stop: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Buffered samples first..stop as (4, T, 3) arrays: up directions, gyro, accelerometer."""
        rows = self._rows[first:stop].transpose(1, 0, 2)
        return rows[:, :, 0:3], rows[:, :, 3:6], rows[:, :, 6:9]


def check_stream(time_s: Sequence[float], ups: Any, gyro: Any, acc: Any, cal: ImuCalibration,
                 params: ImuLearnParams = DEFAULT_LEARN) -> tuple[CalibrationCheck | None, int, str, ImuCalibration]:
    """The live check (``ImuCalibrator.check``) over a whole recording of paired samples (per
    sample: time s, then four up directions, gyros deg/s, accelerometers g): (the check, the
    index of the sample it came with, '') or (None, -1, why there was none); then ``cal`` as the
    node has it after the check (with the gyro biases of a standing pose before the verdict)."""
    checker = ImuCalibrator([None] * N_CHANNELS, [None] * N_CHANNELS, [0.0] * N_CHANNELS, cal, params, check=True)
    for k, (t, u, g, a) in enumerate(zip(time_s, ups, gyro, acc, strict=True)):
        found = checker.check(float(t), u, g, a)
        if found is not None:
            return found, k, "", checker.calibration
    assert checker.calibration is not None
    return None, -1, checker.missing, checker.calibration
