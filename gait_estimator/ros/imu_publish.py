"""Publishing segment angles as four ``sensor_msgs/Imu`` topics (``bench-node --input imu``).

The messages are built as CDR bytes (io/cdr.py ``write_imu``, the inverse of ``read_imu``) and
published serialised, so that the bench spends a few microseconds per message, not the tens rclpy
needs to fill and convert an Imu object. The fields come from ``analysis/imu_sagittal.py``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..analysis.imu_sagittal import BENCH_LATERAL_AXES, BENCH_PROXIMAL_AXES, sagittal_imu
from ..core.channels import CHANNELS, N_CHANNELS
from ..io.cdr import write_imu

IMU_INPUTS = ("imu", "imu-raw")
"""``bench-node --input`` values with IMU messages: with orientations, or gyro + accelerometer only."""


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


def node_imu_arguments(calibration_path: str, lateral: Sequence[str] = BENCH_LATERAL_AXES,
                       proximal: Sequence[str] = BENCH_PROXIMAL_AXES) -> list[str]:
    """``--ros-args`` of an estimator_node fed by ``imu_samples``: ``input_type: imu`` with the
    mounting configured (nothing to learn), its calibration file at ``calibration_path`` (read if
    it exists; pass one that does not, or a saved calibration would take precedence)."""
    def strings(v: Sequence[str]) -> str:
        return "[" + ",".join(f"'{a}'" for a in v) + "]"

    return ["-p", "input_type:=imu", "-p", f"imu_lateral_axes:={strings(lateral)}",
            "-p", f"imu_proximal_axes:={strings(proximal)}", "-p", f"imu_calibration_path:={calibration_path}"]
