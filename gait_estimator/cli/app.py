"""``gait-estimator``: the offline command-line toolkit (no ROS needed).

Subcommands are added by modules listed in ``COMMAND_MODULES``; each provides
``add_commands(subparsers)`` and sets ``func`` (returns the exit code) on its parsers.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from ..core.errors import GaitEstimatorError, missing_extra
from ..io.library_io import load_library, save_library
from ..io.resources import DEFAULT_LIBRARY
from .args import choice_list, int_list, positive_int, prepare_output, read_recording_args, reader_options, save_report

COMMAND_MODULES: tuple[str, ...] = (
    "gait_estimator.cli.node_commands",
    "gait_estimator.cli.bench_node",
    "gait_estimator.cli.bag_commands",
    "gait_estimator.cli.analysis_commands",
    "gait_estimator.cli.teach_command",
    "gait_estimator.cli.watch_command",
    "gait_estimator.cli.dashboard_command",
)
"""Further modules contributing subcommands (kept ROS-free at import time)."""

PROG = "gait-estimator"


def _kernels_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--kernels", "-k", default=DEFAULT_LIBRARY, metavar="LIB",
        help="kernel library: .yaml/.npz file, reference CSV/YAML file or directory, or a bundled "
        "name (able_bodied, prosthesis); default %(default)s",
    )


# ---------------------------------------------------------------------------------------------
# kernels show / convert


def cmd_kernels_show(args: argparse.Namespace) -> int:
    lib = load_library(args.library)
    print(f"library '{lib.name}' from {lib.path}: {len(lib)} modes, {lib.sample_rate_hz:g} Hz")
    print(f"{'mode':<12} {'id':>3} {'N':>5} {'stride_s':>9} {'rate_hz':>8}")
    for m in lib.modes:
        print(f"{m.name:<12} {m.mode_id:>3} {m.length:>5} {m.stride_duration_s:>9.3f} {m.sample_rate_hz:>8g}")
    source = lib.provenance.get("source")
    if source:
        print(f"source: {source}")
    lic = str(lib.provenance.get("license", "")).strip()
    if lic:
        print(f"license: {lic.splitlines()[0]}" + (f" / {lic.splitlines()[2]}" if len(lic.splitlines()) > 2 else ""))
    return 0


def cmd_kernels_convert(args: argparse.Namespace) -> int:
    lib = load_library(args.source)
    if args.name:
        from dataclasses import replace

        lib = replace(lib, name=args.name)
    out = save_library(lib, args.out)
    print(f"wrote {out} ({len(lib)} modes: {', '.join(lib.mode_names)})")
    return 0


# ---------------------------------------------------------------------------------------------
# process


def cmd_process(args: argparse.Namespace) -> int:
    from ..io.process import format_summary, predict, write_predictions_csv
    from .bag_commands import BAG_READING_OPTIONS, finish_process, warn_units
    from .estimator_args import config_from_args

    lib = load_library(args.kernels)
    options = {"rate_hz": lib.sample_rate_hz, **reader_options(args, BAG_READING_OPTIONS)}
    config = config_from_args(args, max_gap_s=options.get("max_gap_s"))
    if args.as_node:
        from .as_node import process_as_node

        return process_as_node(args, lib, config, {**reader_options(args), **options})
    rec = read_recording_args(args, args.recording, **options)
    if args.start is not None and args.stop is not None and args.stop <= args.start:
        raise GaitEstimatorError(f"--stop ({args.stop}) must be greater than --start ({args.start})")
    rec = rec.slice(args.start, args.stop)
    if len(rec) == 0:
        raise GaitEstimatorError(f"{args.recording}: no samples in the selected range")
    warn_units(rec, args.recording, options.get("input_units", "rad"))
    if args.save_adapted:
        if config.adapt_rate <= 0:
            raise GaitEstimatorError("--save-adapted needs personalisation on: --adapt-rate > 0")
        if Path(args.save_adapted).suffix.lower() not in (".yaml", ".yml", ".npz"):
            raise GaitEstimatorError(f"--save-adapted {args.save_adapted}: the file name must end in .yaml or .npz")
        prepare_output(args.save_adapted, "--save-adapted")
    pred = predict(rec, lib, config)  # restarts the window at gaps > max_gap_s, like the node
    if args.out:
        write_predictions_csv(pred, args.out)
    if args.save_adapted and pred.adapted is not None:
        try:
            save_library(pred.adapted, args.save_adapted)
        except OSError as exc:
            raise GaitEstimatorError(f"--save-adapted {args.save_adapted}: {exc.strerror or exc}") from None
    bag_lines = finish_process(args, rec, pred)  # --out-bag; notes on bag stamps and gaps
    if not args.quiet:
        print(format_summary(pred, lib, str(args.recording)))
        if rec.time_from_rate:
            print(f"note: {args.recording} has no time stamps; time = sample / {lib.sample_rate_hz:g} Hz")
        for reason, count in rec.skipped.items():
            print(f"skipped {count} sample(s): {reason}")
        for line in bag_lines:
            print(line)
        if args.out:
            print(f"wrote {args.out}")
        if args.save_adapted and pred.adapted is not None:
            strides = pred.adapted.provenance["adaptation"]["accepted_strides"]
            print(f"wrote {args.save_adapted} (personalised kernels; strides adopted: "
                  + ", ".join(f"{m} {n}" for m, n in strides.items()) + ")")
    return 0


# ---------------------------------------------------------------------------------------------
# bench


def cmd_bench(args: argparse.Namespace) -> int:
    from ..analysis.bench import bench, drift, load_times, preset_target_met, time_reference

    lib = load_library(args.kernels)
    if args.compare_reference and not args.reference_samples:
        raise GaitEstimatorError("--compare-reference needs --reference-samples (samples the command processes)")
    if args.json:
        prepare_output(args.json, "--json")
    try:
        report = bench(lib, args.modes, steps=args.steps, naive_max_modes=args.naive_max_modes, backends=args.backends,
                       preset_max_modes=args.preset_max_modes, process_max_modes=args.process_max_modes)
    except ValueError as exc:
        raise GaitEstimatorError(f"--backends: {exc}") from None
    report["library_load"] = load_times(lib, max(args.modes))
    if args.drift_steps:
        report["drift"] = drift(lib, args.drift_steps)
    if args.compare_reference:
        try:
            report["reference"] = time_reference(args.compare_reference, args.reference_samples)
        except (OSError, RuntimeError, ValueError, subprocess.SubprocessError) as exc:
            raise GaitEstimatorError(f"--compare-reference: {exc}") from None
    mach = report["machine"]
    print(f"{mach['processor']}, {mach['cpus_allowed']} of {mach['cpus']} CPUs, Python {mach['python']}, "
          f"numpy {mach['numpy']}, numba {mach['numba'] or 'not installed'}")
    for r in report["results"]:
        what = f"{r['impl']}, {r['preset']}" + (f" ({r['rows']} rows)" if "rows" in r else "")
        if "samples_per_s" in r:  # offline process throughput
            print(f"M={r['modes']:<5} {what:<42} {r['samples_per_s']:9.0f} samples/s in bulk, "
                  f"{r['streaming_samples_per_s']:9.0f} sample by sample ({r['speedup']:.1f}x)"
                  + ("" if r["same_estimates"] else "  DIFFERENT ESTIMATES"))
            continue
        print(
            f"M={r['modes']:<5} {what:<42} median {r['step_us_median']:9.1f} us  p99 {r['step_us_p99']:9.1f} us"
            + (f"  state {r['state_bytes'] / 1e6:7.2f} MB" if "state_bytes" in r else "")
            + (f"  offline {r['offline_samples_per_s']:9.0f} samples/s" if "offline_samples_per_s" in r else "")
            + (f"  x{r['median_ratio_to_paper']:.2f} paper (p99 x{r['p99_ratio_to_paper']:.2f})"
               if "p99_ratio_to_paper" in r else "")
            + (f"; state x{r['state_ratio_to_paper']:.1f}" if "state_ratio_to_paper" in r else "")
            + (f"; target <= 2x: {'met' if preset_target_met(r) else 'missed'}"
               if r["impl"].startswith("estimator") and "p99_ratio_to_paper" in r else "")
        )
    for r in report["library_load"]:
        print(f"load {r['modes']}-mode library from {r['format']:<4}: {r['load_s']:.3f} s ({r['file_bytes'] / 1e6:.1f} MB)")
    if "drift" in report:
        d = report["drift"]
        print(f"drift after {d['steps']} steps (M={d['modes']}): max relative error {d['max_relative_error']:.2e}")
    if "reference" in report:
        ref = report["reference"]
        print(f"reference command: {ref['us_per_sample_best']:.2f} us per sample (best of {ref['runs']} runs of "
              f"{ref['samples']} samples, process start-up included)")
    save_report(args.json, report)
    return 0


# ---------------------------------------------------------------------------------------------


class OneLineErrors(argparse.ArgumentParser):
    """A usage error is one line, the error and where the usage is, exit 2 (argparse prints the
    whole usage first: 30 lines for ``process``). Subcommands' parsers are of this class too."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (usage: {self.prog} -h)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineErrors(
        prog=PROG,
        description="Locomotion mode classification and gait phase estimation by kernel matching "
        "(Posh, Li, Wensing). Offline tools; the ROS 2 node is 'estimator_node'.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    kernels = sub.add_parser("kernels", help="inspect and convert kernel libraries")
    ksub = kernels.add_subparsers(dest="kernels_command", metavar="ACTION", required=True)
    show = ksub.add_parser("show", help="table of modes: N, stride duration, sample rate")
    show.add_argument("library", help="library file/directory or bundled name")
    show.set_defaults(func=cmd_kernels_show)
    conv = ksub.add_parser("convert", help="convert any supported library to project .yaml or .npz")
    conv.add_argument("source", help="library file/directory or bundled name")
    conv.add_argument("--out", required=True, help="output file (.yaml or .npz)")
    conv.add_argument("--name", help="library name to store (default: keep)")
    conv.set_defaults(func=cmd_kernels_convert)

    proc = sub.add_parser("process", help="run the estimator over a recording, write predictions CSV")
    proc.add_argument("recording", help="recording: project CSV, reference Dimension:4xT CSV, or rosbag2 bag "
                      "(directory, .mcap or .db3 file)")
    _kernels_arg(proc)
    proc.add_argument("--start", type=int, help="first sample index (inclusive); state starts fresh here")
    proc.add_argument("--stop", type=int, help="last sample index (exclusive)")
    proc.add_argument("--out", "-o", help="predictions CSV: time_s, sample, mode, phase, ready, sse_<mode>...")
    proc.add_argument("--quiet", "-q", action="store_true", help="no summary on stdout")
    proc.add_argument("--save-adapted", metavar="LIB", help="with --adapt-rate > 0: write the personalised kernel "
                      "library (.yaml or .npz) at the end")
    proc.add_argument("--as-node", action="store_true", help="a bag (angles or four Imu topics): every message "
                      "through the node's GaitStream, as estimator_node takes it live (docs/bags.md)")
    from .bag_commands import add_process_options
    from .estimator_args import add_estimator_arguments

    add_process_options(proc)
    add_estimator_arguments(proc)
    proc.set_defaults(func=cmd_process)

    b = sub.add_parser("bench", help="benchmark the matcher (per-step time, memory, drift)")
    _kernels_arg(b)
    b.add_argument("--modes", type=int_list, default=[7, 700], help="mode counts, e.g. 7,70,700 (default 7,700)")
    b.add_argument("--steps", type=positive_int, default=5000, help="timed steps per mode count (default 5000)")
    b.add_argument("--naive-max-modes", type=int, default=7, help="also time the naive matcher up to this M (default 7)")
    b.add_argument("--drift-steps", type=int, default=0, help="also run this many steps and report drift vs recomputation")
    b.add_argument("--backends", type=choice_list(("numba", "numpy")), default=["numba", "numpy"],
                   help="matcher step implementations to time, e.g. numba,numpy (default; numba only if installed)")
    b.add_argument("--preset-max-modes", type=int, default=70,
                   help="also time the default preset's bare matcher (every row, every step) up to this M (default "
                   "70); Estimator.update of both presets is timed at every M")
    b.add_argument("--process-max-modes", type=int, default=70,
                   help="also time offline processing (bulk and sample by sample) up to this M (default 70)")
    b.add_argument("--compare-reference", metavar="CMD",
                   help="also time this command (a reference implementation you built; never built here) as a black "
                   "box, e.g. 'ref/swge_bench data.csv'; needs --reference-samples")
    b.add_argument("--reference-samples", type=positive_int, help="samples the --compare-reference command processes")
    b.add_argument("--json", help="write the report as JSON")
    b.set_defaults(func=cmd_bench)

    for name in COMMAND_MODULES:
        importlib.import_module(name).add_commands(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except GaitEstimatorError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except ImportError as exc:  # an optional dependency: name the extra that installs it
        extra = missing_extra(exc)
        if extra is None:
            raise
        print(f"{PROG} {args.command} {extra}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0

