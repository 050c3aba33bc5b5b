"""Split every label range at its midpoint into a training and a test range file.

Used for a 1:1 train/test split of one recording (as the paper splits its trials): kernels are
trained on the first half of every labelled run and evaluated on the second half. Strides that
straddle a midpoint are in neither half for training (train skips strides spanning labels).

Usage: python experiments/split_ranges.py RANGES.csv TRAIN.csv TEST.csv
"""

from __future__ import annotations

import sys

from gait_estimator.analysis.labels import LabelRange, read_label_ranges, write_label_ranges


def main(src: str, train: str, test: str) -> None:
    ranges = read_label_ranges(src)
    mids = [0.5 * (r.start_s + r.end_s) for r in ranges]
    note = f"split of {src} at the midpoint of every range (experiments/split_ranges.py)"
    first = [LabelRange(r.start_s, m, r.mode) for r, m in zip(ranges, mids, strict=True)]
    second = [LabelRange(m, r.end_s, r.mode) for r, m in zip(ranges, mids, strict=True)]
    write_label_ranges(first, train, ["training half: " + note])
    write_label_ranges(second, test, ["test half: " + note])
    print(f"wrote {train} and {test} ({len(ranges)} ranges each)")


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(*sys.argv[1:])
