"""Stamp rules of a stream of samples and the reasons a sample is dropped, ROS-free.

``StreamGuard`` checks time stamps (non-increasing -> rejected; a gap longer than ``max_gap_s`` ->
the matcher window must restart; optionally, a jump back by more than ``restart_back_s`` -> a
restarted stream, the window must restart too) and counts rejections by reason.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from .options import EstimatorConfig

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

STREAM_RESTART_S = 1.0
"""Jump back (s) that restarts a live stream when ``max_gap_s`` is 0 (gap check off); see
``restart_threshold``."""


class SampleRejected(ValueError):
    """A message that cannot become a sample; ``reason`` is one of REASONS."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


def restart_threshold(max_gap_s: float) -> float:
    """How far (s) stamps must jump back to count as a restarted stream rather than a reordered or
    duplicated sample: ``max_gap_s`` (the same discontinuity that restarts the window going
    forward), or STREAM_RESTART_S while the gap check is off (``max_gap_s`` 0 or inf)."""
    return max_gap_s if 0 < max_gap_s < math.inf else STREAM_RESTART_S


@dataclass
class StreamGuard:
    """Stamp checks and rejection counts for one input stream.

    Args:
        max_gap_s: A gap between accepted samples longer than this (seconds) means the window
            must restart (``accept`` returns True, counted in ``resets``); <= 0 or inf disables
            the check.
        restart_back_s: A stamp more than this (seconds) before the previous accepted one is a
            restarted stream (a publisher that restarted its clock, a clock jump back): the
            sample is accepted and the window must restart (``accept`` returns True, counted in
            ``restarts``). A smaller step back, or any step back while this is <= 0, is a
            reordered or duplicated sample: rejected (non_increasing_stamp).
    """

    max_gap_s: float = EstimatorConfig.max_gap_s
    restart_back_s: float = 0.0
    rejected: Counter = field(default_factory=Counter)
    last_detail: dict[str, str] = field(default_factory=dict)
    """The latest rejection's text, by reason."""
    _reported: Counter = field(default_factory=Counter, repr=False)
    accepted: int = 0
    resets: int = 0
    restarts: int = 0
    last_stamp: float | None = None

    def check_stamp(self, stamp_s: float) -> bool:
        """Validate the stamp of the next sample; True if the matcher must be reset first.

        Raises SampleRejected (non_increasing_stamp, non_finite) without changing state.
        """
        if not math.isfinite(stamp_s):
            raise SampleRejected(NON_FINITE, f"non-finite stamp {stamp_s}")
        last = self.last_stamp
        if last is None:
            return False
        if stamp_s <= last:
            if 0 < self.restart_back_s < last - stamp_s:
                return True
            raise SampleRejected(NON_INCREASING_STAMP, f"stamp {stamp_s:.6f} s is not after the previous {last:.6f} s")
        return 0 < self.max_gap_s < math.inf and stamp_s - last > self.max_gap_s

    def accept(self, stamp_s: float) -> bool:
        """Record an accepted sample at ``stamp_s``; True if the window must restart before it
        (a gap, counted in ``resets``, or a jump back, counted in ``restarts``)."""
        last = self.last_stamp
        reset = self.check_stamp(stamp_s)
        if reset and last is not None and stamp_s <= last:
            self.restarts += 1
        elif reset:
            self.resets += 1
        self.last_stamp = stamp_s
        self.accepted += 1
        return reset

    def reject(self, exc: SampleRejected) -> None:
        self.rejected[exc.reason] += 1
        self.last_detail[exc.reason] = str(exc)

    def main_rejection(self) -> str:
        """``reason: its latest detail`` of the most frequent rejection since the previous call
        ('' when none)."""
        new = self.rejected - self._reported
        self._reported = Counter(self.rejected)
        if not new:
            return ""
        reason = new.most_common(1)[0][0]
        return f"{reason}: {self.last_detail[reason]}"

    @property
    def rejected_total(self) -> int:
        return int(sum(self.rejected.values()))
