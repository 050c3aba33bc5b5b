"""The first stage of the estimator: checks each sample and its stamp, and tells the pipeline when
a gap in the stamps restarts the window or forgets what the walking calibrations learnt."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .channels import Sample
from .options import EstimatorConfig
from .rejections import NON_FINITE, NON_INCREASING_STAMP, SampleRejected


@dataclass(frozen=True)
class GapParams:
    """Gap thresholds (the options of the same names).

    Attributes:
        max_gap_s: A longer gap (s) between stamps restarts the window; 0 = never.
        calibration_reset_gap_s: A longer gap (s) also forgets the learnt sensor offsets and
            cadence (the sensors may have been re-donned); 0 = never.
    """

    max_gap_s: float = EstimatorConfig.max_gap_s
    calibration_reset_gap_s: float = EstimatorConfig.calibration_reset_gap_s
    restart_back_s: float = 0.0
    """A stamp more than this (s) before the previous one is a restarted stream (accepted, the
    window restarts); a smaller step back, or any while this is 0, is rejected."""


class GapVerdict(NamedTuple):
    restart_window: bool
    reset_calibration: bool
    jumped_back: bool = False


NO_GAP = GapVerdict(False, False)
JUMPED_BACK = GapVerdict(True, False, True)


class GapCheck:
    """Rejects non-finite samples and stamps that do not increase, and measures the gap since the
    previous accepted stamp.

    Args:
        params: Gap thresholds; may be replaced at any sample (``params`` attribute).
    """

    def __init__(self, params: GapParams) -> None:
        self.params = params
        self.last_time: float | None = None

    def reset(self) -> None:
        """Forget the previous stamp: the next sample starts a stream."""
        self.last_time = None

    def admit(self, time_s: float, x: Sample) -> GapVerdict:
        """Accept sample ``x`` (degrees) stamped ``time_s`` (seconds).

        Raises SampleRejected (a ValueError) for a non-finite sample or stamp, or a stamp not
        after the previous one; the state is then unchanged.
        """
        if not (math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2]) and math.isfinite(x[3])):
            raise SampleRejected(NON_FINITE, f"non-finite sample {list(x)} at {time_s}")
        return self.admit_stamp(time_s)

    def admit_stamp(self, time_s: float) -> GapVerdict:
        """The stamp rule of every stream (the estimator's, ``StreamGuard``'s, the IMU flow's):
        accept ``time_s`` (seconds) and say what its gap does; a jump back by more than
        ``restart_back_s`` restarts the stream. Raises SampleRejected (non_finite,
        non_increasing_stamp) without changing state."""
        if not math.isfinite(time_s):
            raise SampleRejected(NON_FINITE, f"non-finite stamp {time_s}")
        last = self.last_time
        if last is not None and time_s <= last:
            if 0 < self.params.restart_back_s < last - time_s:
                self.last_time = time_s
                return JUMPED_BACK
            raise SampleRejected(NON_INCREASING_STAMP, f"stamp {time_s:.6f} s is not after the previous {last:.6f} s")
        self.last_time = time_s
        if last is None:
            return NO_GAP
        gap = time_s - last
        p = self.params
        restart, recalibrate = 0 < p.max_gap_s < gap, 0 < p.calibration_reset_gap_s < gap
        return GapVerdict(restart, recalibrate) if restart or recalibrate else NO_GAP

    def admit_many(self, time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The bulk form of ``admit`` for stamps (T,) already checked (finite, increasing, after
        ``last_time``): per stamp, whether its gap restarts the window and whether it resets the
        calibrations."""
        prev = np.concatenate([[math.nan if self.last_time is None else self.last_time], time_s[:-1]])
        gap = time_s - prev
        p = self.params
        if time_s.size:
            self.last_time = float(time_s[-1])
        return (0 < p.max_gap_s) & (gap > p.max_gap_s), (0 < p.calibration_reset_gap_s) & (gap > p.calibration_reset_gap_s)
