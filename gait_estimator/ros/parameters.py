"""The parameters of ``estimator_node``: names, defaults, descriptions, validation at set time and
how a change is applied (``NodeParameters``, owned by ``EstimatorNode``).

Estimator options are parameters of the same name; the expert ones (``OPTIONS`` entries flagged
advanced) are ``advanced.<name>`` (in a params file: an ``advanced:`` mapping under
``ros__parameters``). ``config/estimator.yaml`` holds the same defaults (``yaml_defaults``, and
the IMU input's ``imu_input.PARAMETERS``).
"""

from __future__ import annotations

import array
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..core.channels import CHANNELS, N_CHANNELS
from ..core.errors import GaitEstimatorError
from ..core.estimator import Estimator
from ..core.gait_stream import GaitStream
from ..core.kernels import KernelLibrary
from ..core.options import GAP_OPTIONS, OPTIONS, PRESETS, EstimatorConfig
from ..io.library_io import load_library
from ..io.resources import DEFAULT_LIBRARY
from ..io.stream import INPUT_TYPES, UNITS
from . import EXECUTORS
from .priority import MAX_PRIORITY, process_priority, set_process_priority

ADVANCED_PREFIX = "advanced."
REMOVED_OPTIONS = ("window_fraction", "subsample_phase", "switch_evidence_deg2s", "min_dwell_samples")
"""Options that left the product (docs/options.md); a params file still setting one gets a warning."""

OPTION_OF_PARAMETER: dict[str, str] = {(ADVANCED_PREFIX if o.advanced else "") + o.name: o.name for o in OPTIONS}
"""Node parameter name -> estimator option name."""
PARAMETER_OF_OPTION = {v: k for k, v in OPTION_OF_PARAMETER.items()}

DEFAULTS: dict[str, Any] = {
    "kernels": DEFAULT_LIBRARY,
    "joint_names": list(CHANNELS),
    "input_units": "rad",
    "input_type": "joint_state",
    "executor": "events",
    "thread_priority": 0,
    "adapted_library_path": "",
    "preset": "default",
    **{PARAMETER_OF_OPTION[o.name]: o.default for o in OPTIONS},
}
"""Parameter defaults, in declaration order; ``config/estimator.yaml`` holds the same values."""

DESCRIPTIONS: dict[str, str] = {
    "kernels": "Kernel library: a file (.yaml, .npz, reference .csv or per-mode .yaml) or directory, or a "
    "bundled name (able_bodied, prosthesis); '' = none: the node starts without one and publishes only diagnostics "
    "until a mode is taught (teach_mode). Changing it at run time reloads it and restarts the window.",
    "joint_names": "JointState names of right_thigh, left_thigh, right_shank, left_shank, in that order "
    "(4 distinct names; other joints in the message are ignored, message order does not matter).",
    "input_units": "Units of the input angles: rad (REP 103) or deg.",
    "input_type": "Input message type on segment_angles (read-only): joint_state (sensor_msgs/JointState) or "
    "float64_multi_array (std_msgs/Float64MultiArray [right_thigh, left_thigh, right_shank, left_shank]); or imu: "
    "four sensor_msgs/Imu topics instead (imu_* parameters, docs/imu.md).",
    "executor": "Executor of the estimator_node process (read-only): events (rclpy's EventsExecutor, lower "
    "latency) or single_threaded (rclpy's SingleThreadedExecutor).",
    "thread_priority": "Real-time priority of the node: 1-99 runs every thread of its process under SCHED_FIFO at "
    "that priority (as ros2_control's controller_manager runs its loop; needs CAP_SYS_NICE or an rtprio limit, "
    "otherwise the node warns and runs on); 0 leaves the scheduling the process started with (e.g. under chrt).",
    "adapted_library_path": "Where the save_library service writes the personalised kernels (.yaml or .npz); '' = "
    "~/.ros/gait_estimator/<library>_adapted.yaml.",
    "preset": "Values the estimator options start from (read-only): default (robust for a new wearer: resampling, "
    "time-scaled kernels, offset tolerance and calibration) or paper (the paper's algorithm, reproduces the reference "
    "implementation). Options set explicitly (command line, params file) override it.",
    **{
        PARAMETER_OF_OPTION[o.name]: o.description[0].upper() + o.description[1:]
        + ("" if o.name in GAP_OPTIONS else ". Changing it at run time restarts the window.")
        for o in OPTIONS
    },
}
READ_ONLY = frozenset({"input_type", "executor", "preset"})
DYNAMIC_TYPING = frozenset({"resample"})  # auto | on | off, or a boolean


class StartupError(GaitEstimatorError):
    """The node cannot start (bad parameter, unreadable library): reported in one line."""


def yaml_defaults() -> dict[str, Any]:
    """DEFAULTS as a params file holds them: ``advanced.<name>`` under an ``advanced`` mapping."""
    out: dict[str, Any] = {}
    for name, value in DEFAULTS.items():
        if name.startswith(ADVANCED_PREFIX):
            out.setdefault("advanced", {})[name[len(ADVANCED_PREFIX):]] = value
        else:
            out[name] = value
    return out


def one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def parameter_error(exc: ParameterException) -> str:
    """``name: what`` of rclpy's parameter exception (its text is ``what: name``)."""
    what, _, names = one_line(exc).rpartition(": ")
    return f"{names}: {what}" if what else names


def startup_error(exc: Exception) -> StartupError:
    """Why the node cannot start, in one line: a value of the wrong type names its parameter."""
    if isinstance(exc, ParameterException):
        return StartupError(f"invalid parameter {parameter_error(exc)}")
    return StartupError(one_line(exc))


def config_value(value: Any) -> Any:
    """A parameter value as EstimatorConfig wants it (lists become tuples)."""
    return tuple(value) if isinstance(value, (list, tuple, array.array)) else value


def check_kernels(value: Any) -> tuple[str, KernelLibrary | None]:
    """(why ``kernels`` is invalid or '', the library it names)."""
    if not isinstance(value, str):
        return "must be a library path or bundled name, or '' (none: teach modes)", None
    if not value.strip():
        return "", None  # no library: the node starts with none (NodeTeacher refuses it later)
    try:
        return "", load_library(value)
    except (GaitEstimatorError, OSError, ValueError) as exc:
        return one_line(exc), None


CHOICES = {"input_units": UNITS, "input_type": INPUT_TYPES, "executor": EXECUTORS, "preset": PRESETS}


def check_input_parameter(name: str, v: Any) -> str:
    """Why the value ``v`` of a non-estimator parameter is invalid, or '' (also for parameters not ours)."""
    if name == "joint_names":
        names = list(v or [])
        if len(names) != N_CHANNELS:
            return f"needs {N_CHANNELS} names ({', '.join(CHANNELS)}), got {len(names)}"
        if any(not n.strip() for n in names):
            return "names must not be empty"
        if len(set(names)) != len(names):
            return f"names must be distinct, got {names}"
    elif name in CHOICES and v not in CHOICES[name]:
        return f"must be one of {', '.join(CHOICES[name])}, got {v!r}"
    elif name == "thread_priority" and not 0 <= v <= MAX_PRIORITY:
        return f"must be in 0..{MAX_PRIORITY} (0 = the scheduling the process started with), got {v}"
    elif name == "adapted_library_path" and v and Path(v).suffix.lower() not in (".yaml", ".yml", ".npz"):
        return f"must end in .yaml or .npz (or be empty for the default), got {v!r}"
    return ""


class NodeParameters:
    """The parameters of ``node``: declared and validated by ``declare``; once the node's stream
    exists (``attach``), valid changes are applied to it (another library or options: one
    ``GaitStream.swap``)."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.preset = "default"
        self.stream: GaitStream | None = None
        self._library: KernelLibrary | None = None  # until attach: what declaring validated
        self._config = EstimatorConfig()
        self._pending: tuple[KernelLibrary | None, EstimatorConfig, Estimator | None] | None = None
        self._last_rejection = ""

    def declare(self, overrides: dict[str, Any]) -> tuple[KernelLibrary | None, EstimatorConfig]:
        """Declare every parameter (the estimator options at the preset's values unless
        overridden), validating each; the library and options they name. Raises StartupError."""
        node = self.node
        node.add_on_set_parameters_callback(self._validate)
        try:
            for name, default in DEFAULTS.items():
                self._last_rejection = ""
                if name in OPTION_OF_PARAMETER:  # the preset's value unless overridden
                    default = PRESETS[self.preset][OPTION_OF_PARAMETER[name]]
                node.declare_parameter(name, default, ParameterDescriptor(
                    description=DESCRIPTIONS[name], read_only=name in READ_ONLY,
                    # `-p resample:=on` and params files parse on/off as booleans (YAML 1.1)
                    dynamic_typing=name in DYNAMIC_TYPING))
                # Declaring validated the value (kernels: loaded it); keep it for the next ones.
                if self._pending is not None:
                    self._library, self._config = self._pending[0] or self._library, self._pending[1]
                self._pending = None
                if name == "preset":
                    self.preset = node.get_parameter("preset").value
                    self._config = EstimatorConfig.preset(self.preset)
        except ParameterException as exc:
            raise StartupError(f"invalid parameter {self._last_rejection or parameter_error(exc)}") from None
        for name in overrides:
            if name in REMOVED_OPTIONS:
                node.get_logger().warn(f"parameter {name} ignored: the option was removed (docs/options.md)")
            elif name in PARAMETER_OF_OPTION and PARAMETER_OF_OPTION[name] != name:
                node.get_logger().warn(f"parameter {name} ignored: it is {PARAMETER_OF_OPTION[name]} now")
        return self._library, self._config

    def attach(self, stream: GaitStream) -> None:
        """From now on changes go to ``stream`` (which owns the library and options)."""
        self.stream = stream
        self.node.add_post_set_parameters_callback(self._apply)

    def _current(self) -> tuple[KernelLibrary | None, EstimatorConfig]:
        s = self.stream
        return (self._library, self._config) if s is None else (s.library, s.config)

    def _validate(self, params: list[Parameter]) -> SetParametersResult:
        """on-set callback: reject invalid values with a reason; stash what they would build."""
        current, config = self._current()
        lib = current
        values: dict[str, Any] = {}
        for p in params:
            reason = ""
            if p.name == "kernels":
                reason, loaded = check_kernels(p.value)
                lib = loaded or lib
            elif p.name in OPTION_OF_PARAMETER:
                values[OPTION_OF_PARAMETER[p.name]] = config_value(p.value)
            else:
                reason = check_input_parameter(p.name, p.value)
            if reason:
                return self._reject(f"{p.name}: {reason}")
        try:
            config = config.with_options(**values) if values else config
        except (ValueError, TypeError) as exc:
            names = ", ".join(PARAMETER_OF_OPTION[v] for v in values)
            return self._reject(f"{names}: {one_line(exc)}")
        estimator = None
        if lib is not None and (values or lib is not current):
            try:  # also reads a transitions file
                estimator = self.stream.new_estimator(lib, config) if self.stream is not None else Estimator(
                    lib, config, stamped=stamped_input(self.node.get_parameter("input_type").value
                                                       if self.node.has_parameter("input_type") else "joint_state"))
            except (GaitEstimatorError, ValueError, OSError) as exc:
                return self._reject(f"{', '.join(p.name for p in params)}: {one_line(exc)}")
        self._pending = (lib if lib is not current else None, config, estimator)
        return SetParametersResult(successful=True)

    def _reject(self, reason: str) -> SetParametersResult:
        self._last_rejection = reason
        return SetParametersResult(successful=False, reason=reason)

    def _apply(self, params: list[Parameter]) -> None:
        """post-set callback: apply values that passed validation."""
        pending, self._pending = self._pending, None
        names = {p.name for p in params}
        if "thread_priority" in names:
            set_priority(self.node, self.node.get_parameter("thread_priority").value)
        stream = self.stream
        if pending is None or stream is None:
            return
        _, config, estimator = pending
        options = {OPTION_OF_PARAMETER[n] for n in names if n in OPTION_OF_PARAMETER}
        swap = ("kernels" in names or bool(options - GAP_OPTIONS)) and estimator is not None
        stream.set_config(config, gaps_only=not swap and bool(options & GAP_OPTIONS))
        if "kernels" in names:
            stream.forget_taught()  # another library: nothing of it was taught here
        if not swap or estimator is None:
            return
        same = "kernels" not in names and stream.estimator is not None  # same kernels, same sensors: keep what was learnt
        strides = stream.swap(estimator, keep_calibration=same, keep_adaptation=same)
        kept = ""
        if same and strides:
            kept = (f"; personalised kernels ({strides} strides) kept" if estimator.adapter is not None
                    else f"; personalised kernels ({strides} strides) dropped: adapt_rate is 0")
        lib = estimator.library
        self.node.get_logger().info(f"library '{lib.name}' ({len(lib)} modes) from {lib.path}; options: "
                                    f"{self.options_summary()}: window restarted" + kept)
        self.node.library_changed()

    def options_summary(self) -> str:
        changed = self._current()[1].changed_from(self.preset)
        return f"preset {self.preset}" + (
            " with " + ", ".join(f"{PARAMETER_OF_OPTION[k]}={v}" for k, v in changed.items()) if changed else "")


def stamped_input(input_type: str) -> bool:
    """JointState and Imu carry stamps (``resample: auto`` resamples them); Float64MultiArray is
    timed on arrival (not resampled unless ``on``)."""
    return input_type in ("joint_state", "imu")


def set_priority(node: Node, priority: int) -> None:
    """Apply ``thread_priority`` to every thread of the process; a refusal is a warning (the
    node runs on at the priority it has), as in ros2_control."""
    try:
        node.get_logger().info(f"thread_priority {priority}: {set_process_priority(priority)}")
    except OSError as exc:
        node.get_logger().warn(f"thread_priority {priority}: {exc}; running with {process_priority()} scheduling")
