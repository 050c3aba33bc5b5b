"""argparse value types and the output-path check shared by the CLI modules (bad values: one-line usage errors)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from ..core.errors import GaitEstimatorError


def positive_int(text: str) -> int:
    """An integer > 0."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return v


def choice_list(allowed: tuple[str, ...]) -> Any:
    """A comma-separated list of values from ``allowed`` (at least one)."""

    def parse(text: str) -> list[str]:
        values = [v.strip() for v in text.split(",") if v.strip()]
        bad = [v for v in values if v not in allowed]
        if not values or bad:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {', '.join(allowed)}, got {text!r}")
        return values

    return parse


def prepare_output(path: str, option: str) -> None:
    """Create the parent folder of the output file ``path`` (given with ``option``) before any
    work is done, or raise a one-line GaitEstimatorError."""
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GaitEstimatorError(f"{option} {path}: {exc.strerror or exc}") from None


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def seconds(text: str) -> float:
    """A duration in seconds, >= 0 (inf allowed)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected seconds, got {text!r}") from None
    if math.isnan(v) or v < 0:
        raise argparse.ArgumentTypeError(f"expected seconds >= 0, got {text!r}")
    return v


def int_list(text: str) -> list[int]:
    """Comma-separated positive integers, e.g. ``7,70,700``."""
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None
    if not values or any(v <= 0 for v in values):
        raise argparse.ArgumentTypeError(f"expected positive integers, got {text!r}")
    return values
