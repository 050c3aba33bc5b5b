"""gait_estimator: locomotion mode and gait phase by kernel matching (Posh, Li, Wensing).

Architecture (data flows left to right; a subpackage imports only those to its left):

    core  ->  io  ->  analysis  ->  ros  ->  cli

* ``core``: kernels, matcher (numba-compiled step optional), resampling, supervision, calibration,
  personalisation, the estimator pipeline (numpy);
* ``io``: kernel library and recording formats (CSV, rosbag2), stream input checks, output
  layouts, bundled data;
* ``analysis``: strides, labels, training, evaluation, figures, benchmarks;
* ``ros``: the node, its client, the bag player: the only place that imports rclpy;
* ``cli``: the ``gait-estimator`` argparse front ends.

``test/test_architecture.py`` enforces these rules. See docs/architecture.md.
"""

from .core.channels import CHANNELS
from .core.errors import GaitEstimatorError, LibraryError, RecordingError
from .core.kernels import KernelLibrary, KernelMode
from .core.matcher import IncrementalMatcher, NaiveMatcher, StepResult
from .io.library_io import load_library, save_library

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
