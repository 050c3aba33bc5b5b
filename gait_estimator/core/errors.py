"""Exceptions raised for bad user input (files, parameters, recordings)."""

from __future__ import annotations


class GaitEstimatorError(Exception):
    """A problem with user input that the CLI reports in one line (exit code 2)."""


class LibraryError(GaitEstimatorError):
    """A kernel library file is missing, malformed or inconsistent."""


class RecordingError(GaitEstimatorError):
    """A recording file is missing, malformed or inconsistent."""
