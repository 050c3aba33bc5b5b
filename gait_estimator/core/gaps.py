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
_INF = math.inf


class GapCheck:
    """The stamp rule of every stream (the estimator's, ``StreamGuard``'s, each IMU sensor's and
    the IMU flow's): rejects non-finite samples and stamps that do not increase, takes a jump back
    by more than ``restart_back_s`` as a restarted stream, and measures the gap since the previous
    accepted stamp.

    Args:
        params: Gap thresholds (s); may be replaced at any sample (``params`` attribute).
        per_second: Stamp units per second (1e9: integer nanoseconds, compared exactly).
        confirm_restart: A jump back restarts the stream only when the next stamp jumps back too
            and is after it (a driver restart, a bag played again); a single one is a stray old
            message, rejected.
    """

    def __init__(self, params: GapParams, per_second: float = 1.0, confirm_restart: bool = False) -> None:
        self.per_second = per_second
        self.confirm_restart = confirm_restart
        self.params = params
        self.last_time: float | None = None
        self.restart_from: tuple[float, float] | None = None
        """A stamp far back, rejected, and the stamp it was before: the next one may confirm a
        restart while no other stamp was taken (``confirm_restart``)."""

    @property
    def params(self) -> GapParams:
        return self._params

    @params.setter
    def params(self, params: GapParams) -> None:
        self._params = params
        unit = self.per_second
        self._max_gap, self._reset_gap = params.max_gap_s * unit, params.calibration_reset_gap_s * unit
        self._restart_back = params.restart_back_s * unit
        self._least_gap = min([g for g in (self._max_gap, self._reset_gap) if 0 < g < math.inf], default=None)

    def reset(self) -> None:
        """Forget the previous stamp: the next sample starts a stream."""
        self.last_time = self.restart_from = None

    def admit(self, time_s: float, x: Sample) -> GapVerdict:
        """Accept sample ``x`` (degrees) stamped ``time_s`` (seconds).

        Raises SampleRejected (a ValueError) for a non-finite sample or stamp, or a stamp not
        after the previous one; the state is then unchanged but ``admit_stamp``'s restart candidate.
        """
        if not (math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2]) and math.isfinite(x[3])):
            raise SampleRejected(NON_FINITE, f"non-finite sample {list(x)} at {time_s}")
        return self.admit_stamp(time_s)

    def admit_stamp(self, time_s: float) -> GapVerdict:
        """Accept ``time_s`` and say what its gap does. Raises SampleRejected (non_finite,
        non_increasing_stamp) without changing state but the restart candidate."""
        last = self.last_time
        if last is not None and last < time_s < _INF:
            self.last_time = time_s
            least = self._least_gap
            if least is not None and time_s - last > least:
                gap = time_s - last
                return GapVerdict(0 < self._max_gap < gap, 0 < self._reset_gap < gap)
            return NO_GAP
        if not -_INF < time_s < _INF:
            raise SampleRejected(NON_FINITE, f"non-finite stamp {time_s}")
        if last is None:
            self.last_time = time_s
            return NO_GAP
        return self._back(time_s, last)

    def _back(self, time_s: float, last: float) -> GapVerdict:
        """A stamp not after the previous one: a restarted stream or rejected."""
        unit = self.per_second
        if 0 < self._restart_back < last - time_s:
            candidate = self.restart_from
            if self.confirm_restart and (candidate is None or candidate[1] != last or time_s <= candidate[0]):
                self.restart_from = (time_s, last)
                raise SampleRejected(NON_INCREASING_STAMP, f"stamp {time_s / unit:.6f} s is "
                                     f"{(last - time_s) / unit:.3f} s before the previous (a restart?)")
            self.last_time, self.restart_from = time_s, None
            return JUMPED_BACK
        self.restart_from = None
        raise SampleRejected(NON_INCREASING_STAMP,
                             f"stamp {time_s / unit:.6f} s is not after the previous {last / unit:.6f} s")

    def admit_many(self, time_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``admit_stamp`` for stamps (T,) already checked (finite, increasing, after
        ``last_time``), at once: per stamp, whether its gap restarts the window and whether it
        resets the calibrations. The bulk form exists for ``core/batch.py`` (a whole recording
        without a Python step per sample); test/test_gaps.py proves it equal to ``admit_stamp``."""
        prev = np.concatenate([[math.nan if self.last_time is None else self.last_time], time_s[:-1]])
        gap = time_s - prev
        if time_s.size:
            self.last_time = float(time_s[-1])
        return (0 < self._max_gap) & (gap > self._max_gap), (0 < self._reset_gap) & (gap > self._reset_gap)
