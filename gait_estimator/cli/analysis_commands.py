"""CLI subcommands ``train``, ``evaluate``, ``resample`` and ``label-strides`` (listed in
``cli.COMMAND_MODULES``)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis.strides import HEEL_STRIKE_SOURCES, heel_strikes, nearest_index, resample_uniform
from ..core.errors import GaitEstimatorError
from ..core.strides import MAX_STRIDE_S, MIN_PROMINENCE_DEG, MIN_STRIDE_S, DetectionOptions, stride_bounds
from ..core.teach import TEACH_STRIDES
from ..io.library_io import DEFAULT_REFERENCE_RATE_HZ
from ..io.recording import Recording, write_project_csv
from ..io.resources import DEFAULT_LIBRARY
from .args import add_imu_reading_options, positive_float, read_recording_args


def _window(text: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START:END in seconds, got {text!r}") from None
    if not b > a:
        raise argparse.ArgumentTypeError(f"END must be greater than START in {text!r}")
    return a, b


def _label_args(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument("--mode", metavar="NAME", help="label every sample of the recording(s) with this mode")
    g.add_argument(
        "--labels", metavar="RANGES.csv",
        help="label by time ranges: CSV 'start_s,end_s,mode' ('#' comments); replaces any mode column",
    )


def _detection_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--min-stride-s", type=positive_float, default=MIN_STRIDE_S,
                   help="shortest stride / minimum heel-strike spacing in seconds (default %(default)s)")
    p.add_argument("--max-stride-s", type=positive_float, default=MAX_STRIDE_S,
                   help="longest stride in seconds; longer intervals are not strides (default %(default)s)")
    p.add_argument("--prominence", type=positive_float, default=MIN_PROMINENCE_DEG,
                   help="minimum heel-strike peak prominence in degrees (default %(default)s)")


def _time_rate_arg(p: argparse.ArgumentParser, default: float | None = DEFAULT_REFERENCE_RATE_HZ) -> None:
    p.add_argument("--time-rate", type=positive_float, default=default, metavar="HZ",
                   help="time base of recordings without time stamps (reference Dimension CSV): time = "
                   f"sample / HZ (default {default if default is not None else 'the library rate'})")


def detection_options(args: argparse.Namespace) -> DetectionOptions:
    if args.max_stride_s <= args.min_stride_s:
        raise GaitEstimatorError(f"--max-stride-s ({args.max_stride_s}) must exceed --min-stride-s ({args.min_stride_s})")
    return DetectionOptions(args.min_stride_s, args.max_stride_s, args.prominence)


def _read_labelled(path: str, args: argparse.Namespace, rate_hz: float | None = None) -> tuple[Recording, str]:
    """A recording and where its labels came from: --mode, --labels, its mode column, else the
    label file beside it (printed)."""
    from ..analysis.labels import labels_beside, read_label_ranges, with_mode, with_ranges

    rec = read_recording_args(args, path, rate_hz=rate_hz if rate_hz is not None else args.time_rate)
    if args.mode:
        return with_mode(rec, args.mode), f"--mode {args.mode}"
    if args.labels:
        return with_ranges(rec, read_label_ranges(args.labels)), args.labels
    beside = labels_beside(path) if rec.labels is None else None
    if beside is None:
        return rec, "mode column"
    print(f"labels: {beside} (beside the recording; --labels or --mode to use others)")
    return with_ranges(rec, read_label_ranges(beside)), str(beside)


# ---------------------------------------------------------------------------------------------
# train


def cmd_train(args: argparse.Namespace) -> int:
    from ..analysis.train import format_report, train_library
    from ..core.training import OutlierRule, TrainOptions
    from ..io.library_io import save_library

    if args.save_imu_calibration and len(args.recordings) > 1:
        raise GaitEstimatorError(f"--save-imu-calibration: one recording's calibration is saved, {len(args.recordings)} "
                                 "recordings given (convert one of them with --save-imu-calibration)")
    if args.as_node:
        from .as_node import train_as_node

        return train_as_node(args, detection_options(args))
    if args.strides is not None:
        raise GaitEstimatorError("--strides is for --as-node (train averages every usable stride of a mode)")
    recs = [_read_labelled(p, args)[0] for p in args.recordings]
    opts = TrainOptions(
        heel_strikes=args.heel_strikes,
        rate_hz=args.rate,
        min_strides=args.min_strides,
        detection=detection_options(args),
        outliers=OutlierRule(duration_floor=args.duration_tolerance),
    )
    result = train_library(recs, args.name or Path(args.out).stem, opts)
    out = save_library(result.library, args.out)
    print(format_report(result))
    print(f"wrote {out}")
    return 0


# ---------------------------------------------------------------------------------------------
# evaluate


def cmd_evaluate(args: argparse.Namespace) -> int:
    from ..analysis.evaluate import evaluate, format_metrics, read_predictions_csv
    from ..analysis.labels import parse_label_map
    from ..analysis.plots import plot_confusion, plot_phase_error, plot_timeseries

    label_map = parse_label_map(args.label_map)
    pred = read_predictions_csv(args.predictions)
    truth, labels_from = _read_labelled(args.truth, args)
    if truth.labels is None:
        raise GaitEstimatorError(f"{args.truth}: no 'mode' column (give --labels RANGES.csv or --mode NAME)")
    det = detection_options(args)
    hs = None if args.heel_strikes == "none" else heel_strikes(truth, args.heel_strikes, None, det)
    ev = evaluate(pred, truth, hs, label_map, det)
    ev.metrics["labels_from"] = labels_from
    if truth.time_from_rate:
        ev.metrics["truth_time_base"] = f"sample / {args.time_rate:g} Hz (no time stamps in {args.truth})"
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(_finite(ev.metrics), indent=2) + "\n", encoding="utf-8")
    title = args.title or Path(args.predictions).stem
    plot_confusion(ev.metrics, out / "confusion.png", title)
    plot_phase_error(ev.metrics, out / "phase_error.png", title)
    plot_timeseries(ev.aligned, out / "timeseries.png", title, args.window)
    print(format_metrics(ev.metrics))
    print(f"wrote {out / 'metrics.json'}, confusion.png, phase_error.png, timeseries.png")
    return 0


def _finite(value: Any) -> Any:
    """Replace NaN/inf floats by None so metrics.json is strict JSON."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


# ---------------------------------------------------------------------------------------------
# resample


def cmd_resample(args: argparse.Namespace) -> int:
    rec = _read_labelled(args.recording, args)[0]
    rate = args.rate or rec.median_rate_hz
    uni = resample_uniform(rec, rate)
    note = ""
    if args.heel_strikes != "none":
        hs = heel_strikes(rec, args.heel_strikes, rate, detection_options(args))
        flags = np.zeros(len(uni), dtype=bool)
        if hs.times_s.size:
            flags[nearest_index(uni.time_s, hs.times_s)] = True
        uni.heel_strike = flags
        note = f"; {int(flags.sum())} heel strikes ({hs.method})"
    write_project_csv(uni, args.out)
    gaps = np.diff(rec.time_s)
    print(
        f"{args.recording}: {len(rec)} samples (intervals {1e3 * gaps.min():.2f}-{1e3 * gaps.max():.2f} ms, "
        f"median rate {rec.median_rate_hz:.6g} Hz) -> {len(uni)} samples at {rate:.6g} Hz{note}"
    )
    print(f"wrote {args.out}")
    return 0


# ---------------------------------------------------------------------------------------------
# label-strides


def cmd_label_strides(args: argparse.Namespace) -> int:
    from ..analysis.labels import duration_labels, merge_steady, write_label_ranges
    from ..io.library_io import load_library

    lib = load_library(args.kernels)
    names = args.modes.split(",") if args.modes else lib.mode_names
    try:
        durations = {n: lib.mode(n).stride_duration_s for n in names}
    except KeyError as exc:
        raise GaitEstimatorError(str(exc.args[0])) from None
    rec = read_recording_args(args, args.recording, rate_hz=args.time_rate or lib.sample_rate_hz)
    det = detection_options(args)
    hs = heel_strikes(rec, args.heel_strikes, None, det)
    bounds, _ = stride_bounds(hs.times_s, det)
    if len(bounds) == 0:
        raise GaitEstimatorError(f"{args.recording}: no strides found ({hs.method})")
    strides = duration_labels(bounds, durations, args.tolerance)
    ranges = merge_steady(strides, steady_only=not args.all_strides)
    print(f"{'start_s':>8} {'dur_s':>6} {'nearest':>8} {'rel_err':>8} steady")
    for s in strides:
        rel = f"{100 * s.relative_error:7.1f}%"
        print(f"{s.start_s:8.3f} {s.end_s - s.start_s:6.3f} {s.nearest or '-':>8} {rel} {'yes' if s.steady else 'no'}")
    kern = ", ".join(f"{n} {d:.3f} s" for n, d in durations.items())
    modes_opt = (f" --modes {args.modes}" if args.modes else "") + (" --all-strides" if args.all_strides else "")
    comments = [
        f"Labels derived by: gait-estimator label-strides {args.recording} --kernels {args.kernels}{modes_opt} "
        f"--heel-strikes {args.heel_strikes} --tolerance {args.tolerance:g}",
        f"Heel strikes: {hs.method}; strides {det.min_stride_s:g}-{det.max_stride_s:g} s.",
        f"Each stride gets the mode with the nearest kernel stride duration ({kern}) if within "
        f"{100 * args.tolerance:g} %; "
        + ("every such stride is labelled (transitional ones too)." if args.all_strides else
           "only steady strides (both neighbouring strides have the same nearest mode) are labelled."),
        "Derived from cadence, not measured speed: a proxy truth; see README.",
    ]
    write_label_ranges(ranges, args.out, comments)
    steady = sum(s.steady for s in strides)
    labelled = sum(bool(s.steady if not args.all_strides else s.nearest) for s in strides)
    print(f"{len(strides)} strides, {steady} steady, {labelled} labelled -> {len(ranges)} label ranges; wrote {args.out}")
    return 0


# ---------------------------------------------------------------------------------------------


def add_commands(sub: Any) -> None:
    """Register ``train``, ``evaluate``, ``resample`` and ``label-strides``."""
    hs_help = (
        "right heel strikes: 'column' (heel_strike column), 'right_foot' / 'right_shank' (peaks of that angle; "
        "the paper uses the foot for level/ramp, the shank for stairs), 'auto' = column, else right_foot if "
        "present, else right_shank (default %(default)s)"
    )

    t = sub.add_parser("train", help="build a kernel library from labelled recordings (average of strides per mode)")
    t.add_argument("recordings", nargs="+", metavar="REC",
                   help="recording(s): project CSV, reference Dimension CSV or rosbag2 bag")
    t.add_argument("--out", "-o", required=True, help="library file to write (.yaml or .npz)")
    _label_args(t)
    t.add_argument("--heel-strikes", choices=HEEL_STRIKE_SOURCES, default="auto", help=hs_help)
    t.add_argument("--rate", type=positive_float, metavar="HZ",
                   help="uniform rate to resample to and store in the library (default: median rate of the recordings)")
    t.add_argument("--name", help="library name (default: the output file's stem)")
    t.add_argument("--min-strides", type=int, default=3, help="fewest usable strides per mode (default %(default)s)")
    t.add_argument("--duration-tolerance", type=positive_float, default=0.10,
                   help="never reject strides within this fraction of the median duration (default %(default)s)")
    _detection_args(t)
    _time_rate_arg(t)
    add_imu_reading_options(t)
    t.add_argument("--as-node", action="store_true", help="bags: the kernels the node's teaching builds as the bags "
                   "play, teach_mode = --mode, or each --labels range's mode in its range (docs/teach.md)")
    t.add_argument("--strides", type=int, help="--as-node: good strides a taught kernel averages, as teach_strides "
                   f"(default {TEACH_STRIDES})")
    t.set_defaults(func=cmd_train)

    e = sub.add_parser("evaluate", help="accuracy, confusion, phase error and figures of predictions vs truth")
    e.add_argument("--predictions", required=True, metavar="PRED.csv", help="CSV from 'gait-estimator process'")
    e.add_argument("--truth", required=True, metavar="REC.csv", help="recording with labels (mode column, or --labels/--mode)")
    e.add_argument("--out-dir", required=True, metavar="DIR", help="directory for metrics.json and PNG figures")
    _label_args(e)
    e.add_argument("--label-map", metavar="TRUTH=PRED,...",
                   help="rename truth labels, e.g. level=Med; 'level=Slow|Med|Fast' accepts any of them; 'turn=' drops one")
    e.add_argument("--heel-strikes", choices=(*HEEL_STRIKE_SOURCES, "none"), default="auto",
                   help=hs_help.replace(" (default %", "; 'none' = no phase truth (default %"))
    e.add_argument("--window", type=_window, metavar="START:END", help="time window (s) of the time-series figure")
    e.add_argument("--title", help="figure title (default: the predictions file name)")
    _detection_args(e)
    _time_rate_arg(e)
    add_imu_reading_options(e)
    e.set_defaults(func=cmd_evaluate)

    r = sub.add_parser("resample", help="resample a recording to a uniform rate (with labels and heel strikes)")
    r.add_argument("recording", help="recording: project CSV, reference Dimension CSV or rosbag2 bag")
    r.add_argument("--out", "-o", required=True, help="project CSV to write")
    r.add_argument("--rate", type=positive_float, metavar="HZ", help="target rate (default: the recording's median rate)")
    _label_args(r)
    r.add_argument("--heel-strikes", choices=(*HEEL_STRIKE_SOURCES, "none"), default="none",
                   help="add a heel_strike column found this way (default %(default)s)")
    _detection_args(r)
    _time_rate_arg(r)
    add_imu_reading_options(r)
    r.set_defaults(func=cmd_resample)

    ls = sub.add_parser("label-strides", help="label steady strides by the nearest kernel stride duration (cadence)")
    ls.add_argument("recording", help="recording: project CSV, reference Dimension CSV or rosbag2 bag")
    ls.add_argument("--kernels", "-k", default=DEFAULT_LIBRARY, metavar="LIB", help="library giving N_m / rate per mode")
    ls.add_argument("--modes", metavar="A,B,...", help="modes to choose from (default: all of the library)")
    ls.add_argument("--heel-strikes", choices=HEEL_STRIKE_SOURCES, default="auto", help=hs_help)
    ls.add_argument("--tolerance", type=positive_float, default=0.15,
                    help="largest relative difference from the nearest kernel duration (default %(default)s)")
    ls.add_argument("--all-strides", action="store_true",
                    help="label every stride within --tolerance, not only steady ones (harsher: includes speed changes)")
    ls.add_argument("--out", "-o", required=True, help="label range CSV to write")
    _detection_args(ls)
    _time_rate_arg(ls, None)
    add_imu_reading_options(ls)
    ls.set_defaults(func=cmd_label_strides)
