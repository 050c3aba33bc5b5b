"""The ROS 2 edge: ``estimator_node``, the client used by demos, benchmarks and tests, and the
bag player. The only subpackage that imports rclpy.

Imports ``core``, ``io`` and ``analysis``; never ``cli``.
"""

import sys

from ..core.errors import GaitEstimatorError

EXECUTORS = ("events", "single_threaded")
"""Values of the node's ``executor`` parameter: rclpy.experimental.EventsExecutor, SingleThreadedExecutor."""


def require_ros() -> None:
    """Raise a one-line GaitEstimatorError if rclpy cannot be imported (ROS 2 not installed)."""
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        raise GaitEstimatorError(f"ROS 2 Python packages not available ({exc}); source a ROS 2 Jazzy setup "
                                 "or pip install 'gait_estimator[ros]'") from None


def node_main() -> int:
    """The ``estimator_node`` entry point: ``node.main``, or one line and exit code 2 when rclpy
    is missing (a pip install without the 'ros' extra)."""
    try:
        require_ros()
    except GaitEstimatorError as exc:
        print(f"estimator_node: error: {exc}", file=sys.stderr)
        return 2
    from .node import main

    return main()
