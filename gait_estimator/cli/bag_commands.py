"""``gait-estimator`` subcommands for rosbag2 recordings: ``play``, ``convert``, ``bench-bag``,
``repair``, and the bag options of ``process`` (``--topic``, ``--joint-names``, ``--input-units``,
``--max-gap``, ``--out-bag``, ``--storage``).

Importing this module imports neither rclpy nor rosbags (``play`` imports rclpy when it runs).
"""

from __future__ import annotations

import argparse
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from ..core.channels import CHANNELS, N_CHANNELS
from ..core.errors import GaitEstimatorError, RecordingError
from ..core.units import first_problem
from ..io.bag import (
    DEFAULT_MAX_GAP_S,
    DEFAULT_TOPIC,
    INPUT_MSGTYPES,
    BagRecording,
    is_bag_path,
    parse_joint_names,
    read_bag,
)
from ..io.bag_write import STORAGES
from ..io.imu_bag import ImuBagRecording
from ..io.library_io import DEFAULT_REFERENCE_RATE_HZ
from ..io.process import Predictions, predict
from ..io.readers import read_recording
from ..io.recording import Recording, write_project_csv
from ..io.resources import DEFAULT_LIBRARY
from ..io.stream import UNITS
from .args import (
    IMU_READING_OPTIONS,
    add_imu_reading_options,
    positive_float,
    reader_options,
    save_imu_calibration,
    save_report,
    seconds,
)


def _joint_names(text: str) -> tuple[str, ...]:
    try:
        return parse_joint_names(text)
    except RecordingError:
        raise argparse.ArgumentTypeError(
            f"expected {N_CHANNELS} distinct comma-separated names ({','.join(CHANNELS)}), got {text!r}") from None



BAG_READING_OPTIONS = ("topic", "input_units", "joint_names", "max_gap_s")
"""``read_recording`` keywords of ``process``'s bag options (``reader_options`` collects them)."""


def _bag_reading_options(p: Any, max_gap: Any = None) -> None:
    p.add_argument(
        "--joint-names", dest="joint_names", type=_joint_names, metavar="A,B,C,D",
        help="JointState names of right_thigh,left_thigh,right_shank,left_shank (default: those names)",
    )
    (max_gap or p).add_argument(
        "--max-gap", dest="max_gap_s", type=seconds, metavar="SECONDS",
        help=f"a gap between sample times longer than this restarts the window, as in the node (default "
        f"{DEFAULT_MAX_GAP_S:g}; 0 disables; any recording)",
    )
    add_imu_reading_options(p)


def add_process_options(proc: argparse.ArgumentParser) -> None:
    """Bag options of ``process``; ``reader_options(args, BAG_READING_OPTIONS)`` collects the reading ones."""
    g = proc.add_argument_group("rosbag2 input (RECORDING is a bag directory or .mcap/.db3 file)")
    g.add_argument(
        "--topic", dest="topic", metavar="TOPIC",
        help=f"input topic, sensor_msgs/JointState or std_msgs/Float64MultiArray (default {DEFAULT_TOPIC}, "
        "or the only topic of such a type)",
    )
    g.add_argument(
        "--input-units", dest="input_units", choices=UNITS,
        help="units of the angles in the messages (default rad)",
    )
    _bag_reading_options(g, max_gap=proc)
    o = proc.add_argument_group("rosbag2 output")
    o.add_argument(
        "--out-bag", metavar="DIR",
        help="also write the outputs (mode, phase, sse, estimate, as the live node publishes them) to a new bag",
    )
    o.add_argument("--storage", choices=STORAGES, default="mcap", help="storage of --out-bag (default %(default)s)")


def warn_units(rec: Recording, source: str | Path, units: str) -> None:
    """One warning line (stderr) if ``rec``'s angles cannot be degrees as read (core/units.py);
    ``units``: the ``--input-units`` a bag of angles is read with. Angles from IMUs (SI units, by the
    message) are not checked, as in the node: standing, they are near 0 by calibration."""
    if isinstance(rec, ImuBagRecording):
        return
    found = first_problem(rec.time_s, rec.angles_deg)
    if found is not None:
        given = f"input_units {units}" if isinstance(rec, BagRecording) else "angle units"
        print(f"warning: {source}: {given}: from {found[0] - rec.time_s[0]:.1f} s {found[1]}", file=sys.stderr)


def finish_process(args: argparse.Namespace, rec: Recording, pred: Predictions) -> list[str]:
    """After ``process`` predicted: write ``--out-bag``; return notes for the summary."""
    from ..io.bag_write import output_stamps, write_output_bag

    lines = []
    if isinstance(rec, BagRecording):
        lines += [f"note: {n}" for n in rec.notes]
    else:
        bag_only = ("topic", "input_units", "joint_names", *IMU_READING_OPTIONS)
        given = ["--" + k.replace("_", "-") for k in reader_options(args, bag_only)]
        if given:
            lines.append(f"note: {', '.join(given)} apply to bags only; ignored for {args.recording}")
    if getattr(args, "out_bag", None):
        stamps, logs = output_stamps(rec, pred)
        counts = write_output_bag(pred, args.out_bag, stamps, logs, storage=args.storage)
        lines.append(f"wrote {args.out_bag} ({args.storage}: " + ", ".join(f"/{t} {n}" for t, n in counts.items()) + ")")
    return lines


# ---------------------------------------------------------------------------------------------
# convert


def cmd_convert(args: argparse.Namespace) -> int:
    from ..io.bag_write import write_input_bag

    if bool(args.out_bag) == bool(args.out):
        raise GaitEstimatorError("give exactly one of --out-bag DIR (write a bag) or --out CSV (write a CSV)")
    rec = _read_source(args)
    if not args.as_node:  # (--as-node: the stream's, saved on the way)
        save_imu_calibration(args, getattr(rec, "calibration", None), args.source)
    warn_units(rec, args.source, args.units)
    if args.out_bag:
        start_ns = None if args.start_time is None else round(args.start_time * 1e9)
        write_input_bag(
            rec, args.out_bag, storage=args.storage, topic=args.topic or DEFAULT_TOPIC, msg_type=args.type,
            units=args.units, joint_names=args.joint_names or CHANNELS, start_ns=start_ns,
        )
        what = f"{args.out_bag} ({args.storage}, {len(rec)} {INPUT_MSGTYPES[args.type]} messages on {args.topic or DEFAULT_TOPIC}"
        print(what + f", {args.units})")
    else:
        write_project_csv(rec, args.out)
        print(f"wrote {args.out} ({len(rec)} samples)")
    _print_reading_notes(rec)
    return 0


def _read_source(args: argparse.Namespace) -> Recording:
    options = {"input_units": args.units, **reader_options(args, ("topic", "joint_names", "max_gap_s", *IMU_READING_OPTIONS))}
    if args.as_node:
        from .as_node import convert_as_node

        return convert_as_node(args, options)
    return read_recording(args.source, rate_hz=args.sample_rate, **options)


def _print_reading_notes(rec: Recording) -> None:
    for reason, count in rec.skipped.items():
        print(f"skipped {count} message(s): {reason}")
    for note in getattr(rec, "notes", ()):
        print(f"note: {note}")


# ---------------------------------------------------------------------------------------------
# play


def cmd_play(args: argparse.Namespace) -> int:
    from ..ros.player import load_playlist, play

    playlist = load_playlist(
        args.source, topics=args.topic, msg_type=args.type, units=args.units,
        joint_names=args.joint_names or CHANNELS, rate_hz=args.sample_rate,
    )
    # Ctrl-C (SIGINT) ends playback, as for ros2 bag play, also when this process inherited SIGINT
    # ignored (a background job of a script): rclpy installs no handler for the player's context.
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        play(
            playlist, rate=args.rate, loop=args.loop, clock=args.clock,
            wait_for_subscribers_s=args.wait_for_subscribers, qos_depth=args.qos_depth,
        )
    except KeyboardInterrupt:
        return 130
    return 0


# ---------------------------------------------------------------------------------------------
# repair


def cmd_repair(args: argparse.Namespace) -> int:
    from ..io.bag_repair import repair_bag

    result = repair_bag(args.bag, args.out)
    topics = ", ".join(f"{t} {n}" for t, n in sorted(result.counts.items()))
    print(f"wrote {result.out} ({result.storage}, {result.messages} messages: {topics})")
    for topic in result.skipped_topics:
        print(f"note: not copied: {topic} (type unknown to the ROS 2 Jazzy type store, no definition in the bag)")
    if not result.recovered:
        print(f"note: {args.bag} was intact; the copy holds the same messages")
    return 0


# ---------------------------------------------------------------------------------------------
# bench-bag


def bench_bag(bag: Path, library: Any, out_dir: Path, repeat: int, storage: str) -> dict[str, Any]:
    """Time the offline bag pipeline on ``bag``: read (decode + checks), predict, write the
    output bag; median of ``repeat`` runs, as seconds and samples/s."""
    from ..io.bag_write import output_stamps, write_output_bag

    runs: dict[str, list[float]] = {"read": [], "predict": [], "write_out_bag": []}
    n = 0
    for r in range(repeat):
        t0 = time.perf_counter()
        rec = read_bag(bag)
        t1 = time.perf_counter()
        pred = predict(rec, library)
        t2 = time.perf_counter()
        stamps, logs = output_stamps(rec, pred)
        write_output_bag(pred, out_dir / f"out{r}", stamps, logs, storage=storage)
        t3 = time.perf_counter()
        runs["read"].append(t1 - t0)
        runs["predict"].append(t2 - t1)
        runs["write_out_bag"].append(t3 - t2)
        n = len(rec)
    med = {k: statistics.median(v) for k, v in runs.items()}
    med["process"] = med["read"] + med["predict"]
    med["process_out_bag"] = med["process"] + med["write_out_bag"]
    return {
        "samples": n,
        "modes": len(library),
        "repeat": repeat,
        "seconds": med,
        "samples_per_s": {k: n / v for k, v in med.items()},
    }


def cmd_bench_bag(args: argparse.Namespace) -> int:
    from ..analysis.bench import machine_info
    from ..io.bag_write import write_input_bag
    from ..io.library_io import load_library

    lib = load_library(args.kernels)
    with tempfile.TemporaryDirectory(prefix="gait_bench_bag_") as tmp:
        bag = Path(args.source)
        if not is_bag_path(bag):
            rec = read_recording(bag, rate_hz=lib.sample_rate_hz)
            bag = Path(tmp) / "input"
            write_input_bag(rec, bag, storage=args.storage, msg_type=args.type)
        report = bench_bag(bag, lib, Path(tmp), repeat=args.repeat, storage=args.storage)
    report.update(source=str(args.source), storage=args.storage, input_type=args.type, machine=machine_info())
    sps, sec = report["samples_per_s"], report["seconds"]
    print(f"{args.source}: {report['samples']} samples, {report['modes']} modes, {args.storage}, median of {args.repeat}")
    for key, label in (
        ("read", "read bag (decode, checks)"),
        ("predict", "matcher"),
        ("process", "process (read + matcher)"),
        ("write_out_bag", "write --out-bag"),
        ("process_out_bag", "process --out-bag"),
    ):
        print(f"  {label:<28} {sec[key]:8.3f} s  {sps[key]:10.0f} samples/s")
    m = report["machine"]
    print(f"machine: {m['processor']}, {m['cpus']} cpus, Python {m['python']}, numpy {m['numpy']}")
    save_report(args.json, report)
    return 0


# ---------------------------------------------------------------------------------------------


def add_commands(sub: Any) -> None:
    """Add ``convert``, ``play``, ``repair`` and ``bench-bag`` to the ``gait-estimator`` subparsers."""
    conv = sub.add_parser(
        "convert", help="convert a recording CSV to a rosbag2 bag (--out-bag) or a bag topic to a CSV (--out)",
        description="CSV -> bag: one message per sample, stamped from the CSV time (first sample at --start-time). "
        "Bag -> CSV: the project CSV (degrees, time_s from 0 at the first sample).",
    )
    conv.add_argument("source", help="project or reference CSV, or a bag directory / .mcap / .db3 file")
    conv.add_argument("--out-bag", metavar="DIR", help="write a new bag here")
    conv.add_argument("--out", "-o", metavar="CSV", help="write a project CSV here")
    conv.add_argument("--storage", choices=STORAGES, default="mcap", help="bag storage (default %(default)s)")
    conv.add_argument("--topic", help=f"topic to write / read (default {DEFAULT_TOPIC})")
    conv.add_argument(
        "--type", choices=tuple(INPUT_MSGTYPES), default="joint_state",
        help="message type written: sensor_msgs/JointState or std_msgs/Float64MultiArray (default %(default)s)",
    )
    conv.add_argument("--units", choices=UNITS, default="rad", help="angle units in the bag (default %(default)s, REP 103)")
    _bag_reading_options(conv)
    conv.add_argument(
        "--start-time", type=float, metavar="EPOCH_S",
        help="stamp of the first sample in seconds since the epoch (default: now); bag sources keep their stamps",
    )
    conv.add_argument(
        "--sample-rate", type=positive_float, default=DEFAULT_REFERENCE_RATE_HZ, metavar="HZ",
        help="time base of a reference CSV without time column (default %(default)g)",
    )
    conv.add_argument("--as-node", action="store_true", help="a bag (angles or four Imu topics): the angles the node's "
                      "GaitStream feeds its estimator, IMU calibration learnt as the node learns it (docs/bags.md)")
    conv.set_defaults(func=cmd_convert)

    play = sub.add_parser(
        "play", help="publish a bag or CSV into the ROS 2 graph with its recorded timing (needs rclpy)",
        description="Publishes a bag's topics (messages unchanged, at their recorded receive times) or a CSV as "
        "JointState messages (radians, CHANNELS joint names, stamps = CSV time offset to the wall clock at start). "
        "DDS settings come from the environment: set ROS_DOMAIN_ID (and ROS_AUTOMATIC_DISCOVERY_RANGE) as for any node.",
    )
    play.add_argument("source", help="bag directory / .mcap / .db3 file, or a project/reference CSV")
    play.add_argument("--rate", type=positive_float, default=1.0, help="playback speed factor (default %(default)g)")
    play.add_argument(
        "--topic", action="append",
        help="bag: topic to play (repeat for several; default all); CSV: topic to publish on (default segment_angles, "
        "relative)",
    )
    play.add_argument("--clock", action="store_true", help="also publish /clock (rosgraph_msgs/Clock) for use_sim_time")
    play.add_argument("--loop", action="store_true", help="repeat until Ctrl-C (stamps keep increasing)")
    play.add_argument(
        "--type", choices=tuple(INPUT_MSGTYPES), default="joint_state", help="CSV: message type (default %(default)s)"
    )
    play.add_argument("--units", choices=UNITS, default="rad", help="CSV: angle units published (default %(default)s)")
    play.add_argument("--joint-names", type=_joint_names, metavar="A,B,C,D", help="CSV: JointState joint names")
    play.add_argument("--sample-rate", type=positive_float, default=DEFAULT_REFERENCE_RATE_HZ, metavar="HZ",
                      help="reference CSV time base")
    play.add_argument(
        "--wait-for-subscribers", type=seconds, default=0.0, metavar="SECONDS",
        help="first wait up to SECONDS until every topic has a subscriber (default 0: start at once)",
    )
    play.add_argument("--qos-depth", type=int, default=1000, help="publisher history depth, reliable (default %(default)s)")
    play.set_defaults(func=cmd_play)

    rep = sub.add_parser(
        "repair", help="write a complete, indexed copy of a cut or damaged bag (like ros2 bag reindex)",
        description="Reads every complete message of BAG (a cut .mcap, a .db3 with an unfinished transaction, a "
        "directory whose metadata.yaml is missing or wrong) and writes them to a new bag with metadata.yaml and "
        "summary, same storage. The original is never modified; an existing output is never overwritten.",
    )
    rep.add_argument("bag", help="bag directory, .mcap or .db3 file")
    rep.add_argument("--out", "-o", metavar="DIR", help="new bag directory (default: BAG_repaired beside BAG)")
    rep.set_defaults(func=cmd_repair)

    b = sub.add_parser("bench-bag", help="measure offline bag processing throughput (samples/s)")
    b.add_argument("source", help="bag, or a CSV that is first converted to a temporary bag")
    b.add_argument("--kernels", "-k", default=DEFAULT_LIBRARY, metavar="LIB", help="kernel library (default %(default)s)")
    b.add_argument("--storage", choices=STORAGES, default="mcap", help="storage of the temporary bags (default %(default)s)")
    b.add_argument("--type", choices=tuple(INPUT_MSGTYPES), default="joint_state", help="message type of a converted CSV")
    b.add_argument("--repeat", type=int, default=3, help="runs; the median is reported (default %(default)s)")
    b.add_argument("--json", help="write the report as JSON")
    b.set_defaults(func=cmd_bench_bag)
