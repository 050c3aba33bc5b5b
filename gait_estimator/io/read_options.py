"""``ReadOptions``: how a recording is read. Every reader takes one; each uses the fields of its
format and leaves the others alone, so ``read_recording`` passes the same options whatever it finds."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from ..core.imu import FUSION_BY_CHANNEL, FusionParams, ImuCalibration
from ..core.imu_learn import DEFAULT_LEARN, ImuLearnParams
from ..core.options import EstimatorConfig

DEFAULT_MAX_GAP_S = EstimatorConfig.max_gap_s


@dataclass(frozen=True)
class ReadOptions:
    """Options of the readers (``read_recording``, ``read_bag``, ``read_imu_bag``, the CSV readers).

    Attributes:
        rate_hz: Time base (Hz) of a source without time stamps (the reference CSV); None = the
            paper's 230 Hz.
        topic: Bag topic of the angles (default: DEFAULT_TOPIC, or the only JointState or
            Float64MultiArray topic).
        joint_names: Joint names of right_thigh, left_thigh, right_shank, left_shank in a
            JointState (sequence or comma-separated string; default CHANNELS).
        input_units: ``rad`` or ``deg``: units of the angles in a bag's messages.
        max_gap_s: A longer gap (s) between accepted samples restarts the matcher window (<= 0
            disables), as the node's ``max_gap_s``.
        imu_topics: The four Imu topics (CHANNELS order); given, a bag is read as Imu topics even
            when it also has an angle topic.
        imu_calibration: An IMU calibration (or its YAML file) to use instead of learning one.
        imu_lateral_axes, imu_proximal_axes: Configured sensor axes per segment ('' = learn).
        imu_standing_deg: Angle of each segment in the standing pose (deg; default 0).
        imu_tolerance_s: Imu pairing tolerance (s, >= 0); None = measured from the stamps.
        fusion_params: Raw-IMU fusion settings, one for all sensors or per sensor (CHANNELS order).
        learn_params: IMU mount-learning settings.
    """

    rate_hz: float | None = None
    topic: str | None = None
    joint_names: Sequence[str] | str | None = None
    input_units: str = "rad"
    max_gap_s: float = DEFAULT_MAX_GAP_S
    imu_topics: Sequence[str] | None = None
    imu_calibration: str | Path | ImuCalibration | None = None
    imu_lateral_axes: Sequence[str] | None = None
    imu_proximal_axes: Sequence[str] | None = None
    imu_standing_deg: Sequence[float] | None = None
    imu_tolerance_s: float | None = None
    fusion_params: FusionParams | Sequence[FusionParams] = FUSION_BY_CHANNEL
    learn_params: ImuLearnParams = DEFAULT_LEARN

    @classmethod
    def of(cls, options: ReadOptions | None = None, values: Mapping[str, Any] | None = None) -> ReadOptions:
        """``options`` (default: all defaults) with ``values`` by name; TypeError naming any
        unknown name (a misspelt option is never ignored)."""
        values = values or {}
        unknown = sorted(set(values) - READ_OPTION_NAMES)
        if unknown:
            raise TypeError(f"unknown reading option{'s' if len(unknown) > 1 else ''} {', '.join(map(repr, unknown))} "
                            f"(known: {', '.join(sorted(READ_OPTION_NAMES))})")
        return replace(options or cls(), **values)


READ_OPTION_NAMES = frozenset(f.name for f in fields(ReadOptions))
