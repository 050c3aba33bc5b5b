"""Channel order used everywhere: kernels, recordings, matcher input and ROS messages."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

CHANNELS: tuple[str, ...] = ("right_thigh", "left_thigh", "right_shank", "left_shank")
"""Sagittal segment angles, in this order (the paper's d_i vector)."""

N_CHANNELS = len(CHANNELS)

Sample = tuple[float, float, float, float]
"""One sample as four Python floats, CHANNELS order."""


def sample_values(sample: Sequence[float] | np.ndarray) -> Sample:
    """The four values of one sample (CHANNELS order) as Python floats.

    The live path hands samples from stage to stage as such tuples: a tuple or list costs no
    numpy call here, an array one. Raises ValueError unless ``sample`` holds exactly four numbers.
    """
    if isinstance(sample, np.ndarray):
        sample = sample.tolist() if sample.ndim == 1 else sample.ravel().tolist()
    try:
        a, b, c, d = sample
        return float(a), float(b), float(c), float(d)
    except (TypeError, ValueError):
        raise ValueError(f"a sample is {N_CHANNELS} numbers ({', '.join(CHANNELS)}), got {sample!r}") from None
