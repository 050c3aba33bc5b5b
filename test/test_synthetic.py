"""The synthetic recording generator: exact truth, requested variability, sampling."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic import SyntheticConfig, WearerConfig, generate, new_wearer

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


# ---------------------------------------------------------------------------------------------
# New wearers: cadence, per-channel offsets and amplitude, noise, rate and jitter


def test_new_wearers_stay_within_the_requested_ranges():
    wearers = [new_wearer(s) for s in range(300)]
    off = np.array([w.channel_offset_deg for w in wearers])
    gain = np.array([w.channel_gain for w in wearers])
    cad = np.array([w.cadence for w in wearers])
    rate = np.array([w.rate_hz for w in wearers])
    jit = np.array([w.jitter for w in wearers])
    noise = np.array([w.noise_sd_deg for w in wearers])
    assert off.shape == gain.shape == (300, 4)
    assert np.abs(off).max() <= 8.0 and np.abs(off).max() > 7.5  # the whole +-8 deg range is used
    assert np.abs(gain - 1).max() <= 0.15 and np.abs(gain - 1).max() > 0.14
    assert np.abs(cad - 1).max() <= 0.12 and cad.min() < 0.89 and cad.max() > 1.11
    assert rate.min() >= 100 and rate.max() <= 500 and rate.min() < 110 and rate.max() > 490
    assert jit.min() >= 0 and jit.max() <= 0.5
    assert noise.min() >= 0.2 and noise.max() <= 1.0
    # channels are drawn independently: offsets of different channels are not the same numbers
    assert abs(np.corrcoef(off[:, 0], off[:, 1])[0, 1]) < 0.2
    narrow = new_wearer(3, WearerConfig(offset_deg=1.0, amplitude=0.01, cadence=0.02, rate_hz=(200.0, 201.0)))
    assert max(map(abs, narrow.channel_offset_deg)) <= 1.0 and abs(narrow.cadence - 1) <= 0.02
    assert 200 <= narrow.rate_hz <= 201
    assert new_wearer(5) == new_wearer(5) and new_wearer(5) != new_wearer(6)


def test_wearer_offsets_and_amplitude_factors_are_exact(able_bodied):
    cfg = SyntheticConfig(duration_cv=0.0, amplitude_cv=0.0, offset_sd_deg=0.0, noise_sd_deg=0.0, foot_noise_sd_deg=0.0,
                          channel_offset_deg=(8.0, -8.0, 3.0, 0.0), channel_gain=(1.15, 0.85, 1.0, 1.1))
    syn = generate(able_bodied, [("RA", 3)], cfg)
    k = able_bodied.mode("RA").samples
    n = k.shape[0]
    mean = k.mean(axis=0)
    expected = mean + np.array(cfg.channel_gain) * (k - mean) + np.array(cfg.channel_offset_deg)
    np.testing.assert_allclose(syn.recording.angles_deg[: 3 * n], np.tile(expected, (3, 1)), atol=1e-9)


def test_wearer_cadence_scales_every_stride(able_bodied):
    route = [("Slow", 2), ("RD", 2), ("SA", 2)]
    quiet = dict(duration_cv=0.0, amplitude_cv=0.0, offset_sd_deg=0.0, noise_sd_deg=0.0)
    nominal = np.array([able_bodied.mode(m).stride_duration_s for m, c in route for _ in range(c)])
    for cadence in (0.88, 1.12):
        # jittered sampling: stride durations are not rounded to whole samples
        syn = generate(able_bodied, route, SyntheticConfig(**quiet, cadence=cadence, rate_hz=300.0, jitter=0.3), seed=1)
        np.testing.assert_allclose(syn.stride_durations_s, nominal / cadence, rtol=1e-12)
        np.testing.assert_allclose(np.diff(syn.heel_strikes_s), nominal / cadence, rtol=1e-12)
        # uniform sampling at the library rate: durations rounded to whole samples
        uni = generate(able_bodied, route, SyntheticConfig(**quiet, cadence=cadence), seed=1)
        np.testing.assert_allclose(uni.stride_durations_s, nominal / cadence, atol=0.5 / able_bodied.sample_rate_hz + 1e-12)


def test_new_wearer_recording_has_exact_truth_and_its_rate(able_bodied):
    for seed in range(4):
        cfg = new_wearer(seed)
        syn = generate(able_bodied, [("Med", 4), ("RA", 3), ("SD", 3)], cfg, seed=seed)
        rec = syn.recording
        dt = np.diff(rec.time_s)
        assert dt.min() > 0
        # a sample within a quarter interval of a heel strike gives way to the heel strike itself
        assert dt.max() <= (1.25 + cfg.jitter) / cfg.rate_hz + 1e-12
        assert np.percentile(dt, 99) <= (1 + cfg.jitter) / cfg.rate_hz + 1e-12
        assert np.std(dt) * cfg.rate_hz == pytest.approx(cfg.jitter / np.sqrt(3), abs=0.03)
        assert rec.median_rate_hz == pytest.approx(cfg.rate_hz, rel=0.05)
        np.testing.assert_array_equal(rec.time_s[rec.heel_strike], syn.heel_strikes_s)
        assert np.all(syn.phase[rec.heel_strike][:-1] == 0.0)  # the last one closes the last stride (phase 1 - eps)
        k = np.clip(np.searchsorted(syn.heel_strikes_s, rec.time_s, side="right") - 1, 0, len(syn.stride_modes) - 1)
        expected = np.mod((rec.time_s - syn.heel_strikes_s[k]) / syn.stride_durations_s[k], 1.0)
        np.testing.assert_allclose(np.abs(np.mod(syn.phase - expected + 0.5, 1.0) - 0.5), 0.0, atol=1e-12)
        assert np.all((syn.phase >= 0) & (syn.phase < 1))
        assert rec.labels.tolist() == [syn.stride_modes[j] for j in k]
        nominal = np.array([able_bodied.mode(m).stride_duration_s for m in syn.stride_modes]) / cfg.cadence
        assert np.std(syn.stride_durations_s / nominal) < 2 * cfg.duration_cv
        # the offsets show in the channel means (kernel means plus offset, within noise and variability)
        mean = np.mean([able_bodied.mode(m).samples.mean(axis=0) for m in ("Med", "RA", "SD")], axis=0)
        assert np.abs(rec.angles_deg.mean(axis=0) - mean - np.array(cfg.channel_offset_deg)).max() < 4.0


def test_stamp_jitter_keeps_samples_near_the_grid(able_bodied):
    rate, j = 230.0, 0.002
    syn = generate(able_bodied, [("Fast", 6)], SyntheticConfig(rate_hz=rate, stamp_jitter_s=j), seed=9)
    rec = syn.recording
    t = rec.time_s[~rec.heel_strike]
    off_grid = t - np.round(t * rate) / rate
    assert np.abs(off_grid).max() <= j + 1e-12
    assert np.abs(off_grid).max() > 0.9 * j and np.std(off_grid) > 0.4 * j
    assert np.diff(rec.time_s).min() > 0
    np.testing.assert_array_equal(rec.time_s[rec.heel_strike], syn.heel_strikes_s)
    with pytest.raises(ValueError, match="stamp_jitter_s"):
        generate(able_bodied, [("Fast", 2)], SyntheticConfig(rate_hz=500.0, stamp_jitter_s=0.002))
    with pytest.raises(ValueError, match="one of"):
        generate(able_bodied, [("Fast", 2)], SyntheticConfig(jitter=0.1, stamp_jitter_s=0.001))
