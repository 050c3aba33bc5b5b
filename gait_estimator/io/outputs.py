"""Names and layouts of the estimator's outputs, ROS-free.

The live node (rclpy messages) and the bag writer (rosbags messages) both build their messages
from these, so a recorded result is identical to what the node publishes. Topics, types and when
each is published: docs/node.md, "Topics"; here the layouts of ``sse`` (``sse_label``: its
``layout.dim[0]``, size and stride M) and of ``estimate`` (a JointState as stamped named values:
``header.stamp`` = the input sample's stamp, ``name``/``position`` = ``estimate_names`` and
``estimate_array``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..core.estimator import EstimateTrace
from ..core.kernels import KernelLibrary
from ..core.supervisor import Estimate


@dataclass(frozen=True)
class Predictions:
    """Estimator output aligned with the recording samples it came from."""

    time_s: np.ndarray  # (T,) seconds: the input samples' times
    sample: np.ndarray  # (T,) index in the source recording of the (latest) input sample
    trace: EstimateTrace
    adapted: KernelLibrary | None = None  # the personalised library (adapt_rate > 0)


INPUT_TOPIC = "segment_angles"
MODE_TOPIC = "mode"
PHASE_TOPIC = "phase"
SSE_TOPIC = "sse"
ESTIMATE_TOPIC = "estimate"
OUTPUT_TOPICS = (MODE_TOPIC, PHASE_TOPIC, SSE_TOPIC, ESTIMATE_TOPIC)
"""The node's output topics (relative names)."""
SSE_LABEL_PREFIX = "modes:"


def sse_label(mode_names: Sequence[str]) -> str:
    """``layout.dim[0].label`` of the ``sse`` message: ``modes:Slow,Med,...``."""
    return SSE_LABEL_PREFIX + ",".join(mode_names)


def mode_names_from_sse_label(label: str) -> list[str]:
    if not label.startswith(SSE_LABEL_PREFIX):
        raise ValueError(f"not an sse layout label: {label!r}")
    return label[len(SSE_LABEL_PREFIX) :].split(",")


ESTIMATE_HEAD = ("mode_index", "phase", "ready")
ESTIMATE_TAIL = ("confidence", "fit_rms_deg", "held", "phase_rate", "raw_mode_index", "cadence_ratio", "state")


def estimate_names(mode_names: Sequence[str]) -> list[str]:
    """Keys of the ``estimate`` message (JointState ``name``), fixed for a library.

    In order: ``mode_index`` (reported mode, index into the library's modes), ``phase`` ([0, 1)),
    ``ready`` (1.0 or 0.0), ``sse/<mode>`` (match error, deg^2, as on ``sse``) and ``phase/<mode>`` for every mode in library
    order, then ``confidence`` (margin over the best other mode, relative to its SSE),
    ``fit_rms_deg`` (RMS error per sample and channel, degrees), ``held`` (1.0 while the reported
    mode is held), ``phase_rate`` (strides/s, nan until known), ``raw_mode_index`` (the
    matcher's own choice before supervision) and ``cadence_ratio`` (wearer cadence / kernel
    cadence of the reported mode from its best time-scaled kernel variant; nan with one scale),
    ``state`` (``EstimateState``: 0 not ready, 1 walking, 2 stand, 3 unknown; docs/controller.md).
    """
    return [*ESTIMATE_HEAD, *(f"sse/{m}" for m in mode_names), *(f"phase/{m}" for m in mode_names), *ESTIMATE_TAIL]


def estimate_values(est: Estimate) -> list[float]:
    """``estimate_array(est)`` for one Estimate as a list of Python numbers (flags as bools,
    indices as ints): two numpy calls for any number of modes. The node packs it straight into
    its pre-serialised ``estimate`` (``SerializedJointState.set_values``)."""
    return [*[getattr(est, k) for k in ESTIMATE_HEAD], *est.sse.tolist(), *est.phases.tolist(),
            *[getattr(est, k) for k in ESTIMATE_TAIL]]


def estimate_array(est: Estimate | EstimateTrace) -> np.ndarray:
    """Values of the ``estimate`` message (JointState ``position``) in the order of
    ``estimate_names``: float64 (K,) for one Estimate, (T, K) for a whole EstimateTrace.
    No Python loop over modes (the node's hot path)."""
    head = [np.asarray(getattr(est, k), dtype=np.float64) for k in ESTIMATE_HEAD]
    tail = [np.asarray(getattr(est, k), dtype=np.float64) for k in ESTIMATE_TAIL]
    sse = np.asarray(est.sse, dtype=np.float64)
    phases = np.asarray(est.phases, dtype=np.float64)
    if sse.ndim == 1:
        return np.concatenate((np.array(head), sse, phases, np.array(tail)))
    return np.column_stack((*head, sse, phases, *tail))
