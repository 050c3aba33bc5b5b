"""Reading four ``sensor_msgs/Imu`` topics of a rosbag2 bag into a Recording of segment angles.

The same code as the node's ``input_type: imu`` (``core/imu_pairing.py``): each message becomes its
sensor's up direction, the four streams are paired by stamp, and the calibration (given, or
learnt) turns them into angles. Unlike the node, the whole file is known (docs/imu.md, "Offline"):
a learnt calibration applies from the first sample, raw sensors are fused again with the gyro
biases measured standing (for a given or configured calibration: as the node measures them,
before the check's verdict) and backwards in time over the first still stretch, and the pairing
tolerance is measured from the stamps (``auto_tolerance_s``) unless ``imu_tolerance_s`` is given.
Topics: ``imu_topics``, else ``/imu/<channel>``, else the four Imu topics named after the channels.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..core.ahrs import fuse_raw_backwards
from ..core.channels import CHANNELS, N_CHANNELS
from ..core.errors import RecordingError
from ..core.imu import CalibrationError, FusionParams, ImuCalibration
from ..core.imu_calibrator import check_stream
from ..core.imu_learn import (
    STILL_S,
    ImuLearnParams,
    check_configured,
    find_standing,
    learn_calibration,
)
from ..core.imu_pairing import UNPAIRED, ImuPairer, SensorInput, auto_tolerance_s, check_tolerance_s
from ..core.rejections import SampleRejected
from .bag import BagRecording, bag_topics, format_topics, is_bag_path, open_bag, since_time_zero, typestore
from .cdr import stamp_to_ns, write_imu
from .imu_stream import load_calibration
from .read_options import ReadOptions

IMU = "sensor_msgs/msg/Imu"
DEFAULT_IMU_TOPICS = tuple(f"imu/{c}" for c in CHANNELS)
"""Relative topic names of the four IMUs (the node's default ``imu_topics``)."""


@dataclass
class ImuBagRecording(BagRecording):
    """A BagRecording made from four Imu topics; ``calibration`` is the one used; the raw sensors'
    samples before ``fused_backwards_until`` were fused backwards in time from it."""

    calibration: ImuCalibration | None = None
    calibration_note: str = ""
    fused_backwards_until: int = 0

    @property
    def notes(self) -> list[str]:
        out = [n for n in super().notes if "had a zero header stamp" not in n]
        if self.calibration_note:
            out.append(self.calibration_note)
        return out

    def select(self, keep: np.ndarray, skipped: dict[str, int] | None = None) -> ImuBagRecording:
        got = super().select(keep, skipped)
        return replace(got, fused_backwards_until=int(np.count_nonzero(keep[:self.fused_backwards_until])))


def imu_topics_of(topics: dict[str, tuple[str, int]]) -> list[str] | None:
    """The four IMU topics of a bag (CHANNELS order) by the rules in the module docstring."""
    defaults = ["/" + t for t in DEFAULT_IMU_TOPICS]
    if all(topics.get(t, ("",))[0] == IMU for t in defaults):
        return defaults
    imus = [t for t, (ty, _) in topics.items() if ty == IMU]
    found = []
    for c in CHANNELS:
        match = [t for t in imus if t.rstrip("/").endswith(c)]
        if len(match) != 1:
            return None
        found.append(match[0])
    return found


def is_imu_bag(p: Path) -> bool:
    """A bag with Imu topics and no JointState/Float64MultiArray input topic."""
    if not is_bag_path(p):
        return False
    try:
        with open_bag(p, quiet=True) as reader:
            types = {ty for ty, _ in bag_topics(reader).values()}
    except RecordingError:
        return False
    return IMU in types and not types & {"sensor_msgs/msg/JointState", "std_msgs/msg/Float64MultiArray"}


def _front_end(messages: list[tuple[int, int, Any]], rate_hz: float, bias: list | None, tolerance_s: float,
               fusion: Sequence[FusionParams]):
    """Messages (sensor, log_ns, msg) -> paired (stamp_ns, log_ns, ups, gyro, acc) and rejections;
    ``fusion``: per sensor."""
    inputs = [SensorInput(rate_hz, params=f, restart_back_s=0.0) for f in fusion]  # one recording
    if bias is not None:
        for s, b in zip(inputs, bias, strict=False):
            s.set_gyro_bias(b)
    pairer = ImuPairer(tolerance_s)
    rejected: Counter = Counter()
    paired = []
    for sensor, log_ns, m in messages:
        stamp_ns = stamp_to_ns(m.header.stamp) or log_ns
        o, w, a = m.orientation, m.angular_velocity, m.linear_acceleration
        try:
            up, gyro, acc = inputs[sensor].convert(stamp_ns, (o.x, o.y, o.z, o.w), float(m.orientation_covariance[0]),
                                                   (w.x, w.y, w.z), (a.x, a.y, a.z))
        except SampleRejected as exc:
            rejected[exc.reason] += 1
            continue
        for stamp, items in pairer.push(sensor, stamp_ns, (log_ns, up, gyro, acc)):
            paired.append((stamp, items[0][0], [i[1] for i in items], [i[2] for i in items], [i[3] for i in items]))
    if pairer.unpaired:
        rejected[UNPAIRED] += pairer.unpaired
    return paired, rejected


def read_imu_bag(path: str | Path, options: ReadOptions | None = None, /, **values: Any) -> ImuBagRecording:
    """Segment angles (deg, CHANNELS order) from a bag's four Imu topics.

    Args:
        path: rosbag2 directory or storage file.
        options, values: ReadOptions, then fields by name; the ``imu_*`` ones, ``max_gap_s``,
            ``fusion_params`` and ``learn_params`` concern Imu topics (defaults: module docstring).

    Raises:
        RecordingError: one line (missing topics, unusable messages, no calibration possible).
    """
    p = Path(path)
    o = ReadOptions.of(options, values)
    imu_calibration, imu_tolerance_s, learn_params = o.imu_calibration, o.imu_tolerance_s, o.learn_params
    imu_lateral_axes, imu_proximal_axes, fusion_params = o.imu_lateral_axes, o.imu_proximal_axes, o.fusion_params
    try:
        if imu_tolerance_s is not None:
            check_tolerance_s(imu_tolerance_s)
    except ValueError as exc:
        raise RecordingError(str(exc)) from None
    try:
        lateral, proximal = check_configured(imu_lateral_axes or [""] * N_CHANNELS, imu_proximal_axes or [""] * N_CHANNELS)
        cal = imu_calibration or None
        given_as = f"the IMU calibration {cal}" if isinstance(cal, (str, Path)) else "the IMU calibration given"
        if isinstance(cal, (str, Path)):
            cal = load_calibration(cal)
    except CalibrationError as exc:
        raise RecordingError(str(exc)) from None
    standing_deg = list(o.imu_standing_deg or [0.0] * N_CHANNELS)
    names, messages, undecodable = _read_messages(p, o.imu_topics)
    rate = _rate_hz(messages)
    tolerance_s = imu_tolerance_s if imu_tolerance_s is not None else _measured_tolerance(messages)
    fusion = [fusion_params] * N_CHANNELS if isinstance(fusion_params, FusionParams) else list(fusion_params)

    def fused(c: ImuCalibration | None) -> tuple[list, Counter]:
        """The messages paired, raw ones fused with ``c``'s gyro biases (None: none)."""
        paired, rejected = _front_end(messages, rate, None if c is None else [m.gyro_bias_dps for m in c.mounts],
                                      tolerance_s, fusion)
        if undecodable:
            rejected["undecodable"] += undecodable
        return paired, rejected

    paired, rejected = fused(cal)  # as the node applies a saved calibration
    if len(paired) < 2:
        raise RecordingError(
            f"{p}: fewer than 2 samples with all four IMUs within {tolerance_s:g} s; skipped: {dict(rejected)}")
    given = cal is not None
    if cal is None:
        cal, note = _learn(p, paired, lateral, proximal, standing_deg, learn_params)
        if any(any(b) for m in cal.mounts for b in [m.gyro_bias_dps]):
            paired, rejected = fused(cal)
            cal, note = _learn(p, paired, lateral, proximal, standing_deg, learn_params)
    else:
        note = "IMU calibration given: " + cal.summary()
    if given or all(m.source == "configured" for m in cal.mounts):  # made earlier: checked, as in the node
        ending, checked = _check_note(p, paired, cal, learn_params, given_as if given else "")
        note += ending
        if checked is not cal:  # raw sensors' biases of a standing pose before the verdict replace the file's
            cal = checked
            paired, rejected = fused(cal)  # (only raw sensors get measured biases), from the first sample
            note += "; gyro biases from the standing pose"
    paired, backwards_until, backwards = _fused_backwards(paired, cal, fusion, learn_params)
    stamp_ns = np.array([s[0] for s in paired], dtype=np.int64)
    angles = np.array([cal.angles_deg(s[2]) for s in paired], dtype=np.float64)
    return ImuBagRecording(
        time_s=since_time_zero(stamp_ns) * 1e-9,
        angles_deg=angles,
        source=f"{p} {','.join(names)}",
        skipped={k: int(v) for k, v in rejected.items() if v},
        stamp_ns=stamp_ns,
        log_time_ns=np.array([s[1] for s in paired], dtype=np.int64),
        bag=str(p),
        topic=",".join(names),
        msgtype=IMU,
        messages=len(messages) + undecodable,
        max_gap_s=o.max_gap_s,
        calibration=cal,
        calibration_note=note + backwards,
        fused_backwards_until=backwards_until,
    )


def _topic_names(p: Path, topics: dict[str, tuple[str, int]], imu_topics: list[str] | None) -> list[str]:
    """The four IMU topics to read (module docstring); RecordingError (one line) if the bag lacks them."""
    names = ["/" + t.lstrip("/") for t in imu_topics] if imu_topics else imu_topics_of(topics)
    if names is not None and len(names) != N_CHANNELS:
        raise RecordingError(f"{p}: needs {N_CHANNELS} IMU topics ({', '.join(CHANNELS)}), got {len(names)}: "
                             f"{', '.join(names)}")
    if names is not None and imu_topics and any(topics.get(t, ("",))[0] != IMU for t in names):
        bad = ", ".join(t for t in names if topics.get(t, ("",))[0] != IMU)
        raise RecordingError(f"{p}: no {IMU} topic {bad} in the bag; {format_topics(topics)}")
    if names is None or any(topics.get(t, ("",))[0] != IMU for t in names):
        want = ", ".join(names or ["/" + t for t in DEFAULT_IMU_TOPICS])
        raise RecordingError(f"{p}: needs four {IMU} topics ({want}; others: --imu-topics RT,LT,RS,LS); "
                             f"{format_topics(topics)}")
    return names


def _read_messages(p: Path, imu_topics: list[str] | None) -> tuple[list[str], list[tuple[int, int, Any]], int]:
    """(topic names, [(sensor, log_ns, message)] in log order, messages that failed to decode)."""
    with open_bag(p, "imu") as reader:
        names = _topic_names(p, bag_topics(reader), imu_topics)
        index = {t: i for i, t in enumerate(names)}
        conns = [c for c in reader.connections if c.topic in index]
        deserialize = typestore().deserialize_cdr
        messages = []
        undecodable = 0
        for conn, log_ns, raw in reader.messages(connections=conns):
            try:
                messages.append((index[conn.topic], int(log_ns), deserialize(raw, IMU)))
            except Exception:
                undecodable += 1
    return names, messages, undecodable


def _measured_tolerance(messages: list[tuple[int, int, Any]]) -> float:
    """``auto_tolerance_s`` from the header stamps (log times when zero) of the first messages."""
    stamps: list[list[int]] = [[] for _ in range(N_CHANNELS)]
    for sensor, log_ns, m in messages[:4000]:
        stamps[sensor].append(stamp_to_ns(m.header.stamp) or log_ns)
    try:
        return auto_tolerance_s(stamps)
    except ValueError:
        return 0.0  # too few messages to pair anyway: the caller's "fewer than 2 samples" line


def _rate_hz(messages: list[tuple[int, int, Any]]) -> float:
    """The first sensor's message rate (Hz) from its first stamps; 200 Hz if too few."""
    stamps = [stamp_to_ns(m.header.stamp) for s, _, m in messages[:800] if s == 0]
    d = float(np.median(np.diff(np.array(stamps, dtype=np.int64)))) * 1e-9 if len(stamps) > 8 else 0.0
    return 1.0 / d if d > 0 else 200.0


def _arrays(paired: list) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Paired samples -> time (s from the first), ups, gyro and acc (4, T, 3; None: no sensor has them)."""
    t = np.array([s[0] for s in paired], dtype=np.int64)
    ups = np.asarray([s[2] for s in paired], dtype=np.float64).transpose(1, 0, 2)
    gyro = np.asarray([s[3] for s in paired], dtype=np.float64).transpose(1, 0, 2)
    acc = np.asarray([s[4] for s in paired], dtype=np.float64).transpose(1, 0, 2)
    return ((t - t[0]) * 1e-9, ups, gyro if np.isfinite(gyro).any() else None,
            acc if np.isfinite(acc).any() else None)


BACKWARDS_MARGIN_S = 0.2
"""The backward fusion starts this long before the end of the still stretch that ``find_standing``
reports, which can follow the first move by as much as its 0.2 s tilt comparison."""


def _fused_backwards(paired: list, cal: ImuCalibration, fusion: Sequence[FusionParams],
                     params: ImuLearnParams) -> tuple[list, int, str]:
    """``paired`` with the raw sensors' up directions up to the end of the first still stretch
    (a standing pose of ``params.short_still_s``, and as long as it stays still, less
    BACKWARDS_MARGIN_S) fused backwards in time from that end: the forward fusion starts at the
    first sample, from the accelerometer of a sensor that may be moving, and is still settling
    when the stretch begins (``fusion``: per sensor). Also that end (sample index) and the
    calibration note's ending; ``paired``, 0 and '' without raw sensors or such a stretch after the
    first sample."""
    time_s, ups, gyro, acc = _arrays(paired)
    if acc is None or gyro is None:
        return paired, 0, ""
    pose = find_standing(time_s, ups, gyro, acc, still_s=params.short_still_s, params=params)
    if pose is None or pose.start == 0:
        return paired, 0, ""
    end = int(np.searchsorted(time_s, time_s[pose.still_until - 1] - BACKWARDS_MARGIN_S, side="right"))
    end = max(end, pose.stop)
    upto = slice(0, end)
    ups_back = {c: fuse_raw_backwards(time_s[upto], gyro[c, upto], acc[c, upto], cal.mounts[c].gyro_bias_dps,
                                      fusion[c])
                for c in range(N_CHANNELS) if np.isfinite(acc[c, upto]).all()}
    if not ups_back:
        return paired, 0, ""
    out = list(paired)
    for k in range(end):
        stamp, log_ns, u, g, a = paired[k]
        u = list(u)
        for c, up in ups_back.items():
            u[c] = tuple(up[k])
        out[k] = (stamp, log_ns, u, g, a)
    note = (f"; raw sensors fused backwards in time from {time_s[end - 1]:.1f} s, in the first still stretch "
            f"({time_s[pose.start]:.1f}-{time_s[pose.still_until - 1]:.1f} s)")
    return out, end, note


def _learn(p: Path, paired: list, lateral: list, proximal: list, standing_deg: list,
           params: ImuLearnParams) -> tuple[ImuCalibration, str]:
    time_s, ups, gyro, acc = _arrays(paired)
    try:
        for still_s in (STILL_S, params.short_still_s):  # a short still stretch if the file has no longer one
            cal, standing, missing = learn_calibration(
                time_s, ups, lateral=lateral, proximal=proximal, standing_deg=standing_deg,
                gyro_dps=gyro, acc_g=acc, still_s=still_s, params=params,
                search=any(a is None for a in (*lateral, *proximal)))  # configured axes: biases from the check
            if cal is not None:
                break
    except CalibrationError as exc:
        raise RecordingError(f"{p}: IMU calibration: {exc}") from None
    if cal is None:
        raise RecordingError(f"{p}: cannot learn the IMU mounting from this file: {missing} "
                             "(or give --imu-calibration FILE)")
    where = ""
    if standing is not None:
        span = f"the standing pose at {time_s[standing.start]:.1f}-{time_s[standing.stop - 1]:.1f} s"
        if any(a is None for a in proximal):
            where = " from " + span
        elif acc is not None:  # configured proximal axes: the pose gives the raw sensors' gyro biases only
            where = f" (gyro biases from {span})"
    return cal, "IMU calibration learnt" + where + ": " + cal.summary()


def _check_note(p: Path, paired: list, cal: ImuCalibration, params: ImuLearnParams,
                given_as: str) -> tuple[str, ImuCalibration]:
    """The node's check of a calibration made earlier, on the recording's first walking: (the
    note's ending, ``cal`` with the gyro biases the node would have measured before the verdict);
    RecordingError for a given calibration (``given_as`` names it; '' = configured axes) that does
    not fit: the node would learn one again, but the file was asked for, and a recording that
    does not start standing could not be learnt from (configured axes that do not fit are kept,
    as in the node, with a warning in the note)."""
    found, _, missing, checked = check_stream([s[0] * 1e-9 for s in paired], [s[2] for s in paired],
                                              [s[3] for s in paired], [s[4] for s in paired], cal, params)
    if found is None:
        return f"; not checked ({missing})", checked
    if found.fits:
        return "; checked on the walking: " + found.summary(), checked
    if given_as:
        raise RecordingError(f"{p}: {given_as} does not fit this recording ({found.summary()}); "
                             "without --imu-calibration one is learnt from it")
    return "; WARNING: the configured axes do not fit the walking (the angles are wrong): " + found.summary(), checked


def write_imu_bag(path: str | Path, stamps_ns: np.ndarray, gyro_rps: np.ndarray, acc_mps2: np.ndarray,
                  quat_xyzw: np.ndarray | None = None, topics: list[str] | None = None, storage: str = "mcap") -> Path:
    """Write four IMU streams as ``sensor_msgs/msg/Imu`` topics of a new bag.

    Args:
        stamps_ns: (4, T) or (T,) header stamps (int ns); the log time is the stamp.
        gyro_rps, acc_mps2: (4, T, 3) rates (rad/s) and accelerations (m/s^2), sensor frames.
        quat_xyzw: (4, T, 4) orientations (world <- sensor), or None for raw IMUs (also per
            sensor: a list of four (T, 4) arrays or None).
        topics: Four topic names (default ``/imu/<channel>``).

    Messages are those of io/cdr.py ``write_imu`` (no orientation: ``orientation_covariance[0]`` -1).
    """
    from .bag_write import offered_qos, staged_writer

    ts = typestore()
    names = ["/" + t.lstrip("/") for t in (topics or DEFAULT_IMU_TOPICS)]
    stamps = np.broadcast_to(np.asarray(stamps_ns, dtype=np.int64), gyro_rps.shape[:2])
    with staged_writer(path, storage) as writer:
        conns = [writer.add_connection(n, IMU, typestore=ts, offered_qos_profiles=offered_qos(100)) for n in names]
        for k in range(stamps.shape[1]):
            for c in range(N_CHANNELS):
                no_orientation = quat_xyzw is None or quat_xyzw[c] is None
                q = (0.0, 0.0, 0.0, 1.0) if no_orientation else [float(v) for v in quat_xyzw[c][k]]
                data = write_imu(int(stamps[c, k]), CHANNELS[c], q, -1.0 if no_orientation else 0.0,
                                 [float(v) for v in gyro_rps[c, k]], [float(v) for v in acc_mps2[c, k]])
                writer.write(conns[c], int(stamps[c, k]), data)
    return Path(path)
