"""The services of ``estimator_node``: ``~/save_library`` and ``~/reset_calibration`` (the IMU
input adds ``~/calibrate_standing``, ``imu_input.py``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from std_srvs.srv import Trigger

from ..core.errors import GaitEstimatorError
from ..io.library_io import save_library
from .parameters import one_line

SAVE_LIBRARY_SERVICE = "~/save_library"
RESET_CALIBRATION_SERVICE = "~/reset_calibration"


class NodeServices:
    """The services of ``node`` (an EstimatorNode: its stream, IMU input and parameters)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        node.create_service(Trigger, SAVE_LIBRARY_SERVICE, self.save_library)
        node.create_service(Trigger, RESET_CALIBRATION_SERVICE, self.reset_calibration)

    def save_library(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/save_library``: write the library in use, with its taught modes and personalised
        kernels, to ``adapted_library_path``, and a learnt IMU calibration beside it (where the
        next start with that library looks for it)."""
        node = self.node
        est, taught = node.stream.estimator, node.stream.taught
        if est is None or (est.adapter is None and not taught):
            response.success = False
            response.message = ("no library yet: teach a mode first (teach_mode)" if est is None else
                                "no taught modes, and personalisation is off (adapt_rate is 0): nothing to save")
            return response
        path = node.get_parameter("adapted_library_path").value or str(
            Path.home() / ".ros" / "gait_estimator" / f"{est.library.name}_adapted.yaml")
        try:
            Path(path).expanduser().parent.mkdir(parents=True, exist_ok=True)
            lib = est.adapted_library()
            out = save_library(lib, Path(path).expanduser())
        except (GaitEstimatorError, OSError, ValueError) as exc:
            response.success, response.message = False, f"{path}: {one_line(exc)}"
            return response
        strides = lib.provenance.get("adaptation", {}).get("accepted_strides", {})
        response.success = True
        response.message = f"wrote {out} ({len(lib)} modes: {', '.join(lib.mode_names)}" + (
            f"; taught: {', '.join(taught)}" if taught else "") + (
            "; strides adopted: " + ", ".join(f"{m} {n}" for m, n in strides.items()) if est.adapter else "") + ")" + (
            node.imu.save_beside(out, lib.name) if node.imu is not None else "")
        node.get_logger().info(response.message)
        return response

    def reset_calibration(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        """``~/reset_calibration``: forget the learnt sensor offsets and cadence (after
        re-donning, or for another wearer), and the IMU input's calibration."""
        stream, imu = self.node.stream, self.node.imu
        est = stream.estimator
        if est is None:  # no library yet: only the IMU input may have learnt something
            response.success = imu is not None
            response.message = ("no library yet" + imu.reset_calibration()) if imu else "no library yet: nothing calibrated"
            stream.reset_calibration("the IMU calibration was reset" if imu else "")
        else:
            before, scale = est.sensor_offset_deg.copy(), est.cadence_scale
            stream.reset_calibration("the IMU calibration was reset" if imu else "")
            response.success = True
            response.message = ("sensor offsets reset to 0 (were " + ", ".join(f"{v:.2f}" for v in before) + " deg)"
                                + (f", learnt time scale {scale:.3f} forgotten" if math.isfinite(scale) else "")
                                + (imu.reset_calibration() if imu is not None else ""))
        self.node.get_logger().info(response.message)
        return response
