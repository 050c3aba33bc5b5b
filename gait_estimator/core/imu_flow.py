"""Four IMUs' decoded messages -> segment angle samples, ROS-free: the IMU part of ``GaitStream``
(``gait_stream.py``), as ``estimator_node`` runs it with ``input_type: imu``.

Each message becomes its sensor's up direction (``imu_pairing.SensorInput``); the four streams
are paired by stamp (``ImuPairer``); a paired sample becomes four angles through the mounting
calibration (``imu_angles.ImuAngles``, which learns or checks it on the way). Until the
calibration is complete no sample gives angles. A saved or configured calibration is checked on
the first walking: a saved one that does not fit is learnt again; configured axes that do not fit
stay, reported (``check_problem``). After a gap in the paired stamps longer than
``calibration_reset_gap_s``, or a restarted stream, the calibration in use is checked again and
one being learnt starts again. What is worth a log line (and, for the caller, a file to write or
delete) comes back as ``StreamEvent`` through ``on_event``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

from .channels import CHANNELS, N_CHANNELS
from .gaps import NO_GAP, GapCheck, GapParams
from .imu import FUSION_BY_CHANNEL, CalibrationError, ImuCalibration, SegmentMount, Vec3
from .imu_angles import ImuAngles
from .imu_calibrator import ImuCalibrator
from .imu_learn import STILL_S, WALK_S, CalibrationCheck, check_configured
from .imu_pairing import UNPAIRED, ImuPairer, SensorInput
from .rejections import SampleRejected

IMU_INFO = "imu_info"
"""Event: a line about the IMU calibration (biases measured, checked, rechecked)."""
IMU_LEARNT = "imu_learnt"
"""Event: a calibration was learnt (``ImuFlow.calibrator.calibration``): save it; the line is its summary."""
IMU_NOT_FIT = "imu_not_fit"
"""Event: the calibration from the file does not fit the sensors now and is forgotten; the line
says what the check found."""
IMU_WRONG_AXES = "imu_wrong_axes"
"""Event: the configured axes do not fit the walking (they stay in use); an error line."""


def _ignore(_kind: str, _line: str) -> None:
    return None


class ImuFlow:
    """See the module docstring.

    Args:
        lateral, proximal, standing_deg: The configured axes and standing angles (``None``: learn).
        saved: A calibration from a file or the configured axes (None: learn one).
        from_file: ``saved`` came from a file (``source`` names it).
        configured: The axes are all configured (nothing to learn, nothing to save).
        frames: Per sensor, the frame_id its messages must carry ('' = any).
        tolerance_s: Largest stamp spread of the four messages of one sample.
        restart_back_s: A jump back of more than this (s) is a restarted sensor or stream.
        path: The calibration file's name, for the lines about a calibration from it.
        on_event: Called with (kind, line) of what is worth a log line (``GaitStream.attach_imu`` sets it).
    """

    def __init__(self, lateral: list[Vec3 | None], proximal: list[Vec3 | None], standing_deg: list[float],
                 saved: ImuCalibration | None, *, from_file: bool, configured: bool, frames: Sequence[str],
                 tolerance_s: float, restart_back_s: float, path: str,
                 on_event: Callable[[str, str], None] | None = None) -> None:
        self.pairer = ImuPairer(tolerance_s)
        self.inputs = [SensorInput(None, f.strip(), fusion, restart_back_s, on_restart=self.pairer.restarted)
                       for f, fusion in zip(frames, FUSION_BY_CHANNEL, strict=True)]  # raw: rate from stamps
        self.from_file = from_file
        self.configured = configured
        self.path = path
        self.on_event: Callable[[str, str], None] = on_event or _ignore
        self.calibrator = ImuCalibrator(lateral, proximal, standing_deg, saved, check=True)
        self.check_problem = ""
        """Configured axes that do not fit the walking (they stay in use): the check's line."""
        self.not_fit = False
        """The saved calibration did not fit (set by a check; ``GaitStream`` forgets what came from it)."""
        self.angles = ImuAngles(self.inputs, self.calibrator, self._biases_measured, self._learnt, self._checked)
        if saved is not None:
            self.angles.set_gyro_biases([m.gyro_bias_dps for m in saved.mounts])
        self.gaps = GapCheck(GapParams(0.0, 0.0, restart_back_s))  # GaitStream.attach_imu sets its thresholds

    @classmethod
    def from_settings(cls, lateral_axes: Sequence[str], proximal_axes: Sequence[str], standing_deg: Sequence[float],
                      from_file: ImuCalibration | None, *, frames: Sequence[str], tolerance_s: float,
                      restart_back_s: float, path: str) -> ImuFlow:
        """A flow from the node's settings: axis names per segment ('' = learn), standing angles,
        a calibration read from ``path`` (None: none there). Configured axes with no file are the
        calibration (nothing to learn, checked on the first walking). CalibrationError (one line)
        for invalid settings."""
        lateral, proximal = check_configured(list(lateral_axes), list(proximal_axes))
        standing = [float(v) for v in standing_deg]
        if len(standing) != N_CHANNELS or not all(math.isfinite(v) and abs(v) <= 90 for v in standing):
            raise CalibrationError(f"imu_standing_angles_deg: needs {N_CHANNELS} angles within +-90 deg")
        if len(frames) != N_CHANNELS:
            raise CalibrationError(f"imu_frame_ids: needs {N_CHANNELS} entries ('' = any frame)")
        configured = all(a is not None for a in lateral) and all(p is not None for p in proximal)
        saved = from_file
        if saved is None and configured:  # nothing to learn (and nothing to save)
            saved = ImuCalibration(tuple(SegmentMount(a, p, d) for a, p, d in zip(lateral, proximal, standing, strict=True)))
        return cls(lateral, proximal, standing, saved, from_file=from_file is not None, configured=configured,
                   frames=frames, tolerance_s=tolerance_s, restart_back_s=restart_back_s, path=path)

    def convert(self, sensor: int, stamp_ns: int, orientation: Any, cov0: float, gyro: Any, acc: Any,
                frame_id: str) -> Sequence[tuple[int, list[Any]]]:
        """One decoded message of ``sensor``: the paired samples it completes (stamp ns, items).
        Raises SampleRejected for a bad message (``GaitStream`` counts it)."""
        try:
            item = self.inputs[sensor].convert(stamp_ns, orientation, cov0, gyro, acc, frame_id)
        except SampleRejected as exc:
            raise SampleRejected(exc.reason, f"{CHANNELS[sensor]}: {exc}") from None
        return self.pairer.push(sensor, stamp_ns, item)

    def unpaired(self, before: int) -> list[SampleRejected]:
        """The messages dropped without partners since the pairer counted ``before``."""
        pairer = self.pairer
        if pairer.unpaired == before:
            return []
        waiting = [c for c, q in zip(CHANNELS, pairer.queues, strict=True) if not q]
        why = (f"no message from {', '.join(waiting)} within the pairing tolerance of the others" if waiting
               else "a message without partners within the pairing tolerance")
        return [SampleRejected(UNPAIRED, f"{why} (dropped so far: {dict(pairer.dropped)})")
                for _ in range(pairer.unpaired - before)]

    def set_gaps(self, calibration_reset_gap_s: float, restart_back_s: float) -> None:
        """A gap longer than ``calibration_reset_gap_s``, or a jump back by more than
        ``restart_back_s`` (a restarted sensor or stream), has the calibration checked again."""
        self.gaps.params = GapParams(0.0, calibration_reset_gap_s, restart_back_s)
        for sensor in self.inputs:
            sensor.stamps.params = GapParams(0.0, 0.0, restart_back_s)

    def sample(self, stamp_ns: int, items: list, emit: Callable[[tuple[float, ...], int], None]) -> None:
        """One paired sample: ``emit(angles, stamp_ns)`` once calibrated; a gap or restart first
        has the calibration checked again (``GapCheck``'s stamp rule)."""
        last = self.gaps.last_time
        try:
            gap = self.gaps.admit_stamp(stamp_ns * 1e-9)
        except SampleRejected:  # a small step back: the pairer's business, not a restart
            gap = NO_GAP
        if gap.reset_calibration:
            g = self.gaps.params.calibration_reset_gap_s
            self._recheck(f"gap of {stamp_ns * 1e-9 - last:.3f} s in IMU stamps > calibration_reset_gap_s {g:g} s")
        elif gap.jumped_back:
            self._recheck(f"IMU stamps jumped back by {(last or 0.0) - stamp_ns * 1e-9:.3f} s (a restarted stream)")
        self.angles.sample(stamp_ns, items, emit)

    @property
    def unchecked(self) -> bool:
        """The angles are not known to be right yet (a calibration to check, axes that do not fit)."""
        return self.calibrator.checking or bool(self.check_problem)

    def _biases_measured(self, biases_dps: Sequence[Vec3]) -> None:
        self.on_event(IMU_INFO, "IMU gyro bias measured at the standing pose (deg/s): " + "; ".join(
            f"{c} ({', '.join(f'{v:+.2f}' for v in b)})" for c, b in zip(CHANNELS, biases_dps, strict=True)))

    def _checked(self, found: CalibrationCheck) -> None:
        """The check of a saved or configured calibration on the first walking: a saved one that
        does not fit is forgotten (learnt again, or the configured axes used and checked);
        configured axes are kept and reported."""
        source = self.path if self.from_file else "imu_lateral_axes/imu_proximal_axes"
        if found.fits:
            self.check_problem = ""
            self.on_event(IMU_INFO, f"IMU calibration from {source} checked on the walking: {found.summary()}")
        elif self.from_file:
            self.forget()
            self.not_fit = True
            self.on_event(IMU_NOT_FIT, found.summary())
        else:
            self.check_problem = f"the configured {source} do not fit the walking: {found.summary()}"
            self.on_event(IMU_WRONG_AXES, self.check_problem + " (the angles are wrong; correct the parameters)")

    def _learnt(self, cal: ImuCalibration) -> None:
        self.from_file = False  # learnt now, or the configured axes: what a check reports is about them
        self.on_event(IMU_LEARNT, cal.summary())

    def forget(self) -> None:
        """Forget the calibration in use: back to the configured axes (the gyro biases last
        measured at a standing pose stay), and what is learnt or configured next neither comes
        from the file nor has a check's problem."""
        self.calibrator.reset()
        self.check_problem = ""
        self.from_file = False
        self.angles.set_gyro_biases(self.calibrator.gyro_biases or [(0.0, 0.0, 0.0)] * N_CHANNELS)

    def _recheck(self, why: str) -> None:
        """A gap longer than ``calibration_reset_gap_s`` or a restarted stream (``why``): the
        sensors may have been taken off and put on again. A calibration in use is checked again on
        the next walking, as a saved one is at start (one that does not fit is learnt again,
        unless it is the configured axes); one being learnt starts again from the next standing
        pose (learnt lateral axes kept by a standing request are forgotten)."""
        if self.calibrator.calibration is not None:  # in use: the configured axes' only if configured and no file
            self.from_file = self.from_file or not self.configured
            then = "the IMU calibration is checked again on the next walking"
        else:
            then = f"the IMU calibration is learnt again: stand still {STILL_S:g} s, then walk {WALK_S:g} s"
        self.calibrator.recheck()
        self.on_event(IMU_INFO, f"{why} (the sensors may have been re-donned): {then}")
