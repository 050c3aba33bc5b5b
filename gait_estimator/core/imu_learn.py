"""Learning the IMU mounts (``core/imu.py`` ``SegmentMount``) from a standing pose and strides.

* **Standing pose** (the first still ``still_s`` seconds, or the first after a request): every
  sensor's mean up direction is the segment's ``proximal`` axis (segments taken as vertical, or at
  ``standing_deg``); the mean gyro over the whole still stretch that the pose begins is its bias.
* **Strides** after it: the up direction rotates, in the sensor frame, about the segment's
  sagittal axis; the principal axis of those rotations (u[k] x u[k+lag], summed as outer
  products), made perpendicular to ``proximal``, is ``lateral`` up to its sign.
* **Signs** per leg from the knee: with the right signs the knee (shank - thigh) flexes (negative)
  by 40-65 deg in swing and hardly extends past straight; every other sign choice makes it extend
  by tens of degrees. The choice with the smallest 98th percentile of the knee angle wins and must
  beat the next by ``ImuLearnParams.min_sign_margin_deg``.

A calibration made earlier (a saved file, configured axes) is **checked** against a stretch of
walking (``check_calibration``): its lateral axes against the ones learnt there with its proximal
axes, and its knee angles against the knee rule. A sensor turned about its segment or a wrong sign
shows in the first; an angle offset (a sensor tilted within the sagittal plane) only when it
bends the knee past straight. A sensor upside down (its long axis reversed) leaves the signs
undecidable, so no lateral axes are learnt; on a stretch of walking in which every sensor swings
about its calibrated lateral line, its knee past ``max_knee_extension_deg`` is the verdict. A
segment whose median angle on the stretch is more than ``max_segment_angle_deg`` from vertical
does not fit either.

Every function takes whole arrays (a file, or the live node's buffer); ``learn_calibration``
returns the calibration or what is still missing.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .channels import CHANNELS, N_CHANNELS
from .imu import CalibrationError, ImuCalibration, SegmentMount, Vec3

STILL_S = 1.0
"""Length (s) of the still stretch that makes a standing pose."""
WALK_S = 4.0
"""Time of movement (s) after the standing pose before the sagittal axes are learnt."""


@dataclass(frozen=True)
class ImuLearnParams:
    """Thresholds of mount learning (standing pose, swing axis, knee-rule signs).

    Attributes:
        still_max_tilt_deg: Most any sensor's up direction may move within a still stretch (deg).
        still_max_rate_dps: Largest gyro magnitude in a still stretch (deg/s; raw input).
        still_acc_tolerance: Accelerometer magnitude in a still stretch within 1 +- this (g; raw).
        min_swing_deg: Least angle range (2nd-98th percentile, deg) a segment must sweep for its
            axis to be learnt.
        min_planarity: Share of the rotation that must lie about the principal axis (a sagittal
            swing).
        min_sign_margin_deg: Margin (deg) by which the knee rule's best sign choice must beat the next.
        rotation_lag_s: Lag (s) between the up directions whose cross product gives the rotation
            axis when there is no gyro.
        short_still_s: Still stretch (s) taken as the standing pose of a file without one of
            ``STILL_S`` (offline only: the whole file is known).
        learn_every_s: How often (s of stream) the live calibrator tries to learn, or to check.
        max_buffer_s: Longest stream (s) the live calibrator keeps while no standing pose is found.
        check_window_s: Stretch of stream (s) a calibration is checked on (the swing and sign
            thresholds above decide whether it holds enough walking).
        max_axis_change_deg: Largest angle (deg) between a checked calibration's lateral axis
            and the one learnt on the stretch.
        max_knee_extension_deg: Largest knee extension past straight (deg, 98th percentile over
            the stretch) a checked calibration may give.
        max_segment_angle_deg: Largest median |segment angle| (deg) over a checked stretch of
            walking (thighs and shanks stay within about 70 deg of vertical; an upside-down
            sensor reads about 180).
    """

    still_max_tilt_deg: float = 3.0
    still_max_rate_dps: float = 25.0
    still_acc_tolerance: float = 0.1
    min_swing_deg: float = 20.0
    min_planarity: float = 0.8
    min_sign_margin_deg: float = 15.0
    rotation_lag_s: float = 0.05
    short_still_s: float = 0.5
    learn_every_s: float = 0.5
    max_buffer_s: float = 120.0
    check_window_s: float = 8.0
    max_axis_change_deg: float = 30.0
    max_knee_extension_deg: float = 30.0
    max_segment_angle_deg: float = 110.0


DEFAULT_LEARN = ImuLearnParams()
"""The default learning thresholds (a default argument value)."""


LEGS = ((0, 2), (1, 3))
"""(thigh, shank) channel indices of the right and the left leg (CHANNELS order)."""


@dataclass(frozen=True)
class Standing:
    """A standing pose found in a stream.

    Attributes:
        start, stop: Sample range of the pose (``still_s`` long).
        proximal: Per sensor, the mean up direction over the pose (sensor frame).
        gyro_bias_dps: Per sensor, the mean gyro (deg/s) from ``start`` to ``still_until``.
        still_until: End (exclusive sample index) of the still stretch the pose begins: it goes
            on while the stillness tests hold and every up direction stays within the tilt
            tolerance of the pose's.
        ended: The stretch ended within the stream (False: still at its last sample).
    """

    start: int
    stop: int
    proximal: tuple[Vec3, ...]
    gyro_bias_dps: tuple[Vec3, ...]
    still_until: int
    ended: bool


def _norm_rows(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / n


def _moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Trailing mean over ``n`` samples along axis 1 (the first samples: over what there is)."""
    c = np.cumsum(x, axis=1)
    out = c.copy()
    out[:, n:] = c[:, n:] - c[:, :-n]
    count = np.minimum(np.arange(1, x.shape[1] + 1), n)
    return out / count[None, :, None]


def quiet_runs(time_s: np.ndarray, gyro_dps: np.ndarray, still_s: float = STILL_S,
               params: ImuLearnParams = DEFAULT_LEARN) -> list[tuple[int, int]]:
    """Sample ranges [start, end) at least ``still_s`` long in which no gyro (4, T, 3; nan = no
    rates, quiet) exceeds ``still_max_rate_dps``: the only places a standing pose can be (a cheap
    necessary condition; ``end`` == T: still quiet at the last sample)."""
    t = np.asarray(time_s, dtype=np.float64)
    g = np.asarray(gyro_dps, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        loud = (np.einsum("stk,stk->st", g, g) > params.still_max_rate_dps ** 2).any(axis=0)
    edges = np.diff(np.concatenate(([1], loud.astype(np.int8), [1])))
    step = (t[-1] - t[0]) / max(len(t) - 1, 1)
    return [(int(a), int(b)) for a, b in zip(np.flatnonzero(edges == -1), np.flatnonzero(edges == 1), strict=True)
            if t[b - 1] - t[a] >= still_s - step]  # find_standing's length test is still_s - dt / 2


def find_standing(time_s: np.ndarray, ups: np.ndarray, gyro_dps: np.ndarray | None = None,
                  acc_g: np.ndarray | None = None,
                  still_s: float = STILL_S, params: ImuLearnParams = DEFAULT_LEARN) -> Standing | None:
    """The first still stretch of ``still_s`` seconds, or None.

    Args:
        time_s: (T,) sample times, s.
        ups: (4, T, 3) up directions per sensor (sensor frames; from orientation or fusion).
        gyro_dps: (4, T, 3) gyro, deg/s, or None (nan for a sensor without rates).
        acc_g: (4, T, 3) accelerometer, g, or None (nan for a sensor with an orientation): a raw
            sensor's stillness and up direction come from its accelerometer (the fused direction
            may still be settling), with twice the tilt tolerance (accelerometer noise).
        still_s: Length of the stretch (s).
        params: The stillness thresholds.
    """
    t = np.asarray(time_s, dtype=np.float64)
    if len(t) < 2 or (gyro_dps is not None and not quiet_runs(t, gyro_dps, still_s, params)):
        return None  # (walking: the cheap test is enough)
    ups_a = np.asarray(ups, dtype=np.float64)
    acc_a = None if acc_g is None else np.asarray(acc_g, dtype=np.float64)
    raw = np.zeros(len(ups_a), dtype=bool) if acc_a is None else np.isfinite(acc_a).all(axis=(1, 2))
    dt = float(np.median(np.diff(t)))
    if acc_a is not None and raw.any():  # accelerometer noise: its 0.1 s means
        acc_a = acc_a.copy()
        acc_a[raw] = _moving_mean(acc_a[raw], max(1, round(0.1 / dt)))
    u = _norm_rows(np.where(raw[:, None, None], acc_a if acc_a is not None else ups_a, ups_a))
    tilt_limit = np.where(raw, 2.0 * params.still_max_tilt_deg, params.still_max_tilt_deg)
    lag = max(1, round(0.2 / dt))
    ok = np.isfinite(u).all(axis=(0, 2))
    moved = np.zeros(len(t), dtype=bool)
    cos_lim = np.cos(np.radians(tilt_limit))[:, None]
    moved[lag:] = (np.einsum("stk,stk->st", u[:, lag:], u[:, :-lag]) < cos_lim).any(axis=0)
    if gyro_dps is not None:
        with np.errstate(invalid="ignore"):
            moved |= (np.linalg.norm(gyro_dps, axis=2) > params.still_max_rate_dps).any(axis=0)
    if acc_a is not None and raw.any():
        moved |= (np.abs(np.linalg.norm(acc_a[raw], axis=2) - 1.0) > params.still_acc_tolerance).any(axis=0)
    still = ok & ~moved
    length = still_s - dt / 2
    edges = np.diff(np.concatenate(([0], still.astype(np.int8), [0])))
    step = max(1, round(0.1 / dt))  # a stretch that drifts: try again 0.1 s later
    for first, end in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        if t[end - 1] - t[first] < length:
            continue
        last = int(np.searchsorted(t, t[end - 1] - length, side="right")) - 1
        for i in range(int(first), last + 1, step):
            stop = int(np.searchsorted(t, t[i] + length, side="right"))
            win = u[:, i:stop]
            mean = _norm_rows(win.mean(axis=1))  # at rest the accelerometer reads up, unaffected by gyro bias
            spread = np.degrees(np.arccos(np.clip(np.einsum("stk,sk->st", win, mean), -1, 1))).max(axis=1)
            if (spread <= tilt_limit).all():
                near = (np.einsum("stk,sk->st", u[:, stop:end], mean) >= cos_lim).all(axis=0)
                until = stop + (int(np.argmin(near)) if not near.all() else len(near))
                bias = (np.zeros((N_CHANNELS, 3)) if gyro_dps is None
                        else np.nan_to_num(np.asarray(gyro_dps, dtype=np.float64)[:, i:until].mean(axis=1)))
                return Standing(i, stop, tuple(tuple(map(float, m)) for m in mean),
                                tuple(tuple(map(float, b)) for b in bias), until, until < len(t))
    return None


def swing_axis(time_s: np.ndarray, ups: np.ndarray, proximal: Vec3, gyro_dps: np.ndarray | None = None,
               params: ImuLearnParams = DEFAULT_LEARN) -> tuple[Vec3 | None, str]:
    """Sagittal axis (sign undecided) of one sensor while walking: the principal axis of its
    rotation perpendicular to ``proximal`` (which removes turning about the vertical), from the
    gyro (T, 3) when there is one (finite, not all zero: some orientation drivers fill the rates
    with zeros), else from the rotation of its up directions (T, 3); or None and why not."""
    t = np.asarray(time_s, dtype=np.float64)
    if len(t) < 10:
        return None, "too few samples"
    p = np.asarray(proximal)
    if gyro_dps is not None and np.isfinite(gyro_dps).all() and np.any(gyro_dps):
        d = np.asarray(gyro_dps, dtype=np.float64)
    else:
        lag = max(1, round(params.rotation_lag_s / float(np.median(np.diff(t)))))
        u = _norm_rows(np.asarray(ups, dtype=np.float64))
        d = np.cross(u[:-lag], u[lag:])
        d = d[np.isfinite(d).all(axis=1)]
    if len(d) < 10:
        return None, "too few samples"
    d = d - np.outer(d @ p, p)
    m = d.T @ d
    w, v = np.linalg.eigh(m)
    if w[-1] <= 0 or w[-1] / w.sum() < params.min_planarity:
        return None, f"no clear sagittal swing (planarity {w[-1] / max(w.sum(), 1e-300):.2f} < {params.min_planarity})"
    a = v[:, -1] - float(v[:, -1] @ p) * p
    if np.linalg.norm(a) < 0.5:
        return None, "swing axis along the segment"
    return tuple(float(x) for x in a / np.linalg.norm(a)), ""


def _sagittal_swing(time_s: np.ndarray, ups: np.ndarray, proximal: Vec3, standing_deg: float, bias_dps: Vec3,
                    gyro_dps: np.ndarray | None, params: ImuLearnParams) -> tuple[list[SegmentMount] | None, str]:
    """One sensor walking: the two learnt mounts (lateral axis of either sign) with this proximal
    axis, standing angle and gyro bias, or None and why not (no clear sagittal swing, or one
    smaller than ``params.min_swing_deg``)."""
    axis, why = swing_axis(time_s, ups, proximal, gyro_dps, params)
    if axis is None:
        return None, why
    both = [SegmentMount(a, proximal, standing_deg, bias_dps, "learnt") for a in (axis, tuple(-x for x in axis))]
    swept = np.percentile(both[0].angles_deg(ups), [2, 98])
    if not swept[1] - swept[0] >= params.min_swing_deg:  # NaN (no finite angle) too
        return None, f"swings only {swept[1] - swept[0]:.0f} deg"
    return both, ""


def _knee_extension(thigh_deg: np.ndarray, shank_deg: np.ndarray) -> float:
    """The knee angle's (shank - thigh) 98th percentile over its finite samples (deg, + = past
    straight); nan without any."""
    knee = shank_deg - thigh_deg
    knee = knee[np.isfinite(knee)]
    return float(np.percentile(knee, 98)) if len(knee) else math.nan


def _leg_signs(cands: dict[int, list[SegmentMount]], ups: np.ndarray, thigh: int,
               shank: int, margin_deg: float) -> tuple[dict[int, SegmentMount], str]:
    """Pick the mounts of one leg's thigh and shank by the knee rule (module docstring)."""
    scores = [(_knee_extension(mt.angles_deg(ups[thigh]), ms.angles_deg(ups[shank])), mt, ms)
              for mt, ms in itertools.product(cands[thigh], cands[shank])]
    scores.sort(key=lambda s: s[0])
    if len(scores) > 1 and scores[1][0] - scores[0][0] < margin_deg:
        return {}, (f"{CHANNELS[thigh]}/{CHANNELS[shank]}: cannot tell forward from backward "
                    f"(knee rule margin {scores[1][0] - scores[0][0]:.1f} < {margin_deg:g} deg); "
                    "walk a few more strides")
    return {thigh: scores[0][1], shank: scores[0][2]}, ""


def learn_calibration(
    time_s: np.ndarray,
    ups: np.ndarray,
    *,
    lateral: Sequence[Vec3 | None] = (None,) * N_CHANNELS,
    proximal: Sequence[Vec3 | None] = (None,) * N_CHANNELS,
    standing_deg: Sequence[float] = (0.0,) * N_CHANNELS,
    standing: Standing | None = None,
    gyro_dps: np.ndarray | None = None,
    acc_g: np.ndarray | None = None,
    still_s: float = STILL_S,
    params: ImuLearnParams = DEFAULT_LEARN,
    search: bool = True,
) -> tuple[ImuCalibration | None, Standing | None, str]:
    """Complete the configured axes into a calibration from a stream.

    Args:
        time_s: (T,) sample times (s) of the paired four-sensor samples.
        ups: (4, T, 3) up directions (sensor frames).
        lateral, proximal: Configured sensor-frame axes per segment, None = learn.
        standing_deg: Angle (deg) each segment is taken to have in the standing pose.
        standing: A standing pose already found, or None: then (``search``) the first in the
            stream, needed for a learnt proximal axis, else used for the gyro bias alone.
        gyro_dps, acc_g: (4, T, 3) raw rates and accelerations for the still test and the bias.
        still_s: Length of the still stretch taken as the standing pose (s).
        params: Learning thresholds.
        search: Look for a standing pose when ``standing`` is None (False: the caller looked).

    Returns:
        (calibration or None, the standing pose used or None, what is missing: '' when done).
    """
    t = np.asarray(time_s, dtype=np.float64)
    ups = np.asarray(ups, dtype=np.float64)
    need_stand = any(p is None for p in proximal)
    if search and standing is None and (need_stand or gyro_dps is not None):  # configured axes: for the bias only
        standing = find_standing(t, ups, gyro_dps, acc_g, still_s=still_s, params=params)
    if standing is None and need_stand:
        return None, None, f"stand still for {still_s:g} s"
    prox = [p if p is not None else standing.proximal[i] for i, p in enumerate(proximal)]  # type: ignore[union-attr]
    bias = standing.gyro_bias_dps if standing is not None else ((0.0, 0.0, 0.0),) * N_CHANNELS
    tags = ["configured" if (lateral[i] is not None and proximal[i] is not None) else "learnt" for i in range(N_CHANNELS)]
    if all(a is not None for a in lateral):
        return ImuCalibration(tuple(SegmentMount(lateral[i], prox[i], standing_deg[i], bias[i], tags[i])  # type: ignore[arg-type]
                                    for i in range(N_CHANNELS))), standing, ""
    begin = standing.stop if need_stand and standing is not None else 0  # else the pose gave only the bias
    walk = slice(begin, None)
    if len(t) <= begin or t[-1] - t[begin] < WALK_S:  # stream after the standing pose before learning axes
        return None, standing, f"walk {WALK_S:g} s"
    cands: dict[int, list[SegmentMount]] = {}
    for i in range(N_CHANNELS):
        if lateral[i] is not None:
            cands[i] = [SegmentMount(lateral[i], prox[i], standing_deg[i], bias[i], tags[i])]  # type: ignore[arg-type]
            continue
        both, why = _sagittal_swing(t[walk], ups[i, walk], prox[i], standing_deg[i], bias[i],
                                    None if gyro_dps is None else gyro_dps[i, walk], params)
        if both is None:
            return None, standing, f"{CHANNELS[i]}: {why}; walk a few more strides"
        cands[i] = both
    mounts: dict[int, SegmentMount] = {}
    for thigh, shank in LEGS:
        chosen, why = _leg_signs(cands, ups[:, walk], thigh, shank, params.min_sign_margin_deg)
        if why:
            return None, standing, why
        mounts.update(chosen)
    return ImuCalibration(tuple(mounts[i] for i in range(N_CHANNELS))), standing, ""  # type: ignore[arg-type]


@dataclass(frozen=True)
class CalibrationCheck:
    """What ``check_calibration`` found on a stretch of walking.

    Attributes:
        axis_change_deg: Per segment (CHANNELS order), the angle (deg) between the calibration's
            lateral axis and the one learnt on the stretch (180 = opposite sign; NaN when the
            knee rule could not sign the axes learnt there, and the knee alone decided).
        knee_extension_deg: Per leg (right, left), the knee's 98th percentile (deg, + = extended
            past straight) with the calibration.
        problems: What does not fit, one phrase each; empty when the calibration fits.
    """

    axis_change_deg: tuple[float, ...]
    knee_extension_deg: tuple[float, float]
    problems: tuple[str, ...]

    @property
    def fits(self) -> bool:
        return not self.problems

    def summary(self) -> str:
        """One line: the problems, or how close the calibration fits."""
        if self.problems:
            return "; ".join(self.problems)
        knee = max(self.knee_extension_deg)
        return (f"lateral axes within {max(self.axis_change_deg):.0f} deg of the swing, "
                + (f"knee at most {knee:.0f} deg past straight" if round(knee) > 0 else "knee not past straight"))


def check_calibration(time_s: np.ndarray, ups: np.ndarray, cal: ImuCalibration, gyro_dps: np.ndarray | None = None,
                      params: ImuLearnParams = DEFAULT_LEARN) -> tuple[CalibrationCheck | None, str]:
    """Check ``cal`` on a stretch of stream (module docstring): (the check, '') or (None, what
    is missing: a stretch shorter than ``WALK_S``, or too little swing for the learner's
    thresholds). Arrays as ``learn_calibration``'s."""
    t = np.asarray(time_s, dtype=np.float64)
    ups = np.asarray(ups, dtype=np.float64)
    mounts = cal.mounts
    angles = [m.angles_deg(ups[i]) for i, m in enumerate(mounts)]
    knee = [_knee_extension(angles[thigh], angles[shank]) for thigh, shank in LEGS]
    bent = [f"{leg} knee {k:.0f} deg past straight" for leg, k in zip(("right", "left"), knee, strict=True)
            if math.isfinite(k) and round(k) > params.max_knee_extension_deg]  # rounded as printed
    fresh, _, missing = learn_calibration(
        t, ups, proximal=[m.proximal for m in mounts], standing_deg=[m.standing_deg for m in mounts],
        gyro_dps=gyro_dps, params=params, search=False)  # the axes only: no bias wanted
    upright = []
    for i, a in enumerate(angles):
        a = a[np.isfinite(a)]
        if len(a) and abs(float(np.median(a))) > params.max_segment_angle_deg:
            upright.append(f"{CHANNELS[i]}: {float(np.median(a)):+.0f} deg from vertical (median)")
    if fresh is None:
        if bent and _walking_in_its_planes(t, ups, mounts, gyro_dps, params):  # the knee rule could not sign axes
            return CalibrationCheck((math.nan,) * N_CHANNELS, (knee[0], knee[1]), tuple(bent + upright)), ""
        return None, missing
    change = tuple(float(np.degrees(np.arccos(np.clip(np.dot(f.lateral, m.lateral), -1.0, 1.0))))
                   for f, m in zip(fresh.mounts, mounts, strict=True))
    problems = [f"{CHANNELS[i]}: lateral axis {d:.0f} deg from the swing axis" for i, d in enumerate(change)
                if round(d) > params.max_axis_change_deg]
    return CalibrationCheck(change, (knee[0], knee[1]), tuple(problems + bent + upright)), ""


def _walking_in_its_planes(time_s: np.ndarray, ups: np.ndarray, mounts: Sequence[SegmentMount],
                           gyro_dps: np.ndarray | None, params: ImuLearnParams) -> bool:
    """A stretch of walking (``WALK_S`` or more) in which every sensor swings about the line of
    its mount's lateral axis (within ``max_axis_change_deg``, either sign): worn as calibrated
    but for the signs, which the knee rule could not decide (a sensor upside down); not sensors
    carried about."""
    if len(time_s) < 2 or time_s[-1] - time_s[0] < WALK_S:
        return False
    cos_max = math.cos(math.radians(params.max_axis_change_deg))
    for i, m in enumerate(mounts):
        both, _ = _sagittal_swing(time_s, ups[i], m.proximal, m.standing_deg, m.gyro_bias_dps,
                                  None if gyro_dps is None else gyro_dps[i], params)
        if both is None or abs(float(np.dot(both[0].lateral, m.lateral))) < cos_max:
            return False
    return True


def check_configured(lateral: Sequence[str], proximal: Sequence[str]) -> tuple[list[Vec3 | None], list[Vec3 | None]]:
    """Parse configured axis names per segment ('' = learn); CalibrationError names the segment."""
    from .imu import parse_axis

    if len(lateral) != N_CHANNELS or len(proximal) != N_CHANNELS:
        raise CalibrationError(f"IMU axes: need {N_CHANNELS} entries each ({', '.join(CHANNELS)}), '' = learn")
    lat = [parse_axis(a, f"{c} lateral axis") if a.strip() else None for a, c in zip(lateral, CHANNELS, strict=False)]
    prox = [parse_axis(a, f"{c} proximal axis") if a.strip() else None for a, c in zip(proximal, CHANNELS, strict=False)]
    for c, a, p in zip(CHANNELS, lat, prox, strict=False):
        if a is not None and p is not None and abs(float(np.dot(a, p))) > 0.5:
            raise CalibrationError(f"{c}: lateral and proximal axes must differ")
    return lat, prox
