"""One entry point for every recording source: project CSV, reference CSV, rosbag2."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..core.errors import RecordingError
from .bag import is_bag_path, read_bag
from .imu_bag import is_imu_bag, read_imu_bag
from .read_options import ReadOptions
from .recording import Recording, expected_columns, is_project_csv, is_reference_csv, read_project_csv, read_reference_csv

READERS: tuple[tuple[Callable[[Path], bool], Callable[..., Recording]], ...] = (
    (is_imu_bag, read_imu_bag),  # four sensor_msgs/Imu topics -> angles (io/imu_bag.py)
    (is_bag_path, read_bag),
    (is_reference_csv, read_reference_csv),
    (is_project_csv, read_project_csv),
)
"""(detect, read) pairs, tried in order: the first ``detect(path)`` that is true reads it."""


def read_recording(path: str | Path, options: ReadOptions | None = None, /, **values: Any) -> Recording:
    """Read a recording from a project CSV, a reference CSV or a rosbag2 directory/file.

    Args:
        path: File or directory.
        options, values: ReadOptions, then fields by name, for whichever reader reads ``path``;
            ``imu_topics`` reads a bag's four Imu topics even when it also has an angle topic.

    Raises:
        RecordingError: one line naming the file and what is wrong.
        TypeError: an unknown option.
    """
    p = Path(path)
    o = ReadOptions.of(options, values)
    if not p.exists():
        raise RecordingError(f"{p}: no such file or directory")
    if o.imu_topics and is_bag_path(p):  # named IMU topics: read them, whatever else the bag holds
        return read_imu_bag(p, o)
    for detect, read in READERS:
        if detect(p):
            return read(p, o)
    if p.is_file() and p.suffix.lower() == ".csv":
        raise RecordingError(f"{p}: not a recognised recording: {expected_columns(p)}")
    raise RecordingError(f"{p}: not a recognised recording (expected a CSV file or a rosbag2 directory)")
