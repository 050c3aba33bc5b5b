"""Teaching modes in the running ``estimator_node`` (parameters ``teach_mode``, ``teach_strides``,
``teach_channel``), and the node's start without a library (``kernels: ''``).

While ``teach_mode`` names a mode, every accepted input sample also goes to an
``core.teach.StrideCollector``; its events (strides, rejections and why, progress
"Slow: 6/10 strides") are logged with the prefix ``teach:`` and shown in the diagnostics. When
enough good strides are in, the kernel is added to the running library (a new name) or replaces
the mode of that name, and ``teach_mode`` goes back to ''. Setting ``teach_mode`` to '' earlier
cancels; naming another mode starts over with that one. Log times are seconds since the input
started; when its stamps jump back (a recording played again) the strides so far are kept and
times count from the new start.

The other modes keep their state across the library change: the node keeps the input samples of
the last ``replay_s`` seconds (at least the longest stride at the largest time scale); a new
``Estimator`` for the new library replays them, so every mode's window is full at once and holds
the same samples as before, and then adopts the old estimator's walking calibration (sensor
offsets, cadence, typical fit). Kernels personalised so far (``adapt_rate``) are the new
library's (the taught mode's replaces the personalised one of its name); the new estimator
personalises from them.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.parameter import Parameter

from ..core.channels import CHANNELS, Sample
from ..core.errors import GaitEstimatorError
from ..core.kernels import RESERVED_MODE_NAMES, KernelLibrary, make_mode, reserved_name
from ..core.strides import MAX_STRIDE_S
from ..core.teach import (
    HEEL_STRIKE_CHANNEL,
    TEACH_STRIDES,
    StrideCollector,
    TaughtMode,
    TeachOptions,
    change_summary,
    check_teach_strides,
    near_copies,
    with_mode,
)

LOG_PREFIX = "teach: "
PARAMETERS: dict[str, tuple[Any, str]] = {
    "teach_mode": ("", "Mode to teach from the wearer's strides now (a new name adds it to the library, an existing "
                   "one replaces its kernel); '' = not teaching. Goes back to '' when the kernel is built; setting "
                   "'' earlier cancels."),
    "teach_strides": (TEACH_STRIDES, "Good (steady) strides a taught kernel averages; at least train's "
                      "--min-strides (3)."),
    "teach_channel": (HEEL_STRIKE_CHANNEL, "Channel whose maxima are the right heel strikes while teaching: "
                      + ", ".join(CHANNELS) + "."),
}
REPLAY_MARGIN_S = 0.5


class NodeTeacher:
    """The teaching part of ``EstimatorNode`` (see the module docstring).

    The node calls ``on_sample`` for every accepted sample, and asks ``diagnostic_values`` /
    ``status_without_library`` for its diagnostics.
    """

    def __init__(self, node: Any) -> None:  # an EstimatorNode (node.py imports this module)
        self.node = node
        self.session: StrideCollector | None = None
        self.completed = 0
        """Modes taught since the node started."""
        self.last_event = ""
        self.last_result = ""
        self.last_taught: TaughtMode | None = None
        self.taught: list[str] = []
        self._recent: deque[tuple[float, Sample]] = deque()
        self._origin: float | None = None  # node time of the input stream's first sample
        self._replay_for: tuple[Any, Any] = (None, None)  # (library, config) _replay_s was computed for
        self._replay_s = self.replay_s()
        self._clearing = False
        node.add_on_set_parameters_callback(self._validate)
        for name, (default, text) in PARAMETERS.items():
            node.declare_parameter(name, default, ParameterDescriptor(description=text))
        node.add_post_set_parameters_callback(self._apply)
        if node._library is None:
            self._warm_up()
        start = node.get_parameter("teach_mode").value
        if start:
            self._start(start)

    def _warm_up(self) -> None:
        """Run an estimator once, so that the first taught mode does not wait for the matcher's
        compiled step to load (or compile, on a fresh install: seconds, while input piles up)."""
        stride = np.sin(np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False))[:, None] * np.ones(4)
        estimator = self.node._new_estimator(KernelLibrary("warm_up", (make_mode("warm_up", stride, 100.0),)),
                                             self.node._config)
        for i in range(40):
            estimator.update(i / 100.0, stride[i % 16])

    # -- parameters

    def _validate(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            reason = ""
            if p.name == "teach_strides":
                try:
                    check_teach_strides(p.value)
                except GaitEstimatorError as exc:
                    reason = str(exc)
            elif p.name == "teach_channel" and p.value not in CHANNELS:
                reason = f"must be one of {', '.join(CHANNELS)}, got {p.value!r}"
            elif p.name == "teach_mode" and p.value != p.value.strip():
                reason = f"mode names have no leading or trailing spaces, got {p.value!r}"
            elif p.name == "teach_mode" and p.value in RESERVED_MODE_NAMES:
                reason = reserved_name(p.value)
            elif p.name == "kernels" and isinstance(p.value, str) and not p.value.strip() and self.node._library:
                reason = "an empty value ('' = no library) is allowed only at start"
            if reason:
                return SetParametersResult(successful=False, reason=f"{p.name}: {reason}")
        return SetParametersResult(successful=True)

    def _apply(self, params: list[Parameter]) -> None:
        for p in params:
            if p.name == "teach_mode" and not self._clearing:
                if self.session is not None:
                    self._log(f"{self.session.mode}: cancelled at {self.session.good}/{self.session.target} strides")
                    self.session = None
                if p.value:
                    self._start(p.value)
            elif p.name == "kernels":
                self.taught = []  # another library: nothing of it was taught here
            elif p.name == "teach_strides" and self.session is not None:
                self.session.set_target(p.value)
                self._log(self.session.progress())

    def _start(self, mode: str, restarted: str = "") -> None:
        """Collect ``mode``'s strides from the next sample (``restarted``: why the strides so far
        were dropped)."""
        lib = self.node._library
        options = TeachOptions(strides=self.node.get_parameter("teach_strides").value,
                               channel=self.node.get_parameter("teach_channel").value)
        self.session = StrideCollector(mode, options, rate_hz=lib.sample_rate_hz if lib else None)
        if restarted:
            self._log(f"{mode}: {restarted}: strides so far dropped, collecting {options.strides} again", warn=True)
            return
        what = "replaces" if lib is not None and mode in lib.mode_names else "is added to"
        self._log(f"{mode}: collecting {options.strides} steady strides (heel strikes from {options.channel}); "
                  f"the kernel {what} the library")

    # -- samples

    def on_sample(self, time_s: float, sample: Sample) -> None:
        """One accepted input sample (node seconds, degrees)."""
        recent = self._recent
        recent.append((time_s, sample))
        node = self.node
        if node._library is not self._replay_for[0] or node._config is not self._replay_for[1]:
            self._replay_for, self._replay_s = (node._library, node._config), self.replay_s()
        keep_from = time_s - self._replay_s
        while recent[0][0] < keep_from:
            recent.popleft()
        if self._origin is None:
            self._origin = time_s
        session = self.session
        if session is None:
            return
        for line in session.push(time_s - self._origin, sample):  # log times: s since the input started
            self._log(line)
        if session.result is not None:
            self._finish(session.result)

    def stream_restarted(self) -> None:
        """The input's stamps jumped back (a restarted publisher, a recording played again): the
        samples kept for a new estimator no longer hold; a collection in progress keeps its
        strides, as the wearer walked them, and goes on with the new stream."""
        self._recent.clear()
        self._origin = None
        session = self.session
        if session is not None:
            session.restart_stream()
            kept = f"{session.progress()} kept, " if session.candidates else f"{session.mode}: "
            self._log(f"input stamps jumped back (a restarted stream): {kept}collecting on; log times from its start")

    def drop_strides(self, why: str) -> None:
        """The strides so far cannot be trusted (``why``, e.g. the IMU calibration did not fit):
        the kept samples and a collection in progress start again."""
        self._recent.clear()
        self._origin = None
        if self.session is not None:
            self._start(self.session.mode, restarted=why)

    def replay_s(self) -> float:
        """Seconds of input kept for a new estimator: the longest stride a kernel may have (a
        taught one is at most MAX_STRIDE_S) at the largest time scale, plus a margin."""
        lib = self.node._library
        longest = max(MAX_STRIDE_S, max((m.stride_duration_s for m in lib.modes), default=0.0) if lib else 0.0)
        return longest * max(self.node._config.time_scales) + REPLAY_MARGIN_S

    def _finish(self, taught: TaughtMode) -> None:
        node = self.node
        self.session = None
        old = node._estimator
        try:
            lib, replaced = with_mode(self._base_library(), taught.kernel)
            estimator = node._new_estimator(lib, node._config)
            for t, x in self._recent:  # the same window of samples for every mode
                estimator.update(t, x)
        except (GaitEstimatorError, ValueError, OSError) as exc:
            self._log(f"{taught.kernel.name}: kernel not used: {' '.join(str(exc).split())}", warn=True)
            self._clear_parameter()
            return
        kept = ""
        if old is not None:
            estimator.adopt_calibration(old)
            node._resets_before += old.resets
            if old.adapter is not None and old.adapter.accepted.any():
                kept = f"; personalised kernels ({int(old.adapter.accepted.sum())} strides) kept"
        node._library = lib
        node._set_estimator(estimator)
        copies = near_copies(lib, taught.kernel.name, node._config.effective_weights())
        self.completed += 1
        self.last_taught = taught
        self.taught = [*(n for n in self.taught if n != taught.kernel.name), taught.kernel.name]
        self.last_result = taught.summary() + (f"; near copy of {', '.join(copies)}" if copies else "")
        self._log(change_summary(taught, lib, replaced, copies)
                  + f"; window refilled from the last {self._recent[-1][0] - self._recent[0][0]:.2f} s" + kept,
                  warn=bool(copies))
        self._clear_parameter()

    def _base_library(self) -> KernelLibrary | None:
        """The library a taught mode goes into: the running one with the kernels personalised so
        far (``adapt_rate`` > 0), so that teaching one mode keeps what the others learnt."""
        node = self.node
        lib, est = node._library, node._estimator
        if lib is None or est is None or est.adapter is None or not est.adapter.accepted.any():
            return lib
        return replace(est.adapted_library(), path=lib.path)

    def _clear_parameter(self) -> None:
        self._clearing = True
        try:
            self.node.set_parameters([Parameter("teach_mode", value="")])
        finally:
            self._clearing = False

    def _log(self, line: str, warn: bool = False) -> None:
        self.last_event = line
        logger = self.node.get_logger()
        if warn:  # rclpy fixes a call site's severity at its first call: one site per severity
            logger.warning(LOG_PREFIX + line)
        else:
            logger.info(LOG_PREFIX + line)

    # -- diagnostics

    def diagnostic_values(self) -> dict[str, str]:
        s = self.session
        return {
            "teach_mode": s.mode if s else "",
            "teach_progress": f"{s.good}/{s.target}" if s else "",
            "teach_not_used": s.not_used_text() if s else "",
            "teach_heel_strikes": str(len(s.heel_strikes)) if s else "",
            "teach_last_event": self.last_event,
            "teach_completed": str(self.completed),
            "teach_last_result": self.last_result,
            "taught_modes": ",".join(self.taught),
        }

    def message_suffix(self) -> str:
        return f"; teaching {self.session.progress()}" if self.session else ""

    def status_without_library(self, name: str, received: int, accepted: int,
                               imu: tuple[dict[str, str], list[str]] | None = None) -> DiagnosticStatus:
        """Diagnostics before the first mode is taught (``kernels: ''``); ``imu``: the IMU
        input's values and problems (``input_type: imu``)."""
        message = ("no kernel library: teaching " + self.session.progress() if self.session
                   else "no kernel library: set teach_mode to teach a mode")
        values = {
            "ready": "false", "library": "", "modes": "0", "mode_names": "",
            "samples_received": str(received), "samples_accepted": str(accepted),
            **self.diagnostic_values(),
        }
        level = DiagnosticStatus.OK
        if imu is not None:
            values.update(imu[0])
            if imu[1]:
                level, message = DiagnosticStatus.WARN, "; ".join(imu[1]) + "; " + message
        return DiagnosticStatus(level=level, name=name, message=message, hardware_id="",
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

