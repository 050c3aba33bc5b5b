"""``gait-estimator teach``: teach a mode to a running estimator_node, or save its library.

rclpy is imported only when the command runs, so the offline CLI works without ROS.
"""

from __future__ import annotations

import argparse
import os
from typing import Any

from ..core.errors import GaitEstimatorError
from ..core.teach import TEACH_STRIDES, check_teach_strides
from ..ros import require_ros
from .args import add_target_node_options, positive_float

MAX_TIME_S = 120.0
"""``teach``'s default time limit: ten strides take under a minute of steady walking."""


def _strides(text: str) -> int:
    try:
        value = int(text)
        check_teach_strides(value)
    except (ValueError, GaitEstimatorError) as exc:
        raise argparse.ArgumentTypeError(str(exc) if isinstance(exc, GaitEstimatorError) else
                                         f"expected an integer, got {text!r}") from None
    return value


def cmd_teach(args: argparse.Namespace) -> int:
    if not args.mode and not args.save:
        raise GaitEstimatorError("teach: give --mode NAME (teach it) and/or --save PATH (save the node's library)")
    require_ros()
    from ..ros.teach_client import TeachClient

    with TeachClient(args.node, args.domain_id, args.timeout) as client:
        code = 0
        if args.mode:
            client.on_log = lambda line: None if ": kernel built from " in line else print(line, flush=True)
            print(f"teaching {args.mode} on {client.target}: walk steadily in that mode "
                  f"({args.strides} good strides); Ctrl-C cancels", flush=True)
            try:
                done, text = client.teach(args.mode, args.strides, max_s=args.max_time)
            except KeyboardInterrupt:
                client.cancel()
                print(f"cancelled: teach_mode of {client.target} set back to ''", flush=True)
                return 130
            print(("done: " if done else "not taught: ") + text, flush=True)
            code = 0 if done else 1
        if args.save and code == 0:
            print(client.save(os.path.abspath(os.path.expanduser(args.save))), flush=True)
        return code


def add_commands(sub: Any) -> None:
    """Register ``teach`` on the ``gait-estimator`` subparsers."""
    t = sub.add_parser(
        "teach",
        help="teach a mode to a running estimator_node from the wearer's strides, or save its library",
        description="Set teach_mode (and teach_strides) of a running estimator_node, print its progress until "
        "the kernel is built, then the kernel's summary; --save PATH has the node write its library (taught "
        "modes included) there. Uses the environment's ROS_DOMAIN_ID and discovery range unless --domain-id "
        "is given. Exits 2 with one line when no node answers.",
    )
    t.add_argument("--mode", metavar="NAME", help="mode to teach (a new name adds it, an existing one replaces it)")
    t.add_argument("--strides", type=_strides, default=TEACH_STRIDES,
                   help="good strides to average (default %(default)s; at least train's --min-strides, 3)")
    t.add_argument("--save", metavar="PATH", help="have the node save its library to PATH (.yaml or .npz; a "
                   "relative PATH is taken from this directory) (after teaching, when --mode is given too)")
    add_target_node_options(t)
    t.add_argument("--max-time", type=positive_float, default=MAX_TIME_S, metavar="SECONDS",
                   help="give up (and cancel) after this many seconds, saying what to do next (default %(default)g)")
    t.set_defaults(func=cmd_teach)
