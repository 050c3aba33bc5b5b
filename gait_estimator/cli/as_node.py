"""``process --as-node``: a bag (angles or four Imu topics) taken message by message as
``estimator_node`` takes it live (``io/as_node.predict_as_node``, the node's ``GaitStream``)."""

from __future__ import annotations

import argparse
from typing import Any

from ..core.errors import GaitEstimatorError
from ..core.kernels import KernelLibrary
from ..core.options import EstimatorConfig


def process_as_node(args: argparse.Namespace, lib: KernelLibrary, config: EstimatorConfig, options: dict[str, Any]) -> int:
    from ..io.as_node import predict_as_node
    from ..io.process import format_summary, write_predictions_csv
    from ..io.read_options import ReadOptions

    for flag, given in (("--start", args.start), ("--stop", args.stop), ("--out-bag", args.out_bag),
                        ("--save-adapted", args.save_adapted),
                        ("--save-imu-calibration", getattr(args, "save_imu_calibration", None))):
        if given is not None:
            raise GaitEstimatorError(f"--as-node takes the whole bag as the node does: {flag} is not for it")
    pred, stream = predict_as_node(args.recording, lib, config, ReadOptions.of(None, options))
    if args.out:
        write_predictions_csv(pred, args.out)
    if not args.quiet:
        print(format_summary(pred, lib, str(args.recording)))
        rejected = {r: n for r, n in stream.guard.rejected.items() if n}
        print(f"as the node: {stream.received} messages, {stream.accepted} accepted, window restarts "
              f"{stream.window_resets} ({stream.stream_restarts} jumps back)"
              + ("; dropped: " + ", ".join(f"{n} {r}" for r, n in rejected.items()) if rejected else ""))
        for event in stream.take_events():
            if event.warn:
                print(f"warning: {event.line}")
        if args.out:
            print(f"wrote {args.out}")
    return 0
