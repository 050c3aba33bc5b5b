#!/usr/bin/env python3
"""What taking one JointState costs under rclpy's EventsExecutor: as a message object or serialised.

    python experiments/take_cost.py [--json experiments/results/node/take_cost.json]

One process, two nodes: a publisher queues 4,000 OSL JointState messages (4 names, 4 positions)
reliably, then the EventsExecutor hands them to a subscription whose callback only counts; the
wall time per message is the executor's take plus, for a message object, rclpy's conversion of
the serialised message into Python objects. Once with a typed subscription, once with a raw one
(``raw=True``: the bytes, as estimator_node subscribes), alternating, three rounds each; the
median of the rounds. LOCALHOST discovery, ROS_DOMAIN_ID 85.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = "85"

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gait_estimator.analysis.bench import machine_info  # noqa: E402
from gait_estimator.core.channels import CHANNELS  # noqa: E402

MESSAGES = 4000


def per_message_us(raw: bool) -> float:
    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    ctx = Context()
    rclpy.init(context=ctx)
    try:
        sub_node = rclpy.create_node("take_cost_sub", context=ctx)
        pub_node = rclpy.create_node("take_cost_pub", context=ctx)
        qos = QoSProfile(depth=MESSAGES, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
        count = [0]

        def on_message(_msg: object) -> None:
            count[0] += 1

        sub_node.create_subscription(JointState, "take_cost", on_message, qos, raw=raw)
        pub = pub_node.create_publisher(JointState, "take_cost", qos)
        executor = EventsExecutor(context=ctx)
        executor.add_node(sub_node)
        deadline = time.monotonic() + 10.0
        while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.5)
        msg = JointState()
        msg.name = list(CHANNELS)
        msg.position = [0.1, 0.2, 0.3, 0.4]
        for _ in range(MESSAGES):
            pub.publish(msg)
        time.sleep(0.5)  # all delivered to the reader's queue before the clock starts
        t = time.perf_counter()
        while count[0] < MESSAGES and time.perf_counter() - t < 30.0:
            executor.spin_once(timeout_sec=0.25)
        dt = time.perf_counter() - t
        if count[0] < MESSAGES:
            raise SystemExit(f"only {count[0]} of {MESSAGES} messages arrived")
        executor.shutdown()
        return dt / MESSAGES * 1e6
    finally:
        rclpy.shutdown(context=ctx)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write the results here")
    args = ap.parse_args()
    rounds: dict[str, list[float]] = {"message object": [], "serialised": []}
    for _ in range(3):
        rounds["message object"].append(per_message_us(raw=False))
        rounds["serialised"].append(per_message_us(raw=True))
    result = {k: sorted(v)[1] for k, v in rounds.items()}
    for k, v in result.items():
        print(f"{k:<15} {v:6.1f} µs per message (rounds: {', '.join(f'{x:.1f}' for x in rounds[k])})")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        report = {"machine": machine_info(), "messages": MESSAGES, "per_message_us": result, "rounds_us": rounds}
        args.json.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
