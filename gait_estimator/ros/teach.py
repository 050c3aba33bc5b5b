"""Teaching modes in the running ``estimator_node`` (parameters ``teach_mode``, ``teach_strides``,
``teach_channel``), and the node's start without a library (``kernels: ''``).

While ``teach_mode`` names a mode, the node's ``GaitStream`` (``core/gait_stream.py``) collects
its strides (``core.teach.StrideCollector``); its events (strides, rejections and why, progress
"Slow: 6/10 strides") are logged with the prefix ``teach:`` and shown in the diagnostics. When
enough good strides are in, the kernel is added to the running library (a new name) or replaces
the mode of that name, and ``teach_mode`` goes back to ''. Setting ``teach_mode`` to '' earlier
cancels; naming another mode starts over with that one. Log times are seconds since the input
started; when its stamps jump back (a recording played again) the strides so far are kept and
times count from the new start.

The other modes keep their state across the library change: the stream keeps the input samples of
the last ``replay_s`` seconds (at least the longest stride at the largest time scale); a new
``Estimator`` for the new library replays them, so every mode's window is full at once and holds
the same samples as before, and then adopts the old estimator's walking calibration (sensor
offsets, cadence, typical fit). Kernels personalised so far (``adapt_rate``) are the new
library's (the taught mode's replaces the personalised one of its name); the new estimator
personalises from them.
"""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..core.channels import CHANNELS
from ..core.errors import GaitEstimatorError
from ..core.gait_stream import GaitStream
from ..core.kernels import RESERVED_MODE_NAMES, reserved_name
from ..core.teach import HEEL_STRIKE_CHANNEL, TEACH_STRIDES, TeachOptions, check_teach_strides

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


class TeachParameters:
    """``teach_mode``, ``teach_strides``, ``teach_channel`` of ``node``, applied to ``stream``."""

    def __init__(self, node: Node, stream: GaitStream) -> None:
        self.node = node
        self.stream = stream
        node.add_on_set_parameters_callback(self._validate)
        for name, (default, text) in PARAMETERS.items():
            node.declare_parameter(name, default, ParameterDescriptor(description=text))
        node.add_post_set_parameters_callback(self._apply)
        start = node.get_parameter("teach_mode").value
        if start:
            stream.start_teaching(start, self.options())

    def options(self) -> TeachOptions:
        get = self.node.get_parameter
        return TeachOptions(strides=get("teach_strides").value, channel=get("teach_channel").value)

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
            elif p.name == "kernels" and isinstance(p.value, str) and not p.value.strip() and self.stream.library:
                reason = "an empty value ('' = no library) is allowed only at start"
            if reason:
                return SetParametersResult(successful=False, reason=f"{p.name}: {reason}")
        return SetParametersResult(successful=True)

    def _apply(self, params: list[Parameter]) -> None:
        for p in params:
            if p.name == "teach_mode":
                if p.value:
                    self.stream.start_teaching(p.value, self.options())
                else:
                    self.stream.cancel_teaching()
            elif p.name == "teach_strides":
                self.stream.set_teach_target(p.value)
