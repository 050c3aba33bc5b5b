"""Stamp rules of a stream of samples and the reasons a sample is dropped, ROS-free.

``StreamGuard`` checks time stamps (non-increasing -> rejected; a gap longer than ``max_gap_s`` ->
the matcher window must restart; optionally, a jump back by more than ``restart_back_s`` -> a
restarted stream, the window must restart too) and counts rejections by reason.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import replace

from .gaps import GapCheck, GapParams
from .options import EstimatorConfig
from .rejections import SampleRejected

STREAM_RESTART_S = 1.0
"""Jump back (s) that restarts a live stream when ``max_gap_s`` is 0 (gap check off); see
``restart_threshold``."""


def restart_threshold(max_gap_s: float) -> float:
    """How far (s) stamps must jump back to count as a restarted stream rather than a reordered or
    duplicated sample: ``max_gap_s`` (the same discontinuity that restarts the window going
    forward), or STREAM_RESTART_S while the gap check is off (``max_gap_s`` 0 or inf)."""
    return max_gap_s if 0 < max_gap_s < math.inf else STREAM_RESTART_S


class StreamGuard:
    """Stamp checks and rejection counts for one input stream: ``GapCheck``'s stamp rule
    (``core/gaps.py``, the one the estimator and the IMU flow use) with counts.

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

    def __init__(self, max_gap_s: float = EstimatorConfig.max_gap_s, restart_back_s: float = 0.0) -> None:
        self.check = GapCheck(GapParams(max_gap_s, 0.0, restart_back_s))
        self.rejected: Counter = Counter()
        self.last_detail: dict[str, str] = {}
        """The latest rejection's text, by reason."""
        self._reported: Counter = Counter()
        self.resets = 0
        self.restarts = 0

    @property
    def max_gap_s(self) -> float:
        return self.check.params.max_gap_s

    @property
    def restart_back_s(self) -> float:
        return self.check.params.restart_back_s

    @restart_back_s.setter
    def restart_back_s(self, seconds: float) -> None:
        self.check.params = replace(self.check.params, restart_back_s=seconds)

    def accept(self, stamp_s: float) -> bool:
        """Accept a sample stamped ``stamp_s``; True if the window must restart before it
        (a gap, counted in ``resets``, or a jump back, counted in ``restarts``). Raises
        SampleRejected (non_increasing_stamp, non_finite) without changing state."""
        verdict = self.check.admit_stamp(stamp_s)
        if verdict.jumped_back:
            self.restarts += 1
        elif verdict.restart_window:
            self.resets += 1
        return verdict.restart_window

    def reject(self, exc: SampleRejected) -> None:
        self.rejected[exc.reason] += 1
        self.last_detail[exc.reason] = str(exc)

    def main_rejection(self, ignore: str = "") -> tuple[int, str]:
        """The rejections since the previous call, but those for ``ignore``: how many, and
        ``reason: its latest detail`` of the most frequent ('' when none)."""
        new = self.rejected - self._reported
        self._reported = Counter(self.rejected)
        new.pop(ignore, None)
        if not new:
            return 0, ""
        reason = new.most_common(1)[0][0]
        return sum(new.values()), f"{reason}: {self.last_detail[reason]}"

    @property
    def rejected_total(self) -> int:
        return int(sum(self.rejected.values()))
