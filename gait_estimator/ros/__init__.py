"""The ROS 2 edge: ``estimator_node``, the client used by demos, benchmarks and tests, and the
bag player. The only subpackage that imports rclpy.

Imports ``core``, ``io`` and ``analysis``; never ``cli``.
"""

from ..core.errors import GaitEstimatorError


def require_ros() -> None:
    """Raise a one-line GaitEstimatorError if rclpy cannot be imported (ROS 2 not installed)."""
    try:
        import rclpy  # noqa: F401
    except ImportError as exc:
        raise GaitEstimatorError(f"ROS 2 Python packages not available ({exc}); source a ROS 2 Jazzy setup "
                                 "or pip install 'gait_estimator[ros]'") from None
