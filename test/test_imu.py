"""IMU -> segment angles (core/imu.py, core/imu_learn.py, core/imu_pairing.py, io/imu_bag.py) on
synthetic IMU streams made from known segment angles (test/imu_synth.py)."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import re
import subprocess
import sys
from functools import partial

import numpy as np
import pytest
from fusion_reference import RawFusion
from imu_synth import ALONG_SEGMENT, gait_angles, random_mounts, synthesize, turned
from scipy.spatial.transform import Rotation

from gait_estimator.analysis.evaluate import read_predictions_csv
from gait_estimator.core.ahrs import CompiledFusion, fuse_raw, fuse_raw_backwards
from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.errors import RecordingError
from gait_estimator.core.imu import (
    DEFAULT_FUSION,
    FUSION_BY_CHANNEL,
    MAX_STEP_S,
    SHANK_FUSION,
    THIGH_FUSION,
    CalibrationError,
    FusionParams,
    ImuCalibration,
    SegmentMount,
    parse_axis,
    up_from_quaternion,
    ups_from_quaternions,
)
from gait_estimator.core.imu_angles import ImuAngles
from gait_estimator.core.imu_calibrator import ImuCalibrator
from gait_estimator.core.imu_learn import (
    ImuLearnParams,
    check_calibration,
    check_configured,
    find_standing,
    learn_calibration,
    quiet_runs,
)
from gait_estimator.core.imu_pairing import WRONG_FRAME, ZERO_NORM, ImuPairer, SensorInput, auto_tolerance_s
from gait_estimator.core.rejections import NON_FINITE, NON_INCREASING_STAMP, OUT_OF_RANGE, SampleRejected
from gait_estimator.io.imu_bag import ImuBagRecording, read_imu_bag, write_imu_bag
from gait_estimator.io.imu_stream import load_calibration, save_calibration
from gait_estimator.io.read_options import ReadOptions
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import read_project_csv

RATE = 200.0
BASE_NS = 1_700_000_000 * 1_000_000_000
G = 9.80665


def rms(a: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.square(a), axis=0))


@pytest.fixture(scope="module")
def angles() -> np.ndarray:
    return gait_angles(RATE, walk_s=18.0)


def _ups(s) -> np.ndarray:
    return np.stack([ups_from_quaternions(s.quat_xyzw[c]) for c in range(4)])


@pytest.mark.parametrize("seed", range(6))
def test_orientation_input_any_mounting_learnt_within_half_degree(angles, seed):
    rng = np.random.default_rng(seed)
    s = synthesize(angles, RATE, random_mounts(rng), rng)
    ups = _ups(s)
    cal, standing, missing = learn_calibration(s.time_s, ups)
    assert missing == "" and standing is not None and standing.start == 0
    got = np.stack([cal.mounts[c].angles_deg(ups[c]) for c in range(4)], axis=1)
    assert (rms(got - s.angles_deg) < 0.5).all(), rms(got - s.angles_deg)
    # the scalar path (the node's) gives the same angles as the vectorised one
    k = len(s.time_s) // 2
    assert np.allclose(cal.angles_deg([tuple(ups[c, k]) for c in range(4)]), got[k], atol=1e-9)


def test_orientation_input_with_noisy_quaternions_and_standing_angle(angles):
    """Orientation noise of 0.3 deg and a known standing pose of +5/-6 deg."""
    rng = np.random.default_rng(11)
    stand = np.array([5.0, 4.0, -6.0, -7.0])
    truth = angles + stand
    s = synthesize(truth, RATE, random_mounts(rng), rng)
    noise = Rotation.from_rotvec(rng.normal(0, math.radians(0.3), (4 * len(truth), 3)))
    q = (Rotation.from_quat(s.quat_xyzw.reshape(-1, 4)) * noise).as_quat().reshape(s.quat_xyzw.shape)
    ups = np.stack([ups_from_quaternions(q[c]) for c in range(4)])
    cal, _, missing = learn_calibration(s.time_s, ups, standing_deg=stand)
    assert missing == ""
    got = np.stack([cal.mounts[c].angles_deg(ups[c]) for c in range(4)], axis=1)
    assert (rms(got - truth) < 0.5).all(), rms(got - truth)


def test_configured_axes_need_no_learning(angles):
    """Sensors mounted along the segment axes: configured '+z'/'-x' style axes give the angles
    with no standing pose or strides at all."""
    rng = np.random.default_rng(3)
    s = synthesize(angles[400:], RATE, [ALONG_SEGMENT] * 4, rng, stand_s=0.0)
    lateral, proximal = check_configured(["+z"] * 4, ["-x"] * 4)
    cal, standing, missing = learn_calibration(s.time_s, _ups(s), lateral=lateral, proximal=proximal)
    assert missing == "" and standing is None
    assert all(m.source == "configured" for m in cal.mounts)
    got = np.stack([cal.mounts[c].angles_deg(_ups(s)[c]) for c in range(4)], axis=1)
    assert np.abs(got - s.angles_deg).max() < 1e-9


def test_raw_input_within_one_degree_after_ten_seconds(angles):
    """Gyro + accelerometer only (noise, 2 deg/s gyro bias, arbitrary mounts): imufusion with the
    bias measured while standing."""
    for seed in range(3):
        rng = np.random.default_rng(100 + seed)
        s = synthesize(angles, RATE, random_mounts(rng), rng, acc_noise_g=0.02, gyro_noise_dps=0.5, gyro_bias_dps=2.0)
        first = np.stack([fuse_raw(s.time_s, s.gyro_dps[c], s.acc_g[c], params=FUSION_BY_CHANNEL[c]) for c in range(4)])
        _, standing, _ = learn_calibration(s.time_s, first, gyro_dps=s.gyro_dps, acc_g=s.acc_g)
        assert standing is not None
        assert standing.ended and 1.9 * RATE <= standing.still_until <= 2.7 * RATE, "the whole 2 s standing"
        truth = s.gyro_dps[:, :round(2.0 * RATE)].mean(axis=1)  # standing: no rotation, the bias and noise
        assert np.abs(np.array(standing.gyro_bias_dps) - truth).max() < 0.1
        ups = np.stack([fuse_raw(s.time_s, s.gyro_dps[c], s.acc_g[c], standing.gyro_bias_dps[c], FUSION_BY_CHANNEL[c])
                        for c in range(4)])
        cal, _, missing = learn_calibration(s.time_s, ups, gyro_dps=s.gyro_dps, acc_g=s.acc_g)
        assert missing == ""
        got = np.stack([cal.mounts[c].angles_deg(ups[c]) for c in range(4)], axis=1)
        late = s.time_s >= 10.0
        assert (rms((got - s.angles_deg)[late]) < 1.0).all(), rms((got - s.angles_deg)[late])


def test_live_raw_input_measures_its_rate_as_bag_reading_does(angles):
    """The node's SensorInput(None) takes the raw sensor's rate from its first stamps (offline
    reading measures it over the bag): a 100 Hz stream is fused at 100 Hz, not at the 200 Hz guess."""
    rng = np.random.default_rng(7)
    s = synthesize(angles, 100.0, random_mounts(rng), rng, acc_noise_g=0.02, gyro_noise_dps=0.5)
    live, known, guess = SensorInput(None), SensorInput(100.0), SensorInput(200.0)
    ups = {id(x): [] for x in (live, known, guess)}
    for k in range(min(s.time_s.size, 1000)):
        ns = round(float(s.time_s[k]) * 1e9) + int(rng.integers(-200_000, 200_000))  # 0.2 ms jitter
        gyro, acc = np.radians(s.gyro_dps[0][k]), s.acc_g[0][k] * G
        for x in (live, known, guess):
            ups[id(x)].append(x.convert(ns, (0.0, 0.0, 0.0, 1.0), -1.0, gyro, acc)[0])
    assert live._rate_hz == pytest.approx(100.0, rel=0.01) and live.fusion.rate_hz == pytest.approx(100.0, rel=0.01)
    late = slice(300, None)
    live_err = np.abs(np.array(ups[id(live)]) - np.array(ups[id(known)]))[late].max()
    guess_err = np.abs(np.array(ups[id(guess)]) - np.array(ups[id(known)]))[late].max()
    assert live_err < 1e-6 <= guess_err
    for k in range(40):  # the driver restarted at 50 Hz: measured again (the first message back is taken as stray)
        with contextlib.suppress(SampleRejected):
            live.convert(round((1.0 + k * 0.02) * 1e9), (0.0, 0.0, 0.0, 1.0), -1.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))
    assert live.restarts == 1 and live.fusion.rate_hz == pytest.approx(50.0, rel=1e-6)


@pytest.mark.parametrize("fusion", ["imufusion", "compiled"])
def test_raw_fusion_integrates_each_step_more_than_a_microsecond_off_its_period(fusion):
    """Drivers stamp with microsecond jitter: a 5.001 ms step at 200 Hz is integrated over 5.001 ms,
    a step within 1 us of the period in use over that period."""
    cls = RawFusion if fusion == "imufusion" else CompiledFusion

    def up_after(step_s: float) -> list[float]:
        f = cls(200.0, params=FusionParams(gain=0.0, still_gain=0.0))  # the gyro alone
        f.update((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        return list(f.update((500.0, 0.0, 0.0), (0.0, 0.0, 1.0), step_s))

    assert up_after(0.005001) != up_after(0.005)
    assert up_after(0.0050009) == up_after(0.005)


@pytest.mark.parametrize("fusion", ["imufusion", "compiled"])
def test_raw_fusion_integrates_at_most_max_step_across_a_gap(fusion):
    """Messages lost for 2 s: the rate of the message after the gap is integrated over MAX_STEP_S,
    not over the whole gap (which would turn the sensor by 400 deg at 200 deg/s)."""
    cls = RawFusion if fusion == "imufusion" else CompiledFusion

    def turned_deg(step_s: float, rate_hz: float = 200.0, dps: float = 200.0) -> float:
        f = cls(rate_hz, params=FusionParams(gain=0.0, still_gain=0.0))  # the gyro alone
        f.update((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        up = f.update((dps, 0.0, 0.0), (0.0, 0.0, 1.0), step_s)
        return math.degrees(math.atan2(math.hypot(up[0], up[1]), up[2]))

    assert turned_deg(0.05) == pytest.approx(10.0, rel=0.01)
    assert turned_deg(2.0) == turned_deg(MAX_STEP_S) == pytest.approx(200.0 * MAX_STEP_S, rel=0.01)
    # a sensor slower than 20 Hz: its whole period is integrated, a gap two of them
    assert turned_deg(0.125, 8.0, 40.0) == pytest.approx(5.0, rel=0.01)
    assert turned_deg(2.0, 8.0, 40.0) == pytest.approx(10.0, rel=0.01)


def test_compiled_fusion_is_imufusions_filter_to_rounding():
    """CompiledFusion (core/ahrs.py) against imufusion's AHRS through RawFusion: every gain tier,
    acceleration rejection and its recovery, a gyroscope overrange (soft restart, startup ramp), a
    new rate and jittered steps give the same gravity direction to 1e-5 (single vs double
    precision)."""
    rng = np.random.default_rng(11)
    n = 3000
    gyro = rng.normal(0.0, 80.0, (n, 3))
    gyro[:400] *= 0.05  # still, then turning slowly, then moving
    gyro[400:800] *= 0.4
    gyro[1500:1503, 1] = 2500.0  # beyond 98 % of the 2000 deg/s range
    tilted = np.array([0.3, 0.1, 0.95])
    acc = tilted + rng.normal(0.0, 0.2, (n, 3))
    acc[:800] = tilted / np.linalg.norm(tilted) + rng.normal(0.0, 0.005, (800, 3))
    for k0 in range(2000, 2600, 50):  # calm 25 samples (every tier), the accelerometer 8-15 deg off, then moving
        gyro[k0:k0 + 25] *= 0.02
        off = Rotation.from_rotvec(rng.normal(size=(25, 3)) * np.radians(rng.uniform(8.0, 15.0, (25, 1))) / np.sqrt(3))
        acc[k0:k0 + 25] = off.apply(tilted / np.linalg.norm(tilted))
    steps = 0.005 * (1.0 + 0.01 * np.sin(np.arange(n)))
    rejecting = [FusionParams(acceleration_rejection_deg=5.0, rejection_timeout_s=s, quasi_gain=2.0) for s in (0.2, 0.29)]
    for params in (DEFAULT_FUSION, THIGH_FUSION, SHANK_FUSION, *rejecting):
        ref, ours = RawFusion(200.0, (1.0, -2.0, 0.5), params), CompiledFusion(200.0, (1.0, -2.0, 0.5), params)
        worst, tiers = 0.0, set()
        for k in range(n):
            if k == 1000:
                ref.set_rate(190.0)
                ours.set_rate(190.0)
            dt = None if k == 0 else float(steps[k])
            a, b = ref.update(gyro[k], acc[k], dt), ours.update(gyro[k], acc[k], dt)
            worst = max(worst, float(np.abs(np.subtract(a, b)).max()))
            tiers.add(ref.tier)
        assert worst < 1e-5, (params, worst)
        assert tiers == ({0, 2} if params.quasi_gain is None else {0, 1, 2})


def test_raw_input_without_numba_or_imufusion_runs_the_same_filter_uncompiled(tmp_path):
    """Without numba (``GAIT_ESTIMATOR_NO_NUMBA``) and imufusion the raw-input fusion is
    ``CompiledFusion``'s step as plain Python: the same up directions as compiled, to 1e-12."""
    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.004, 0.006, 600))
    gyro, acc = rng.normal(0.0, 60.0, (600, 3)), np.array([0.1, -0.2, 1.0]) + rng.normal(0.0, 0.1, (600, 3))
    np.savez(tmp_path / "in.npz", t=t, gyro=gyro, acc=acc)
    code = ("import sys; sys.modules['imufusion'] = None; import numpy as np\n"
            "from gait_estimator.core import ahrs; from gait_estimator.core.imu import SHANK_FUSION\n"
            "d = np.load(sys.argv[1]); ups = ahrs.fuse_raw(d['t'], d['gyro'], d['acc'], (1.0, -2.0, 0.5), SHANK_FUSION)\n"
            "print(ahrs.AVAILABLE, type(ahrs.make_fusion()).__name__); np.save(sys.argv[2], ups)\n")
    env = {**os.environ, "GAIT_ESTIMATOR_NO_NUMBA": "1"}
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path / "in.npz"), str(tmp_path / "ups.npy")],
                       capture_output=True, text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["False", "CompiledFusion"]
    compiled_ups = fuse_raw(t, gyro, acc, (1.0, -2.0, 0.5), SHANK_FUSION)
    assert np.abs(np.load(tmp_path / "ups.npy") - compiled_ups).max() < 1e-12


def test_learning_and_fusion_take_their_thresholds_as_parameters(angles):
    """The thresholds are passed in (ImuLearnParams, FusionParams), not read from module globals."""
    rng = np.random.default_rng(5)
    s = synthesize(angles, RATE, random_mounts(rng), rng)
    ups = _ups(s)
    assert learn_calibration(s.time_s, ups, params=ImuLearnParams())[2] == ""
    cal, _, missing = learn_calibration(s.time_s, ups, params=ImuLearnParams(min_swing_deg=500.0))
    assert cal is None and "swings only" in missing
    cal, _, missing = learn_calibration(s.time_s, ups, params=ImuLearnParams(min_sign_margin_deg=1e4))
    assert cal is None and "knee rule margin" in missing and "< 10000 deg" in missing
    k = slice(0, 1000)
    base = fuse_raw(s.time_s[k], s.gyro_dps[0, k], s.acc_g[0, k])
    assert np.array_equal(base, fuse_raw(s.time_s[k], s.gyro_dps[0, k], s.acc_g[0, k], params=FusionParams()))
    other = fuse_raw(s.time_s[k], s.gyro_dps[0, k], s.acc_g[0, k], params=FusionParams(gain=0.05, still_gain=0.05))
    assert not np.array_equal(base, other)
    same = FusionParams(quasi_gain=FusionParams().gain)  # the slow-turning tier at the moving gain: no change
    assert np.array_equal(base, fuse_raw(s.time_s[k], s.gyro_dps[0, k], s.acc_g[0, k], params=same))
    quasi = fuse_raw(s.time_s[k], s.gyro_dps[0, k], s.acc_g[0, k], params=FusionParams(quasi_gain=3.0))
    assert not np.array_equal(base, quasi)


def test_thighs_and_shanks_fuse_with_their_own_settings_in_the_node_and_offline():
    """FUSION_BY_CHANNEL: thighs THIGH_FUSION, shanks SHANK_FUSION, in read_imu_bag as in the node."""
    assert FUSION_BY_CHANNEL == (THIGH_FUSION, THIGH_FUSION, SHANK_FUSION, SHANK_FUSION)
    assert SHANK_FUSION.quasi_gain is not None and SHANK_FUSION.gain < THIGH_FUSION.gain < DEFAULT_FUSION.gain
    assert ReadOptions().fusion_params is FUSION_BY_CHANNEL  # read_imu_bag's default
    # the node's inputs: test_node_imu.py::test_configured_axes_need_no_calibration_file


def test_learning_says_what_is_missing(angles):
    rng = np.random.default_rng(5)
    s = synthesize(angles, RATE, random_mounts(rng), rng)
    ups = _ups(s)
    walking = slice(500, None)  # no standing pose in the stream
    cal, standing, missing = learn_calibration(s.time_s[walking], ups[:, walking])
    assert cal is None and standing is None and missing.startswith("stand still")
    early = s.time_s < 3.0  # standing, then only one second of walking
    cal, standing, missing = learn_calibration(s.time_s[early], ups[:, early])
    assert cal is None and standing is not None and missing.startswith("walk")


def test_live_calibrator_learns_from_the_stream(angles):
    rng = np.random.default_rng(6)
    s = synthesize(angles, RATE, random_mounts(rng), rng)
    ups = _ups(s)
    cal_offline, _, _ = learn_calibration(s.time_s, ups)
    calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4)
    learnt_at = None
    nan3 = (math.nan,) * 3
    for k, t in enumerate(s.time_s):
        got = calib.add(float(t), [tuple(ups[c, k]) for c in range(4)], [tuple(s.gyro_dps[c, k]) for c in range(4)], [nan3] * 4)
        if got is not None:
            learnt_at = t
            break
    assert learnt_at is not None and learnt_at < 2.0 + 1.0 + 4.0 + 0.6
    for m_live, m_off in zip(calib.calibration.mounts, cal_offline.mounts, strict=False):
        assert np.allclose(m_live.proximal, m_off.proximal, atol=1e-6)
        assert np.dot(m_live.lateral, m_off.lateral) > math.cos(math.radians(2.0))
    calib.reset()
    assert calib.calibration is None
    # a stream restarted mid-learning (stamps jump back): learning starts again on the new stamps
    again = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4)
    rows = [([tuple(ups[c, k]) for c in range(4)], [tuple(s.gyro_dps[c, k]) for c in range(4)]) for k in range(len(s.time_s))]
    for k in range(700):  # 3.5 s: standing and the first steps, stamps from 50 s
        assert again.add(50.0 + float(s.time_s[k]), *rows[k], [nan3] * 4) is None
    relearnt = next((float(t) for k, t in enumerate(s.time_s) if again.add(10.0 + float(t), *rows[k], [nan3] * 4)), None)
    assert relearnt is not None and relearnt == learnt_at


def test_recheck_forgets_the_stream_before_a_gap(angles):
    """After a gap (sensors perhaps re-donned): a calibration in use, or one being checked, is
    checked on a whole window of walking after the gap, its gyro biases from the standing pose
    after it; one being learnt (also after ~/calibrate_standing) starts again from the standing
    pose after the gap."""
    rng = np.random.default_rng(23)
    mounts = random_mounts(rng)
    before = synthesize(angles, RATE, mounts, rng, gyro_bias_dps=2.0)
    after = synthesize(angles, RATE, mounts, rng, gyro_bias_dps=2.0)  # other biases

    def rows(s):
        ups = _ups(s)
        return [([tuple(ups[c, k]) for c in range(4)], [tuple(s.gyro_dps[c, k]) for c in range(4)],
                 [tuple(s.acc_g[c, k]) for c in range(4)]) for k in range(len(s.time_s))]

    rows_before, rows_after = rows(before), rows(after)
    bias_after = after.gyro_dps[:, :300].mean(axis=1)  # standing: the rates are the biases
    cal, _, _ = learn_calibration(before.time_s, _ups(before))
    gap_s = 1.5 + 6.0  # after 1.5 s of stream, 6 s without: shorter than the 8 s window
    for checking in (False, True):
        calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, cal, check=checking)
        for k in range(300 if checking else 0):  # being checked: 1.5 s of standing before the gap
            assert calib.check(float(before.time_s[k]), *rows_before[k]) is None
        calib.recheck()
        assert calib.checking and not calib.bias_measured and calib.status == "calibrated, to be checked on the walking"
        verdict = None
        for k in range(len(after.time_s)):  # the stream again after the gap: stand, walk
            verdict = calib.check(gap_s + float(after.time_s[k]), *rows_after[k])
            if verdict is not None:
                break
        assert verdict is not None and verdict.fits and after.time_s[k] >= 8.0, "a whole window after the gap"
        assert np.abs(np.array(calib.calibration.mounts[0].gyro_bias_dps) - bias_after[0]).max() < 0.1
    learner = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4)
    for k in range(500):  # the standing pose and the first steps, then a gap
        assert learner.add(float(before.time_s[k]), *rows_before[k]) is None
    assert learner.standing_s is not None
    learner.recheck()
    walk = int(np.searchsorted(after.time_s, 3.0))  # after the gap: walking only
    assert all(learner.add(gap_s + float(after.time_s[k]), *rows_after[k]) is None for k in range(walk, len(after.time_s)))
    assert learner.calibration is None and learner.status.startswith("stand still")
    # ~/calibrate_standing keeps the learnt lateral axes (a standing pose is enough), a gap forgets them
    for gap in (False, True):
        asked = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, cal)
        asked.request_standing()
        if gap:
            asked.recheck()
        got = next((float(t) for t, r in zip(after.time_s, rows_after, strict=True) if asked.add(float(t), *r)), None)
        assert got is not None and (got >= 5.0 if gap else got < 3.0), got  # 1 s standing pose + 4 s walking


def test_a_calibration_made_earlier_is_checked_on_the_walking(angles):
    rng = np.random.default_rng(9)
    s = synthesize(angles, RATE, random_mounts(rng), rng)
    ups = _ups(s)
    cal, _, _ = learn_calibration(s.time_s, ups)
    window = (s.time_s >= 6.0) & (s.time_s < 14.0)  # walking only: no standing pose needed
    t, u, g = s.time_s[window], ups[:, window], s.gyro_dps[:, window]
    found, missing = check_calibration(t, u, cal, g)
    assert missing == "" and found.fits, found
    assert max(found.axis_change_deg) < 3.0 and max(found.knee_extension_deg) < 10.0
    assert found.summary().startswith("lateral axes within")
    for channel, deg in ((2, 45.0), (1, 90.0), (0, 180.0)):  # a sensor turned about the segment, a wrong sign
        found, _ = check_calibration(t, u, turned(cal, channel, deg), g)
        assert not found.fits and found.problems[0].startswith(CHANNELS[channel] + ": lateral axis")
        assert abs(found.axis_change_deg[channel] - deg) < 3.0
    # a sensor tilted in the sagittal plane: no other axis, but a right shank 45 deg ahead overextends the knee
    mounts = list(cal.mounts)
    mounts[2] = dataclasses.replace(mounts[2], standing_deg=45.0)
    found, _ = check_calibration(t, u, ImuCalibration(tuple(mounts)), g)
    assert found.problems == (f"right knee {found.knee_extension_deg[0]:.0f} deg past straight",)
    # without rates (orientation-only drivers, some filling them with zeros) the axis comes from the
    # up directions' rotation
    for no_rates in (None, np.zeros_like(g)):
        found, _ = check_calibration(t, u, turned(cal, 3, 90.0), no_rates)
        assert not found.fits and abs(found.axis_change_deg[3] - 90.0) < 5.0
    # nothing to check on yet: too short, or standing only
    found, missing = check_calibration(s.time_s[:300], ups[:, :300], cal, s.gyro_dps[:, :300])
    assert found is None and missing == "walk 4 s"
    still = synthesize(np.zeros((1600, 4)), RATE, s.mounts, rng)
    found, missing = check_calibration(still.time_s, _ups(still), cal, still.gyro_dps)
    assert found is None and missing.endswith("walk a few more strides")
    # a sensor upside down (its long axis reversed): the knee rule cannot sign the axes learnt with it,
    # so the walking's knee decides; standing (or sensors lying about, before they are put on) decides nothing
    mounts = list(cal.mounts)
    mounts[3] = dataclasses.replace(mounts[3], proximal=tuple(-x for x in mounts[3].proximal))
    flipped = ImuCalibration(tuple(mounts))
    found, missing = check_calibration(t, u, flipped, g)
    assert found is not None and missing == ""
    assert found.problems[0] == f"left knee {found.knee_extension_deg[1]:.0f} deg past straight"
    assert re.fullmatch(r"left_shank: [+-]1[3-8]\d deg from vertical \(median\)", found.problems[1]), found.problems
    assert found.knee_extension_deg[1] > 150.0 and found.knee_extension_deg[0] < 10.0
    assert np.isnan(found.axis_change_deg).all()
    # both right sensors upside down (turned about their forward axes): the knee can look plausible
    both = list(cal.mounts)
    for c in (0, 2):
        both[c] = dataclasses.replace(both[c], proximal=tuple(-x for x in both[c].proximal),
                                      lateral=tuple(-x for x in both[c].lateral))
    found, _ = check_calibration(t, u, ImuCalibration(tuple(both)), g)
    assert {"right_thigh", "right_shank"} <= {p.split(":")[0] for p in found.problems if "from vertical" in p}
    for lean in (-3.0, 0.0, 3.0):
        leaning = synthesize(np.full((1600, 4), lean), RATE, s.mounts, rng)
        assert check_calibration(leaning.time_s, _ups(leaning), flipped, leaning.gyro_dps)[0] is None
    lying = synthesize(np.zeros((1600, 4)), RATE, random_mounts(rng), rng)  # the right calibration, sensors elsewhere
    assert check_calibration(lying.time_s, _ups(lying), cal, lying.gyro_dps)[0] is None
    assert check_calibration(t[:0], u[:, :0], cal, g[:, :0]) == (None, "walk 4 s")
    assert check_calibration(t, np.full_like(u, np.nan), cal, g)[0] is None


def test_configured_proximal_axes_need_no_standing_before_the_strides(angles):
    """Proximal axes configured: a standing pose gives only the gyro bias, so the strides before it
    count (a stream whose only standing pose is at its end still learns)."""
    rng = np.random.default_rng(12)
    s = synthesize(angles[::-1], RATE, [ALONG_SEGMENT] * 4, rng, gyro_bias_dps=1.0, turn_dps=0.0, stand_s=0.0)
    cal, standing, missing = learn_calibration(s.time_s, _ups(s), proximal=[(-1.0, 0.0, 0.0)] * 4,
                                               gyro_dps=s.gyro_dps, acc_g=s.acc_g)
    assert missing == "" and standing is not None and standing.start > len(s.time_s) // 2
    assert [m.gyro_bias_dps for m in cal.mounts] == list(standing.gyro_bias_dps)


def test_live_learning_waits_for_the_end_of_the_standing_for_the_gyro_bias(angles):
    """Lateral axes configured, so the standing pose completes the calibration: with raw sensors it
    is complete when the wearer moves, its gyro biases averaged over the whole standing."""
    rng = np.random.default_rng(13)
    s = synthesize(angles, RATE, [ALONG_SEGMENT] * 4, rng, acc_noise_g=0.01, gyro_noise_dps=0.3, gyro_bias_dps=2.0)
    calib = ImuCalibrator([(0.0, 0.0, 1.0)] * 4, [None] * 4, [0.0] * 4)
    ups = _ups(s)
    done = None
    for k, t in enumerate(s.time_s):
        done = calib.add(float(t), [tuple(ups[c, k]) for c in range(4)], [tuple(s.gyro_dps[c, k]) for c in range(4)],
                         [tuple(s.acc_g[c, k]) for c in range(4)])
        if done is not None:
            break
        if 1.5 < t < 2.0:
            assert calib.status == "standing: the gyro bias is measured until you move"
    assert done is not None and 2.0 <= t < 3.0, t
    truth = s.gyro_dps[:, :round(2.0 * RATE)].mean(axis=1)
    assert np.abs(np.array([m.gyro_bias_dps for m in done.mounts]) - truth).max() < 0.05
    assert calib.gyro_biases == tuple(m.gyro_bias_dps for m in done.mounts)


def test_live_learning_gives_the_gyro_biases_when_the_standing_ends_before_the_strides(angles):
    """Raw sensors, axes learnt: the standing pose's gyro biases are the calibrator's (the node
    fuses with them from then on) once the wearer moves, not only when the strides complete the
    calibration seconds later; the calibration carries the same."""
    rng = np.random.default_rng(15)
    s = synthesize(angles, RATE, random_mounts(rng), rng, acc_noise_g=0.01, gyro_noise_dps=0.3, gyro_bias_dps=2.0)
    calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4)
    ups = _ups(s)
    biases_at = done = None
    for k, t in enumerate(s.time_s):
        done = calib.add(float(t), [tuple(ups[c, k]) for c in range(4)], [tuple(s.gyro_dps[c, k]) for c in range(4)],
                         [tuple(s.acc_g[c, k]) for c in range(4)])
        if biases_at is None and calib.gyro_biases is not None:
            biases_at, biases = float(t), calib.gyro_biases
        if done is not None:
            break
    assert done is not None and biases_at is not None and 2.0 <= biases_at < 3.0 and float(t) >= biases_at + 2.5
    truth = s.gyro_dps[:, :round(2.0 * RATE)].mean(axis=1)
    assert np.abs(np.array(biases) - truth).max() < 0.05
    assert calib.gyro_biases is biases and tuple(m.gyro_bias_dps for m in done.mounts) == biases


def _record_applied(events: list, inputs: list, biases: object) -> None:
    events.append(("biases", biases, [i.gyro_bias_dps for i in inputs]))


def _record_emitted(emitted: list, k: int, calibrator: ImuCalibrator, items: list, events: list,
                    angles: tuple, stamp_ns: int) -> None:
    emitted.append((k, stamp_ns, angles, calibrator.calibration.angles_deg([i[0] for i in items]), len(events)))


def _check_after_emit(check, emitted: list, t: float, *args):
    assert emitted and emitted[-1][1] * 1e-9 == t, "a sample's angles go out before its check attempt"
    return check(t, *args)


def _record(events: list, kind: str, value: object, then=None) -> None:
    events.append((kind, value))
    if then is not None:
        then()


def test_imu_angles_run_the_nodes_flow_from_learning_to_a_checked_calibration(angles):
    """ImuAngles (the node's flow after pairing): no angles while learning; the standing pose's
    gyro biases go to the raw sensors when the wearer moves, before the strides complete the
    calibration; then the calibration's angles. A calibration being checked gives each sample's
    angles before the check attempt on it, to the misfit verdict that makes the hook forget it;
    then nothing until it is learnt again."""
    rng = np.random.default_rng(18)
    s = synthesize(angles, RATE, random_mounts(rng), rng, acc_noise_g=0.01, gyro_noise_dps=0.3, gyro_bias_dps=2.0)
    truth = s.gyro_dps[:, :round(2.0 * RATE)].mean(axis=1)
    learnt = learn_calibration(s.time_s, _ups(s))[0]
    for given in (None, turned(learnt, 2, 60.0)):
        inputs, events = [SensorInput(None, "", fusion) for fusion in FUSION_BY_CHANNEL], []
        calibrator = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, given, check=True)
        flow = ImuAngles(inputs, calibrator, on_gyro_biases=partial(_record_applied, events, inputs),
                         on_learnt=partial(_record, events, "learnt"),
                         on_checked=partial(_record, events, "checked", then=calibrator.reset))
        out = np.full((len(s.time_s), 4), np.nan)
        emitted = []  # (sample, stamp, angles, the calibration's own angles for it when emitted)
        calibrator.check = partial(_check_after_emit, calibrator.check, emitted)
        for k, t in enumerate(s.time_s):
            stamp = BASE_NS + round(t * 1e9)
            items = [inputs[c].convert(stamp, (0.0, 0.0, 0.0, 1.0), -1.0, tuple(np.radians(s.gyro_dps[c, k])),
                                       tuple(s.acc_g[c, k] * G)) for c in range(4)]
            n_events = len(events)
            flow.sample(stamp, items, partial(_record_emitted, emitted, k, calibrator, items, events))
            if emitted and emitted[-1][0] == k:
                out[k] = emitted[-1][2]
                assert emitted[-1][1] == stamp and emitted[-1][2] == emitted[-1][3]
                assert emitted[-1][4] == n_events, "emitted before any hook of its sample"
        assert all(list(e[1]) == e[2] for e in events if e[0] == "biases"), "applied before the hook"
        kinds = [e[0] for e in events]
        assert kinds == (["biases", "learnt"] if given is None else ["biases", "checked"]), kinds
        assert np.abs(np.array(events[0][1]) - truth).max() < 0.1
        put_out = np.flatnonzero(np.isfinite(out[:, 0]))
        if given is None:
            assert put_out[0] > 4.5 * RATE and np.all(np.diff(put_out) == 1), "nothing before the calibration"
            late = s.time_s > 12.0
            assert (rms(out[late] - s.angles_deg[late]) < 1.0).all(), rms(out[late] - s.angles_deg[late])
        else:  # forgotten at the verdict; this stream has no second standing pose to learn from
            assert not events[1][1].fits and put_out[0] == 0 and 8.0 * RATE <= put_out[-1] < 8.6 * RATE
            assert calibrator.calibration is None and calibrator.status == "stand still for 1 s"


def test_quiet_runs_are_where_a_standing_pose_can_be(angles):
    rng = np.random.default_rng(14)
    s = synthesize(angles, RATE, random_mounts(rng), rng, gyro_noise_dps=0.5)
    (start, end), = quiet_runs(s.time_s, s.gyro_dps)  # the 2 s standing, then walking and turning
    assert start == 0 and 2.0 * RATE - 1 <= end < 2.6 * RATE
    walking = slice(end, None)
    assert quiet_runs(s.time_s[walking], s.gyro_dps[:, walking]) == []
    assert find_standing(s.time_s[walking], _ups(s)[:, walking], s.gyro_dps[:, walking]) is None
    no_rates = np.full_like(s.gyro_dps, np.nan)
    assert quiet_runs(s.time_s, no_rates) == [(0, len(s.time_s))], "no rates: quiet, to the last sample"


def test_live_calibrator_looks_for_a_standing_pose_only_after_quiet_gyros(angles, monkeypatch):
    """The bias search runs in the node's callback: on walking alone it never calls the (costly)
    standing-pose search; a standing pose is searched once its quiet stretch has ended."""
    import gait_estimator.core.imu_calibrator as imu_calibrator

    calls = []
    monkeypatch.setattr(imu_calibrator, "find_standing", lambda *a, **k: calls.append(1) or find_standing(*a, **k))
    rng = np.random.default_rng(11)
    mounts = random_mounts(rng)
    nan3 = (math.nan,) * 3
    for stand_s, raw, searches in ((0.0, True, 0), (2.0, True, 1), (2.0, False, 0)):  # no raw sensor: no bias
        s = synthesize(gait_angles(RATE, walk_s=6.0, stand_s=stand_s), RATE, mounts, rng, stand_s=stand_s)
        ups = _ups(s)
        calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, learn_calibration(s.time_s, ups)[0] if stand_s else
                              ImuCalibration(tuple(SegmentMount.from_axes("+z", "-x") for _ in range(4))), check=True)
        calls.clear()
        for k in range(len(s.time_s)):
            calib.check(float(s.time_s[k]), [tuple(ups[c, k]) for c in range(4)],
                        [tuple(s.gyro_dps[c, k]) for c in range(4)],
                        [tuple(s.acc_g[c, k]) for c in range(4)] if raw else [nan3] * 4)
        assert len(calls) == searches and calib.bias_measured == (searches > 0 or not raw), (stand_s, raw, len(calls))


def test_live_calibrator_checks_a_calibration_on_the_first_walking(angles):
    rng = np.random.default_rng(10)
    s = synthesize(angles, RATE, random_mounts(rng), rng, gyro_bias_dps=2.0)  # raw sensors' gyros and accelerations
    ups = _ups(s)
    cal, _, _ = learn_calibration(s.time_s, ups)
    nan3 = (math.nan,) * 3
    for given, fits in ((cal, True), (turned(cal, 2, 60.0), False)):
        calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, given, check=True)
        assert calib.checking and calib.status.startswith("calibrated, to be checked")
        found = None
        for k in range(len(s.time_s)):
            found = calib.check(float(s.time_s[k]), [tuple(ups[c, k]) for c in range(4)],
                                [tuple(s.gyro_dps[c, k]) for c in range(4)], [tuple(s.acc_g[c, k]) for c in range(4)])
            if found is not None:
                break
        assert found is not None and found.fits == fits
        assert 8.0 <= s.time_s[k] < 8.6, "checked on the first window of stream with walking"
        assert not calib.checking and calib.status.endswith(": " + found.summary())
        truth = s.gyro_dps[:, :round(2.0 * RATE)].mean(axis=1)  # standing: no rotation, the bias
        assert calib.bias_measured and np.abs(np.array([m.gyro_bias_dps for m in calib.calibration.mounts])
                                              - truth).max() < 0.05, "the gyro biases of the standing pose"
        assert all(m.lateral == g.lateral and m.proximal == g.proximal
                   for m, g in zip(calib.calibration.mounts, given.mounts, strict=True)), "the axes given"
    assert not ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, cal).checking  # asked for only
    # stamps going back (a restarted stream) while checking: the window starts again on the new stamps
    calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, cal, check=True)
    rows = [([tuple(ups[c, k]) for c in range(4)], [tuple(s.gyro_dps[c, k]) for c in range(4)], [nan3] * 4)
            for k in range(len(s.time_s))]
    assert all(calib.check(50.0 + float(s.time_s[k]), *rows[k]) is None for k in range(1400))
    at = next(float(s.time_s[k]) for k in range(len(s.time_s)) if calib.check(float(s.time_s[k]), *rows[k]))
    assert 8.0 <= at < 8.6
    # a standing pose asked for before the check: the unchecked axes are not kept, strides are needed
    calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4, turned(cal, 2, 60.0), check=True)
    calib.request_standing()
    assert not calib.checking and calib.calibration is None
    assert all(calib.add(100.0 + float(s.time_s[k]), *rows[k]) is None for k in range(800)), "strides needed"
    again = next(c for k in range(800, len(s.time_s)) if (c := calib.add(100.0 + float(s.time_s[k]), *rows[k])))
    assert np.dot(again.mounts[2].lateral, cal.mounts[2].lateral) > math.cos(math.radians(3.0))
    # configured axes are checked whenever they are put in use, also after a reset
    configured = ImuCalibrator([m.lateral for m in cal.mounts], [m.proximal for m in cal.mounts], [0.0] * 4)
    for _ in range(2):
        assert configured.add(0.0, *rows[0]) is not None and configured.checking
        configured.reset()


def test_calibration_file_round_trip_and_bad_files(tmp_path):
    cal = ImuCalibration(tuple(SegmentMount.from_axes("+z", "-x", standing_deg=3.0) for _ in CHANNELS))
    p = save_calibration(cal, tmp_path / "sub" / "lib.imu.yaml")
    assert load_calibration(p) == cal
    with pytest.raises(CalibrationError, match="no such IMU calibration file"):
        load_calibration(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("segments:\n  right_thigh: {lateral: [0, 0, 1], proximal: [0, 0, 1]}\n")
    with pytest.raises(CalibrationError) as err:
        load_calibration(bad)
    assert str(bad) in str(err.value) and "\n" not in str(err.value)
    bad.write_text("segments: {}\n")
    with pytest.raises(CalibrationError, match="no mount for right_thigh"):
        load_calibration(bad)
    with pytest.raises(CalibrationError, match="not a sensor axis"):
        parse_axis("+w")
    with pytest.raises(CalibrationError, match="lateral and proximal axes must differ"):
        check_configured(["+z"] * 4, ["-z", "", "", ""])


def test_bad_messages_are_rejected_with_a_reason():
    s = SensorInput()
    ok = s.convert(10, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))
    assert ok[0] == pytest.approx((0.0, 0.0, 1.0))
    cases = [
        (20, (math.nan, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G), NON_FINITE),
        (20, (0.0, 0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G), ZERO_NORM),
        (10, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G), NON_INCREASING_STAMP),
        (5, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G), NON_INCREASING_STAMP),
    ]
    for stamp, q, cov0, w, a, reason in cases:
        with pytest.raises(SampleRejected) as err:
            s.convert(stamp, q, cov0, w, a)
        assert err.value.reason == reason
    raw = SensorInput()
    for w, a, reason in [((math.inf, 0, 0), (0, 0, G), NON_FINITE), ((0, 0, 0), (0, 0, 0), ZERO_NORM),
                         ((1e200, 0, 0), (0, 0, G), OUT_OF_RANGE), ((0, 0, 0), (0, -1e200, G), OUT_OF_RANGE),
                         ((0, 400.0, 0), (0, 0, G), OUT_OF_RANGE), ((0, 0, 0), (0, 0, 2e4), OUT_OF_RANGE),
                         ((0, 0, math.nan), (0, 1e200, G), NON_FINITE)]:
        with pytest.raises(SampleRejected) as err:
            raw.convert(30, (0.0, 0.0, 0.0, 1.0), -1.0, w, a)
        assert err.value.reason == reason
    assert raw.convert(30, (0.0, 0.0, 0.0, 1.0), -1.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))[0] == pytest.approx((0, 0, 1))
    absurd = s.convert(50, (0.0, 0.0, 0.0, 1.0), 0.0, (400.0, 0.0, 0.0), (0.0, 0.0, G))  # an orientation driver's
    assert absurd[0] == pytest.approx((0.0, 0.0, 1.0)) and all(math.isnan(v) for v in absurd[1]), "used without its rates"
    assert up_from_quaternion(0.0, 0.0, 0.0, 0.0) is None
    framed = SensorInput(frame_id="thigh_r_imu")
    with pytest.raises(SampleRejected) as err:
        framed.convert(40, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G), "shank_r_imu")
    assert err.value.reason == WRONG_FRAME
    assert framed.convert(40, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G), "thigh_r_imu")


def test_pairer_waits_for_a_silent_sensor_and_drops_unpaired_messages():
    p = ImuPairer(tolerance_s=0.002)
    period = 5_000_000
    out = []
    for k in range(10):
        for c in range(4):
            if c == 2 and 3 <= k < 7:  # right shank silent for four periods
                continue
            out += p.push(c, k * period + c * 100_000, (c, k))
    ks = [items[0][1] for _, items in out]
    assert ks == [0, 1, 2, 7, 8, 9]  # never a sample with a stale shank value
    assert all(len({i[1] for i in items}) == 1 for _, items in out)
    assert p.unpaired == 3 * 4
    # one sensor's stamps offset by more than the tolerance: nothing pairs, memory stays bounded
    q = ImuPairer(tolerance_s=0.002)
    got = []
    for k in range(200):
        for c in range(4):
            got += q.push(c, k * period + (2_500_000 if c == 1 else 0), k)
    assert got == [] and max(len(d) for d in q.queues) <= 50


def test_a_restarted_sensor_stream_is_taken_up_again():
    """A driver restart or a bag played again: stamps jump back by more than restart_back_s. The
    sensor starts afresh instead of rejecting every later message; the pairer drops what was queued
    under the old stamps and pairs the new ones once every sensor has restarted."""
    period = 5_000_000
    p = ImuPairer(tolerance_s=0.002)
    inputs = [SensorInput(restart_back_s=1.0, on_restart=p.restarted) for _ in range(4)]
    out = []
    for start in (50_000_000_000, 10_000_000_000):  # 50 s, then restarted at 10 s
        for k in range(40):
            for c in range(4):
                t = start + k * period
                try:
                    inputs[c].convert(t, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))
                except SampleRejected:
                    assert k == 0 and start < 50_000_000_000
                    continue
                out += [stamp for stamp, _ in p.push(c, t, k)]
    assert [i.restarts for i in inputs] == [1, 1, 1, 1]  # each sensor's first message back is taken as stray
    assert len(out) == 79 and out[40] == 10_000_000_000 + period and np.all(np.diff(out[40:]) == period)
    stray = SensorInput(restart_back_s=1.0)  # one old message between new ones: rejected, no restart
    for t in (50_000_000_000, 10_000_000_000, 50_005_000_000):
        with contextlib.suppress(SampleRejected):
            stray.convert(t, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))
    assert stray.restarts == 0 and stray.stamps.last_time == 50_005_000_000
    with pytest.raises(SampleRejected) as err:  # a step back within restart_back_s stays a bad stamp
        inputs[0].convert(10_000_000_000 + 30 * period, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))
    assert err.value.reason == NON_INCREASING_STAMP
    never = SensorInput(restart_back_s=0.0)
    never.convert(50_000_000_000, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))
    with pytest.raises(SampleRejected):
        never.convert(10_000_000_000, (0.0, 0.0, 0.0, 1.0), 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, G))


def test_pairing_tolerance_is_checked_and_measured():
    with pytest.raises(ValueError, match="pairing tolerance must be a finite number of seconds >= 0"):
        ImuPairer(-0.001)
    with pytest.raises(ValueError, match="pairing tolerance"):
        ImuPairer(math.nan)
    period = 10_000_000
    stamps = [np.arange(100) * period + c * 3_000_000 for c in range(4)]
    assert auto_tolerance_s(stamps) == pytest.approx(0.9 * 0.010)
    with pytest.raises(ValueError, match="message period"):
        auto_tolerance_s([[5], [], [1, 1], [2]])


def test_unsynchronised_100_hz_sensors_pair_every_sample(tmp_path):
    """Four sensors at 100 Hz, each with its own phase and stamp jitter: the measured tolerance
    pairs (nearly) every sample; the node's fixed 4 ms pairs none."""
    rate = 100.0
    ang = gait_angles(rate, walk_s=10.0)
    rng = np.random.default_rng(31)
    s = synthesize(ang, rate, random_mounts(rng), rng)
    phases = np.array([0.0, 2.6e6, 5.1e6, 7.7e6])[rng.permutation(4)]  # the four phases spread over a period
    jitter = rng.integers(-300_000, 300_000, (4, len(s.time_s)))
    stamps = BASE_NS + np.round(s.time_s * 1e9).astype(np.int64)[None, :] + phases.astype(np.int64)[:, None] + jitter
    bag = write_imu_bag(tmp_path / "unsync", stamps, np.radians(s.gyro_dps), s.acc_g * G, s.quat_xyzw)
    rec = read_imu_bag(bag)
    assert len(rec) >= len(s.time_s) - 2, (len(rec), rec.skipped)
    assert (rms(rec.angles_deg - s.angles_deg[-len(rec):]) < 0.5).all()
    with pytest.raises(RecordingError, match=r"fewer than 2 samples with all four IMUs within 0.004 s"):
        read_imu_bag(bag, imu_tolerance_s=0.004)
    with pytest.raises(RecordingError, match="pairing tolerance must be a finite number of seconds >= 0"):
        read_imu_bag(bag, imu_tolerance_s=-1.0)


@pytest.fixture(scope="module")
def synthetic_bags(tmp_path_factory, angles):
    rng = np.random.default_rng(21)
    s = synthesize(angles[:3000], RATE, random_mounts(rng), rng, acc_noise_g=0.01, gyro_noise_dps=0.3, gyro_bias_dps=1.0)
    d = tmp_path_factory.mktemp("imu_bags")
    stamps = BASE_NS + np.round(s.time_s * 1e9).astype(np.int64)
    # sensors stamped up to 1 ms apart, as four drivers would be
    stamps4 = stamps[None, :] + np.array([0, 300_000, 600_000, 900_000])[:, None]
    write_imu_bag(d / "orientation", stamps4, np.radians(s.gyro_dps), s.acc_g * G, s.quat_xyzw)
    write_imu_bag(d / "raw.db3dir", stamps4, np.radians(s.gyro_dps), s.acc_g * G, None, storage="sqlite3")
    return s, d


def test_imu_bag_note_says_what_the_standing_pose_gave(tmp_path, angles):
    """Configured proximal axes: the standing pose gives raw sensors their gyro biases only, and
    orientation sensors nothing; the note says so instead of 'learnt from the standing pose'."""
    rng = np.random.default_rng(23)
    s = synthesize(angles[:3000], RATE, [ALONG_SEGMENT] * 4, rng, acc_noise_g=0.01, gyro_noise_dps=0.3, gyro_bias_dps=1.0)
    stamps = BASE_NS + np.round(s.time_s * 1e9).astype(np.int64)
    notes = {}
    for kind, quat in (("raw", None), ("orientation", s.quat_xyzw)):
        bag = write_imu_bag(tmp_path / kind, stamps, np.radians(s.gyro_dps), s.acc_g * G, quat)
        got = read_imu_bag(bag, imu_proximal_axes=["-x"] * 4)
        notes[kind] = next(n for n in got.notes if n.startswith("IMU calibration learnt"))
    assert notes["raw"].startswith("IMU calibration learnt (gyro biases from the standing pose at "), notes
    assert notes["orientation"].startswith("IMU calibration learnt: "), notes


def test_fuse_raw_backwards_is_fuse_raw_on_the_stream_played_backwards():
    """Time reversed: the samples in reverse order, rates and bias negated, the accelerometer as is."""
    rng = np.random.default_rng(8)
    t = np.cumsum(rng.uniform(0.004, 0.006, 400))
    gyro, acc = rng.normal(0.0, 60.0, (400, 3)), np.array([0.1, -0.2, 1.0]) + rng.normal(0.0, 0.1, (400, 3))
    bias = (1.0, -2.0, 0.5)
    back = fuse_raw_backwards(t, gyro, acc, bias, THIGH_FUSION)
    mirrored = fuse_raw(t[-1] - t[::-1], -gyro[::-1], acc[::-1], tuple(-b for b in bias), THIGH_FUSION)
    assert np.allclose(back, mirrored[::-1], rtol=0.0, atol=1e-9)
    assert not np.allclose(back, fuse_raw(t, gyro, acc, bias, THIGH_FUSION), atol=1e-3)


def test_raw_imu_bag_walking_before_the_standing_pose_is_fused_backwards_from_it(tmp_path):
    """A bag that starts walking: the forward fusion starts from an accelerometer that reads gravity
    plus motion; up to near the end of the first still stretch the angles come from the fusion run
    backwards from there, within 2 deg RMS of the truth, as the walking after it."""
    angles = np.concatenate([gait_angles(RATE, walk_s=4.0, stand_s=1.5, seed=1)[::-1],  # walking to a stop
                             gait_angles(RATE, walk_s=12.0, stand_s=0.0, seed=2)])
    rng = np.random.default_rng(31)
    s = synthesize(angles, RATE, random_mounts(rng), rng, acc_noise_g=0.01, gyro_noise_dps=0.3, gyro_bias_dps=3.0,
                   stand_s=5.5)  # (turning from 5.5 s)
    moving = (np.abs(angles).max(axis=1) > 0)[:, None]
    motion = 0.15 * np.cos(2 * np.pi * s.time_s)[:, None] * np.array([1.0, 0.0, 0.5]) * moving  # world frame, g
    acc = np.stack([s.acc_g[c] + Rotation.from_quat(s.quat_xyzw[c]).inv().apply(motion) for c in range(4)])
    stamps = BASE_NS + np.round(s.time_s * 1e9).astype(np.int64)
    rec = read_imu_bag(write_imu_bag(tmp_path / "walk_first", stamps, np.radians(s.gyro_dps), acc * G, None))
    assert rec.calibration_note.endswith("; raw sensors fused backwards in time from 5.3 s, in the first still stretch "
                                         "(4.2-5.5 s)"), rec.calibration_note  # standing: 4.0-5.5 s
    k = rec.fused_backwards_until
    for c in range(4):  # [0, k): the backward run from sample k - 1, with the calibration's bias
        m = rec.calibration.mounts[c]
        back = fuse_raw_backwards(rec.time_s[:k], s.gyro_dps[c, :k], acc[c, :k], m.gyro_bias_dps, FUSION_BY_CHANNEL[c])
        assert np.allclose(rec.angles_deg[:k, c], m.angles_deg(back), rtol=0.0, atol=1e-6)
    err = rec.angles_deg - s.angles_deg
    assert (np.abs(err[(s.time_s > 4.0) & (s.time_s < 5.5)]) < 1.0).all()  # standing, either side of k
    assert (rms(err[s.time_s < 5.5]) < 2.0).all(), rms(err[s.time_s < 5.5])
    assert (rms(err[s.time_s > 8.0]) < 2.0).all()
    assert rec.slice(100).fused_backwards_until == k - 100 and rec.slice(k + 5).fused_backwards_until == 0


def test_imu_bag_reads_as_a_recording_of_the_four_angles(synthetic_bags):
    s, d = synthetic_bags
    rec = read_recording(d / "orientation")
    assert len(rec) == len(s.time_s) and rec.time_s[0] == 0.0
    assert (rms(rec.angles_deg - s.angles_deg) < 0.5).all()
    assert any("IMU calibration learnt from the standing pose" in n for n in rec.notes)
    # a given calibration is used as is, with its gyro biases for raw input
    again = read_imu_bag(d / "orientation", imu_calibration=rec.calibration)
    assert np.array_equal(again.angles_deg, rec.angles_deg)
    raw = read_imu_bag(d / "raw.db3dir")
    late = s.time_s >= 10.0
    assert (rms((raw.angles_deg - s.angles_deg)[late]) < 1.0).all()
    assert any(any(m.gyro_bias_dps) for m in raw.calibration.mounts)
    raw_again = read_imu_bag(d / "raw.db3dir", imu_calibration=raw.calibration)
    assert np.array_equal(raw_again.angles_deg, raw.angles_deg)


def test_raw_imu_bag_with_a_saved_calibration_reads_as_the_node_converts(synthetic_bags):
    """The node, started with a saved calibration, sets each sensor's gyro bias from it before its
    first message (ros/imu_input.py ``_apply_biases``); reading the bag with that calibration gives
    the same angles. The node measures the rate from its first stamps, the reader over the bag."""
    s, d = synthetic_bags
    cal = read_imu_bag(d / "raw.db3dir").calibration
    offline = read_imu_bag(d / "raw.db3dir", imu_calibration=cal)
    inputs = [SensorInput(None, "", fusion) for fusion in FUSION_BY_CHANNEL]  # as the node builds them
    for sensor, mount in zip(inputs, cal.mounts, strict=True):
        sensor.set_gyro_bias(mount.gyro_bias_dps)
    pairer = ImuPairer()
    live = []
    stamps = BASE_NS + np.round(s.time_s * 1e9).astype(np.int64)
    for k, stamp in enumerate(stamps.tolist()):
        for c in range(4):
            ns = stamp + (0, 300_000, 600_000, 900_000)[c]  # as synthetic_bags stamps them
            item = inputs[c].convert(ns, (0.0, 0.0, 0.0, 0.0), -1.0, tuple(np.radians(s.gyro_dps[c, k])),
                                     tuple(s.acc_g[c, k] * G))
            live += [cal.angles_deg([i[0] for i in items]) for _, items in pairer.push(c, ns, item)]
    assert len(live) == len(offline)
    assert np.abs(np.array(live) - offline.angles_deg).max() < 1e-6


def test_a_given_calibration_that_does_not_fit_the_bag_is_an_error(synthetic_bags, tmp_path):
    _, d = synthetic_bags
    cal = read_imu_bag(d / "orientation").calibration
    fits = read_imu_bag(d / "orientation", imu_calibration=cal)
    assert any("checked on the walking: lateral axes within" in n for n in fits.notes)
    fit = r"does not fit this recording \(right_shank: lateral axis (8[7-9]|9[0-3]) deg from the swing axis\)"
    with pytest.raises(RecordingError, match=fit):
        read_imu_bag(d / "orientation", imu_calibration=turned(cal, 2, 90.0))
    path = save_calibration(turned(cal, 2, 90.0), tmp_path / "other_day.imu.yaml")
    r = subprocess.run([sys.executable, "-m", "gait_estimator.cli", "convert", str(d / "raw.db3dir"), "--out",
                        str(tmp_path / "x.csv"), "--imu-calibration", str(path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "does not fit this recording" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.csv").exists()


def test_convert_imu_bag_to_csv_and_process_it(synthetic_bags, tmp_path):
    s, d = synthetic_bags
    out = tmp_path / "rec.csv"
    cmd = [sys.executable, "-m", "gait_estimator.cli", "convert", str(d / "orientation"), "--out", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "IMU calibration learnt" in r.stdout
    rec = read_project_csv(out)
    assert (rms(rec.angles_deg - s.angles_deg) < 0.5).all()
    cal = tmp_path / "cal.yaml"
    cal.write_text("segments: {}\n")
    r = subprocess.run([*cmd[:-1], str(tmp_path / "x.csv"), "--imu-calibration", str(cal)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "no mount for right_thigh" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = subprocess.run([sys.executable, "-m", "gait_estimator.cli", "process", str(d / "orientation")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert "IMU calibration learnt" in r.stdout + r.stderr  # process says how the angles were made, as convert does
    for bag in ("orientation", "raw.db3dir"):  # IMU angles (SI units by the message; standing near 0 by
        # calibration, the fused ones with noise): no units check, as in the node
        r = subprocess.run([sys.executable, "-m", "gait_estimator.cli", "process", str(d / bag), "-q"],
                           capture_output=True, text=True, timeout=300)
        assert r.returncode == 0 and "warning" not in r.stderr, r.stderr
    whole = read_imu_bag(d / "raw.db3dir")
    part = whole.slice(100, 2000)
    assert isinstance(part, ImuBagRecording) and part.calibration == whole.calibration and len(part) == 1900
    assert part.notes == whole.notes and part.stamp_ns.tolist() == whole.stamp_ns[100:2000].tolist()


DRIVER_TOPICS = ["/thigh_r/imu/data", "/thigh_l/imu/data", "/shank_r/imu/data", "/shank_l/imu/data"]


def test_imu_bag_with_driver_topic_names_is_read_with_imu_topics(synthetic_bags, tmp_path):
    s, _ = synthetic_bags
    stamps = BASE_NS + np.round(s.time_s * 1e9).astype(np.int64)
    bag = write_imu_bag(tmp_path / "drivers", stamps, np.radians(s.gyro_dps), s.acc_g * G, s.quat_xyzw,
                        topics=DRIVER_TOPICS)
    cli = [sys.executable, "-m", "gait_estimator.cli"]
    out = tmp_path / "rec.csv"

    def run(*extra: str) -> subprocess.CompletedProcess:
        return subprocess.run([*cli, "convert", str(bag), "--out", str(out), *extra],
                              capture_output=True, text=True, timeout=120)

    r = run()
    assert r.returncode == 2 and "--imu-topics RT,LT,RS,LS" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = run("--imu-topics", ",".join(DRIVER_TOPICS[:3]))
    assert r.returncode == 2 and "needs 4 IMU topics" in r.stderr and "got 3" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = run("--imu-topics", ",".join([*DRIVER_TOPICS[:3], "/shank_x/imu/data"]))
    assert r.returncode == 2 and "no sensor_msgs/msg/Imu topic /shank_x/imu/data" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    r = run("--imu-topics", ",".join(DRIVER_TOPICS))
    assert r.returncode == 0, r.stderr
    assert (rms(read_project_csv(out).angles_deg - s.angles_deg) < 0.5).all()
    # the same option (and the tolerance) reach process through its reader options
    r = subprocess.run([*cli, "process", str(bag), "--imu-topics", ",".join(DRIVER_TOPICS), "--imu-tolerance-s", "0.002",
                        "--out", str(tmp_path / "pred.csv")], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert len(read_predictions_csv(tmp_path / "pred.csv").time_s) == len(s.time_s)
    # a robot's recording: the same IMUs and a JointState topic; --imu-topics reads the IMUs
    mixed = _with_joint_states(bag, tmp_path / "mixed")
    assert len(read_recording(mixed, imu_topics=DRIVER_TOPICS)) == len(s.time_s)
    r = subprocess.run([*cli, "convert", str(mixed), "--out", str(out), "--imu-topics", ",".join(DRIVER_TOPICS)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert (rms(read_project_csv(out).angles_deg - s.angles_deg) < 0.5).all()


def _with_joint_states(src, dst):
    """A copy of the IMU bag ``src`` with a /joint_states topic beside its Imu topics."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    js = store.types["sensor_msgs/msg/JointState"]
    header, stamp = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    with AnyReader([src], default_typestore=store) as reader, Writer(dst, version=8) as writer:
        conns = {c.topic: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        joints = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        for c, t, raw in reader.messages():
            writer.write(conns[c.topic], t, raw)
            if c.topic == DRIVER_TOPICS[0]:
                msg = js(header(stamp(t // 10**9, t % 10**9), ""), ["knee"], np.zeros(1), np.zeros(0), np.zeros(0))
                writer.write(joints, t, store.serialize_cdr(msg, js.__msgtype__))
    return dst


@pytest.mark.parametrize("command", [
    ["convert", "B", "--out", "o.csv"], ["process", "B"], ["train", "B", "--out", "l.yaml"],
    ["evaluate", "--predictions", "p.csv", "--truth", "B", "--out-dir", "d"], ["resample", "B", "--out", "o.csv"],
    ["label-strides", "B", "--out", "o.csv"], ["demo", "B"],
])
def test_every_command_that_reads_recordings_takes_the_imu_options(command):
    from gait_estimator.cli.app import build_parser
    from gait_estimator.cli.args import reader_options

    args = build_parser().parse_args([*command, "--imu-topics", "/a, /b,/c,/d", "--imu-calibration", "c.yaml",
                                      "--imu-tolerance-s", "0.01", "--imu-lateral-axes", "+z,,+z,",
                                      "--imu-proximal-axes=-x,-x,-x,-x"])
    assert reader_options(args) == {"imu_topics": ["/a", "/b", "/c", "/d"], "imu_calibration": "c.yaml",
                                    "imu_tolerance_s": 0.01, "imu_lateral_axes": ["+z", "", "+z", ""],
                                    "imu_proximal_axes": ["-x"] * 4}


def test_convert_with_the_nodes_configured_axes(tmp_path):
    rng = np.random.default_rng(21)
    s = synthesize(gait_angles(RATE, walk_s=8.0), RATE, [ALONG_SEGMENT] * 4, rng)
    bag = write_imu_bag(tmp_path / "along", BASE_NS + np.round(s.time_s * 1e9).astype(np.int64), np.radians(s.gyro_dps),
                        s.acc_g * G, s.quat_xyzw)
    cli = [sys.executable, "-m", "gait_estimator.cli", "convert", str(bag), "--out", str(tmp_path / "o.csv")]
    r = subprocess.run([*cli, "--imu-lateral-axes", "+z,+z,+z,+z", "--imu-proximal-axes=-x,-x,-x,-x"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "[configured]" in r.stdout and "[learnt]" not in r.stdout and "checked on the walking" in r.stdout
    assert (rms(read_project_csv(tmp_path / "o.csv").angles_deg - s.angles_deg) < 0.5).all()
    r = subprocess.run([*cli, "--imu-lateral-axes", "+z,+z,+y,+z", "--imu-proximal-axes=-x,-x,-x,-x"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "right_shank: lateral axis 90 deg from the swing axis" in r.stdout, r.stdout + r.stderr
    r = subprocess.run([*cli, "--imu-lateral-axes", "+z,+z,+z", "--imu-proximal-axes=-x,-x,-x,-x"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "IMU axes: need 4 entries each" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_imu_options_on_a_csv_are_reported(capsys):
    from pathlib import Path

    from gait_estimator.cli.app import main

    csv = Path(__file__).resolve().parents[1] / "data/swge/recordings/LG_2_Ramp_AB_Sample.csv"
    assert main(["process", str(csv), "--stop", "500", "--imu-topics", "/a,/b,/c,/d", "--imu-tolerance-s", "0.01"]) == 0
    assert f"note: --imu-topics, --imu-tolerance-s apply to bags only; ignored for {csv}" in capsys.readouterr().out


def test_a_bag_without_the_four_imus_says_which_topics_it_has(synthetic_bags, tmp_path):
    s, _ = synthetic_bags
    stamps = BASE_NS + np.round(s.time_s[:100] * 1e9).astype(np.int64)
    write_imu_bag(tmp_path / "b", stamps, np.zeros((4, 100, 3)), np.tile([0, 0, G], (4, 100, 1)), None,
                  topics=["/a", "/b", "/c", "/d"])
    with pytest.raises(RecordingError, match=r"needs four sensor_msgs/msg/Imu topics.*topics in the bag: /a"):
        read_recording(tmp_path / "b")


def test_standing_pose_on_request_keeps_the_learnt_axes(angles):
    rng = np.random.default_rng(8)
    s = synthesize(angles, RATE, random_mounts(rng), rng)
    ups = _ups(s)
    calib = ImuCalibrator([None] * 4, [None] * 4, [0.0] * 4)
    nan3 = (math.nan,) * 3

    def feed(ks, t_offset=0.0):
        for k in ks:
            got = calib.add(float(s.time_s[k] + t_offset), [tuple(ups[c, k]) for c in range(4)],
                            [tuple(s.gyro_dps[c, k]) for c in range(4)], [nan3] * 4)
            if got is not None:
                return got
        return None

    first = feed(range(len(s.time_s)))
    assert first is not None
    calib.request_standing()
    assert calib.calibration is None and calib.status == "stand still"
    again = feed(range(400), t_offset=100.0)  # standing again: no strides needed this time
    assert again is not None
    for a, b in zip(first.mounts, again.mounts, strict=True):
        assert np.allclose(a.lateral, b.lateral) and np.allclose(a.proximal, b.proximal, atol=1e-6)
    # every axis configured, raw sensors: the pose asked for is waited for, and gives the new gyro biases
    raw = synthesize(angles, RATE, random_mounts(rng), rng, gyro_noise_dps=0.3, gyro_bias_dps=2.0)
    raw_ups = _ups(raw)
    cal = learn_calibration(raw.time_s, raw_ups)[0]
    calib = ImuCalibrator([m.lateral for m in cal.mounts], [m.proximal for m in cal.mounts], [0.0] * 4)
    rows = [([tuple(raw_ups[c, k]) for c in range(4)], [tuple(raw.gyro_dps[c, k]) for c in range(4)],
             [tuple(raw.acc_g[c, k]) for c in range(4)]) for k in range(len(raw.time_s))]
    assert calib.add(0.0, *rows[round(10 * RATE)]) is not None, "configured: complete at once"
    calib.request_standing()
    walking = range(round(10 * RATE), round(12 * RATE))
    assert all(calib.add(50.0 + float(raw.time_s[k]), *rows[k]) is None for k in walking), "waits while walking"
    assert calib.status == "stand still for 1 s"
    k_done, done = next((k, c) for k in range(len(raw.time_s)) if (c := calib.add(100.0 + float(raw.time_s[k]), *rows[k])))
    assert 2.0 <= raw.time_s[k_done] < 3.0, "when the wearer moves"
    truth = raw.gyro_dps[:, :round(2.0 * RATE)].mean(axis=1)
    assert np.abs(np.array([m.gyro_bias_dps for m in done.mounts]) - truth).max() < 0.1
    # proximal axes configured, lateral learnt: after a pose asked for, the kept lateral axes are still
    # learnt ones (not checked again as configured; saved beside a library)
    half = ImuCalibrator([None] * 4, [m.proximal for m in cal.mounts], [0.0] * 4)
    first = next(c for k in range(len(raw.time_s)) if (c := half.add(float(raw.time_s[k]), *rows[k][:2], [nan3] * 4)))
    half.request_standing()
    again = next(c for k in range(len(raw.time_s)) if (c := half.add(300.0 + float(raw.time_s[k]), *rows[k][:2], [nan3] * 4)))
    assert [m.source for m in first.mounts] == [m.source for m in again.mounts] == ["learnt"] * 4
    assert not half.checking and [m.lateral for m in again.mounts] == [m.lateral for m in first.mounts]
    # orientation sensors (no accelerations): the still second is enough, before any move
    calib.request_standing()
    k_done = next(k for k in range(len(raw.time_s)) if calib.add(200.0 + float(raw.time_s[k]), *rows[k][:2], [nan3] * 4))
    assert 1.0 <= raw.time_s[k_done] < 2.0 and calib.calibration is not None
