"""``gait-estimator watch``: print a running estimator_node's mode, phase and diagnostics.

rclpy is imported only when the command runs, so the offline CLI works without ROS.
"""

from __future__ import annotations

import argparse
import re
import time
from collections.abc import Sequence
from typing import Any

from ..dashboard.state import STALE_AFTER_S
from ..ros import require_ros
from .args import add_target_node_options, positive_float

_READY = re.compile(r"^ready: \S+ phase [0-9.]+(; )?")
"""The diagnostics message's start that repeats the mode and phase columns."""


def watch_line(elapsed_s: float, mode: str | None, phase: float | None, level: str, message: str,
               values: dict[str, str], keys: Sequence[str]) -> str:
    """One line: seconds since the start, the mode and phase published since the previous line
    (``-``: none), the diagnostics level and message, and the diagnostics ``keys`` asked for."""
    status = f"[{level}] {_READY.sub('', message)}".rstrip() if level else "(no diagnostics yet)"
    line = f"{elapsed_s:7.1f} s  {mode or '-':<12}  {'-' if phase is None else f'{phase:.3f}':>5}  {status}"
    return "  ".join([line, *(f"{k}={values.get(k, '?')}" for k in keys)])


def cmd_watch(args: argparse.Namespace) -> int:
    require_ros()
    from ..ros.watch_client import TargetStatus, WatchClient

    keys = [k.strip() for k in (args.keys or "").split(",") if k.strip()]
    try:
        with WatchClient(args.node, args.domain_id, args.timeout) as client:
            print(f"watching {client.target} on ROS_DOMAIN_ID={client.context.get_domain_id()}: mode, phase, "
                  f"diagnostics every {1 / args.rate:g} s; Ctrl-C stops", flush=True)
            seen, start, counted = client.seen, time.monotonic(), 0
            while args.duration is None or time.monotonic() - start < args.duration:
                client.spin_until(lambda: False, 1.0 / args.rate)
                now = time.monotonic()
                fresh = seen.estimates > counted
                counted = seen.estimates
                st = seen.status or TargetStatus("", "", {}, start)
                level, message, age = st.level, st.message, now - st.at
                if age > STALE_AFTER_S:
                    level, message = "STALE", f"no diagnostics for {age:.0f} s (has the node stopped?)"
                print(watch_line(now - start, seen.mode if fresh else None, seen.phase if fresh else None,
                                 level, message, st.values, keys), flush=True)
    except KeyboardInterrupt:
        return 130
    return 0


def add_commands(sub: Any) -> None:
    """Register ``watch`` on the ``gait-estimator`` subparsers."""
    w = sub.add_parser(
        "watch",
        help="print a running estimator_node's mode, phase and diagnostics (no ros2 CLI needed)",
        description="Subscribe to a running estimator_node's mode and phase topics and its /diagnostics, and "
        "print one line every 1/RATE s: seconds, the latest mode and phase ('-': no estimate since the "
        "previous line), the diagnostics level and message (problems, IMU calibration, teaching), and the "
        "diagnostics values named by --keys; STALE when none came for 3 s. Watching makes the node publish "
        "mode and phase (it skips topics without subscribers); topics remapped on the node are not followed. "
        "Uses the environment's ROS_DOMAIN_ID and discovery range unless --domain-id is given. Exits 2 with "
        "one line when the node is not found, 130 on Ctrl-C.",
    )
    w.add_argument("--keys", metavar="KEY,...", help="diagnostics values to print too, e.g. "
                   "imu_calibration_status,sensor_offset_deg,input_rate_hz (docs/node.md, docs/imu.md list them)")
    w.add_argument("--rate", type=positive_float, default=2.0, help="lines per second (default %(default)s)")
    w.add_argument("--duration", type=positive_float, help="stop after this many seconds (default: Ctrl-C)")
    add_target_node_options(w, node_note="; its mode and phase topics are in its namespace")
    w.set_defaults(func=cmd_watch)
