#!/usr/bin/env python3
"""The node's per-sample work timed back to back and spaced out like a real stream.

    python experiments/spaced_calls.py [--json experiments/results/node/spaced_calls.json]

``bench-node --profile`` shows the node's per-sample stages at 230 Hz taking several times what
``gait-estimator bench`` measures for the same work in a tight loop. This script separates the
machine from ROS 2: it builds ``estimator_node`` in-process (no executor, no input over DDS; a
serialised subscriber in the same process makes it publish ``estimate``), and calls its input
callback with prepared serialised JointState messages (as its subscription delivers them)

* back to back;
* spaced by 1 ms and by 1/230 s, sleeping in between (as the node does between samples);
* spaced by 1/230 s, busy-waiting in between (the thread never sleeps);

and does the same for ``Estimator.update`` alone (no ROS), and for a few small numpy calls on a
4-vector against the same arithmetic on four Python floats (why the live path hands a sample from
stage to stage as Python floats). Blocks of 500 calls, the conditions interleaved in two rounds,
median and p99 per condition. LOCALHOST discovery, ROS_DOMAIN_ID 84.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = "84"

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gait_estimator.analysis.bench import machine_info, synthetic_walk  # noqa: E402
from gait_estimator.core.channels import CHANNELS  # noqa: E402
from gait_estimator.core.estimator import Estimator, EstimatorConfig  # noqa: E402
from gait_estimator.io.library_io import load_library  # noqa: E402
from gait_estimator.io.resources import DEFAULT_LIBRARY  # noqa: E402

CONDITIONS = {  # name: (gap between calls in s, busy-wait instead of sleeping)
    "back to back": (0.0, False),
    "every 1 ms, sleeping": (1e-3, False),
    "every 1/230 s, sleeping": (1 / 230, False),
    "every 1/230 s, busy-waiting": (1 / 230, True),
}
BLOCK = 500


def timed(call: Callable[[int], None], start: int, n: int, gap_s: float, busy: bool) -> list[float]:
    clock = time.perf_counter
    out = []
    for i in range(start, start + n):
        t = clock()
        call(i)
        out.append(clock() - t)
        if gap_s and busy:
            end = clock() + gap_s
            while clock() < end:
                pass
        elif gap_s:
            time.sleep(gap_s)
    return out


def measure(call: Callable[[int], None], warmup: int) -> dict[str, dict[str, float]]:
    i = warmup
    for k in range(warmup):
        call(k)
    times: dict[str, list[float]] = {name: [] for name in CONDITIONS}
    for _ in range(2):
        for name, (gap, busy) in CONDITIONS.items():
            times[name] += timed(call, i, BLOCK, gap, busy)
            i += BLOCK
    return {name: {"median_us": float(np.median(t) * 1e6), "p99_us": float(np.percentile(t, 99) * 1e6), "calls": len(t)}
            for name, t in times.items()}


def node_calls(lib: Any, preset: str, deg: np.ndarray, warmup: int) -> dict[str, dict[str, float]]:
    import rclpy
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from gait_estimator.ros.node import EstimatorNode

    period_ns = round(1e9 / lib.sample_rate_hz)
    msgs = []
    for i, row in enumerate(np.radians(deg)):
        m = JointState()
        m.name = list(CHANNELS)
        m.position = row.tolist()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(1_700_000_000_000_000_000 + i * period_ns, 1_000_000_000)
        msgs.append(serialize_message(m))  # as the node's input subscription delivers them
    rclpy.init(args=["--ros-args", "-p", f"preset:={preset}", "-p", "executor:=events"])
    try:
        node = EstimatorNode()
        node.create_subscription(JointState, "estimate", lambda _m: None, 10, raw=True)
        return measure(lambda i: node._on_input(msgs[i]), warmup)
    finally:
        rclpy.shutdown()


SAMPLE = (10.0, -5.0, 30.0, 2.0)
DEG_PER_RAD = 180.0 / math.pi


def numpy_calls(_i: int) -> None:
    """Six small numpy calls on one sample, as the live path made before it used Python floats."""
    d = np.asarray(SAMPLE, dtype=np.float64).reshape(4)
    np.isfinite(d).all()
    float(d @ d)
    np.empty(7), np.empty(7)
    np.degrees(d)


def float_calls(_i: int) -> None:
    """The same arithmetic on four Python floats."""
    a, b, c, d = SAMPLE
    math.isfinite(a) and math.isfinite(b) and math.isfinite(c) and math.isfinite(d)
    a * a + b * b + c * c + d * d
    a * DEG_PER_RAD, b * DEG_PER_RAD, c * DEG_PER_RAD, d * DEG_PER_RAD


def estimator_calls(lib: Any, preset: str, deg: np.ndarray, warmup: int) -> dict[str, dict[str, float]]:
    est = Estimator(lib, EstimatorConfig.preset(preset))
    dt = 1.0 / lib.sample_rate_hz
    return measure(lambda i: est.update(i * dt, deg[i]), warmup)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write the results here")
    args = ap.parse_args()

    lib = load_library(DEFAULT_LIBRARY)
    warmup = int(lib.lengths.max()) + 100
    n = warmup + 2 * len(CONDITIONS) * BLOCK
    deg = synthetic_walk(lib, n, seed=3)
    report: dict[str, Any] = {"machine": machine_info(), "library": lib.name, "load_average_before": list(os.getloadavg()),
                              "results": []}
    for preset in ("default", "paper"):
        for what, res in (("node input callback (estimator, publish)", node_calls(lib, preset, deg, warmup)),
                          ("Estimator.update", estimator_calls(lib, preset, deg, warmup))):
            report["results"].append({"preset": preset, "what": what, "conditions": res})
            print(f"{preset:<8} {what:<42} " + "  ".join(f"{c}: {r['median_us']:.0f} / {r['p99_us']:.0f} us"
                                                             for c, r in res.items()))
    for what, call in (("six small numpy calls on a 4-vector (asarray, isfinite, dot, 2 x empty, degrees)", numpy_calls),
                       ("the same arithmetic on four Python floats", float_calls)):
        res = measure(call, warmup)
        report["results"].append({"preset": None, "what": what, "conditions": res})
        print(f"{'':<8} {what[:42]:<42} " + "  ".join(f"{c}: {r['median_us']:.1f} / {r['p99_us']:.1f} us"
                                                       for c, r in res.items()))
    report["load_average_after"] = list(os.getloadavg())
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
