"""Exceptions raised for bad user input (files, parameters, recordings)."""

from __future__ import annotations


class GaitEstimatorError(Exception):
    """A problem with user input that the CLI reports in one line (exit code 2)."""


class LibraryError(GaitEstimatorError):
    """A kernel library file is missing, malformed or inconsistent."""


class RecordingError(GaitEstimatorError):
    """A recording file is missing, malformed or inconsistent."""


EXTRAS: dict[str, str] = {
    "scipy": "analysis",
    "matplotlib": "analysis",
    "rosbags": "bags",
    "numba": "fast",
    "rclpy": "ros",
    "aiohttp": "dashboard",
}
"""Optional third-party packages -> the ``pip install 'gait_estimator[EXTRA]'`` extra that brings them."""


class MissingExtraError(GaitEstimatorError):
    """An optional dependency is not installed; the message names the extra that installs it."""

    def __init__(self, extra: str, module: str) -> None:
        self.extra = extra
        self.module = module
        super().__init__(f"needs the '{extra}' extra ({module} is not installed): "
                         f"pip install 'gait_estimator[{extra}]'")


def missing_extra(exc: ImportError) -> MissingExtraError | None:
    """The MissingExtraError for an ImportError of an optional dependency (EXTRAS), else None."""
    root = (getattr(exc, "name", None) or "").split(".")[0]
    return MissingExtraError(EXTRAS[root], root) if root in EXTRAS else None
