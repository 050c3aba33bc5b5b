"""Paired IMU samples -> segment angles through a calibration learnt or checked on the way, ROS-free.

``ImuAngles`` is the flow of estimator_node's IMU input after pairing (``ros/imu_input.py``), so
that benchmarks and tests run exactly what the node runs: while no calibration is complete, each
sample goes to ``ImuCalibrator.add`` and no angles come out; the raw sensors are fused with the
standing pose's gyro biases from the wearer's first move on. A calibration in use but not checked
yet (a file, configured axes) gives angles, then ``ImuCalibrator.check`` looks at the walking.
What the node does about a learnt calibration or a check's verdict (save, log, forget) is its own,
through the hooks.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

from .channels import N_CHANNELS
from .imu import ImuCalibration, Vec3
from .imu_calibrator import ImuCalibrator
from .imu_learn import CalibrationCheck


class SensorInput(Protocol):
    """One sensor's input (``core/imu_pairing.SensorInput``) as far as the flow sets it."""

    def set_gyro_bias(self, bias_dps: Vec3) -> None: ...


def _ignore(_: Any) -> None:
    return None


class ImuAngles:
    """The four sensors' paired samples -> their segments' angles (deg), none while learning.

    Args:
        inputs: The four ``SensorInput`` (CHANNELS order) whose gyro biases the flow sets.
        calibrator: Learns or checks the calibration.
        on_gyro_biases: Called with the four sensors' gyro biases (deg/s) once a standing pose of
            the stream has ended, after they are applied.
        on_learnt: Called with a calibration ``calibrator`` has just completed (its biases applied).
        on_checked: Called with the verdict on a calibration that was being checked (after the
            sample's angles); it may ``calibrator.reset()``.
    """

    def __init__(self, inputs: Sequence[SensorInput], calibrator: ImuCalibrator,
                 on_gyro_biases: Callable[[Sequence[Vec3]], None] = _ignore,
                 on_learnt: Callable[[ImuCalibration], None] = _ignore,
                 on_checked: Callable[[CalibrationCheck], None] = _ignore) -> None:
        if len(inputs) != N_CHANNELS:
            raise ValueError(f"ImuAngles needs {N_CHANNELS} sensor inputs, got {len(inputs)}")
        self.inputs = list(inputs)
        self.calibrator = calibrator
        self.on_gyro_biases, self.on_learnt, self.on_checked = on_gyro_biases, on_learnt, on_checked

    def set_gyro_biases(self, biases_dps: Sequence[Vec3]) -> None:
        """The raw sensors' gyro biases (deg/s, sensor frame), subtracted before fusion from now on."""
        for sensor, bias in zip(self.inputs, biases_dps, strict=True):
            sensor.set_gyro_bias(bias)

    def sample(self, stamp_ns: int, items: Sequence[Any], emit: Callable[[tuple[float, ...], int], None]) -> None:
        """One paired sample (stamp in ns; ``SensorInput.convert``'s (up, gyro, acc) per sensor):
        ``emit(angles, stamp_ns)`` with the four segment angles (deg, CHANNELS order) once a
        calibration is in use; nothing while it is learnt. A calibration being checked gives its
        angles before the check attempt runs on the sample, so that the attempt's cost does not
        delay them."""
        i0, i1, i2, i3 = items
        ups = (i0[0], i1[0], i2[0], i3[0])
        calibrator = self.calibrator
        cal, checking = calibrator.calibration, calibrator.checking
        if cal is not None:
            emit(cal.angles_deg(ups), stamp_ns)
            if not checking:
                return
        t = stamp_ns * 1e-9
        gyro, acc = (i0[1], i1[1], i2[1], i3[1]), (i0[2], i1[2], i2[2], i3[2])
        if cal is None:
            biases = calibrator.gyro_biases
            learnt = calibrator.add(t, ups, gyro, acc)
            if calibrator.gyro_biases is not biases:  # a standing pose has ended: its biases from now on
                self.set_gyro_biases(calibrator.gyro_biases)
                self.on_gyro_biases(calibrator.gyro_biases)
            if learnt is not None:
                self.set_gyro_biases([m.gyro_bias_dps for m in learnt.mounts])
                self.on_learnt(learnt)
            return
        found = calibrator.check(t, ups, gyro, acc)
        if calibrator.calibration is not cal:  # this stream's gyro biases, from its standing pose
            biases = [m.gyro_bias_dps for m in calibrator.calibration.mounts]
            self.set_gyro_biases(biases)
            self.on_gyro_biases(biases)
        if found is not None:
            self.on_checked(found)
