#!/bin/sh
# Reproduces every number of docs/training.md, "Results on the bundled recordings", and the
# accuracy rows of the README's results table (then run: make docs).
# Usage (with gait-estimator installed; paths are relative to the repository root):
#     sh experiments/run.sh [OUT_DIR]        # default OUT_DIR: experiments/results
# Uses the recordings bundled in data/swge.
set -eu
cd "$(dirname "$0")/.."  # repository root: paths below (and in the outputs) are relative to it
HERE=experiments
REC=data/swge/recordings
OUT=${1:-$HERE/results}
GE=${GAIT_ESTIMATOR:-gait-estimator}
mkdir -p "$OUT"
LG2=$REC/LG_2_Ramp_AB_Sample.csv
MS=$REC/Multispeed_Walk_AB.csv

echo "== LG_2_Ramp: train level/RA/RD kernels (labels by time range, right-foot heel strikes)"
$GE train "$LG2" --labels "$HERE/lg2_ramp_labels.csv" --heel-strikes right_foot --out "$OUT/lg2_kernels.yaml"

echo "== LG_2_Ramp: uniform copy at the library rate (median rate) with labels and heel strikes, then in-sample evaluation"
$GE resample "$LG2" --labels "$HERE/lg2_ramp_labels.csv" --heel-strikes right_foot --out "$OUT/lg2_uniform.csv"
$GE process "$OUT/lg2_uniform.csv" --kernels "$OUT/lg2_kernels.yaml" --out "$OUT/lg2_pred.csv" --quiet
$GE evaluate --predictions "$OUT/lg2_pred.csv" --truth "$OUT/lg2_uniform.csv" --out-dir "$OUT/lg2_insample" \
    --title "LG_2_Ramp, kernels trained on the same recording (in-sample)"

echo "== LG_2_Ramp: bundled able_bodied kernels (230 Hz copy); level counts as correct for Slow, Med or Fast"
$GE resample "$LG2" --rate 230 --labels "$HERE/lg2_ramp_labels.csv" --heel-strikes right_foot --out "$OUT/lg2_230.csv"
$GE process "$OUT/lg2_230.csv" --kernels able_bodied --out "$OUT/lg2_able_bodied_pred.csv" --quiet
$GE evaluate --predictions "$OUT/lg2_able_bodied_pred.csv" --truth "$OUT/lg2_230.csv" --label-map 'level=Slow|Med|Fast' \
    --out-dir "$OUT/lg2_able_bodied" --title "LG_2_Ramp, bundled able_bodied kernels"

echo "== Multispeed: labels from stride durations (right-shank heel strikes), bundled able_bodied kernels"
$GE label-strides "$MS" --kernels able_bodied --modes Slow,Med,Fast --heel-strikes right_shank --out "$OUT/multispeed_labels.csv"
$GE process "$MS" --kernels able_bodied --out "$OUT/multispeed_pred.csv" --quiet
$GE evaluate --predictions "$OUT/multispeed_pred.csv" --truth "$MS" --labels "$OUT/multispeed_labels.csv" \
    --heel-strikes right_shank --out-dir "$OUT/multispeed" --title "Multispeed_Walk_AB, bundled able_bodied kernels"

echo "== Multispeed, harsher labels: every stride within 15 % of a kernel duration (speed changes included)"
$GE label-strides "$MS" --kernels able_bodied --modes Slow,Med,Fast --heel-strikes right_shank --all-strides \
    --out "$OUT/multispeed_labels_all.csv"
$GE evaluate --predictions "$OUT/multispeed_pred.csv" --truth "$MS" --labels "$OUT/multispeed_labels_all.csv" \
    --heel-strikes right_shank --out-dir "$OUT/multispeed_all" --title "Multispeed_Walk_AB, all strides labelled, able_bodied"

echo "== Multispeed, personal kernels: 1:1 split (train on the first half of every steady run, test on the second)"
${PYTHON:-python} "$HERE/split_ranges.py" "$OUT/multispeed_labels.csv" "$OUT/multispeed_train.csv" "$OUT/multispeed_test.csv"
$GE train "$MS" --labels "$OUT/multispeed_train.csv" --heel-strikes right_shank --out "$OUT/multispeed_kernels.yaml"
$GE process "$MS" --kernels "$OUT/multispeed_kernels.yaml" --out "$OUT/multispeed_personal_pred.csv" --quiet
$GE evaluate --predictions "$OUT/multispeed_personal_pred.csv" --truth "$MS" --labels "$OUT/multispeed_test.csv" \
    --heel-strikes right_shank --out-dir "$OUT/multispeed_split" --title "Multispeed_Walk_AB, kernels from the first halves, tested on the second halves"

if [ "$OUT" = "$HERE/results" ]; then
    echo "== Tables for README.md and docs/ (experiments/results/evaluation and headline/tables.md)"
    ${PYTHON:-python} "$HERE/summary_tables.py"
fi
