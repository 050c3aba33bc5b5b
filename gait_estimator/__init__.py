"""gait_estimator: locomotion mode and gait phase by kernel matching (Posh, Li, Wensing).

Architecture (data flows left to right; a subpackage imports only those to its left):

    core  ->  io  ->  analysis  ->  ros  ->  dashboard  ->  cli

* ``core``: kernels, matcher (numba-compiled step optional), resampling, supervision, calibration,
  personalisation, the estimator pipeline (numpy);
* ``io``: kernel library and recording formats (CSV, rosbag2), stream input checks, output
  layouts, bundled data;
* ``analysis``: strides, labels, training, evaluation, figures, benchmarks;
* ``ros``: the node, its client, the bag player: the only place that imports rclpy;
* ``dashboard``: the live web page of a running node (aiohttp; its ROS side is in ``ros``);
* ``cli``: the ``gait-estimator`` argparse front ends.

``test/test_architecture.py`` enforces these rules. See docs/architecture.md.

The public API: ``Estimator`` (one sample in, one ``Estimate`` out), ``EstimatorConfig`` (its
options, ``EstimatorConfig.preset("default" | "paper", **overrides)``), ``load_library`` and
``run_recording`` (a whole CSV or bag through a fresh estimator: an ``EstimateTrace``).
"""

from .core.channels import CHANNELS
from .core.errors import GaitEstimatorError, LibraryError, RecordingError
from .core.estimator import EstimateTrace, Estimator
from .core.kernels import KernelLibrary, KernelMode
from .core.matcher import IncrementalMatcher, StepResult
from .core.options import EstimatorConfig
from .core.states import EstimateState
from .core.supervisor import Estimate
from .io.library_io import load_library, save_library
from .io.process import run_recording
from .io.recording import Recording

__version__ = "0.1.0"

__all__ = [
    "CHANNELS",
    "Estimate",
    "EstimateState",
    "EstimateTrace",
    "Estimator",
    "EstimatorConfig",
    "GaitEstimatorError",
    "IncrementalMatcher",
    "KernelLibrary",
    "KernelMode",
    "LibraryError",
    "Recording",
    "RecordingError",
    "StepResult",
    "load_library",
    "run_recording",
    "save_library",
]
