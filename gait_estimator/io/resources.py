"""Finding files shipped with the package: kernel libraries and default parameters
(``config/``), and the paper's recordings and reference output (``data/``).

Both folders are installed to ``share/gait_estimator/`` by ``colcon build`` and
``pip install``; a source checkout (or an editable install) uses the checkout's folders.
"""

from __future__ import annotations

import sys
from pathlib import Path

PACKAGE_NAME = "gait_estimator"
DEFAULT_LIBRARY = "able_bodied"
_BUNDLED = {"able_bodied": "able_bodied.yaml", "prosthesis": "prosthesis.yaml"}
DEMO_RECORDING = "swge/recordings/Multispeed_Walk_AB.csv"
"""The recording ``gait-estimator demo`` streams by default (relative to ``data_dir()``)."""


def _share_candidates() -> list[Path]:
    candidates = [Path(__file__).resolve().parents[2]]  # source checkout / editable install
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

        try:
            candidates.insert(0, Path(get_package_share_directory(PACKAGE_NAME)))
        except (PackageNotFoundError, OSError, ValueError):
            pass
    except ImportError:
        pass
    # pip install (also --prefix/--user): PREFIX/lib/pythonX.Y/site-packages/gait_estimator/io/ here,
    # data_files in PREFIX/share/gait_estimator
    here = Path(__file__).resolve()
    if len(here.parents) > 5:
        candidates.append(here.parents[5] / "share" / PACKAGE_NAME)
    candidates.append(Path(sys.prefix) / "share" / PACKAGE_NAME)
    return candidates


def _find(sub: str, marker: str) -> Path:
    candidates = [c / sub for c in _share_candidates()]
    for c in candidates:
        if (c / marker).exists():
            return c
    raise FileNotFoundError(f"bundled {sub} directory not found (looked in: " + ", ".join(str(c) for c in candidates) + ")")


def config_dir() -> Path:
    """The directory holding ``kernels/`` and ``estimator.yaml``."""
    return _find("config", "kernels")


def data_dir() -> Path:
    """The directory holding the bundled recordings (``swge/``, with its LICENSE)."""
    return _find("data", "swge/LICENSE")


def data_path(relative: str) -> Path:
    """A bundled data file, e.g. ``data_path("swge/recordings/LG_2_Ramp_AB_Sample.csv")``."""
    p = data_dir() / relative
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such bundled data file")
    return p


def bundled_library_names() -> list[str]:
    return sorted(_BUNDLED)


def bundled_library_path(name: str = DEFAULT_LIBRARY) -> Path:
    """Path of a bundled kernel library (``able_bodied`` or ``prosthesis``)."""
    if name not in _BUNDLED:
        raise KeyError(f"unknown bundled library {name!r} (have: {', '.join(sorted(_BUNDLED))})")
    return config_dir() / "kernels" / _BUNDLED[name]
