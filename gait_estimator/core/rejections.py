"""Why a sample of a stream is dropped: the reason codes counted in diagnostics and summaries,
and the exception that carries one (ROS-free)."""

from __future__ import annotations

# Reason codes, as counted in diagnostics and summaries.
NON_FINITE = "non_finite"
MISSING_JOINT = "missing_joint"
WRONG_LENGTH = "wrong_length"
NON_INCREASING_STAMP = "non_increasing_stamp"
OUT_OF_RANGE = "out_of_range"
MALFORMED = "malformed"  # bytes that do not decode as the input message type (live streams)
REASONS = (NON_FINITE, MISSING_JOINT, WRONG_LENGTH, NON_INCREASING_STAMP, OUT_OF_RANGE, MALFORMED)
ANGLE_MESSAGE_ONLY = (MISSING_JOINT, WRONG_LENGTH)
"""Reasons only a segment-angle message gives (not the IMU input)."""

class SampleRejected(ValueError):
    """A message that cannot become a sample; ``reason`` is one of REASONS."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason
