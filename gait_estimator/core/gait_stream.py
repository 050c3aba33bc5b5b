"""One stream of decoded samples -> estimates, ROS-free: what ``estimator_node`` does with each
input, and what ``gait-estimator process --as-node`` does offline.

``GaitStream`` owns the way of a sample after decoding: the stamp verdict (``core/stamps.py``:
order, duplicates, jump-back restarts; forward gaps and calibration resets are the
``Estimator``'s, read back from ``Estimator.last_gap``), the estimator, the units check, teaching
(``core/teach.StrideCollector`` with the replay buffer a new library is filled from), the one
estimator swap (parameter changes and taught modes), and the counters the diagnostics show. Each
sample gets an estimate, ``None`` (no library yet: it only teaches) or ``SampleRejected`` (counted).
What is worth a log line comes back as ``StreamEvent`` in ``events``, for the caller to log or print.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple, Protocol

import numpy as np

from .channels import Sample
from .errors import GaitEstimatorError
from .estimator import Estimator, EstimatorConfig
from .gaps import NO_GAP
from .imu_flow import IMU_NOT_FIT, ImuFlow
from .kernels import KernelLibrary, make_mode
from .stamps import SampleRejected, StreamGuard, restart_threshold
from .strides import MAX_STRIDE_S
from .supervisor import Estimate
from .teach import StrideCollector, TaughtMode, TeachOptions, change_summary, near_copies, with_mode
from .units import UnitsCheck

RESTART_BACK = "restart_back"
"""Event: stamps jumped back by more than the restart threshold; the window restarted."""
RESTART_GAP = "restart_gap"
"""Event: a gap longer than ``max_gap_s``; the window restarted."""
CALIBRATION_RESET = "calibration_reset"
"""Event: a gap longer than ``calibration_reset_gap_s``; learnt offsets and cadence forgotten."""
UNITS = "units"
"""Event: the angles cannot be degrees once converted (``input_units`` wrong)."""
TEACH = "teach"
"""Event: teaching progress (a stride, a rejection, a restart)."""
TEACH_DONE = "teach_done"
"""Event: teaching ended (the kernel is in the library, or not used); ``teach_mode`` goes back to ''."""
REPLAY_MARGIN_S = 0.5


class Stamp(Protocol):
    sec: int
    nanosec: int


class SampleStamp(NamedTuple):
    """A paired IMU sample's stamp, as a message's ``header.stamp``."""

    sec: int
    nanosec: int


Output = tuple[Stamp, Sample, Estimate | None] | SampleRejected
"""What ``push_imu`` gives per sample or dropped message, in order."""


@dataclass(frozen=True)
class StreamEvent:
    """Something worth one log line: ``kind`` (the constants above), the line, and whether it is
    a warning."""

    kind: str
    line: str
    warn: bool = False


class Period(NamedTuple):
    """Counts since the previous ``GaitStream.take_period``."""

    received: int
    rejected: int
    accepted: int
    first_stamp_s: float | None
    last_stamp_s: float | None


class GaitStream:
    """Decoded samples -> estimates; see the module docstring.

    Args:
        library: Kernel library; None: no library yet, samples only teach.
        config: Estimator options.
        stamped: The input carries real stamps (``resample: auto`` resamples it).
        units: The input units named in a units warning; None: no units check (IMU input).
    """

    def __init__(self, library: KernelLibrary | None, config: EstimatorConfig, *, stamped: bool = True,
                 units: str | None = "rad") -> None:
        self.config = config
        self.stamped = stamped
        self.guard = StreamGuard(max_gap_s=0.0, restart_back_s=restart_threshold(config.max_gap_s))
        self.units = units
        self.units_check = UnitsCheck()
        self.estimator: Estimator | None = None if library is None else self.new_estimator(library, config)
        self.last_estimate: Estimate | None = None
        self.events: list[StreamEvent] = []
        """Events since the caller last cleared the list (``take_events``)."""
        self.received = 0
        """Inputs: each angle message; with four IMUs each message dropped on its own (bad or
        unpaired) and each paired sample. Always ``accepted`` + the rejected (``rejected``)."""
        self.accepted = 0
        """Inputs taken: samples past the stamp check and the estimator; with four IMUs also the
        paired samples the IMU calibration takes while it is learnt (no angles yet)."""
        self.first_stamp_ns: int | None = None
        """Stamp of the first input taken (``accepted``), ns; ``--as-node``'s time 0 (io/as_node.py)."""
        self._resets_before = 0  # window restarts of estimators swapped out
        self._epoch_sec: int | None = None
        self._period_received = self._period_rejected = self._period_accepted = 0
        self._first: float | None = None
        self._last: float | None = None
        self.teaching: StrideCollector | None = None
        self.taught: list[str] = []
        self.teach_completed = 0
        self.teach_last_event = ""
        self.teach_last_result = ""
        self.last_taught: TaughtMode | None = None
        self._recent: deque[tuple[float, Sample]] = deque()
        self._origin: float | None = None
        self._replay_for: tuple[object, object] = (None, None)
        self._replay_s = 0.0
        self.imu: ImuFlow | None = None
        """The four-IMU flow (``attach_imu``), None for angle input."""
        self._imu_out: list[Output] = []
        if library is None:
            self._warm_up()

    # -- samples

    def seconds(self, stamp: Stamp) -> float:
        """A stamp in seconds since the whole second of the first stamp: float64 keeps nanoseconds
        there, which seconds since 1970 do not (the resampler interpolates at these times)."""
        if self._epoch_sec is None:
            self._epoch_sec = stamp.sec
        return (stamp.sec - self._epoch_sec) + stamp.nanosec * 1e-9

    def push(self, stamp: Stamp, angles_deg: Sample, counted: bool = False) -> Estimate | None:
        """One decoded sample (four angles, degrees, CHANNELS order): its estimate, or None while
        there is no library. Raises SampleRejected (counted) for a stamp not after the previous
        one, unless it jumped back by more than ``restart_back_s`` (a restarted stream: the window
        restarts with it). ``counted``: the input was already counted as received
        (``count_received``)."""
        if not counted:
            self.received += 1
            self._period_received += 1
        t = self.seconds(stamp)
        guard = self.guard
        prev = guard.check.last_time
        try:
            restart = guard.accept(t)
        except SampleRejected as exc:
            self._count_rejection(exc)
            raise
        if restart:
            self._teaching_restarted()
        est = self.estimator
        estimate = None
        if est is not None:
            if restart:
                est.reset()
                self.events.append(StreamEvent(RESTART_BACK, f"input stamps jumped back by {(prev or t) - t:.3f} s "
                                               f"(> {guard.restart_back_s:g} s)"))
            units = self.units_check
            if units.problem is None and self.units is not None and units.observe(t, angles_deg) is not None:
                self.events.append(StreamEvent(UNITS, f"input_units {self.units}: {units.problem}", warn=True))
            try:
                estimate = est.update(t, angles_deg)
            except SampleRejected as exc:  # non-finite angles: callers check them first
                self._count_rejection(exc)
                raise
            gap = est.last_gap
            if gap is not NO_GAP:
                self._gap_events(t - (prev if prev is not None else t), gap.restart_window, gap.reset_calibration)
            self.last_estimate = estimate
            if self._first is None:
                self._first = t
            self._last = t
            self._period_accepted += 1
        self._took(stamp.sec * 1_000_000_000 + stamp.nanosec)
        # the samples a new library's estimator is filled from (``swap``), with or without a library
        recent = self._recent
        recent.append((t, angles_deg))
        if est is not self._replay_for[0] or self.config is not self._replay_for[1]:
            self._replay_for, self._replay_s = (est, self.config), self.replay_s()
        keep_from = t - self._replay_s
        while recent[0][0] < keep_from:
            recent.popleft()
        if self._origin is None:
            self._origin = t
        if self.teaching is not None:
            self._collect(t, angles_deg)  # may swap the library and the estimator
        return estimate

    def _took(self, stamp_ns: int) -> None:
        self.accepted += 1
        if self.first_stamp_ns is None:
            self.first_stamp_ns = stamp_ns

    def _gap_events(self, gap_s: float, restart: bool, recalibrate: bool) -> None:
        c = self.config
        if restart:
            self.events.append(StreamEvent(RESTART_GAP, f"gap of {gap_s:.3f} s in input stamps > max_gap_s "
                                           f"{c.max_gap_s:g} s"))
        if recalibrate:
            self.events.append(StreamEvent(
                CALIBRATION_RESET, f"gap of {gap_s:.3f} s in input stamps > calibration_reset_gap_s "
                f"{c.calibration_reset_gap_s:g} s: learnt sensor offsets and cadence forgotten "
                "(the sensors may have been re-donned)"))

    def count_received(self) -> None:
        """An input that will reach ``push`` with ``counted=True``, or is a paired IMU sample."""
        self.received += 1
        self._period_received += 1

    def reject(self, exc: SampleRejected) -> None:
        """Count an input dropped before ``push`` (undecodable, a missing joint, ...), as received
        and rejected."""
        self.count_received()
        self._count_rejection(exc)

    def _count_rejection(self, exc: SampleRejected) -> None:
        self._period_rejected += 1
        self.guard.reject(exc)

    def take_events(self) -> list[StreamEvent]:
        """The events so far; the list starts again empty."""
        events = list(self.events)
        self.events.clear()
        return events

    # -- four IMUs

    def attach_imu(self, flow: ImuFlow) -> None:
        """Take four-IMU input through ``flow`` (``push_imu``); its events join ``events``."""
        self.imu = flow
        flow.on_event = self._imu_event
        flow.set_gaps(self.config.calibration_reset_gap_s, self.guard.restart_back_s)

    def _imu_event(self, kind: str, line: str) -> None:
        self.events.append(StreamEvent(kind, line, warn=kind == IMU_NOT_FIT))  # the caller knows the others' levels

    def push_imu(self, sensor: int, stamp_ns: int, orientation: Any, cov0: float, gyro: Any, acc: Any,
                 frame_id: str) -> list[Output]:
        """One decoded Imu message of ``sensor`` (CHANNELS index): what it gave, in order, each a
        counted SampleRejected or a paired sample's (stamp, angles, estimate or None)."""
        flow = self.imu
        assert flow is not None
        before = flow.pairer.unpaired
        try:
            paired = flow.convert(sensor, stamp_ns, orientation, cov0, gyro, acc, frame_id)
        except SampleRejected as exc:
            self.reject(exc)
            return [exc]
        out = [o for ns, items in paired for o in self.push_paired(ns, items)]
        for exc in flow.unpaired(before):
            self.reject(exc)
            out.append(exc)
        return out

    def push_paired(self, stamp_ns: int, items: list) -> list[Output]:
        """One paired IMU sample (``ImuPairer``): its angles, once calibrated, through ``push``."""
        flow = self.imu
        assert flow is not None
        self.count_received()
        out = self._imu_out = []
        flow.sample(stamp_ns, items, self._emit)
        if not out:  # taken by the IMU calibration
            self._took(stamp_ns)
        if flow.not_fit:  # the window and learnt offsets came from wrong angles, the strides too
            flow.not_fit = False
            self.reset_calibration("the IMU calibration did not fit")
        return out

    def _emit(self, angles: Sample, stamp_ns: int) -> None:
        est = self.estimator
        if est is not None and est.personaliser is not None:  # kernels learn only from angles known to be right
            est.pause_adaptation(self.imu is not None and self.imu.unchecked)
        stamp = SampleStamp(*divmod(stamp_ns, 1_000_000_000))
        try:
            self._imu_out.append((stamp, angles, self.push(stamp, angles, counted=True)))
        except SampleRejected as exc:
            self._imu_out.append(exc)

    def take_period(self) -> Period:
        """Counts since the previous call."""
        period = Period(self._period_received, self._period_rejected, self._period_accepted, self._first, self._last)
        self._period_received = self._period_rejected = self._period_accepted = 0
        self._first = self._last = None
        return period

    # -- state

    @property
    def library(self) -> KernelLibrary | None:
        return self.estimator.library if self.estimator is not None else None

    @property
    def epoch_sec(self) -> int | None:
        """The whole second of the first stamp: time 0 of ``seconds``."""
        return self._epoch_sec

    @property
    def stream_restarts(self) -> int:
        """Jumps back that restarted the stream."""
        return self.guard.restarts

    @property
    def window_resets(self) -> int:
        """Window restarts caused by the input stream: gaps > max_gap_s and jumps back."""
        resets = self.estimator.resets if self.estimator is not None else 0
        return self._resets_before + resets + self.guard.restarts

    def rejected(self, reasons: Sequence[str] | None = None) -> dict[str, int]:
        """Dropped inputs so far, by reason: every reason in ``reasons`` listed (None: the
        reasons counted so far, sorted). Every rejection is counted here (``reject``, ``push``,
        ``push_imu``), as reasons the guard keeps."""
        counts = self.guard.rejected
        return {r: int(counts.get(r, 0)) for r in (sorted(counts) if reasons is None else reasons)}

    # -- options and libraries

    def new_estimator(self, library: KernelLibrary, config: EstimatorConfig) -> Estimator:
        """An estimator for this stream (a parameter change validates one before ``swap``)."""
        return Estimator(library, config, stamped=self.stamped)

    def set_config(self, config: EstimatorConfig, gaps_only: bool = False) -> None:
        """Options from now on (the jump-back threshold follows ``max_gap_s``); ``gaps_only``: they
        differ only in GAP_OPTIONS, which the estimator takes keeping its window."""
        self.config = config
        self.guard.restart_back_s = restart_threshold(config.max_gap_s)
        if self.imu is not None:  # a sensor restarts where the stream does
            self.imu.set_gaps(config.calibration_reset_gap_s, self.guard.restart_back_s)
        if gaps_only and self.estimator is not None:
            self.estimator.set_gap_options(config)

    def set_units(self, units: str | None) -> None:
        """Other input units (or joint names): the units check starts again."""
        self.units = units
        self.units_check.reset()

    def swap(self, estimator: Estimator, *, keep_calibration: bool, keep_adaptation: bool,
             replay: bool = False) -> int:
        """Use ``estimator`` (another library or options) from now on: ``replay`` fills its window
        with the last samples (every mode's window full at once); ``keep_calibration``: it adopts
        the learnt sensor offsets and cadence; ``keep_adaptation``: the personalised kernels (same
        library). Returns the strides the old estimator's personalisation had adopted."""
        if replay:
            for t, x in self._recent:
                estimator.update(t, x)
        old, strides = self.estimator, 0
        if old is not None:
            self._resets_before += old.resets
            if keep_calibration:
                estimator.adopt_calibration(old)
            if keep_adaptation:
                strides = estimator.adopt_adaptation(old)
            elif old.adapter is not None:
                strides = int(old.adapter.accepted.sum())
        self.estimator = estimator
        self.last_estimate = None
        return strides

    def reset_calibration(self, mounting_lost: str = "") -> None:
        """Forget the learnt sensor offsets and cadence. ``mounting_lost``: why the IMU mounting
        the angles came from no longer holds; then the window and a teaching session's strides
        start again too."""
        if self.estimator is not None:
            self.estimator.reset_calibration()
            if mounting_lost:
                self.estimator.reset()
        if mounting_lost:
            self.drop_strides(mounting_lost)

    # -- teaching

    def _warm_up(self) -> None:
        """Run an estimator once, so that the first taught mode does not wait for the matcher's
        compiled step to load (or compile, on a fresh install: seconds, while input piles up)."""
        stride = np.sin(np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False))[:, None] * np.ones(4)
        estimator = self.new_estimator(KernelLibrary("warm_up", (make_mode("warm_up", stride, 100.0),)), self.config)
        for i in range(40):
            estimator.update(i / 100.0, stride[i % 16])

    def start_teaching(self, mode: str, options: TeachOptions, restarted: str = "") -> None:
        """Collect ``mode``'s strides from the next sample (``restarted``: why the strides so far
        were dropped); a collection in progress is cancelled."""
        self.cancel_teaching()
        lib = self.library
        self.teaching = StrideCollector(mode, options, rate_hz=lib.sample_rate_hz if lib else None)
        if restarted:
            self._teach_event(f"{mode}: {restarted}: strides so far dropped, collecting {options.strides} again",
                              warn=True)
            return
        what = "replaces" if lib is not None and mode in lib.mode_names else "is added to"
        self._teach_event(f"{mode}: collecting {options.strides} steady strides (heel strikes from "
                          f"{options.channel}); the kernel {what} the library")

    def cancel_teaching(self) -> None:
        s = self.teaching
        if s is not None:
            self._teach_event(f"{s.mode}: cancelled at {s.good}/{s.target} strides")
            self.teaching = None

    def set_teach_target(self, strides: int) -> None:
        if self.teaching is not None:
            self.teaching.set_target(strides)
            self._teach_event(self.teaching.progress())

    def drop_strides(self, why: str) -> None:
        """The strides so far cannot be trusted (``why``, e.g. the IMU calibration did not fit):
        the kept samples and a collection in progress start again."""
        self._recent.clear()
        self._origin = None
        s = self.teaching
        if s is not None:
            self.teaching = None
            self.start_teaching(s.mode, s.options, restarted=why)

    def forget_taught(self) -> None:
        """Another library: none of its modes was taught here."""
        self.taught = []

    def _teaching_restarted(self) -> None:
        """Stamps jumped back: the samples kept for a new estimator no longer hold; a collection in
        progress keeps its strides, as the wearer walked them, and goes on with the new stream."""
        self._recent.clear()
        self._origin = None
        s = self.teaching
        if s is not None:
            s.restart_stream()
            kept = f"{s.progress()} kept, " if s.candidates else f"{s.mode}: "
            self._teach_event(f"input stamps jumped back (a restarted stream): {kept}collecting on; "
                              "log times from its start")

    def replay_s(self) -> float:
        """Seconds of input kept for a new estimator: the longest stride a kernel may have (a
        taught one is at most MAX_STRIDE_S) at the largest time scale, plus a margin."""
        lib = self.library
        longest = max(MAX_STRIDE_S, max((m.stride_duration_s for m in lib.modes), default=0.0) if lib else 0.0)
        return longest * max(self.config.time_scales) + REPLAY_MARGIN_S

    def _collect(self, time_s: float, sample: Sample) -> None:
        session = self.teaching
        assert session is not None
        for line in session.push(time_s - (self._origin or 0.0), sample):  # log times: s since the input started
            self._teach_event(line)
        if session.result is not None:
            self._finish(session.result)

    def _finish(self, taught: TaughtMode) -> None:
        self.teaching = None
        name = taught.kernel.name
        try:
            lib, replaced = with_mode(self._base_library(), taught.kernel)
            strides = self.swap(self.new_estimator(lib, self.config), keep_calibration=True, keep_adaptation=False,
                                replay=True)
        except (GaitEstimatorError, ValueError, OSError) as exc:
            self._teach_event(f"{name}: kernel not used: {' '.join(str(exc).split())}", warn=True, kind=TEACH_DONE)
            return
        copies = near_copies(lib, name, self.config.effective_weights())
        self.teach_completed += 1
        self.last_taught = taught
        self.taught = [*(n for n in self.taught if n != name), name]
        self.teach_last_result = taught.summary() + (f"; near copy of {', '.join(copies)}" if copies else "")
        kept = f"; personalised kernels ({strides} strides) kept" if strides else ""
        self._teach_event(change_summary(taught, lib, replaced, copies) + f"; window refilled from the last "
                          f"{self._recent[-1][0] - self._recent[0][0]:.2f} s" + kept, warn=bool(copies), kind=TEACH_DONE)

    def _base_library(self) -> KernelLibrary | None:
        """The library a taught mode goes into: the running one with the kernels personalised so
        far (``adapt_rate`` > 0), so that teaching one mode keeps what the others learnt."""
        est = self.estimator
        if est is None or est.adapter is None or not est.adapter.accepted.any():
            return self.library
        return replace(est.adapted_library(), path=est.library.path)

    def _teach_event(self, line: str, warn: bool = False, kind: str = TEACH) -> None:
        self.teach_last_event = line
        self.events.append(StreamEvent(kind, line, warn))

    def teach_values(self) -> dict[str, str]:
        """Teaching's key/values for the diagnostics."""
        s = self.teaching
        return {
            "teach_mode": s.mode if s else "",
            "teach_progress": f"{s.good}/{s.target}" if s else "",
            "teach_not_used": s.not_used_text() if s else "",
            "teach_heel_strikes": str(len(s.heel_strikes)) if s else "",
            "teach_last_event": self.teach_last_event,
            "teach_completed": str(self.teach_completed),
            "teach_last_result": self.teach_last_result,
            "taught_modes": ",".join(self.taught),
        }
