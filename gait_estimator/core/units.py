"""Whether a stream's angles can be degrees: the check that catches ``input_units`` set wrong.

The estimator reads degrees (converted from the input's configured units). Segment angles of a
person lie within +-180 deg, and walking swings the thigh and shank by tens of degrees. So, at
the end of every ``STEP_S`` of input:

* any |angle| in that step above ``MAX_DEG``: these cannot be degrees (degrees read as radians
  give 57x);
* over the ``WINDOW_S`` before that step, one channel moved by ``RADIAN_RANGE`` or more and
  another by half that, and every |angle| of the window and the step stayed within
  ``RADIAN_BOUND``: radians read as degrees (walking in radians: segment angles within +-1.2,
  the shank's range about 1, the thigh's 0.7). A wearer moving in degrees leaves +-1.6 within a
  step (a start from a pose at 0), one standing or shifting weight in radians reads as one
  standing still in degrees: the check decides from the first steps. A wearer whose four angles
  all stay within +-1.6 deg while swaying by ``RADIAN_RANGE`` or more would be flagged.

``UnitsCheck.observe`` is the one rule, O(1) per sample; the node warns (throttled) and its
diagnostics say WARN, the offline commands print one warning line (``first_problem``).
"""

from __future__ import annotations

import math
import operator
from collections import deque
from collections.abc import Collection, Sequence

import numpy as np

STEP_S = 0.25
WINDOW_S = 1.0
MAX_DEG = 360.0
RADIAN_BOUND = 1.6
RADIAN_RANGE = 0.5


class UnitsCheck:
    """Watches a stream of angles (degrees, as converted from ``input_units``) and says when they
    cannot be degrees. ``problem`` keeps the first verdict until ``reset``."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.problem: str | None = None
        self._start: float | None = None
        self._low = [math.inf] * 4
        self._high = [-math.inf] * 4
        self._steps: deque[tuple[list[float], list[float]]] = deque(maxlen=round(WINDOW_S / STEP_S))

    def observe(self, time_s: float, x: Sequence[float]) -> str | None:
        """Take one sample ``x`` (4 angles, degrees) at ``time_s`` (s); return a new verdict (a
        sentence) the first time the step it ends shows angles that cannot be degrees."""
        low, high = self._low, self._high
        x0, x1, x2, x3 = x
        if x0 < low[0]:
            low[0] = x0
        if x0 > high[0]:
            high[0] = x0
        if x1 < low[1]:
            low[1] = x1
        if x1 > high[1]:
            high[1] = x1
        if x2 < low[2]:
            low[2] = x2
        if x2 > high[2]:
            high[2] = x2
        if x3 < low[3]:
            low[3] = x3
        if x3 > high[3]:
            high[3] = x3
        if self._start is None:
            self._start = time_s
        if time_s - self._start < STEP_S or self.problem is not None:
            return None
        steps = self._steps
        verdict = step_verdict(low, high, steps)
        steps.append((low, high))
        self._start, self._low, self._high = None, [math.inf] * 4, [-math.inf] * 4
        if verdict is not None:
            self.problem = verdict
        return verdict


def step_verdict(low: Sequence[float], high: Sequence[float],
                 before: Collection[tuple[Sequence[float], Sequence[float]]]) -> str | None:
    """The verdict on a step whose angles (degrees) ranged from ``low`` to ``high`` per channel,
    after the steps ``before`` it (each a (low, high) pair; ``WINDOW_S`` of them at most)."""
    peak = max(-min(low), max(high))
    if peak > MAX_DEG:
        return (f"angles reach {peak:.0f} deg: not degrees (radians read as degrees give at most "
                f"{MAX_DEG:.0f}); the input is likely in degrees read as radians")
    if peak > RADIAN_BOUND or not before:
        return None
    window_low = list(map(min, zip(*(b[0] for b in before), strict=True)))
    window_high = list(map(max, zip(*(b[1] for b in before), strict=True)))
    peak = max(peak, -min(window_low), max(window_high))
    ranges = sorted(map(operator.sub, window_high, window_low))
    if peak <= RADIAN_BOUND and ranges[-1] >= RADIAN_RANGE and ranges[-2] >= RADIAN_RANGE / 2:
        return (f"angles stay within +-{peak:.2f} deg while the segments move: the input is likely in "
                "radians read as degrees")
    return None


def first_problem(time_s: np.ndarray, angles_deg: np.ndarray) -> tuple[float, str] | None:
    """``UnitsCheck`` over a whole recording: (time of the verdict, s; the verdict), or None."""
    check = UnitsCheck()
    for t, row in zip(np.asarray(time_s).tolist(), np.asarray(angles_deg).tolist(), strict=True):
        verdict = check.observe(t, row)
        if verdict is not None:
            return t, verdict
    return None
