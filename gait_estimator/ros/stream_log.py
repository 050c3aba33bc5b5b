"""``estimator_node``'s log lines about its input: dropped samples and the stream's events
(``core/gait_stream.StreamEvent``), throttled per reason or kind so that a bad stream cannot
flood the log."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Iterable
from typing import Any

from ..core.gait_stream import RESTART_BACK, RESTART_GAP, TEACH, TEACH_DONE, StreamEvent
from ..core.rejections import SampleRejected
from .teach import LOG_PREFIX

WARN_THROTTLE_S = 2.0
"""Minimum wall time (s) between two lines about dropped samples of the same reason (or window
restarts of the same kind)."""


class StreamLog:
    """Lines to ``logger``; ``source``: what a dropped input is named by ("dropped sample on ...: ")."""

    def __init__(self, logger: Any, source: str) -> None:
        self.logger = logger
        self.source = source
        self._warned_at: dict[str, float] = {}
        self._suppressed: Counter = Counter()

    def _throttled(self, key: str) -> int:
        """-1: suppressed (the last line of ``key`` is less than WARN_THROTTLE_S old), else how
        many were suppressed since that line."""
        now = time.monotonic()
        last = self._warned_at.get(key)
        if last is not None and now - last < WARN_THROTTLE_S:
            self._suppressed[key] += 1
            return -1
        self._warned_at[key] = now
        return self._suppressed.pop(key, 0)

    def rejected(self, exc: SampleRejected) -> None:
        more = self._throttled(exc.reason)
        if more >= 0:
            self.logger.warn(f"{self.source}{exc.reason}: {exc}"
                             + (f" ({more} more {exc.reason} dropped since the last warning)" if more else ""))

    def events(self, events: Iterable[StreamEvent]) -> bool:
        """Log ``events``; True if teaching ended among them."""
        done = False
        for event in events:
            kind, line = event.kind, event.line
            if kind in (RESTART_BACK, RESTART_GAP):
                more = self._throttled(kind)
                if more >= 0:
                    self.logger.info(f"{line}: window restarted"
                                     + (f" ({more} more restarts since the last message)" if more else ""))
                continue
            line = LOG_PREFIX + line if kind in (TEACH, TEACH_DONE) else line
            if event.warn:  # rclpy fixes a call site's severity at its first call: one site per severity
                self.logger.warning(line)
            else:
                self.logger.info(line)
            done = done or kind == TEACH_DONE
        return done
