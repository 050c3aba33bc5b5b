"""``gait-estimator demo``: the ROS 2 node at work (``bench-node`` is in bench_node.py).

Both start ``estimator_node`` as a child process and talk to it over real DDS restricted to
this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, a domain ID of their own). rclpy is
imported only when a command runs, so the offline CLI works without ROS.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import GaitEstimatorError
from ..io.resources import DEFAULT_LIBRARY
from ..ros import require_ros
from .args import add_imu_reading_options, domain_id, port_number, positive_float, read_recording_args

DEMO_DOMAIN_ID = 77
"""``demo``'s ROS domain when neither ``--domain-id`` nor ``ROS_DOMAIN_ID`` is set."""


def demo_domain(given: int | None) -> tuple[int, str]:
    """(domain ID, where it came from): ``--domain-id``, else the environment's ``ROS_DOMAIN_ID``,
    else DEMO_DOMAIN_ID."""
    if given is not None:
        return given, "--domain-id"
    env = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not env:
        return DEMO_DOMAIN_ID, "the demo's default; set ROS_DOMAIN_ID or --domain-id to change it"
    try:
        return domain_id(env), "from the environment"
    except argparse.ArgumentTypeError as exc:
        raise GaitEstimatorError(f"ROS_DOMAIN_ID: {exc}") from None


@contextmanager
def running_node(domain_id: int, kernels: str, extra_ros_args: list[str], node_cmd: str | None, timeout_s: float,
                 **client_options: Any) -> Iterator[tuple[Any, Any]]:
    """(node, client): estimator_node in a child process and an EstimatorClient (``client_options``)
    connected to it within ``timeout_s``; both closed at the end."""
    from ..ros.node_client import EstimatorClient, NodeProcess, local_ros_environment, node_command

    ros_args = ["-p", f"kernels:={kernels}", *extra_ros_args]
    with NodeProcess(node_command(ros_args, node_cmd), local_ros_environment(domain_id)) as node:
        with EstimatorClient(domain_id, **client_options) as client:
            deadline = time.monotonic() + timeout_s
            while not client.wait_for_node(timeout_s=0.2, settle_s=0.5):
                if node.poll() is not None:
                    out = node.output().strip().splitlines()
                    raise GaitEstimatorError(f"estimator_node exited with code {node.poll()}: "
                                             f"{out[-1] if out else '(no output)'}")
                if time.monotonic() > deadline:
                    raise GaitEstimatorError(f"estimator_node did not connect within {timeout_s:g} s")
            yield node, client


def percentiles(values_ms: np.ndarray) -> dict[str, float]:
    if values_ms.size == 0:
        return {}
    p50, p90, p99 = np.percentile(values_ms, [50, 90, 99])
    return {"p50_ms": float(p50), "p90_ms": float(p90), "p99_ms": float(p99), "max_ms": float(values_ms.max())}


# ---------------------------------------------------------------------------------------------
# demo


def _demo_recording(args: argparse.Namespace) -> tuple[Path, Any, Any]:
    """(path, library, recording slice) of ``demo``'s arguments; one-line errors."""
    from ..io.library_io import load_library
    from ..io.resources import DEMO_RECORDING, data_path

    try:
        path = Path(args.recording) if args.recording else data_path(DEMO_RECORDING)
    except FileNotFoundError as exc:
        raise GaitEstimatorError(f"{exc} (pass a recording: gait-estimator demo RECORDING)") from None
    if not path.exists():
        raise GaitEstimatorError(f"{path}: recording not found")
    lib = load_library(args.kernels)
    rec = read_recording_args(args, path, rate_hz=lib.sample_rate_hz)
    rec = rec.slice(args.start, args.stop)
    if len(rec) == 0:
        raise GaitEstimatorError(f"{path}: no samples in the selected range")
    return path, lib, rec


def _echo(client: Any, echo_every: int) -> None:
    """Print mode and phase messages as ``ros2 topic echo`` would: 1 in ``echo_every``, and
    every mode change."""
    state = {"mode": None, "n_mode": 0, "n_phase": 0}

    def on_mode(mode: str) -> None:
        state["n_mode"] += 1
        changed = mode != state["mode"]
        if changed or state["n_mode"] % echo_every == 0:
            print(f"mode: data: {mode}" + ("   <- mode change" if changed and state["mode"] else ""), flush=True)
        state["mode"] = mode

    def on_phase(phase: float) -> None:
        state["n_phase"] += 1
        if state["n_phase"] % echo_every == 0:
            print(f"phase: data: {phase:.4f}", flush=True)

    client.on_mode, client.on_phase = on_mode, on_phase


def _demo_summary(client: Any, path: Path, lib: Any, rec: Any, stamps: np.ndarray, sent: np.ndarray,
                  wall: float, diag: dict[str, str] | None) -> bool:
    """Print what the node published against offline ``process``; True if every answered sample
    has the offline mode."""
    from ..io.process import Predictions, format_summary, predict
    from ..io.recording import Recording

    got = client.received
    stamp_index = {int(s): i for i, s in enumerate(stamps)}
    idx = np.array([stamp_index.get(s, -1) for s in got.estimate_stamp_ns], dtype=np.int64)
    live = Predictions(rec.time_s[idx], np.asarray(rec.index)[idx], got.trace(lib.mode_names))
    print()
    print("summary of what the node published:")
    print(format_summary(live, lib, f"{path.name} via estimator_node"))
    print(
        f"sent {len(rec)} samples in {wall:.1f} s; received {client.estimate_count} estimates, "
        f"{client.mode_count} mode and {client.phase_count} phase messages"
    )
    answered = Recording(time_s=rec.time_s[idx], angles_deg=rec.angles_deg[idx], index=np.asarray(rec.index)[idx])
    offline = predict(answered, lib).trace
    same = int(((offline.mode_index == live.trace.mode_index) & (offline.mode == live.trace.mode)).sum())
    print(f"same mode as offline 'gait-estimator process' on the same samples: {same}/{idx.size}")
    if idx.size < len(rec):
        missing = np.setdiff1d(np.arange(len(rec)), idx)
        print(f"{len(rec) - idx.size} input samples were not answered (best-effort input; try --reliable): {missing[:10]}")
    lat = (np.array(got.estimate_recv_ns, dtype=np.int64) - sent[idx]) / 1e6
    if lat.size:
        p = percentiles(lat)
        print(f"input -> estimate latency: p50 {p['p50_ms']:.2f} ms, p99 {p['p99_ms']:.2f} ms")
    if diag:
        rejected = {k[len("rejected_") :]: v for k, v in diag.items() if k.startswith("rejected_") and v not in ("0", "")}
        print(
            f"node diagnostics: processing time mean {diag['processing_time_mean_ms']} ms, "
            f"max {diag['processing_time_max_ms']} ms (last second); accepted {diag['samples_accepted']}, "
            f"rejected {diag['samples_rejected']}" + (f" {rejected}" if rejected else "")
        )
    return same == idx.size


def cmd_demo(args: argparse.Namespace) -> int:
    path, lib, rec = _demo_recording(args)
    rate = (rec.median_rate_hz if len(rec) > 1 else lib.sample_rate_hz) * args.speed
    due_s = (rec.time_s - rec.time_s[0]) / args.speed  # the recording's own timing
    require_ros()
    from ..ros.node_client import use_local_ros

    domain, source = demo_domain(args.domain_id)
    use_local_ros(domain)
    print(
        f"starting estimator_node (library '{lib.name}', {len(lib)} modes; ROS_DOMAIN_ID={domain} ({source}), "
        "discovery LOCALHOST)",
        flush=True,
    )
    code = 0
    page = None
    try:
        with running_node(domain, lib.path or args.kernels, [], args.node_cmd, args.timeout,
                          reliable=args.reliable) as (node, client):
            if args.dashboard:
                page = _start_dashboard(domain, args.dashboard_port)
            echo_every = max(1, args.echo_every)
            _echo(client, echo_every)
            print(
                f"streaming {len(rec)} samples of {path.name} into segment_angles (sensor_msgs/JointState, rad) "
                f"at {rate:.0f} Hz (x{args.speed:g}, recorded timing); echoing 1 in {echo_every} mode/phase messages "
                "and every mode change",
                flush=True,
            )
            base_ns = time.time_ns()
            stamps = base_ns + np.round((rec.time_s - rec.time_s[0]) * 1e9).astype(np.int64)
            t0 = time.monotonic()
            sent = client.stream(np.radians(rec.angles_deg), stamps, rate, due_s=due_s)
            client.spin_until(lambda: client.estimate_count >= len(rec), 3.0)
            wall = time.monotonic() - t0
            diag = client.latest_diagnostics(timeout_s=2.5)
            stop_code = node.stop(signal.SIGINT)
            if not _demo_summary(client, path, lib, rec, stamps, sent, wall, diag):
                code = 1
            print(f"estimator_node stopped with SIGINT: exit code {stop_code}")
            if stop_code != 0:
                code = 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        code = 130
    finally:
        if page is not None:
            page.close()
    return code


def _start_dashboard(domain: int, port: int) -> Any:
    """``demo --dashboard``: the dashboard beside the node, its URL printed; the process."""
    from ..dashboard.process import start_dashboard
    from ..ros.node_client import local_ros_environment

    proc, url = start_dashboard(["--port", str(port), "--domain-id", str(domain)], local_ros_environment(domain))
    print(f"dashboard: open {url} (live while the recording streams)", flush=True)
    return proc


# ---------------------------------------------------------------------------------------------


def add_commands(sub: Any) -> None:
    """Register ``demo`` on the ``gait-estimator`` subparsers."""
    d = sub.add_parser(
        "demo",
        help="run estimator_node on a recording streamed over ROS 2 and echo mode/phase",
        description="Start estimator_node, stream a recording into segment_angles at its real rate, print the "
        "mode and phase messages as they arrive (like 'ros2 topic echo'), then a summary. Uses "
        f"ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and the environment's ROS_DOMAIN_ID (unset: {DEMO_DOMAIN_ID}).",
    )
    d.add_argument(
        "recording",
        nargs="?",
        help="recording (reference Dimension:4xT CSV, project CSV or rosbag2); default: the bundled "
        "data/swge/recordings/Multispeed_Walk_AB.csv",
    )
    d.add_argument("--kernels", "-k", default=DEFAULT_LIBRARY, metavar="LIB", help="kernel library (default %(default)s)")
    d.add_argument("--speed", type=positive_float, default=1.0, help="playback speed factor (default 1 = real time)")
    d.add_argument("--start", type=int, help="first sample index (inclusive)")
    d.add_argument("--stop", type=int, help="last sample index (exclusive)")
    add_imu_reading_options(d)
    d.add_argument("--echo-every", type=int, default=23, metavar="N",
                   help="print every Nth mode/phase message, and every mode change (default 23, ~10 lines/s; 1 = all)")
    d.add_argument("--reliable", action="store_true", help="publish the input reliably (default best effort)")
    d.add_argument("--domain-id", type=domain_id,
                   help=f"ROS_DOMAIN_ID (default: the environment's, else {DEMO_DOMAIN_ID})")
    d.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for the node to connect")
    d.add_argument("--node-cmd", help="estimator_node executable (default: python -m gait_estimator.ros.node)")
    d.add_argument("--dashboard", action="store_true", help="also serve the live web view (gait-estimator dashboard) "
                   "at the printed URL; needs the 'dashboard' extra")
    d.add_argument("--dashboard-port", type=port_number, default=8080, help="its port (default %(default)s)")
    d.set_defaults(func=cmd_demo)
