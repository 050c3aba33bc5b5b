"""``gait-estimator bench-node``: estimator_node in a child process over real DDS on this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, a domain ID of its own): input->estimate latency and
the highest input rate it sustains. rclpy is imported only when the command runs."""

from __future__ import annotations

import argparse
import math
import os
import signal
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis.imu_sagittal import BENCH_LATERAL_AXES, BENCH_PROXIMAL_AXES, imu_samples
from ..core.errors import GaitEstimatorError
from ..io.resources import DEFAULT_LIBRARY
from ..ros import EXECUTORS, require_ros
from .args import checked_number, choice_list, domain_id, positive_float, positive_int, positive_list, prepare_output, save_report
from .bench_profile import PROFILE_LABELS, clock_offset_ns, profile_stages
from .node_commands import percentiles, running_node

BENCH_DOMAIN_ID = 78
DEFAULT_RATES = (500, 1000, 1500, 2000, 3000, 4000, 6000, 8000)
KEEP_UP_MS = 10.0
"""A rate is sustained only if the median input->estimate latency stays below this."""


def _priority(text: str) -> int:
    from ..ros.priority import MAX_PRIORITY

    return checked_number(text, int, lambda v: 0 <= v <= MAX_PRIORITY, f"an integer 0..{MAX_PRIORITY}",
                          f"SCHED_FIFO priorities are 1..{MAX_PRIORITY} (0 = as started), got {{text}}")


def _rates(text: str) -> list[float]:
    return positive_list(text, float, "rates in Hz", "rates")

INPUTS = ("joint_state", "imu", "imu-raw")
"""bench-node --input: JointState angles, or four Imu topics with orientations / gyro + accelerometer only."""
OUTPUT_SETS = ("estimate", "all")
"""bench-node --outputs: the bench subscribes to ``estimate`` only (like a controller), or to
``mode``, ``phase``, ``sse`` and ``estimate`` (the node publishes all four per sample)."""


def node_imu_arguments(calibration_path: str, lateral: Sequence[str] = BENCH_LATERAL_AXES,
                       proximal: Sequence[str] = BENCH_PROXIMAL_AXES) -> list[str]:
    """``--ros-args`` of an estimator_node fed by ``imu_samples``: ``input_type: imu`` with the
    mounting configured (nothing to learn), its calibration file at ``calibration_path`` (read if
    it exists; pass one that does not, or a saved calibration would take precedence)."""
    def strings(v: Sequence[str]) -> str:
        return "[" + ",".join(f"'{a}'" for a in v) + "]"

    return ["-p", "input_type:=imu", "-p", f"imu_lateral_axes:={strings(lateral)}",
            "-p", f"imu_proximal_axes:={strings(proximal)}", "-p", f"imu_calibration_path:={calibration_path}"]


class _Variant:
    """One estimator_node process under measurement: the runs of synthetic input through it.

    Args:
        lib: The node's kernel library.
        client: EstimatorClient subscribed to the node's outputs and diagnostics.
        log: Prints one line.
        label: Prefix of the log lines.
        input_kind: One of INPUTS (IMU: the angles become four Imu messages per sample, their
            gyro continuing from the previous run's last angles).
    """

    def __init__(self, lib: Any, client: Any, log: Any, label: str, input_kind: str = "joint_state") -> None:
        self.lib, self.client, self.log, self.label, self.input_kind = lib, client, log, label, input_kind
        self.next_stamp = time.time_ns()
        self.last_deg = np.zeros(4)  # IMU input: the angles of the last sample sent

    def node_received(self, at_least: int = 0) -> int:
        """The node's samples_received from a report newer than now; up to 3 s for one that
        counts ``at_least`` (a report composed before the last answered sample can arrive after
        its estimate: the topics travel separately)."""
        client = self.client
        deadline = time.monotonic() + 3.0
        d = client.latest_diagnostics(timeout_s=3.0)
        while d is not None and int(d["samples_received"]) < at_least and time.monotonic() < deadline:
            d = client.latest_diagnostics(timeout_s=max(deadline - time.monotonic(), 0.0)) or d
        if d is None:
            raise GaitEstimatorError("no diagnostics from estimator_node")
        return int(d["samples_received"])

    def run(self, n: int, rate: float, with_profile: bool = False, standing: bool = False) -> dict[str, Any]:
        """Stream ``n`` samples at ``rate`` Hz (``standing``: all angles 0); latency, drops and
        the node's processing time."""
        from ..analysis.bench import synthetic_walk

        client, lib = self.client, self.lib
        deg = np.zeros((n, 4)) if standing else synthetic_walk(lib, n, seed=n)
        period = int(1e9 / lib.sample_rate_hz)  # stamps keep the library's time base
        stamps = self.next_stamp + period * np.arange(1, n + 1, dtype=np.int64)
        self.next_stamp = int(stamps[-1])
        if self.input_kind == "joint_state":
            x: Any = np.radians(deg)
        else:  # from the last angles sent into this run's in 0.25 s: no jump for the gyro
            k = min(n, round(0.25 * lib.sample_rate_hz))
            deg[:k] = self.last_deg + (deg[k - 1] - self.last_deg) * (np.arange(1, k + 1) / k)[:, None]
            x = imu_samples(deg, stamps, period * 1e-9, self.input_kind == "imu-raw", self.last_deg)
            self.last_deg = deg[-1].copy()
        before = self.node_received()
        n_diag = len(client.received.diagnostics)
        got = client.received
        got.clear()
        first = client.estimate_count
        offset = clock_offset_ns()
        sent = client.stream(x, stamps, rate)
        achieved = (n - 1) / max((sent[-1] - sent[0]) / 1e9, 1e-9) if n > 1 else rate
        last, last_change = client.estimate_count, time.monotonic()
        while client.estimate_count - first < n and time.monotonic() - last_change < 0.5:
            client.spin_once(0.05)
            if client.estimate_count != last:
                last, last_change = client.estimate_count, time.monotonic()
        answered_now = client.estimate_count - first
        processed = self.node_received(at_least=before + answered_now)
        if with_profile:  # the rows of the last samples come with the next diagnostics period
            client.latest_diagnostics(timeout_s=3.0)
            client.spin_for(0.2)
        processed -= before
        index = {int(s): i for i, s in enumerate(stamps)}
        idx = np.array([index.get(s, -1) for s in got.estimate_stamp_ns], dtype=np.int64)
        ok = idx >= 0
        recv = np.array(got.estimate_recv_ns, dtype=np.int64)
        lat = (recv[ok] - sent[idx[ok]]) / 1e6
        dds_lat = (np.array(got.estimate_dds_ns, dtype=np.int64)[ok] - (sent[idx[ok]] + offset)) / 1e6
        busy = [d for d in client.received.diagnostics[n_diag:] if float(d["input_rate_hz"]) > 0]
        res: dict[str, Any] = {
            "rate_hz": rate,
            "samples": n,
            "achieved_rate_hz": float(achieved),
            "node_processed": processed,
            "input_drops": n - processed,
            "answered": int(ok.sum()),
            **percentiles(lat),
            **{f"dds_{k}": v for k, v in percentiles(dds_lat).items()},
        }
        if busy:
            res["node_processing_mean_ms"] = float(np.mean([float(d["processing_time_mean_ms"]) for d in busy]))
            res["node_processing_max_ms"] = float(max(float(d["processing_time_max_ms"]) for d in busy))
        if with_profile:
            res["profile"] = profile_stages(got, stamps, sent + offset, recv + offset)
        return res

    def latency(self, samples: int, rate_hz: float, profile: bool, out: dict[str, Any]) -> None:
        """The latency run (and with ``profile`` its time split), into ``out``."""
        from ..ros.node_client import publishing_costs_us

        label, log = self.label, self.log
        lt = self.run(samples, rate_hz, with_profile=profile)
        out["latency"] = lt
        log(
            f"{label} latency at {rate_hz:g} Hz: {lt['samples']} samples, {lt['answered']} answered: "
            f"p50 {lt.get('p50_ms', math.nan):.3f} ms, p90 {lt.get('p90_ms', math.nan):.3f} ms, "
            f"p99 {lt.get('p99_ms', math.nan):.3f} ms, max {lt.get('max_ms', math.nan):.3f} ms "
            f"(to the bench's DDS reader: p50 {lt.get('dds_p50_ms', math.nan):.3f}, "
            f"p99 {lt.get('dds_p99_ms', math.nan):.3f} ms); node processing "
            f"mean {lt.get('node_processing_mean_ms', math.nan):.3f} ms, max {lt.get('node_processing_max_ms', math.nan):.3f} ms"
        )
        if profile:
            out["micro_us"] = publishing_costs_us(self.lib, self.client.node)
            stages = lt["profile"].get("stages", {})
            for name, text in PROFILE_LABELS.items():
                st = stages.get(name)
                if st:
                    log(f"{label}   {text:<76} mean {st['mean_ms']:6.3f}  p50 {st['p50_ms']:6.3f}  p99 {st['p99_ms']:6.3f} ms")
            if "error" in lt["profile"]:
                log(f"{label}   profile: {lt['profile']['error']}")
            log(f"{label}   in this process: " + ", ".join(f"{k} {v:.2f}" for k, v in out["micro_us"].items()))

    def throughput(self, rates: Any, rate_seconds: float) -> dict[str, Any]:
        """The highest of ``rates`` sustained (see bench_node): each rate ``rate_seconds`` long,
        one retry; stops at the first rate that fails twice."""
        steps = []
        best = 0.0
        ok = True
        for rate in sorted(rates):
            n = max(500, int(rate * rate_seconds))
            for attempt in (1, 2):  # one retry: the machine is noisy
                step = self.run(n, rate)
                step["attempt"] = attempt
                keeps_up = step.get("p50_ms", math.inf) < KEEP_UP_MS
                ok = step["input_drops"] == 0 and step["achieved_rate_hz"] >= 0.95 * rate and keeps_up
                step["sustained"] = ok
                steps.append(step)
                why = "" if ok else "  <- input drops" if step["input_drops"] else (
                    "  <- falling behind" if not keeps_up else "  <- publisher too slow")
                self.log(
                    f"{self.label} rate {rate:6.0f} Hz (attempt {attempt}): sent {n} at {step['achieved_rate_hz']:6.0f} Hz, "
                    f"node processed {step['node_processed']}, estimates received {step['answered']}"
                    + (f", latency p50 {step['p50_ms']:.3f} ms p99 {step['p99_ms']:.3f} ms" if "p50_ms" in step else "")
                    + why
                )
                if ok:
                    break
            if not ok:
                break
            best = rate
        self.log(f"{self.label} highest input rate sustained without drops: {best:g} Hz" + (" (the highest tried)" if ok else ""))
        return {"steps": steps, "max_sustained_rate_hz": best, "rates_tried": sorted(rates)}


def _bench_variant(lib: Any, kernels: str, executor: str, outputs: str, args: argparse.Namespace, log: Any) -> dict[str, Any]:
    """One variant of bench_node: a fresh estimator_node process, its latency and throughput."""
    from ..io.outputs import ESTIMATE_TOPIC, MODE_TOPIC, PHASE_TOPIC, SSE_TOPIC
    from ..ros.diagnostics import DIAGNOSTICS_TOPIC
    from ..ros.node import NODE_NAME

    input_kind, rate_hz = args.input, args.rate
    topics = (ESTIMATE_TOPIC,) if outputs == "estimate" else (MODE_TOPIC, PHASE_TOPIC, SSE_TOPIC, ESTIMATE_TOPIC)
    extra = ["-p", f"thread_priority:={args.thread_priority}"] if args.thread_priority else []
    if input_kind != "joint_state":  # configured mounting; a path without a file: no saved calibration
        extra += node_imu_arguments(os.path.join(tempfile.gettempdir(), f"gait_estimator_bench_{os.getpid()}.imu.yaml"))
    with running_node(args.domain_id, kernels, ["-p", f"executor:={executor}", "-p", f"preset:={args.preset}", *extra],
                      args.node_cmd, 30.0, input_type="imu" if input_kind != "joint_state" else "joint_state",
                      reliable=True, record=False, outputs=(*topics, DIAGNOSTICS_TOPIC),
                      profile_topic=f"/{NODE_NAME}/profile" if args.profile else None) as (node, client):
        out: dict[str, Any] = {"executor": executor, "outputs": outputs, "node_cmd": node.cmd}
        bench = _Variant(lib, client, log, f"[executor {executor}, outputs {outputs}"
                         + ("]" if input_kind == "joint_state" else f", input {input_kind}]"), input_kind)
        if input_kind != "joint_state":  # as a wearer would: stand (the fusion settles), then walk
            bench.run(round(lib.sample_rate_hz), rate_hz, standing=True)
        bench.run(int(lib.lengths.max()) + 50, rate_hz)  # warm-up: fill the window, first-call costs
        bench.latency(args.samples, rate_hz, args.profile, out)
        if outputs == "estimate":
            out["throughput"] = bench.throughput(args.rates, args.seconds)
        out["node_exit_code"] = node.stop(signal.SIGINT)
    return out


def bench_node(args: argparse.Namespace, log: Any = print) -> dict[str, Any]:
    """Measure estimator_node in a child process over DDS on this machine, once per variant
    (``--executor`` x ``--outputs``, a fresh node process each), with the options of ``bench-node``
    (``args``; its help says what ``--modes``, ``--thread-priority`` and ``--input`` change).

    1. Latency: ``--samples`` inputs at ``--rate``; latency = arrival of the ``estimate``
       message carrying an input's stamp in the bench's callback - publication of that input
       (same clock, this process); ``dds_*``: arrival at the bench's DDS reader instead (the
       message info's ``received_timestamp``), i.e. without the bench's own executor.
    2. Throughput (variants with outputs ``estimate``): for each rate in ``--rates`` (ascending),
       ``--seconds`` of input; sustained = the node processed every input (its diagnostics
       ``samples_received``, so nothing was lost in its best-effort input queue), the input went
       out at >= 95% of the requested rate, and the median latency stayed below KEEP_UP_MS (no
       growing backlog). Stops at the first rate that fails twice.
    3. With ``--profile``: the latency run's time split per sample (node's ``~/profile`` topic and
       the message info of ``estimate``; see PROFILE_LABELS), and the per-call costs of the
       publishing levers in this process.

    Input: synthetic strides of the library's kernels with noise (``_Variant.run``), published
    reliably. The report's top-level ``latency``/``throughput`` are the first variant's.
    """
    from ..analysis.bench import machine_info
    from ..io.library_io import load_library, save_library
    from ..ros.node_client import use_local_ros

    lib = load_library(args.kernels)
    kernels = str(lib.path or args.kernels)
    with tempfile.TemporaryDirectory(prefix="gait_estimator_bench_") as tmp:
        if args.modes is not None:
            lib = lib.replicated(args.modes)
            kernels = str(save_library(lib, Path(tmp) / f"{lib.name}_{args.modes}.npz"))
        use_local_ros(args.domain_id)
        report: dict[str, Any] = {
            "machine": machine_info(),
            "load_average_before": list(os.getloadavg()),
            "library": lib.name,
            "modes": len(lib),
            "domain_id": args.domain_id,
            "preset": args.preset,
            "thread_priority": args.thread_priority,
            "variants": [],
        }
        if args.input != "joint_state":
            report["input"] = args.input
        for executor in args.executor:
            for out in args.outputs:
                report["variants"].append(_bench_variant(lib, kernels, executor, out, args, log))
        first = report["variants"][0]
        report["node_cmd"] = first["node_cmd"]
        report["executor"], report["outputs"] = first["executor"], first["outputs"]
        report["latency"] = first["latency"]
        if "throughput" in first:
            report["throughput"] = first["throughput"]
        codes = [v["node_exit_code"] for v in report["variants"]]
        report["node_exit_code"] = next((c for c in codes if c != 0), 0)
        report["load_average_after"] = list(os.getloadavg())
        return report


def cmd_bench_node(args: argparse.Namespace) -> int:
    require_ros()
    if args.json:  # before minutes of measuring, not after
        prepare_output(args.json, "--json")
    if args.thread_priority:  # this process too, as the controller subscribing to the node would run
        from ..ros.priority import set_process_priority

        try:
            set_process_priority(args.thread_priority)
        except OSError as exc:
            raise GaitEstimatorError(f"--thread-priority {args.thread_priority}: {exc}") from None
    report = bench_node(args)
    m = report["machine"]
    print(f"machine: {m['processor']}, {m['cpus']} CPUs ({m['cpus_allowed']} allowed), Python {m['python']}; "
          f"library {report['library']} ({report['modes']} modes), input {args.input}; load average before "
          f"{report['load_average_before'][0]:.2f}, after {report['load_average_after'][0]:.2f}")
    print(f"summary (latency at {args.rate:g} Hz, p50 / p99 ms, to the bench's callback | to its DDS reader; "
          "highest rate):")
    for v in report["variants"]:
        lt = v["latency"]
        tp = v.get("throughput")
        print(
            f"  executor {v['executor']:<15} outputs {v['outputs']:<8} "
            f"{lt.get('p50_ms', math.nan):6.3f} / {lt.get('p99_ms', math.nan):6.3f} | "
            f"{lt.get('dds_p50_ms', math.nan):6.3f} / {lt.get('dds_p99_ms', math.nan):6.3f}"
            + (f"; {tp['max_sustained_rate_hz']:g} Hz" if tp else "")
        )
    save_report(args.json, report)
    return 0 if report.get("node_exit_code") == 0 else 1


# ---------------------------------------------------------------------------------------------


def add_commands(sub: Any) -> None:
    """Register ``bench-node`` on the ``gait-estimator`` subparsers."""
    b = sub.add_parser(
        "bench-node",
        help="benchmark estimator_node over ROS 2: latency and highest sustained input rate",
        description="Start estimator_node, measure input->estimate latency at --rate, then the highest of --rates "
        "at which every input is answered. LOCALHOST discovery, its own ROS_DOMAIN_ID.",
    )
    b.add_argument("--kernels", "-k", default=DEFAULT_LIBRARY, metavar="LIB", help="kernel library (default %(default)s)")
    b.add_argument("--rate", type=positive_float, default=230.0, help="rate of the latency run, Hz (default 230)")
    b.add_argument("--samples", type=positive_int, default=2300, help="samples in the latency run (default 2300 = 10 s)")
    b.add_argument("--rates", type=_rates, default=list(DEFAULT_RATES),
                   help="input rates to try, Hz (default " + ",".join(str(r) for r in DEFAULT_RATES) + ")")
    b.add_argument("--seconds", type=positive_float, default=2.0, help="duration of each rate step (default 2 s)")
    b.add_argument("--domain-id", type=domain_id, default=BENCH_DOMAIN_ID, help="ROS_DOMAIN_ID (default %(default)s)")
    b.add_argument("--node-cmd", help="estimator_node executable (default: python -m gait_estimator.ros.node)")
    b.add_argument("--executor", type=choice_list(EXECUTORS), default=list(EXECUTORS), metavar="LIST",
                   help="node executors to measure, side by side (default " + ",".join(EXECUTORS) + "; the first "
                   "one's numbers are the report's top-level latency/throughput)")
    b.add_argument("--outputs", type=choice_list(OUTPUT_SETS), default=list(OUTPUT_SETS), metavar="LIST",
                   help="what the bench subscribes to: estimate (like a controller) and/or all (mode, phase, sse, "
                   "estimate; latency only); default " + ",".join(OUTPUT_SETS))
    b.add_argument("--input", choices=INPUTS, default="joint_state",
                   help="joint_state (default), or four Imu topics (input_type: imu, configured mounting) with "
                   "orientations (imu) or gyro + accelerometer only (imu-raw); a rate counts four-message samples")
    b.add_argument("--preset", choices=("default", "paper"), default="default",
                   help="the node's estimator preset (default: default)")
    b.add_argument("--modes", type=positive_int, metavar="M",
                   help="run the node with a library of M modes cycled from --kernels (as 'bench --modes'; "
                   "default: the library as it is)")
    b.add_argument("--thread-priority", type=_priority, default=0, metavar="P",
                   help="run the node with thread_priority P (SCHED_FIFO, 1-99) and the bench process at the same "
                   "priority, like 'chrt -f P'; needs CAP_SYS_NICE (default 0: as started)")
    b.add_argument("--profile", action="store_true",
                   help="split the latency run's time per sample: DDS in + executor, estimator, publish, DDS out, "
                   "bench callback (from the node's ~/profile topic)")
    b.add_argument("--json", help="write the report as JSON")
    b.set_defaults(func=cmd_bench_node)
