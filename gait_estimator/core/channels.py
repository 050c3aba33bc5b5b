"""Channel order used everywhere: kernels, recordings, matcher input and ROS messages."""

from __future__ import annotations

CHANNELS: tuple[str, ...] = ("right_thigh", "left_thigh", "right_shank", "left_shank")
"""Sagittal segment angles, in this order (the paper's d_i vector)."""

N_CHANNELS = len(CHANNELS)
