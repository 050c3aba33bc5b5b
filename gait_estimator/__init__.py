"""gait_estimator: locomotion mode and gait phase by kernel matching (Posh, Li, Wensing).

Data flow: kernels (libraries of average strides) -> matcher (per-sample SSE against every
kernel shift) -> node (ROS 2) or offline tools (process, bench, ...). Nothing here imports rclpy
except ``gait_estimator.node``.
"""

from .channels import CHANNELS
from .errors import GaitEstimatorError, LibraryError, RecordingError
from .kernels import KernelLibrary, KernelMode
from .library_io import load_library, save_library
from .matcher import IncrementalMatcher, NaiveMatcher, StepResult

__version__ = "0.1.0"

__all__ = [
    "CHANNELS",
    "GaitEstimatorError",
    "IncrementalMatcher",
    "KernelLibrary",
    "KernelMode",
    "LibraryError",
    "NaiveMatcher",
    "RecordingError",
    "StepResult",
    "load_library",
    "save_library",
]
