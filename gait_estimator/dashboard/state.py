"""What the page shows of one estimate: the wearer's state and the frame pushed to the page.

Pure functions of the node's ``estimate`` key/values (``io/outputs.py``) and diagnostics, so that
they are tested without ROS or a browser.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from ..core.kernels import KernelLibrary
from ..core.states import STAND, UNKNOWN, EstimateState

STATES = tuple(s.name for s in EstimateState)
"""The page's names of the ``state`` key of ``estimate`` (``core/states.py``)."""
STALE_AFTER_S = 3.0
"""Diagnostics older than this (s; they come every second) mean the node is not answering."""
QUIET_AFTER_S = 1.0
"""No estimate for this long (s) while the node is there: it has no input."""


def gait_state(values: Mapping[str, float]) -> str:
    """One of ``STATES``, from the ``state`` key; a message without a valid one is not trusted:
    ``not_ready``."""
    state = values.get("state", math.nan)
    return STATES[int(state)] if math.isfinite(state) and int(state) in range(len(STATES)) else "not_ready"


def _number(v: Any) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def estimate_view(names: Sequence[str], values: Sequence[float]) -> dict[str, Any]:
    """The page's view of one ``estimate`` message (JSON-ready: NaN becomes None)."""
    v = dict(zip(names, values, strict=False))  # a short message: its missing keys read as absent
    modes = [k[4:] for k in names if k.startswith("sse/")]
    index = v.get("mode_index", math.nan)
    mode = modes[int(index)] if math.isfinite(index) and 0 <= int(index) < len(modes) else None
    state = gait_state(v)
    shown = {"walking": mode, "stand": STAND, "unknown": UNKNOWN, "not_ready": None}[state]
    return {
        "state": state,
        "mode": shown,
        "phase": _number(v.get("phase")) if state == "walking" else None,
        "confidence": _number(v.get("confidence")),
        "phase_rate": _number(v.get("phase_rate")),
        "fit_rms_deg": _number(v.get("fit_rms_deg")),
        "sse": [[m, _number(v.get(f"sse/{m}"))] for m in modes],
    }


def link_view(present: bool, ever_seen: bool, estimate_age_s: float, diagnostics_age_s: float, target: str) -> dict:
    """Whether the node is there and sending, for the banner: status ``live``, ``idle``,
    ``silent``, ``lost`` or ``waiting``."""
    if present and estimate_age_s < QUIET_AFTER_S:
        return {"status": "live", "text": f"{target}: live"}
    if present and diagnostics_age_s < STALE_AFTER_S:
        return {"status": "idle", "text": f"{target} is running, no estimates (no input on segment_angles?)"}
    if present:
        return {"status": "silent", "text": f"{target} is in the graph but sends nothing: waiting for it"}
    if ever_seen:
        return {"status": "lost", "text": f"{target} is gone (stopped or restarting): waiting for it to come back"}
    return {"status": "waiting", "text": f"waiting for {target} to start"}


DIAGNOSTIC_KEYS = ("input_rate_hz", "samples_received", "samples_rejected", "window", "imu_calibration_status",
                   "imu_calibration", "imu_silent", "sensor_offset_deg", "cadence_scale", "library")
TEACH_KEYS = ("teach_mode", "teach_progress", "teach_last_event", "teach_completed", "teach_last_result",
              "taught_modes")


def diagnostics_view(level: str, message: str, values: Mapping[str, str]) -> dict[str, Any]:
    """Level, message, input rate, rejected samples by reason (non-zero ones), IMU calibration."""
    rejected = {k.split("_", 1)[1]: v for k, v in values.items()
                if k.startswith("rejected_") and v not in ("", "0")}
    return {"level": level, "message": message, **{k: values.get(k, "") for k in DIAGNOSTIC_KEYS},
            "rejected": rejected, "teach": {k[len("teach_"):] if k.startswith("teach_") else k: values.get(k, "")
                                            for k in TEACH_KEYS}}


def kernels_view(library: KernelLibrary | None, note: str) -> dict[str, Any]:
    """The library's kernels for the page's overlay (degrees, 2 decimals)."""
    if library is None:
        return {"type": "kernels", "library": "", "note": note, "modes": {}}
    return {"type": "kernels", "library": library.name, "note": note,
            "modes": {m.name: {"rate_hz": m.sample_rate_hz, "samples": m.samples.round(2).tolist()}
                      for m in library}}
