"""The synthetic recording generator: exact truth, requested variability, sampling."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import SyntheticConfig, generate

from gait_estimator.analysis.strides import heel_strikes

QUIET = SyntheticConfig(duration_cv=0.0, amplitude_cv=0.0, offset_sd_deg=0.0, noise_sd_deg=0.0, foot_noise_sd_deg=0.0)


def test_noise_free_recording_repeats_the_kernel(able_bodied):
    syn = generate(able_bodied, [("Med", 3)], QUIET)
    k = able_bodied.mode("Med").samples
    n = k.shape[0]
    rec = syn.recording
    assert len(rec) == 3 * n + 1  # three strides plus the closing heel strike
    np.testing.assert_allclose(rec.angles_deg[: 3 * n], np.tile(k, (3, 1)), atol=1e-9)
    np.testing.assert_allclose(syn.heel_strikes_s, np.arange(4) * n / able_bodied.sample_rate_hz)


def test_truth_labels_heel_strikes_and_phase(able_bodied):
    syn = generate(able_bodied, [("Slow", 2), ("Fast", 3)], SyntheticConfig(), seed=3)
    rec = syn.recording
    assert syn.stride_modes == ["Slow", "Slow", "Fast", "Fast", "Fast"]
    np.testing.assert_allclose(rec.time_s[rec.heel_strike], syn.heel_strikes_s, atol=1e-12)
    assert np.all(syn.phase[rec.heel_strike] == 0.0)
    assert np.all((syn.phase >= 0) & (syn.phase < 1))
    change = syn.heel_strikes_s[2]
    assert set(rec.labels[rec.time_s < change]) == {"Slow"}
    assert set(rec.labels[rec.time_s >= change]) == {"Fast"}
    # phase grows linearly inside a stride
    inside = (rec.time_s >= syn.heel_strikes_s[3]) & (rec.time_s < syn.heel_strikes_s[4])
    expected = (rec.time_s[inside] - syn.heel_strikes_s[3]) / syn.stride_durations_s[3]
    np.testing.assert_allclose(syn.phase[inside], expected, atol=1e-12)


def test_requested_duration_and_amplitude_variability(able_bodied):
    cfg = SyntheticConfig(duration_cv=0.04, amplitude_cv=0.0, offset_sd_deg=0.0, noise_sd_deg=0.0)
    syn = generate(able_bodied, [("Med", 300)], cfg, seed=1)
    nominal = able_bodied.mode("Med").stride_duration_s
    cv = np.std(syn.stride_durations_s / nominal)
    assert 0.03 < cv < 0.05
    flat = generate(able_bodied, [("Med", 300)], SyntheticConfig(duration_cv=0.0, amplitude_cv=0.0,
                                                                  offset_sd_deg=0.0, noise_sd_deg=0.0), seed=1)
    assert np.ptp(flat.stride_durations_s) < 1e-12
    amp = generate(able_bodied, [("Med", 50)], SyntheticConfig(duration_cv=0.0, amplitude_cv=0.1,
                                                               offset_sd_deg=0.0, noise_sd_deg=0.0), seed=1)
    n = able_bodied.mode("Med").length
    ranges = np.ptp(amp.recording.angles_deg[: 50 * n].reshape(50, n, 4), axis=1)
    assert 0.05 < np.std(ranges / np.ptp(able_bodied.mode("Med").samples, axis=0)) < 0.2


def test_sensor_noise_level(able_bodied):
    base = generate(able_bodied, [("Fast", 20)], QUIET, seed=2)
    noisy = generate(able_bodied, [("Fast", 20)], SyntheticConfig(duration_cv=0.0, amplitude_cv=0.0, offset_sd_deg=0.0,
                                                                  noise_sd_deg=0.8), seed=2)
    assert np.std(noisy.recording.angles_deg - base.recording.angles_deg) == pytest.approx(0.8, rel=0.05)


def test_mode_change_is_continuous(able_bodied):
    syn = generate(able_bodied, [("Slow", 2), ("RA", 2), ("SD", 2)], QUIET)
    jumps = np.abs(np.diff(syn.recording.angles_deg, axis=0)).max()
    assert jumps < 3.0  # degrees per sample at 230 Hz; the kernels themselves step up to ~2.2


def test_jittered_sampling_keeps_exact_heel_strikes(able_bodied):
    cfg = SyntheticConfig(rate_hz=267.0, jitter=0.6)
    syn = generate(able_bodied, [("RD", 6)], cfg, seed=5)
    dt = np.diff(syn.recording.time_s)
    assert dt.min() > 0
    assert dt.max() <= 1.6 / 267.0 + 1e-12
    assert np.std(dt) > 0.2 / 267.0
    np.testing.assert_array_equal(syn.recording.time_s[syn.recording.heel_strike], syn.heel_strikes_s)


def test_same_seed_same_recording(able_bodied):
    a = generate(able_bodied, [("Med", 4)], seed=7)
    b = generate(able_bodied, [("Med", 4)], seed=7)
    c = generate(able_bodied, [("Med", 4)], seed=8)
    np.testing.assert_array_equal(a.recording.angles_deg, b.recording.angles_deg)
    assert len(a.recording) != len(c.recording) or not np.array_equal(a.recording.angles_deg, c.recording.angles_deg)


def test_foot_angle_peaks_mark_the_heel_strikes(able_bodied):
    syn = generate(able_bodied, [("Med", 8)], SyntheticConfig(rate_hz=250.0, jitter=0.5), seed=4)
    found = heel_strikes(syn.recording, "right_foot").times_s
    # the first and last heel strikes are the recording's ends: no peak can be found there
    np.testing.assert_allclose(found, syn.heel_strikes_s[1:-1], atol=2.0 / 250.0)
