"""A publisher process for test_faults.py: streams Multispeed samples into estimator_node.

    python test/fault_publisher.py DOMAIN NAMESPACE START STOP BASE_NS

Publishes samples [START, STOP) of the bundled Multispeed recording as JointState (rad) on
NAMESPACE/segment_angles, stamped BASE_NS + k * (1/230 s) for the k-th sample it sends, reliably
and with flow control (at most WINDOW unanswered samples, so the node's input queue never
overflows), at most one sample per SEND_PERIOD_S (a 1 kHz sensor). Prints ``sent N`` after every
50 samples; test_faults.py kills it with SIGKILL mid-stream to play a publisher that dies.
LOCALHOST discovery, the given ROS_DOMAIN_ID.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

WINDOW = 50
SEND_PERIOD_S = 0.001
"""Unpaced (as fast as the node answered, ~4 kHz) the node, this process and the test process
filled both cores, and the test's own reader missed two or three reliable estimates mid-stream
(a gap in their stamps; the node's counts were right) in 9 of 54 runs of
test_publisher_dies_and_restarts_with_its_stamps_back_at_zero; paced, in none of 40 (in 2 of
them this process's own reader missed one, which costs its 30 s wait for the last estimates)."""


def main(argv: list[str]) -> int:
    domain, namespace, start, stop, base_ns = int(argv[0]), argv[1], int(argv[2]), int(argv[3]), int(argv[4])
    from gait_estimator.io.outputs import ESTIMATE_TOPIC
    from gait_estimator.ros.node_client import EstimatorClient, use_local_ros

    use_local_ros(domain)
    from ros_helpers import PERIOD_NS, load_multispeed

    rec = load_multispeed(Path(__file__).resolve().parents[1] / "data" / "swge" / "recordings" / "Multispeed_Walk_AB.csv",
                          start, stop)
    x = np.radians(rec.angles_deg)
    client = EstimatorClient(domain, namespace=namespace, reliable=True, record=False, outputs=(ESTIMATE_TOPIC,),
                             node_name=f"fault_publisher_{start}")
    try:
        if not client.wait_for_node(timeout_s=30.0, settle_s=0.3):
            print("no estimator_node", flush=True)
            return 1
        print("connected", flush=True)
        due = time.monotonic()
        for k in range(len(x)):
            while k - client.estimate_count >= WINDOW:
                client.spin_once(0.005)
            while time.monotonic() < due:
                client.spin_once(max(0.0, due - time.monotonic()))
            due += SEND_PERIOD_S
            client.publish(x[k], base_ns + k * PERIOD_NS)
            if (k + 1) % 50 == 0:
                print(f"sent {k + 1}", flush=True)
                client.spin_once(0.0)
        deadline = time.monotonic() + 30.0
        while client.estimate_count < len(x) and time.monotonic() < deadline:
            client.spin_once(0.01)
        print(f"done {client.estimate_count}", flush=True)
    finally:
        client.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
