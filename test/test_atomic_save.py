"""Atomic saves: a process killed while saving never leaves a broken file in place of the last
good one (a taught or personalised library, a calibration, a labelled recording).

A forked child saves two large libraries in turn, forever, over one target; the parent kills it
(SIGKILL) after a random delay, many times, and checks that the target is always exactly one of
the two complete files.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.core.kernels import KernelLibrary, make_mode
from gait_estimator.io.library_io import load_library, save_library
from gait_estimator.io.recording import read_project_csv, write_project_csv

KILLS = 40
"""Kills in total, alternating between the .npz and .yaml forms."""


def _big(lib: KernelLibrary, name: str, offset: float, copies: int = 4) -> KernelLibrary:
    modes = [
        make_mode(f"{m.name}_{k}", m.samples + offset + 0.001 * k, m.sample_rate_hz, m.mode_id)
        for k in range(copies)
        for m in lib.modes
    ]
    return KernelLibrary(name, tuple(modes), {"source": "test_atomic_save"}, "")


def _kill_while_saving(target: Path, libs: list[KernelLibrary], delay_s: float) -> None:
    pid = os.fork()
    if pid == 0:  # the child: save old, new, old, ... until killed
        try:
            k = 0
            while True:
                save_library(libs[k % 2], target)
                k += 1
        finally:
            os._exit(1)
    time.sleep(delay_s)
    os.kill(pid, signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL


def _same(a: KernelLibrary, b: KernelLibrary) -> bool:
    return a.name == b.name and a.mode_names == b.mode_names and all(
        np.array_equal(x.samples, y.samples) for x, y in zip(a.modes, b.modes, strict=True)
    )


def test_killed_saves_leave_the_old_or_the_new_library(tmp_path, able_bodied):
    libs = [_big(able_bodied, "old", 0.0), _big(able_bodied, "new", 1.0)]
    rng = np.random.default_rng(31)
    interrupted = 0
    for suffix in (".npz", ".yaml"):
        target = tmp_path / f"lib{suffix}"
        refs = [tmp_path / f"ref_{lib.name}{suffix}" for lib in libs]
        for lib, ref in zip(libs, refs, strict=True):
            save_library(lib, ref)
        ref_bytes = [r.read_bytes() for r in refs]
        ref_libs = [load_library(r) for r in refs] if suffix == ".npz" else []
        t0 = time.perf_counter()
        save_library(libs[0], target)
        save_s = time.perf_counter() - t0
        for _ in range(KILLS // 2):
            _kill_while_saving(target, libs, rng.uniform(0.002, 0.002 + 2 * save_s))
            if suffix == ".yaml":  # deterministic text: the file is byte for byte one of the two
                assert target.read_bytes() in ref_bytes
            else:
                got = load_library(target)
                assert any(_same(got, ref) for ref in ref_libs)
            stray = list(tmp_path.glob(f".{target.name}.*.tmp"))
            interrupted += bool(stray)
            for f in stray:  # a kill inside a save leaves its temporary file, never the target
                f.unlink()
        assert load_library(target).name in ("old", "new")
    assert interrupted > 0, "no kill landed inside a save: the test did not test anything"


def test_a_csv_write_that_fails_midway_keeps_the_old_file(tmp_path, swge):
    """Project CSVs (and label ranges, predictions) are written the same way: an error after
    half the rows leaves the previous file, and no temporary file."""
    rec = read_project_csv(swge / "recordings" / "LG_2_Ramp_AB_Sample.csv").slice(0, 200)
    target = write_project_csv(rec, tmp_path / "rec.csv")
    before = target.read_bytes()
    rec.extra = {"foot_deg": np.zeros(100)}  # too short: the writer fails at row 100
    with pytest.raises(IndexError):
        write_project_csv(rec, target)
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["rec.csv"]
