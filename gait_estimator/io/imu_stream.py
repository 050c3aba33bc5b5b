"""Four ``sensor_msgs/Imu`` streams -> segment angle samples, ROS-free (the node and bag reading).

* ``SensorInput``: one sensor's message fields -> its up direction (``core/imu.py``): from the
  orientation, or (``orientation_covariance[0] == -1``, REP 145: no orientation) from gyro +
  accelerometer through ``core/ahrs.make_fusion``; bad messages raise ``SampleRejected`` (non-finite values,
  a zero quaternion or acceleration, a stamp not after the sensor's previous one).
* ``ImuPairer``: the four streams paired by stamp within a tolerance; a message without partners
  is dropped (``unpaired``), so a silent sensor stops the samples instead of repeating its last
  value. ``auto_tolerance_s``: the tolerance of unsynchronised sensors, from their stamps.
* ``ImuCalibrator``: while no calibration is complete, keeps the paired samples and learns the
  mounts from them (``core/imu_learn.py``); the standing pose can be asked for again. A
  calibration made earlier (a file, configured axes) is checked on the first walking while in
  use (``check``; ``check_stream`` over a whole recording), and takes the raw sensors' gyro
  biases of a standing pose that ends before the verdict (``gyro_biases``).
* ``save_calibration`` / ``load_calibration``: the calibration as YAML (atomic write).
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import yaml

from ..core.ahrs import CompiledFusion, make_fusion
from ..core.channels import CHANNELS, N_CHANNELS
from ..core.imu import DEFAULT_FUSION, STANDARD_GRAVITY, CalibrationError, FusionParams, ImuCalibration, RawFusion, Vec3
from ..core.imu_learn import (
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
from .atomic import atomic_write_text
from .stream import NON_FINITE, NON_INCREASING_STAMP, OUT_OF_RANGE, STREAM_RESTART_S, SampleRejected

ZERO_NORM = "zero_norm"
UNPAIRED = "unpaired"
WRONG_FRAME = "wrong_frame"
MAX_RATE_RPS = 350.0
"""Largest angular rate (rad/s, about 20000 deg/s) taken from a message: beyond any IMU's range,
so a raw message with more is dropped (``out_of_range``) and an orientation message is used
without its rates."""
MAX_ACC_MPS2 = 10_000.0
"""Largest acceleration (m/s^2, about 1000 g) taken from a raw message; see ``MAX_RATE_RPS``."""
_MAX_RATE2, _MAX_ACC2 = MAX_RATE_RPS ** 2, MAX_ACC_MPS2 ** 2
DEFAULT_TOLERANCE_S = 0.004
"""Largest stamp spread (s) of four messages that make one sample (a 200 Hz period is 0.005 s):
the node's default, for sensors sampled together."""
AUTO_TOLERANCE_PERIODS = 0.9
"""``auto_tolerance_s``: this share of the message period (see there)."""
MAX_QUEUE = 50
"""Messages kept per sensor while waiting for partners; older ones are dropped (unpaired)."""
RATE_STEPS = 16
"""Stamp steps of a raw sensor whose median gives its rate, when ``SensorInput`` measures it."""
_RAD2DEG = 180.0 / math.pi
_INF = math.inf
_G = STANDARD_GRAVITY
NO_RATES: Vec3 = (math.nan, math.nan, math.nan)
_NOTHING: tuple = ()
TO_BE_CHECKED = "calibrated, to be checked on the walking"


class SensorInput:
    """One IMU's messages -> (up, gyro deg/s, acc g), sensor frame; see the module docstring.

    Args:
        rate_hz: Nominal rate for the raw-input fusion (Hz); None = measured from the first
            ``rate_steps`` stamp steps (a live stream; until then 200 Hz), again after a restart.
        frame_id: The ``header.frame_id`` this sensor's messages must carry ('' = any).
        params: Settings of the raw-input fusion.
        restart_back_s: Two messages in a row stamped more than this (s) before the previous
            accepted one, the second after the first, are a restarted sensor (a driver restart, a
            bag played again): from the second on they are accepted, the fusion started afresh and
            ``restarts`` counted; a single such message, or a smaller step back, is rejected (0 =
            always rejected).
    """

    def __init__(self, rate_hz: float | None = 200.0, frame_id: str = "", params: FusionParams = DEFAULT_FUSION,
                 restart_back_s: float = STREAM_RESTART_S, rate_steps: int = RATE_STEPS) -> None:
        self._rate_hz = 200.0 if rate_hz is None else rate_hz
        self._measured = rate_hz is None
        self._steps: list[int] | None = [] if rate_hz is None else None  # stamp steps (ns) while measuring
        self.rate_steps = rate_steps
        self.params = params
        self.frame_id = frame_id
        self.restart_back_ns = round(restart_back_s * 1e9)
        self.fusion: CompiledFusion | RawFusion | None = None
        self.gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0)
        self.last_ns: int | None = None
        self.restarts = 0
        self._restart_from: int | None = None  # stamp of a message far before the previous one

    def convert(self, stamp_ns: int, orientation: Any, orientation_cov0: float, gyro_rps: Any,
                acc_mps2: Any, frame_id: str = "") -> tuple[Sequence[float], Vec3, Vec3]:
        """Fields of one Imu message (quaternion x, y, z, w; rad/s; m/s^2) -> (up, gyro, acc)."""
        if self.frame_id and frame_id != self.frame_id:
            raise SampleRejected(WRONG_FRAME, f"frame_id {frame_id!r}, expected {self.frame_id!r}")
        last = self.last_ns
        if last is not None and stamp_ns <= last:
            candidate, self._restart_from = self._restart_from, None
            if 0 < self.restart_back_ns < last - stamp_ns:
                if candidate is None or stamp_ns <= candidate:  # a stray old message, until the next confirms
                    self._restart_from = stamp_ns
                    raise SampleRejected(NON_INCREASING_STAMP, f"stamp {stamp_ns * 1e-9:.6f} s is "
                                         f"{(last - stamp_ns) * 1e-9:.3f} s before the previous (a restart?)")
                self.restarts += 1  # a second message after the first on the earlier stamps: restarted
                self.fusion = None
                if self._measured:  # the driver may come back at another rate
                    self._steps = []
                last = None
            else:
                raise SampleRejected(NON_INCREASING_STAMP,
                                     f"stamp {stamp_ns * 1e-9:.6f} s is not after the previous {last * 1e-9:.6f} s")
        elif self._restart_from is not None:
            self._restart_from = None
        gx, gy, gz = gyro_rps
        if orientation_cov0 != -1.0:
            x, y, z, w = orientation
            n = x * x + y * y + z * z + w * w
            if not 1e-12 < n < _INF:  # (up_from_quaternion, inlined: this runs for every message)
                raise SampleRejected(ZERO_NORM if x == x and y == y and z == z and w == w else NON_FINITE,
                                     f"unusable orientation quaternion ({x}, {y}, {z}, {w})")
            s = 2.0 / n
            up = (s * (x * z - w * y), s * (y * z + w * x), 1.0 - s * (x * x + y * y))
            gyro = (gx * _RAD2DEG, gy * _RAD2DEG, gz * _RAD2DEG) if gx * gx + gy * gy + gz * gz < _MAX_RATE2 \
                else NO_RATES
            self.last_ns = stamp_ns
            return up, gyro, NO_RATES  # the accelerometer is the orientation filter's business
        ax, ay, az = acc_mps2
        if not (gx * gx + gy * gy + gz * gz < _MAX_RATE2 and 1e-6 <= ax * ax + ay * ay + az * az < _MAX_ACC2):
            self._reject_raw(gx, gy, gz, ax, ay, az)  # false for NaN too
        fusion = self.fusion
        if fusion is None:
            fusion = self.fusion = make_fusion(self._rate_hz, self.gyro_bias_dps, self.params)
        gx, gy, gz, ax, ay, az = gx * _RAD2DEG, gy * _RAD2DEG, gz * _RAD2DEG, ax / _G, ay / _G, az / _G
        up = fusion.update_xyz(gx, gy, gz, ax, ay, az, None if last is None else (stamp_ns - last) * 1e-9)
        self.last_ns = stamp_ns
        if self._steps is not None and last is not None:
            self._measure_rate(stamp_ns - last)
        return up, (gx, gy, gz), (ax, ay, az)

    @staticmethod
    def _reject_raw(gx: float, gy: float, gz: float, ax: float, ay: float, az: float) -> NoReturn:
        """Raise ``SampleRejected`` for raw values that are not finite, beyond ``MAX_RATE_RPS`` or
        ``MAX_ACC_MPS2`` in magnitude, or without gravity."""
        values = f"({gx}, {gy}, {gz} rad/s; {ax}, {ay}, {az} m/s^2)"
        if not all(math.isfinite(v) for v in (gx, gy, gz, ax, ay, az)):
            raise SampleRejected(NON_FINITE, f"non-finite rate or acceleration {values}")
        if ax * ax + ay * ay + az * az < 1e-6:
            raise SampleRejected(ZERO_NORM, "zero acceleration (no gravity in the accelerometer)")
        raise SampleRejected(OUT_OF_RANGE, f"rate or acceleration beyond any IMU's range {values}")

    def _measure_rate(self, step_ns: int) -> None:
        """One more stamp step while the rate is measured (``rate_hz`` None): the fusion's rate
        from the median of ``rate_steps`` of them."""
        steps = self._steps
        assert steps is not None and self.fusion is not None
        steps.append(step_ns)
        if len(steps) == self.rate_steps:
            self._rate_hz = 1e9 / float(np.median(steps))
            self.fusion.set_rate(self._rate_hz)
            self._steps = None

    def set_gyro_bias(self, bias_dps: Vec3) -> None:
        self.gyro_bias_dps = bias_dps
        if self.fusion is not None:
            self.fusion.gyro_bias_dps = bias_dps


def auto_tolerance_s(stamps_ns: Sequence[Any]) -> float:
    """Pairing tolerance (s) for sensors that are not sampled together: AUTO_TOLERANCE_PERIODS of
    the message period (the median over the sensors of each one's median stamp step).

    Four sensors at one rate with any phases always have one message each within 3/4 of a period
    (the largest of the four gaps between their phases is at least 1/4); a tolerance below one
    period never puts two messages a period apart into one sample. ``stamps_ns``: per sensor, its
    stamps (ns) in order. ValueError when no sensor has two increasing stamps.
    """
    periods = []
    for st in stamps_ns:
        d = np.diff(np.asarray(st, dtype=np.int64))
        d = d[d > 0]
        if len(d):
            periods.append(float(np.median(d)) * 1e-9)
    if not periods:
        raise ValueError("cannot measure the IMU message period (fewer than two increasing stamps per sensor)")
    return AUTO_TOLERANCE_PERIODS * float(np.median(periods))


class ImuPairer:
    """Pairs the four sensors' messages by stamp.

    Args:
        tolerance_s: Largest spread of the four stamps in one sample (s, >= 0); for sensors not
            sampled together see ``auto_tolerance_s``.
        max_queue: Messages kept per sensor while waiting for partners.
    """

    def __init__(self, tolerance_s: float = DEFAULT_TOLERANCE_S, max_queue: int = MAX_QUEUE) -> None:
        if not (math.isfinite(tolerance_s) and tolerance_s >= 0):
            raise ValueError(f"IMU pairing tolerance must be a finite number of seconds >= 0, got {tolerance_s!r}")
        self.tolerance_ns = round(tolerance_s * 1e9)
        self.max_queue = max_queue
        self.queues: list[deque] = [deque() for _ in range(N_CHANNELS)]
        self.dropped: Counter = Counter()  # unpaired messages per sensor name
        self.unpaired = 0
        """Unpaired messages, all sensors (the sum of ``dropped``)."""
        self._newest = [-1] * N_CHANNELS

    def push(self, sensor: int, stamp_ns: int, item: Any) -> Sequence[tuple[int, list[Any]]]:
        """Add one accepted message; returns the samples it completes: (stamp_ns = the latest
        of the four, [item per sensor])."""
        newest = self._newest
        if stamp_ns < newest[sensor]:
            self._restarted(stamp_ns)
        newest[sensor] = stamp_ns
        queues = self.queues
        q = queues[sensor]
        q.append((stamp_ns, item))
        if len(q) > self.max_queue:
            q.popleft()
            self._drop(sensor)
        q0, q1, q2, q3 = queues
        if not (q0 and q1 and q2 and q3):
            return _NOTHING
        out = []
        tol = self.tolerance_ns
        while q0 and q1 and q2 and q3:
            (s0, i0), (s1, i1), (s2, i2), (s3, i3) = q0[0], q1[0], q2[0], q3[0]
            lo, hi = min(s0, s1, s2, s3), max(s0, s1, s2, s3)
            if hi - lo <= tol:
                q0.popleft(), q1.popleft(), q2.popleft(), q3.popleft()
                out.append((hi, [i0, i1, i2, i3]))
                continue
            oldest = (s0, s1, s2, s3).index(lo)
            queues[oldest].popleft()
            self._drop(oldest)
        return out

    def _drop(self, sensor: int, n: int = 1) -> None:
        """Count ``n`` unpaired messages of ``sensor``: per sensor and in the running total."""
        self.dropped[CHANNELS[sensor]] += n
        self.unpaired += n

    def _restarted(self, stamp_ns: int) -> None:
        """A sensor restarted (a stamp before its newest): drop what was queued under the old stamps."""
        limit = stamp_ns + self.tolerance_ns
        for i, old in enumerate(self.queues):
            kept = [m for m in old if m[0] <= limit]
            self._drop(i, len(old) - len(kept))
            self.queues[i] = deque(kept)

    def clear(self) -> None:
        for q in self.queues:
            q.clear()


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


# ---------------------------------------------------------------------------------------------
# Files


def save_calibration(cal: ImuCalibration, path: str | Path) -> Path:
    """Write ``cal`` as YAML (atomically: a crash leaves the old file or the new one)."""
    p = Path(path).expanduser()
    p.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(p, yaml.safe_dump(cal.as_dict(), sort_keys=False))
    return p


def load_calibration(path: str | Path) -> ImuCalibration:
    """Read a calibration written by ``save_calibration``; CalibrationError (one line naming the
    file) when it is missing or malformed."""
    p = Path(path).expanduser()
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CalibrationError(f"{p}: no such IMU calibration file") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise CalibrationError(f"{p}: cannot read the IMU calibration ({' '.join(str(exc).split())[:200]})") from None
    try:
        return ImuCalibration.from_dict(data)
    except CalibrationError as exc:
        raise CalibrationError(f"{p}: {exc}") from None


def calibration_path_for(library_path: str | Path | None, library_name: str) -> Path:
    """Where a learnt calibration is kept by default: beside a user's library file
    (``<stem>.imu.yaml``), or ``~/.ros/gait_estimator/<name>.imu.yaml`` for a bundled one."""
    from .resources import config_dir

    if library_path:
        lib = Path(library_path)
        try:
            bundled = lib.resolve().is_relative_to(config_dir().resolve())
        except Exception:
            bundled = True
        if not bundled and lib.is_file():
            return lib.with_name(lib.stem + ".imu.yaml")
    return Path.home() / ".ros" / "gait_estimator" / f"{library_name}.imu.yaml"
