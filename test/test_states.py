"""The states beside the mode (core/states.py) and the units check (core/units.py)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from imu_synth import gait_angles
from synthetic import generate, new_wearer, with_stops

from gait_estimator.analysis.train import TrainOptions, train_library
from gait_estimator.cli import main
from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.core.pipeline import PipelineParams
from gait_estimator.core.states import (
    FIT_LIMIT_KEY,
    MEMORY,
    NOT_READY,
    STANDING,
    UNKNOWN_STATE,
    WALKING,
    StateParams,
    knee_speed_dps,
    state_step,
)
from gait_estimator.core.units import UnitsCheck, first_problem
from gait_estimator.io.library_io import load_library, save_library
from gait_estimator.io.readers import read_recording

REPO = Path(__file__).resolve().parents[1]


def test_stop_and_start_of_a_new_wearer(able_bodied) -> None:
    """A new wearer stops twice for 4 s: ``stand`` within 0.5 s of the segments coming to rest,
    walking again within one stride of the first movement; never a phase unless walking."""
    syn = generate(able_bodied, [("Med", 10)], new_wearer(3), seed=5)
    stand_pose = able_bodied.mode("Med").samples[0]
    fade = 0.6
    rec = with_stops(syn.recording, {3: 4.0, 6: 4.0}, stand_pose, seed=1, fade_s=fade)
    tr = run_estimator(Estimator(able_bodied), rec.time_s, rec.angles_deg)
    t = rec.time_s
    stopped = rec.labels == ""
    edges = np.flatnonzero(np.diff(stopped.astype(int)))
    assert len(edges) == 4
    stride = float(np.median(syn.stride_durations_s))
    for a, b in zip(edges[::2] + 1, edges[1::2], strict=True):
        rest, go = t[a] + fade, t[b] - fade
        first_stand = t[(t >= rest) & (tr.state == STANDING)][0]
        assert first_stand - rest <= 0.5
        assert (tr.state[(t >= first_stand) & (t < go)] == STANDING).all()
        assert t[(t >= go) & (tr.state == WALKING)][0] - go <= stride
    assert set(tr.mode[tr.state == STANDING]) == {"stand"}
    assert np.isnan(tr.phase[tr.state != WALKING]).all()
    assert np.isfinite(tr.phase[tr.state == WALKING]).all()
    assert (tr.state[~tr.ready] == NOT_READY).all() and set(tr.mode[~tr.ready]) == {""}


def test_the_paper_preset_reports_library_modes_only(able_bodied, multispeed_csv: Path) -> None:
    """states off: mode and phase as the paper's (the best of a partial window too), state 0/1."""
    rec = read_recording(multispeed_csv).slice(0, 3000)  # standing, then walking
    on = run_estimator(Estimator(able_bodied), rec.time_s, rec.angles_deg)
    off = run_estimator(Estimator(able_bodied, EstimatorConfig(states=False)), rec.time_s, rec.angles_deg)
    assert (on.state == STANDING).any()
    np.testing.assert_array_equal(off.state, off.ready.astype(int))
    np.testing.assert_array_equal(off.mode, np.asarray(able_bodied.mode_names, dtype=object)[off.mode_index])
    assert np.isfinite(off.phase).all()
    np.testing.assert_array_equal(on.mode_index, off.mode_index)
    assert not EstimatorConfig.preset("paper").states


def fast_strides(library, duration: float, knee_gain: float, **states: float):
    """12 strides of the Fast kernel ``duration`` times as long with ``knee_gain`` x its knee
    flexion (shank - thigh about its mean), through the default preset with ``states``."""
    fast = library.mode("Fast").samples
    knee = (fast[:, 2:] - fast[:, :2]) - (fast[:, 2:] - fast[:, :2]).mean(axis=0)
    run = fast.copy()
    run[:, 2:] += (knee_gain - 1.0) * knee
    n = round(len(run) * duration)
    src = np.linspace(0, 1, len(run), endpoint=False)
    stride = np.stack([np.interp(np.linspace(0, 1, n, endpoint=False), src, run[:, c], period=1.0) for c in range(4)], 1)
    x = np.tile(stride, (12, 1))
    t = np.arange(len(x)) / library.sample_rate_hz
    config = EstimatorConfig()
    est = Estimator(library, config, params=PipelineParams.from_config(config, states=states) if states else None)
    return run_estimator(est, t, x)


def test_running_like_strides_are_unknown(able_bodied) -> None:
    """Strides 0.7 as long as the Fast kernel's with 1.6x its knee flexion match no mode."""
    tr = fast_strides(able_bodied, 0.7, 1.6)
    assert np.mean(tr.state[tr.ready] == UNKNOWN_STATE) >= 0.9


def test_short_strides_with_a_walking_knee_are_walking(able_bodied) -> None:
    """Strides 0.74 as long as the Fast kernel's (over ``max_cadence_ratio``) with its knee
    flexion: walking (a last stride before a stop); unknown on cadence alone."""
    tr = fast_strides(able_bodied, 0.74, 1.0)
    assert np.mean(tr.mode[tr.ready] == "Fast") >= 0.9
    alone = fast_strides(able_bodied, 0.74, 1.0, knee_speed_ratio=0.0)
    assert np.mean(alone.state[alone.ready] == UNKNOWN_STATE) >= 0.9


def lg2_states(library, swge: Path, **states: float) -> tuple[np.ndarray, np.ndarray]:
    """LG_2_Ramp's time and states with ``states`` (StateParams fields) on the default preset."""
    rec = read_recording(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv")
    config = EstimatorConfig()
    est = Estimator(library, config, params=PipelineParams.from_config(config, states=states))
    return rec.time_s, run_estimator(est, rec.time_s, rec.angles_deg).state


def test_walking_from_the_first_stride_after_a_stop(able_bodied, swge: Path) -> None:
    """LG_2_Ramp stands 3.0-4.9 s; the window still holds the standing samples in the first
    stride (labelled level from 5.5 s), whose fit is beyond the limit: judged one stride later."""
    t, state = lg2_states(able_bodied, swge)
    first = (t >= 5.5) & (t < 6.0)
    assert np.all(state[(t >= 4.2) & (t < 4.9)] == STANDING) and np.all(state[first] == WALKING)
    assert np.mean(lg2_states(able_bodied, swge, start_strides=0.0)[1][first] == UNKNOWN_STATE) > 0.5


def test_slowing_to_a_stop_is_unknown(able_bodied, swge: Path) -> None:
    """After its last stride (to 13.6 s) LG_2_Ramp's legs drift to a halt; the fit stays within
    the limit to 14.3 s."""
    t, state = lg2_states(able_bodied, swge)
    slowing = (t >= 14.2) & (t < 14.4)
    assert np.all(state[slowing] == UNKNOWN_STATE)
    assert np.all(lg2_states(able_bodied, swge, slow_speed_dps=0.0)[1][slowing] == WALKING)


def test_train_stores_each_modes_fit_limit_and_old_files_load(able_bodied, tmp_path: Path) -> None:
    syn = generate(able_bodied, [("Slow", 8), ("Fast", 8)], new_wearer(1), seed=2).recording
    lib = train_library([syn], "taught", TrainOptions(heel_strikes="column")).library
    limits = [m.info[FIT_LIMIT_KEY] for m in lib.modes]
    assert all(0 < v < 10 for v in limits)
    back = load_library(save_library(lib, tmp_path / "lib.yaml"))
    assert [m.info[FIT_LIMIT_KEY] for m in back.modes] == limits
    params = StateParams()
    np.testing.assert_allclose(params.limits(back), params.fit_limit_scale * np.array(limits))
    np.testing.assert_array_equal(params.limits(able_bodied), params.default_fit_limit_deg)  # the paper's files


def test_units_check_flags_the_wrong_unit_and_nothing_else(swge: Path) -> None:
    for name in ("Multispeed_Walk_AB.csv", "LG_2_Ramp_AB_Sample.csv"):
        rec = read_recording(swge / "recordings" / name)
        t = rec.time_s - rec.time_s[0]
        assert first_problem(t, rec.angles_deg) is None
        when, why = first_problem(t, np.degrees(rec.angles_deg))
        assert when <= 0.5 and "degrees read as radians" in why
        when, why = first_problem(t, np.radians(rec.angles_deg))
        # the first step (a segment swinging 30 deg within 1 s): Multispeed 8.7 s (before it the
        # wearer stands and shifts weight: in radians, a still wearer in degrees), LG_2_Ramp 1.2 s
        first_step = 8.7 if name.startswith("Multi") else 1.2
        assert first_step < when <= first_step + 2.0 and "radians read as degrees" in why, when
    check = UnitsCheck()
    assert all(check.observe(i / 100, [0.0, 0.0, 0.0, 0.0]) is None for i in range(500))  # still: no verdict


def test_units_check_leaves_a_start_from_a_pose_at_zero_alone() -> None:
    """The IMU tests' angles (standing at 0, walking blended in from 0): within +-1.6 deg and moving
    for a few samples, then far beyond: degrees. In radians the same start is flagged."""
    for rate in (100.0, 200.0, 230.0):
        for seed in range(6):
            a = gait_angles(rate, walk_s=6.0, seed=seed)
            t = np.arange(len(a)) / rate
            assert first_problem(t, a) is None, (rate, seed)
            assert first_problem(t, np.radians(a))[0] <= 2.0 + 2.0


def test_process_warns_once_about_a_bag_in_the_wrong_unit(multispeed_csv: Path, tmp_path: Path, capsys) -> None:
    bag = tmp_path / "deg_bag"
    assert main(["convert", str(multispeed_csv), "--out-bag", str(bag), "--units", "deg"]) == 0
    capsys.readouterr()
    assert main(["process", str(bag), "--stop", "2000", "-q"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"warning: {bag}: input_units rad: from ") and "degrees" in err[0]
    assert main(["process", str(bag), "--input-units", "deg", "--stop", "2000", "-q"]) == 0
    assert capsys.readouterr().err == ""


def test_the_controller_page_shows_the_tested_example() -> None:
    """docs/controller.md quotes examples/impedance_controller.py (test_controller.py runs it)."""
    doc = (REPO / "docs" / "controller.md").read_text(encoding="utf-8")
    (code,) = re.findall(r"```python\n(.*?)```", doc, re.S)
    assert code.strip() in (REPO / "examples" / "impedance_controller.py").read_text(encoding="utf-8")


def test_a_kernels_knee_speed_is_what_state_step_measures_of_it(able_bodied) -> None:
    """``knee_speed_dps`` (the filters' periodic steady state) equals ``state_step``'s knee speed
    average over a stride of that kernel streamed at its own rate, for every mode."""
    p = StateParams()
    span = p.slow_tau_s - p.fast_tau_s
    for mode in able_bodied.modes:
        x = np.tile(mode.samples, (30, 1))
        t = np.arange(len(x)) / mode.sample_rate_hz
        mem = np.zeros(MEMORY)
        seen = []
        for i in range(len(x)):
            state_step(mem, t[i], *x[i], np.ones(4), True, 0.0, 1.0, 1.0, 0.0, 1.0, 2.0, 1.0, 4.0, p.fast_tau_s,
                       p.slow_tau_s, p.knee_tau_s, p.stand_after_s, p.unknown_after_s)
            seen.append(0.5 * (mem[18] + mem[19]) / span)
        expected = knee_speed_dps(mode.samples, mode.sample_rate_hz, p.fast_tau_s, p.slow_tau_s)
        assert np.mean(seen[-mode.length:]) == pytest.approx(expected, rel=1e-9), mode.name
