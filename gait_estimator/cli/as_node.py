"""``--as-node`` of ``process``, ``convert`` and ``train``: a bag (angles or four Imu topics) taken
message by message as ``estimator_node`` takes it live (``io/as_node.bag_as_node``, the node's
``GaitStream``): its estimates, the angles it feeds its estimator, the kernels its teaching builds."""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from itertools import chain
from pathlib import Path
from typing import Any

from ..core.errors import GaitEstimatorError
from ..core.kernels import KernelLibrary
from ..core.options import EstimatorConfig
from .args import reader_options, save_imu_calibration


def refuse(args: argparse.Namespace, *flags: str) -> None:
    """One-line error for any of ``flags`` (``--name``) given with ``--as-node``."""
    for flag in flags:
        if getattr(args, flag[2:].replace("-", "_"), None) not in (None, False):
            raise GaitEstimatorError(f"--as-node takes the bag as the node does: {flag} is not for it")


def finish(args: argparse.Namespace, stream: Any, source: str, quiet: bool = False) -> None:
    """``--save-imu-calibration``, then (unless ``quiet``) the stream's counts and warnings."""
    save_imu_calibration(args, stream.imu.calibrator.calibration if stream.imu is not None else None, source)
    if quiet:
        return
    rejected = {r: n for r, n in stream.rejected().items() if n}
    print(f"as the node: {stream.received} received, {stream.accepted} accepted, window restarts "
          f"{stream.window_resets} ({stream.stream_restarts} jumps back)"
          + ("; dropped: " + ", ".join(f"{n} {r}" for r, n in rejected.items()) if rejected else ""))
    for event in stream.take_events():
        if event.warn:
            print(f"warning: {event.line}")


def process_as_node(args: argparse.Namespace, lib: KernelLibrary, config: EstimatorConfig, options: dict[str, Any]) -> int:
    from ..io.as_node import predict_as_node
    from ..io.process import format_summary, write_predictions_csv
    from ..io.read_options import ReadOptions

    refuse(args, "--start", "--stop", "--out-bag", "--save-adapted")
    pred, stream = predict_as_node(args.recording, lib, config, ReadOptions.of(None, options))
    if args.out:
        write_predictions_csv(pred, args.out)
    if not args.quiet:
        print(format_summary(pred, lib, str(args.recording)))
    finish(args, stream, args.recording, args.quiet)
    if args.out and not args.quiet:
        print(f"wrote {args.out}")
    return 0


def _config(args: argparse.Namespace) -> EstimatorConfig:
    from .estimator_args import config_from_args

    return config_from_args(args, max_gap_s=getattr(args, "max_gap_s", None))


def convert_as_node(args: argparse.Namespace, options: dict[str, Any]) -> Any:
    """``convert BAG --as-node``: the recording of the angles the node's stream feeds its estimator."""
    from ..io.as_node import read_as_node
    from ..io.read_options import ReadOptions

    rec, stream = read_as_node(args.source, _config(args), ReadOptions.of(None, options))
    finish(args, stream, args.source)
    return rec


def train_as_node(args: argparse.Namespace, detection: Any) -> int:
    """``train BAG... --as-node``: the bags played one after another to a node (each started with the
    library taught so far) whose ``teach_mode`` is ``--mode`` from the start, or each ``--labels``
    range's mode from its start_s to its end_s (seconds from the bag's first sample, as ``convert
    --as-node`` times it), each mode until it is taught; exit 1 when a mode was not taught."""
    from ..analysis.labels import read_label_ranges
    from ..core.channels import CHANNELS
    from ..core.teach import HEEL_STRIKE_CHANNEL, TEACH_STRIDES, TeachOptions
    from ..core.training import OutlierRule
    from ..io.as_node import bag_as_node
    from ..io.library_io import save_library
    from ..io.read_options import ReadOptions

    refuse(args, "--rate")
    channel = HEEL_STRIKE_CHANNEL if args.heel_strikes == "auto" else args.heel_strikes
    if channel not in CHANNELS:
        raise GaitEstimatorError(f"--as-node: heel strikes are maxima of a channel ({', '.join(CHANNELS)}), "
                                 f"not {args.heel_strikes}")
    if not (args.mode or args.labels):
        raise GaitEstimatorError("--as-node: give the mode(s) to teach: --mode NAME or --labels RANGES.csv")
    ranges = [(-math.inf, math.inf, args.mode)] if args.mode else sorted(
        (r.start_s, r.end_s, r.mode) for r in read_label_ranges(args.labels) if r.mode)
    teach = TeachOptions(strides=args.strides or TEACH_STRIDES, channel=channel, min_strides=args.min_strides,
                         detection=detection,
                         outliers=OutlierRule(duration_floor=args.duration_tolerance))
    lib, config = None, _config(args)
    for path in args.recordings:
        with bag_as_node(path, lib, config, ReadOptions.of(None, reader_options(args))) as (stream, samples):
            todo, end = list(ranges), math.inf
            for t in chain([-math.inf], (s.time_ns * 1e-9 for s in samples)):
                if t >= end:
                    stream.cancel_teaching()
                if todo and t >= todo[0][0]:
                    _, end, mode = todo.pop(0)
                    if mode not in _taught(stream.library):
                        stream.start_teaching(mode, teach)
                _print_teaching(stream)
            stream.cancel_teaching()
            _print_teaching(stream)
            lib = stream.library
        finish(args, stream, path, quiet=True)
    if lib is None:
        raise GaitEstimatorError(f"no mode taught from {', '.join(args.recordings)}: too few good strides")
    missing = sorted({m for _, _, m in ranges} - set(_taught(lib)))
    out = save_library(replace(lib, name=args.name or Path(args.out).stem), args.out)
    print(f"wrote {out} ({len(lib)} modes: {', '.join(lib.mode_names)})")
    if missing:
        print(f"not taught: {', '.join(missing)}")
    return 1 if missing else 0


def _taught(lib: KernelLibrary | None) -> list[str]:
    return lib.provenance.get("taught", []) if lib is not None else []


def _print_teaching(stream: Any) -> None:
    for event in stream.take_events():
        print(("warning: " if event.warn else "") + event.line)
