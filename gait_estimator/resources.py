"""Finding files shipped with the package (bundled kernel libraries, default parameters).

They live in the package's ``config/`` directory, which is installed to
``share/gait_estimator/config`` by both ``colcon build`` and ``pip install``; running from a
source checkout uses the checkout's ``config/`` directly.
"""

from __future__ import annotations

import sys
from pathlib import Path

PACKAGE_NAME = "gait_estimator"
DEFAULT_LIBRARY = "able_bodied"
_BUNDLED = {"able_bodied": "able_bodied.yaml", "prosthesis": "prosthesis.yaml"}


def config_dir() -> Path:
    """The directory holding ``kernels/`` and ``estimator.yaml``."""
    candidates = [Path(__file__).resolve().parent.parent / "config"]
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        try:
            candidates.insert(0, Path(get_package_share_directory(PACKAGE_NAME)) / "config")
        except (PackageNotFoundError, OSError, ValueError):
            pass
    except ImportError:
        pass
    candidates.append(Path(sys.prefix) / "share" / PACKAGE_NAME / "config")
    for c in candidates:
        if (c / "kernels").is_dir():
            return c
    raise FileNotFoundError(
        "bundled config directory not found (looked in: " + ", ".join(str(c) for c in candidates) + ")"
    )


def bundled_library_names() -> list[str]:
    return sorted(_BUNDLED)


def bundled_library_path(name: str = DEFAULT_LIBRARY) -> Path:
    """Path of a bundled kernel library (``able_bodied`` or ``prosthesis``)."""
    if name not in _BUNDLED:
        raise KeyError(f"unknown bundled library {name!r} (have: {', '.join(sorted(_BUNDLED))})")
    return config_dir() / "kernels" / _BUNDLED[name]
