"""The IMU calibration's file (YAML, atomic write) and where it is kept."""

from __future__ import annotations

from pathlib import Path

import yaml

from ..core.imu import CalibrationError, ImuCalibration
from .atomic import atomic_write_text


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
