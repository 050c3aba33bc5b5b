"""``gait-estimator dashboard`` (also the ``estimator_dashboard`` executable for launch files): the
live web view of a running estimator_node (gait_estimator/dashboard/, docs/dashboard.md).

rclpy and aiohttp are imported only when the command runs, so the offline CLI works without them.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import secrets
import signal
import sys
from collections.abc import Sequence
from typing import Any

from ..core.errors import GaitEstimatorError
from ..ros import require_ros
from .args import add_target_node_options, port_number, positive_float

MAX_RATE_HZ = 60.0
"""Most page updates per second: each page's frames cost the leg's computer."""


def frame_rate(text: str) -> float:
    v = positive_float(text)
    if v > MAX_RATE_HZ:
        raise argparse.ArgumentTypeError(f"at most {MAX_RATE_HZ:g} updates per second, got {text}")
    return v


def dashboard_token(host: str, given: str | None, env: dict[str, str]) -> str | None:
    """The token the page and socket ask for: ``--token``, else the environment's, else a new one
    when ``host`` is not loopback (None: loopback without a token)."""
    from ..dashboard.server import TOKEN_ENV, is_loopback

    token = given if given is not None else env.get(TOKEN_ENV) or None
    if token is not None and len(token) < 8:
        raise GaitEstimatorError("--token: at least 8 characters")
    if token is None and not is_loopback(host):
        token = secrets.token_urlsafe(18)
    return token


def cmd_dashboard(args: argparse.Namespace) -> int:
    require_ros()
    import aiohttp  # noqa: F401  (the 'dashboard' extra; named in one line when missing)

    from ..dashboard.server import Dashboard, ServerOptions, serve
    from ..ros.dashboard_client import DashboardLink

    logging.basicConfig(level=logging.INFO, format="dashboard: %(message)s", stream=sys.stdout, force=True)
    logging.getLogger("aiohttp").setLevel(logging.WARNING)
    token = dashboard_token(args.host, args.token, dict(os.environ))
    options = ServerOptions(args.host, args.port, token, args.read_only, args.rate)
    try:
        link = DashboardLink(args.node, args.domain_id)
    except Exception as exc:  # an invalid node name: rclpy's own exception types vary
        raise GaitEstimatorError(f"--node {args.node}: {str(exc).splitlines()[0]}") from None
    link.start()

    async def run() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop.set)

        def ready(url: str) -> None:
            print(f"dashboard of {link.target} on ROS_DOMAIN_ID={link.client.context.get_domain_id()}"
                  f"{' (read-only)' if args.read_only else ''}: open {url}", flush=True)

        await serve(Dashboard(link, options), ready, stop)

    try:
        asyncio.run(run())
    except OSError as exc:  # the port is taken, or the host is not an address of this machine
        raise GaitEstimatorError(f"--host {args.host} --port {args.port}: {exc.strerror or exc}") from None
    finally:
        link.close()
    return 0


def add_commands(sub: Any) -> None:
    """Register ``dashboard`` on the ``gait-estimator`` subparsers."""
    d = sub.add_parser(
        "dashboard",
        help="serve a live web page of a running estimator_node (mode, phase, stride over kernel; teaching)",
        description="Follow a running estimator_node (it may start later, restart or stop) and serve one page "
        "that shows its state, phase, the last stride over the mode's kernel, per-mode errors, input and "
        "diagnostics, and teaches it (teach_mode, ~/save_library). Loopback only unless --host is given, then "
        "with a token. Uses the environment's ROS_DOMAIN_ID unless --domain-id is given. Needs the 'ros' and "
        "'dashboard' extras. docs/dashboard.md",
    )
    d.add_argument("--host", default="127.0.0.1", help="address to serve on (default %(default)s: this machine only; "
                   "any other asks for a token)")
    d.add_argument("--port", type=port_number, default=8080, help="TCP port (default %(default)s; 0 = any free one)")
    d.add_argument("--token", help="the token the page asks for (default: $GAIT_DASHBOARD_TOKEN, else a new one "
                   "printed with the URL when --host is not loopback; given, it is asked on loopback too)")
    d.add_argument("--read-only", action="store_true", help="show the node only: no teaching, no saving")
    d.add_argument("--rate", type=frame_rate, default=30.0, help="page updates per second, at most 60 (default %(default)s)")
    add_target_node_options(d)
    d.set_defaults(func=cmd_dashboard)


def main(argv: Sequence[str] | None = None) -> int:
    """The ``estimator_dashboard`` executable (``ros2 run`` / launch files): ``gait-estimator
    dashboard``'s options; the ``--ros-args ...`` a launch file appends are ignored."""
    from .app import main as cli_main

    argv = list(sys.argv[1:] if argv is None else argv)
    if "--ros-args" in argv:
        argv = argv[: argv.index("--ros-args")]
    return cli_main(["dashboard", *argv])
