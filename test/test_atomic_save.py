"""Atomic saves: a process killed while saving never leaves a broken file in place of the last
good one (a taught or personalised library, a calibration, a labelled recording, label ranges).

For each kind of file a later run loads, a forked child saves two versions of it in turn,
forever, over one target; the parent kills it (SIGKILL) after a random delay, many times, and
checks that the target is always exactly one of the two complete files.
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gait_estimator.analysis.labels import LabelRange, read_label_ranges, write_label_ranges
from gait_estimator.core.channels import CHANNELS
from gait_estimator.core.imu import ImuCalibration, SegmentMount
from gait_estimator.core.kernels import KernelLibrary, make_mode
from gait_estimator.io.imu_stream import load_calibration, save_calibration
from gait_estimator.io.library_io import load_library, save_library
from gait_estimator.io.readers import read_recording
from gait_estimator.io.recording import read_project_csv, write_project_csv

KILLS = 20
"""Kills per kind of file."""

Save = Callable[[int, Path], object]
"""``save(k, target)`` writes version ``k`` (0 old, 1 new) of a file to ``target``."""


def _big(lib: KernelLibrary, name: str, offset: float, copies: int = 4) -> KernelLibrary:
    modes = [
        make_mode(f"{m.name}_{k}", m.samples + offset + 0.001 * k, m.sample_rate_hz, m.mode_id)
        for k in range(copies)
        for m in lib.modes
    ]
    return KernelLibrary(name, tuple(modes), {"source": "test_atomic_save"}, "")


def _same(a: KernelLibrary, b: KernelLibrary) -> bool:
    return a.name == b.name and a.mode_names == b.mode_names and all(
        np.array_equal(x.samples, y.samples) for x, y in zip(a.modes, b.modes, strict=True)
    )


def _savers(kind: str, able_bodied: KernelLibrary, swge: Path) -> tuple[str, Save, Callable[[Path], object]]:
    """Target file name, ``save(k, target)``, and how the file is loaded by a later run."""
    if kind.startswith("library"):
        libs = [_big(able_bodied, "old", 0.0), _big(able_bodied, "new", 1.0)]
        return f"lib{kind[7:]}", lambda k, t: save_library(libs[k], t), load_library
    if kind == "calibration":
        cals = [ImuCalibration(tuple(SegmentMount.from_axes("+z", "-x", standing_deg=s) for _ in CHANNELS))
                for s in (3.0, -7.5)]
        return "user.imu.yaml", lambda k, t: save_calibration(cals[k], t), load_calibration
    if kind == "recording csv":
        rec = read_recording(swge / "recordings" / "Multispeed_Walk_AB.csv")
        recs = [rec, rec.slice(0, len(rec) // 2)]
        return "rec.csv", lambda k, t: write_project_csv(recs[k], t), read_project_csv
    ranges = [[LabelRange(10.0 * i + k, 10.0 * i + 5, f"m{i % 7}") for i in range(2000)] for k in (0, 1)]
    return "labels.csv", lambda k, t: write_label_ranges(ranges[k], t), read_label_ranges


def _strays(target: Path) -> list[Path]:
    """Temporary files of saves over ``target`` (atomic.py names them .NAME.*.tmp)."""
    return list(target.parent.glob(f".{target.name}.*.tmp"))


def _kill_while_saving(target: Path, save: Save, delay_s: float, in_write: bool) -> None:
    """Kill a child saving over ``target`` after ``delay_s``; ``in_write``: counted from the
    moment its temporary file appears (a kill then lands inside the write, or just after)."""
    pid = os.fork()
    if pid == 0:  # the child: save old, new, old, ... until killed
        try:
            k = 0
            while True:
                save(k % 2, target)
                k += 1
        finally:
            os._exit(1)
    deadline = time.monotonic() + 5.0
    while in_write and not _strays(target) and time.monotonic() < deadline:
        pass
    time.sleep(delay_s)
    os.kill(pid, signal.SIGKILL)
    _, status = os.waitpid(pid, 0)
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL


@pytest.mark.parametrize("kind", ["library.npz", "library.yaml", "calibration", "recording csv", "label ranges"])
def test_killed_saves_leave_the_old_or_the_new_file(tmp_path, able_bodied, swge, kind):
    name, save, load = _savers(kind, able_bodied, swge)
    target = tmp_path / name
    refs = [tmp_path / f"ref{k}_{name}" for k in (0, 1)]
    for k, ref in enumerate(refs):
        save(k, ref)
    ref_bytes = [r.read_bytes() for r in refs]
    ref_libs = [load_library(r) for r in refs] if name.endswith(".npz") else []
    t0 = time.perf_counter()
    save(0, target)
    save_s = time.perf_counter() - t0
    rng = np.random.default_rng(31)
    interrupted = 0
    for i in range(KILLS):
        in_write = i % 2 == 1
        _kill_while_saving(target, save, rng.uniform(0, save_s / 4 if in_write else 2 * save_s), in_write)
        if ref_libs:  # npz: zip entries carry times; the content is one of the two
            assert any(_same(load_library(target), ref) for ref in ref_libs)
        else:  # deterministic text: byte for byte one of the two
            assert target.read_bytes() in ref_bytes
        load(target)
        stray = _strays(target)
        interrupted += bool(stray)
        for f in stray:  # a kill inside a save leaves its temporary file, never the target
            f.unlink()
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
