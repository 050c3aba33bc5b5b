"""A minimal impedance controller on estimator_node's ``estimate`` (docs/controller.md).

    ros2 run gait_estimator estimator_node &
    python examples/impedance_controller.py
"""

import sys

import rclpy
from rclpy.node import Node
from sensor_msgs.msg import JointState

WALKING = 1  # estimate "state": 0 not ready, 1 walking, 2 stand, 3 unknown
HOLD = 6.0
"""Knee stiffness (N*m/deg) while not walking: stand, unknown, not ready. No phase to follow."""
STIFFNESS = {"Slow": (4.0, 0.5), "Med": (4.5, 0.5), "Fast": (5.0, 0.6), "RA": (5.5, 0.6),
             "RD": (5.0, 0.4), "SA": (6.0, 0.7), "SD": (4.0, 0.4)}
"""Stance and swing stiffness per mode (placeholders: tune them on the bench)."""
TOE_OFF = 0.6  # phase where stance ends


def stiffness(state: int, mode: str, phase: float) -> float:
    if state != WALKING:
        return HOLD
    stance, swing = STIFFNESS.get(mode, (HOLD, HOLD))
    return stance if phase < TOE_OFF else swing


class ImpedanceController(Node):
    def __init__(self, **kwargs) -> None:
        super().__init__("impedance_controller", **kwargs)
        self.command = HOLD
        self.create_subscription(JointState, "estimate", self.on_estimate, 10)

    def on_estimate(self, msg: JointState) -> None:
        v = dict(zip(msg.name, msg.position, strict=True))
        modes = [k[4:] for k in msg.name if k.startswith("sse/")]  # in mode_index order; a taught mode adds one
        state = int(v["state"])
        mode = modes[int(v["mode_index"])] if state == WALKING else ""
        self.command = stiffness(state, mode, v["phase"])  # phase is NaN unless walking
        # ... send self.command to the knee here


def main() -> int:
    rclpy.init()
    node = ImpedanceController()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
