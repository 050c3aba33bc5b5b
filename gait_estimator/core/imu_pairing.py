"""Four ``sensor_msgs/Imu`` streams -> paired sensor samples, ROS-free (the node and bag reading).

* ``SensorInput``: one sensor's message fields -> its up direction (``core/imu.py``): from the
  orientation, or (``orientation_covariance[0] == -1``, REP 145: no orientation) from gyro +
  accelerometer through ``core/ahrs.make_fusion``; bad messages raise ``SampleRejected`` (non-finite values,
  a zero quaternion or acceleration, a stamp not after the sensor's previous one).
* ``ImuPairer``: the four streams paired by stamp within a tolerance; a message without partners
  is dropped (``unpaired``), so a silent sensor stops the samples instead of repeating its last
  value. ``auto_tolerance_s``: the tolerance of unsynchronised sensors, from their stamps.
* The mounting learnt or checked from the paired samples: ``core/imu_calibrator.py``; its file:
  ``io/imu_stream.py``.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Callable, Sequence
from typing import Any, NoReturn

import numpy as np

from .ahrs import CompiledFusion, make_fusion
from .channels import CHANNELS, N_CHANNELS
from .gaps import JUMPED_BACK, GapCheck, GapParams
from .imu import DEFAULT_FUSION, STANDARD_GRAVITY, FusionParams, Vec3
from .rejections import ANGLE_MESSAGE_ONLY, NON_FINITE, OUT_OF_RANGE, REASONS, SampleRejected
from .stamps import STREAM_RESTART_S

ZERO_NORM = "zero_norm"
UNPAIRED = "unpaired"
WRONG_FRAME = "wrong_frame"
IMU_REASONS = (*(r for r in REASONS if r not in ANGLE_MESSAGE_ONLY), ZERO_NORM, UNPAIRED, WRONG_FRAME)
"""Every reason four-IMU input can be rejected for."""
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


class SensorInput:
    """One IMU's messages -> (up, gyro deg/s, acc g), sensor frame; see the module docstring.

    Args:
        rate_hz: Nominal rate for the raw-input fusion (Hz); None = measured from the first
            ``rate_steps`` stamp steps (a live stream; until then 200 Hz), again after a restart.
        frame_id: The ``header.frame_id`` this sensor's messages must carry ('' = any).
        params: Settings of the raw-input fusion.
        restart_back_s: Two messages in a row stamped more than this (s) before the previous
            accepted one, the second after the first, are a restarted sensor (a driver restart, a
            bag played again; ``GapCheck`` with ``confirm_restart``): from the second on they are
            accepted, the fusion started afresh and ``restarts`` counted; a single such message,
            or a smaller step back, is rejected (0 = always rejected).
        on_restart: Called with the stamp (ns) of a message that restarted the sensor, before it
            is converted (``ImuPairer.restarted``).
    """

    def __init__(self, rate_hz: float | None = 200.0, frame_id: str = "", params: FusionParams = DEFAULT_FUSION,
                 restart_back_s: float = STREAM_RESTART_S, rate_steps: int = RATE_STEPS,
                 on_restart: Callable[[int], None] | None = None) -> None:
        self._rate_hz = 200.0 if rate_hz is None else rate_hz
        self._measured = rate_hz is None
        self._steps: list[int] | None = [] if rate_hz is None else None  # stamp steps (ns) while measuring
        self.rate_steps = rate_steps
        self.params = params
        self.frame_id = frame_id
        self.stamps = GapCheck(GapParams(0.0, 0.0, restart_back_s), per_second=1e9, confirm_restart=True)
        """The stamp rule, on the stamps (ns) of the messages with usable values."""
        self.fusion: CompiledFusion | None = None
        self.gyro_bias_dps: Vec3 = (0.0, 0.0, 0.0)
        self.restarts = 0
        self.on_restart = on_restart

    def convert(self, stamp_ns: int, orientation: Any, orientation_cov0: float, gyro_rps: Any,
                acc_mps2: Any, frame_id: str = "") -> tuple[Sequence[float], Vec3, Vec3]:
        """Fields of one Imu message (quaternion x, y, z, w; rad/s; m/s^2) -> (up, gyro, acc)."""
        if self.frame_id and frame_id != self.frame_id:
            raise SampleRejected(WRONG_FRAME, f"frame_id {frame_id!r}, expected {self.frame_id!r}")
        gx, gy, gz = gyro_rps
        stamps = self.stamps
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
            if stamps.admit_stamp(stamp_ns) is JUMPED_BACK:
                self._restart(stamp_ns)
            return up, gyro, NO_RATES  # the accelerometer is the orientation filter's business
        ax, ay, az = acc_mps2
        if not (gx * gx + gy * gy + gz * gz < _MAX_RATE2 and 1e-6 <= ax * ax + ay * ay + az * az < _MAX_ACC2):
            self._reject_raw(gx, gy, gz, ax, ay, az)  # false for NaN too
        last = stamps.last_time
        if stamps.admit_stamp(stamp_ns) is JUMPED_BACK:
            self._restart(stamp_ns)
            last = None
        fusion = self.fusion
        if fusion is None:
            fusion = self.fusion = make_fusion(self._rate_hz, self.gyro_bias_dps, self.params)
        gx, gy, gz, ax, ay, az = gx * _RAD2DEG, gy * _RAD2DEG, gz * _RAD2DEG, ax / _G, ay / _G, az / _G
        up = fusion.update_xyz(gx, gy, gz, ax, ay, az, None if last is None else (stamp_ns - last) * 1e-9)
        if self._steps is not None and last is not None:
            self._measure_rate(stamp_ns - last)
        return up, (gx, gy, gz), (ax, ay, az)

    def _restart(self, stamp_ns: int) -> None:
        """The sensor restarted (a driver restart, a bag played again): its fusion starts afresh."""
        self.restarts += 1
        self.fusion = None
        if self._measured:  # the driver may come back at another rate
            self._steps = []
        if self.on_restart is not None:
            self.on_restart(stamp_ns)

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


def check_tolerance_s(tolerance_s: float) -> float:
    """``tolerance_s`` if it can be a pairing tolerance (s), else ValueError (one line)."""
    if not (math.isfinite(tolerance_s) and tolerance_s >= 0):
        raise ValueError(f"IMU pairing tolerance must be a finite number of seconds >= 0, got {tolerance_s!r}")
    return tolerance_s


class ImuPairer:
    """Pairs the four sensors' messages by stamp.

    Args:
        tolerance_s: Largest spread of the four stamps in one sample (s, >= 0); for sensors not
            sampled together see ``auto_tolerance_s``.
        max_queue: Messages kept per sensor while waiting for partners.
    """

    def __init__(self, tolerance_s: float = DEFAULT_TOLERANCE_S, max_queue: int = MAX_QUEUE) -> None:
        self.tolerance_ns = round(check_tolerance_s(tolerance_s) * 1e9)
        self.max_queue = max_queue
        self.queues: list[deque] = [deque() for _ in range(N_CHANNELS)]
        self.dropped: Counter = Counter()  # unpaired messages per sensor name
        self.unpaired = 0
        """Unpaired messages, all sensors (the sum of ``dropped``)."""

    def push(self, sensor: int, stamp_ns: int, item: Any) -> Sequence[tuple[int, list[Any]]]:
        """Add one accepted message; returns the samples it completes: (stamp_ns = the latest
        of the four, [item per sensor])."""
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

    def restarted(self, stamp_ns: int) -> None:
        """A sensor restarted with a message stamped ``stamp_ns`` (``SensorInput.on_restart``):
        drop what was queued under the old stamps."""
        limit = stamp_ns + self.tolerance_ns
        for i, old in enumerate(self.queues):
            kept = [m for m in old if m[0] <= limit]
            self._drop(i, len(old) - len(kept))
            self.queues[i] = deque(kept)

    def clear(self) -> None:
        for q in self.queues:
            q.clear()
