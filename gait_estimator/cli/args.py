"""argparse value types, the output-path check, the JSON report and the IMU reading options (with
``--save-imu-calibration``) shared by the CLI modules (bad values: one-line usage errors)."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..core.errors import GaitEstimatorError


def checked_number(text: str, kind: type, ok: Callable[[Any], bool], expected: str, bad: str = "") -> Any:
    """``kind(text)`` when ``ok`` of it is true; otherwise ArgumentTypeError ``expected
    {expected}, got {text!r}``, or ``bad`` formatted with ``text`` when the value is out of range."""
    try:
        v = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
    if not ok(v):
        raise argparse.ArgumentTypeError(bad.format(text=text) if bad else f"expected {expected}, got {text!r}")
    return v


def positive_list(text: str, kind: type, listed: str, positive: str) -> list[Any]:
    """Comma-separated finite numbers > 0 of ``kind``; errors say ``expected comma-separated
    {listed}`` or ``expected positive {positive}``."""
    try:
        values = [kind(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated {listed}, got {text!r}") from None
    if not values or any(not (math.isfinite(v) and v > 0) for v in values):
        raise argparse.ArgumentTypeError(f"expected positive {positive}, got {text!r}")
    return values


def positive_int(text: str) -> int:
    """An integer > 0."""
    return checked_number(text, int, lambda v: v > 0, "a positive integer")


def choice_list(allowed: tuple[str, ...]) -> Any:
    """A comma-separated list of values from ``allowed`` (at least one)."""

    def parse(text: str) -> list[str]:
        values = [v.strip() for v in text.split(",") if v.strip()]
        bad = [v for v in values if v not in allowed]
        if not values or bad:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {', '.join(allowed)}, got {text!r}")
        return values

    return parse


def prepare_output(path: str, option: str) -> None:
    """Create the parent folder of the output file ``path`` (given with ``option``) before any
    work is done, or raise a one-line GaitEstimatorError."""
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise GaitEstimatorError(f"{option} {path}: {exc.strerror or exc}") from None


def save_report(path: str | None, report: dict[str, Any]) -> None:
    """``--json PATH``: ``report`` written there as JSON, and a line saying so (nothing without a path)."""
    if path:
        Path(path).write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
        print(f"wrote {path}")


def port_number(text: str) -> int:
    """A TCP port, 0..65535 (0: any free one)."""
    return checked_number(text, int, lambda v: 0 <= v <= 65535, "a TCP port", "TCP ports are 0..65535, got {text}")


def positive_float(text: str) -> float:
    """A finite number > 0."""
    return checked_number(text, float, lambda v: math.isfinite(v) and v > 0, "a positive number")


def domain_id(text: str) -> int:
    """A ROS domain ID, 0..232."""
    return checked_number(text, int, lambda v: 0 <= v <= 232, "an integer ROS domain ID",
                          "ROS domain IDs are 0..232, got {text}")


def add_target_node_options(p: Any, node_note: str = "") -> None:
    """``--node``, ``--domain-id``, ``--timeout``: the running estimator node a command talks to."""
    p.add_argument("--node", default="/estimator_node",
                   help=f"the estimator node's name{node_note} (default %(default)s)")
    p.add_argument("--domain-id", type=domain_id, help="ROS_DOMAIN_ID (default: the environment's)")
    p.add_argument("--timeout", type=positive_float, default=5.0,
                   help="seconds to wait for the node (default %(default)s)")


def seconds(text: str) -> float:
    """A duration in seconds, >= 0 (inf allowed)."""
    return checked_number(text, float, lambda v: v >= 0, "seconds", "expected seconds >= 0, got {text!r}")


def int_list(text: str) -> list[int]:
    """Comma-separated positive integers, e.g. ``7,70,700``."""
    return positive_list(text, int, "integers", "integers")


IMU_READING_OPTIONS = ("imu_topics", "imu_calibration", "imu_lateral_axes", "imu_proximal_axes", "imu_tolerance_s")
"""``read_recording`` keywords set by ``add_imu_reading_options`` (read_imu_bag's arguments)."""


def _topic_list(text: str) -> list[str]:
    """Comma-separated names (topics, axes); their number is checked by the reader (one line)."""
    return [t.strip() for t in text.split(",")]


def add_imu_reading_options(p: Any) -> None:
    """The options of a recording that is a bag of four sensor_msgs/Imu topics (docs/imu.md), on
    every command that reads recordings; ``reader_options`` collects them."""
    p.add_argument(
        "--imu-topics", dest="imu_topics", type=_topic_list, metavar="RT,LT,RS,LS",
        help="bag of sensor_msgs/Imu topics: those of right_thigh,left_thigh,right_shank,left_shank (default "
        "/imu/<channel>, or the Imu topics named after the channels)",
    )
    p.add_argument(
        "--imu-calibration", dest="imu_calibration", metavar="YAML",
        help="bag of sensor_msgs/Imu topics: the IMU mounting to use, a file the node or --save-imu-calibration "
        "wrote; checked on the walking, a misfit is an error (with process --as-node: learnt again, as the node "
        "does) (default: learnt from the bag; docs/imu.md)",
    )
    p.add_argument(
        "--imu-lateral-axes", dest="imu_lateral_axes", type=_topic_list, metavar="RT,LT,RS,LS",
        help="bag of sensor_msgs/Imu topics: per segment, the sensor axis pointing to the wearer's right (+x, -y, "
        "...; empty = learn), as the node's imu_lateral_axes; a list starting with - needs '=': --imu-lateral-axes=-z,...",
    )
    p.add_argument(
        "--imu-proximal-axes", dest="imu_proximal_axes", type=_topic_list, metavar="RT,LT,RS,LS",
        help="bag of sensor_msgs/Imu topics: per segment, the sensor axis along it towards the hip or knee "
        "(empty = learn), as the node's imu_proximal_axes (--imu-proximal-axes=-x,... when it starts with -)",
    )
    p.add_argument(
        "--imu-tolerance-s", dest="imu_tolerance_s", type=seconds, metavar="SECONDS",
        help="bag of sensor_msgs/Imu topics: largest stamp spread of the four messages of one sample (default: "
        "0.9 of the message period, for sensors not sampled together)",
    )
    p.add_argument(
        "--save-imu-calibration", dest="save_imu_calibration", metavar="YAML",
        help="bag of sensor_msgs/Imu topics: write the IMU calibration used (learnt or given) in the node's file "
        "format, for --imu-calibration on the wearer's other recordings (docs/imu.md)",
    )


def reader_options(args: argparse.Namespace, names: Sequence[str] = IMU_READING_OPTIONS) -> dict[str, Any]:
    """The reading options ``names`` (default: the IMU ones) given on the command line, as
    ``read_recording`` keywords."""
    return {k: getattr(args, k) for k in names if getattr(args, k, None) is not None}


def read_recording_args(args: argparse.Namespace, path: str | Path, **options: Any) -> Any:
    """The recording at ``path`` read with ``options`` and the IMU reading options given on the
    command line, after ``--save-imu-calibration`` wrote its calibration."""
    from ..io.readers import read_recording

    rec = read_recording(path, **{**reader_options(args), **options})
    save_imu_calibration(args, getattr(rec, "calibration", None), path)
    return rec


def save_imu_calibration(args: argparse.Namespace, calibration: Any, source: str | Path) -> None:
    """``--save-imu-calibration``: write ``calibration`` (the ImuCalibration ``source`` was read
    with; None: none) as the node saves its own (``io/imu_stream.save_calibration``); none: one-line error."""
    path = getattr(args, "save_imu_calibration", None)
    if not path:
        return
    from ..io.imu_stream import save_calibration

    if calibration is None:
        raise GaitEstimatorError(f"--save-imu-calibration: {source}: no IMU calibration to save (not a bag of "
                                 "sensor_msgs/Imu topics, or none learnt from it)")
    try:
        print(f"wrote IMU calibration {save_calibration(calibration, path)}")
    except OSError as exc:
        raise GaitEstimatorError(f"--save-imu-calibration {path}: {exc.strerror or exc}") from None
