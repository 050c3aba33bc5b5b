"""Teaching without ROS: the online stride collector against ``train``, and its guard rails, on
the bundled Multispeed recording (and doctored copies of it)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.analysis.strides import heel_strikes
from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.core.errors import GaitEstimatorError
from gait_estimator.core.estimator import Estimator
from gait_estimator.core.teach import (
    ANALYSIS_PERIOD_S,
    KEEP_MARGIN_S,
    StrideCollector,
    TeachOptions,
    change_summary,
    near_copies,
    with_mode,
)
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import Recording

RATE_HZ = 230.0


@pytest.fixture(scope="module")
def rec(multispeed_csv: Path) -> Recording:
    return read_recording(multispeed_csv, rate_hz=RATE_HZ)


def feed(collector: StrideCollector, time_s: np.ndarray, angles: np.ndarray) -> list[str]:
    events: list[str] = []
    for t, x in zip(time_s, angles, strict=True):
        events += collector.push(float(t), tuple(x))
        if collector.done:
            break
    return events


def window(rec: Recording, start_s: float, stop_s: float) -> tuple[np.ndarray, np.ndarray]:
    i0, i1 = np.searchsorted(rec.time_s, [start_s, stop_s])
    return rec.time_s[i0:i1].copy(), rec.angles_deg[i0:i1].copy()


def offline(rec: Recording, collector: StrideCollector, mode: str):
    """train on labels covering exactly the collector's candidate strides."""
    inside = np.zeros(len(rec.time_s), dtype=bool)
    for a, b in collector.candidates:
        inside |= (rec.time_s >= a) & (rec.time_s < b)
    labels = np.where(inside, mode, "")
    labelled = Recording(rec.time_s, rec.angles_deg, labels=labels, source="Multispeed")
    return train_library([labelled], "offline", TrainOptions(heel_strikes="right_shank", rate_hz=RATE_HZ))


@pytest.mark.parametrize(("mode", "start_s", "strides"), [("Slow", 8.0, 5), ("Med", 22.5, 8), ("Fast", 37.0, 9)])
def test_kernel_equals_train_on_the_same_strides(rec: Recording, mode: str, start_s: float, strides: int) -> None:
    c = StrideCollector(mode, TeachOptions(strides=strides), rate_hz=RATE_HZ)
    events = feed(c, *window(rec, start_s, start_s + 20.0))
    assert c.done, events
    assert f"{mode}: 1/{strides} strides" in events and f"{mode}: {strides}/{strides} strides" in events
    assert events[-1].startswith(f"{mode}: kernel built from {strides} strides")
    trained = offline(rec, c, mode)
    kernel = c.result.kernel
    ref = trained.library.mode(mode)
    assert kernel.length == ref.length and kernel.info["strides"] == ref.info["strides"] == strides
    np.testing.assert_allclose(kernel.samples, ref.samples, rtol=0, atol=1e-9)
    assert kernel.info["duration_mean_s"] == ref.info["duration_mean_s"]
    # the heel strikes are train's (right shank peaks of the whole recording)
    offline_hs = heel_strikes(rec, "right_shank", RATE_HZ).times_s
    for h in c.heel_strikes:
        assert np.min(np.abs(offline_hs - h)) < 1e-9


def test_a_stop_and_a_missing_heel_strike_are_reported_not_used(rec: Recording) -> None:
    t, x = window(rec, 8.0, 16.0)
    stop = np.searchsorted(t, 12.5)
    still = np.repeat(x[stop:stop + 1], round(4.0 * RATE_HZ), axis=0)  # 4 s standing still mid-walk
    t2 = np.concatenate([t[:stop], t[stop] + np.arange(len(still)) / RATE_HZ, t[stop:] + len(still) / RATE_HZ])
    x2 = np.concatenate([x[:stop], still, x[stop:]])
    c = StrideCollector("Slow", TeachOptions(strides=10), rate_hz=RATE_HZ)
    events = feed(c, t2, x2)
    assert not c.done
    assert sum("no heel strike found in the last" in e for e in events) == 1, events  # once per stop
    assert any("not a stride (> 2.5 s: a stop or a turn), not used" in e for e in events), events
    assert all(b - a <= 2.5 for a, b in c.candidates)


def test_a_heel_strike_not_found_is_named_as_such(rec: Recording) -> None:
    """Two good strides' time between heel strikes (Med, 2.8 s > 2.5 s; made by stretching one
    stride in time): not used, and the log says a heel strike between may not have been found."""
    t, x = window(rec, 22.5, 45.0)
    hs = heel_strikes(Recording(t, x), "right_shank", RATE_HZ).times_s
    a, b = hs[5], hs[6]
    t = np.where((t >= a) & (t < b), a + (t - a) * 2.0, np.where(t >= b, t + (b - a), t))
    c = StrideCollector("Med", TeachOptions(strides=20), rate_hz=RATE_HZ)
    events = feed(c, t, x)
    gap = [e for e in events if "not a stride" in e]
    assert len(gap) == 1 and gap[0].endswith("a stop or a turn, or a heel strike between not found), not used"), events


def test_duration_and_shape_outliers_are_not_used(rec: Recording) -> None:
    t, x = window(rec, 22.5, 45.0)
    hs = heel_strikes(Recording(t, x), "right_shank", RATE_HZ).times_s
    # Stride 4 lasts 25 % longer (time stretched), stride 6 has a 20-degree bump on every channel.
    a, b = hs[4], hs[5]
    inside = (t >= a) & (t < b)
    t = np.where(inside, a + (t - a) * 1.25, np.where(t >= b, t + 0.25 * (b - a), t))
    c0, c1 = hs[6] + 0.25 * (b - a), hs[7] + 0.25 * (b - a)
    bump = (t >= c0) & (t < c1)
    x[bump] += 20.0 * np.sin(np.pi * (t[bump] - c0) / (c1 - c0))[:, None]
    c = StrideCollector("Med", TeachOptions(strides=8), rate_hz=RATE_HZ)
    events = feed(c, t, x)
    assert c.done
    rejected = {round(s.start_s, 2): s.rejected for s in c.result.strides if s.rejected}
    assert any(r.startswith("duration") for r in rejected.values()), rejected
    assert any(r.startswith("shape") for r in rejected.values()), rejected
    assert any("not used: duration" in e for e in events) and any("not used: shape" in e for e in events)
    assert c.result.kernel.info["strides"] == 8 and c.result.kernel.info["strides_found"] == 10


def test_never_fewer_than_train_min_strides(rec: Recording) -> None:
    for bad in (0, 2, 101, 2.5, True):
        with pytest.raises(GaitEstimatorError, match=r"teach strides must be an integer 3\.\.100"):
            TeachOptions(strides=bad)
    with pytest.raises(GaitEstimatorError, match="heel-strike channel"):
        TeachOptions(channel="tail")
    c = StrideCollector("Slow", TeachOptions(strides=3), rate_hz=RATE_HZ)
    events = feed(c, *window(rec, 8.0, 30.0))
    assert c.done and c.result.kernel.info["strides"] == 3 and "Slow: 2/3 strides" in events


def test_rate_from_the_samples_without_a_library(rec: Recording) -> None:
    t, x = window(rec, 8.0, 20.0)
    c = StrideCollector("Slow", TeachOptions(strides=3))
    feed(c, t, x)
    assert c.done and c.result.kernel.sample_rate_hz == pytest.approx(RATE_HZ, rel=1e-9)


def test_library_add_replace_and_near_copies(rec: Recording, able_bodied) -> None:
    c = StrideCollector("Slow", TeachOptions(strides=4), rate_hz=RATE_HZ)
    feed(c, *window(rec, 8.0, 20.0))
    taught = c.result
    lib, old = with_mode(None, taught.kernel)
    assert lib.mode_names == ["Slow"] and old is None and lib.provenance["taught"] == ["Slow"]
    assert near_copies(lib, "Slow") == []
    # the same strides taught under another name: a near copy, said so
    copy = replace(taught.kernel, name="Slow2")
    lib2, _ = with_mode(lib, copy)
    assert near_copies(lib2, "Slow2") == ["Slow"]
    assert "near copy of Slow" in change_summary(replace(taught, kernel=copy), lib2, None, ["Slow"])
    # replacing a mode of a loaded library keeps the others and their order
    lib3, replaced = with_mode(able_bodied, taught.kernel)
    assert lib3.mode_names == able_bodied.mode_names and replaced is able_bodied.mode("Slow")
    assert lib3.mode("Slow") is taught.kernel and lib3.mode("Med") is able_bodied.mode("Med")
    assert "replaced Slow (was N=392" in change_summary(taught, lib3, replaced, [])
    assert near_copies(lib3, "Slow") == []
    with pytest.raises(GaitEstimatorError, match="Hz"):
        with_mode(lib, replace(copy, name="x", sample_rate_hz=100.0))


def test_one_taught_mode_estimates_mode_and_phase(rec: Recording) -> None:
    """A library of one mode: every ready estimate is that mode, with the phase of the stride."""
    c = StrideCollector("Slow", TeachOptions(strides=3), rate_hz=RATE_HZ)
    feed(c, *window(rec, 8.0, 20.0))
    lib, _ = with_mode(None, c.result.kernel)
    est = Estimator(lib)
    t, x = window(rec, 14.0, 21.0)
    out = [est.update(float(ti), xi) for ti, xi in zip(t, x, strict=True)]
    ready = [e for e in out if e.ready]
    assert len(ready) > 0.5 * len(out) and {e.mode for e in ready} == {"Slow"}
    hs = heel_strikes(rec, "right_shank", RATE_HZ).times_s
    errors = []
    for e in ready:
        k = np.searchsorted(hs, e.time_s) - 1
        if 0 <= k < hs.size - 1 and hs[k + 1] - hs[k] < 2.5:
            truth = (e.time_s - hs[k]) / (hs[k + 1] - hs[k])
            errors.append(min(abs(e.phase - truth), 1 - abs(e.phase - truth)))
    assert errors and float(np.mean(errors)) < 0.03


def test_minutes_without_a_stride_keep_the_buffer_bounded(rec: Recording) -> None:
    """Ten minutes of standing while teaching: the collector keeps a few seconds of the stream
    (not ten minutes), and strides before and after the stop still give train's kernel."""
    t1, x1 = window(rec, 8.0, 14.0)
    t2, x2 = window(rec, 14.0, 30.0)
    n = round(600.0 * RATE_HZ)
    still = x1[-1] + np.random.default_rng(1).normal(0.0, 0.05, (n, 4))
    t = np.concatenate([t1, t1[-1] + np.arange(1, n + 1) / RATE_HZ, t2 + n / RATE_HZ])
    x = np.concatenate([x1, still, x2])
    c = StrideCollector("Slow", TeachOptions(strides=6), rate_hz=RATE_HZ)
    most, events = 0, []
    for ti, xi in zip(t, x, strict=True):
        events += c.push(float(ti), tuple(xi))
        most = max(most, c.buffered)
        if c.done:
            break
    det = c.options.detection
    bound = (det.max_stride_s + det.min_stride_s + KEEP_MARGIN_S + 2 * ANALYSIS_PERIOD_S) * RATE_HZ
    assert most <= bound, f"{most} samples kept (at most {bound:.0f} expected)"
    assert c.done, events
    assert sum("no heel strike found in the last" in e for e in events) == 1, events
    assert c.candidates[0][1] < t1[-1] < c.candidates[-1][0], "strides from before and after the stop"
    doctored = Recording(t, x)
    ref = offline(doctored, c, "Slow").library.mode("Slow")
    assert c.result.kernel.info["strides"] == ref.info["strides"] == 6
    np.testing.assert_allclose(c.result.kernel.samples, ref.samples, rtol=0, atol=1e-9)
