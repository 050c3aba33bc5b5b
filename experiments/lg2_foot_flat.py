"""Evidence for experiments/lg2_ramp_labels.csv: foot-flat angle of every stride of LG_2_Ramp.

For each stride (right heel strike to the next, detected as in `gait-estimator train`), prints
the median right- and left-foot angle over the samples where that foot is flat (angular speed
below 15 deg/s): the slope of the ground under it plus the sensor's standing offset. As a
cross-check it also prints the bundled able-bodied kernel nearest to the stride (RMS over the
4 input angles after time-normalising the stride to the kernel's length, at 230 Hz), and what
the labelled strides whose nearest kernel is of another mode cost an estimator that reads every
stride as its nearest kernel: the bound on level and overall accuracy (level = Slow, Med or Fast)
over the recording's labelled samples (its raw stamps, as docs/new_wearer.md's LG2-AB).

Usage: python experiments/lg2_foot_flat.py [path/to/LG_2_Ramp_AB_Sample.csv]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from gait_estimator import load_library
from gait_estimator.analysis.labels import labels_from_ranges, read_label_ranges
from gait_estimator.analysis.strides import heel_strikes, normalise_strides, resample_uniform, stride_bounds
from gait_estimator.io.readers import read_recording

HERE = Path(__file__).resolve().parent
DEFAULT = HERE.parent / "data" / "swge" / "recordings" / "LG_2_Ramp_AB_Sample.csv"
FLAT_DEG_PER_S = 15.0
STANDING_S = (3.0, 4.9)
LEVEL = ("Slow", "Med", "Fast")


def main(path: Path) -> None:
    rec = read_recording(path)
    uni = resample_uniform(rec, rec.median_rate_hz)
    hs = heel_strikes(rec, "right_foot")
    bounds, others = stride_bounds(hs.times_s)
    ranges = read_label_ranges(HERE / "lg2_ramp_labels.csv")
    lib = load_library("able_bodied")
    ref = resample_uniform(rec, lib.sample_rate_hz)
    still = (uni.time_s >= STANDING_S[0]) & (uni.time_s < STANDING_S[1])
    print(f"{path.name}: heel strikes from {hs.method}")
    print(
        f"standing {STANDING_S[0]:g}-{STANDING_S[1]:g} s: right foot {np.median(uni.extra['right_foot_deg'][still]):+.1f} deg, "
        f"left foot {np.median(uni.extra['left_foot_deg'][still]):+.1f} deg"
    )
    print(f"{'start_s':>8} {'end_s':>7} {'dur_s':>6} {'R_flat':>7} {'L_flat':>7}  {'label':<6} nearest bundled kernel (RMS deg)")
    labels = labels_from_ranges(rec.time_s, ranges)  # per raw sample
    lost = np.zeros(len(rec.time_s), dtype=bool)
    for a, b in bounds:
        inside = (uni.time_s >= a) & (uni.time_s < b)
        cells = []
        for col in ("right_foot_deg", "left_foot_deg"):
            x = uni.extra[col]
            flat = inside & (np.abs(np.gradient(x, uni.time_s)) < FLAT_DEG_PER_S)
            cells.append(f"{np.median(x[flat]):+7.1f}" if flat.any() else "    n/a")
        rms = {
            m.name: float(np.sqrt(np.mean((normalise_strides(ref.time_s, ref.angles_deg, np.array([[a, b]]), m.length)[0]
                                           - m.samples) ** 2)))
            for m in lib.modes
        }
        best = sorted(rms, key=rms.__getitem__)[:2]
        mid = labels_from_ranges(np.array([0.5 * (a + b)]), ranges)[0] or "-"
        near = ", ".join(f"{n} {rms[n]:.1f}" for n in best)
        print(f"{a:8.3f} {b:7.3f} {b - a:6.3f} {cells[0]} {cells[1]}  {mid:<6} {near}")
        if mid != "-" and best[0] != mid and not (mid == "level" and best[0] in LEVEL):
            lost |= (rec.time_s >= a) & (rec.time_s < b) & (labels == mid)
    for a, b in others:
        print(f"not a stride: {a:.3f}-{b:.3f} s ({b - a:.2f} s)")
    labelled = labels != ""
    level = labels == "level"
    print(f"labelled samples whose stride is nearest to another mode's kernel: {int(lost.sum())} of "
          f"{int(labelled.sum())} ({int((lost & level).sum())} of {int(level.sum())} level): read that way, "
          f"accuracy at most {100 * (1 - lost.sum() / labelled.sum()):.1f} %, level at most "
          f"{100 * (1 - (lost & level).sum() / level.sum()):.1f} %")


if __name__ == "__main__":
    if sys.argv[1:2] in (["-h"], ["--help"]):
        sys.exit(print(__doc__))
    if len(sys.argv) > 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT)
