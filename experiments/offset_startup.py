"""Does the walking offset calibration start when one sensor is far off? (new_wearer.md, offsets)

The kernels' own Slow, Med and Fast strides (25 each, 230 Hz) with sensor offsets added: each
sensor 6 deg up and down, and two mixed sets; 30 cases per offset tolerance. A case fails when
the learnt offset ends more than 1 deg from the true one; the mode is wrong when it is not the
walked mode on more than 5 % of the last 5 s. Deterministic; about 40 s.

    python experiments/offset_startup.py [--tolerances 0,1,2]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import numpy as np

from gait_estimator.core.estimator import Estimator, EstimatorConfig, run_estimator
from gait_estimator.io.library_io import load_library

MODES = ("Slow", "Med", "Fast")
STRIDES = 25
OFF_DEG = 6.0


def cases() -> list[np.ndarray]:
    out = []
    for c in range(4):
        for sign in (1.0, -1.0):
            o = np.zeros(4)
            o[c] = sign * OFF_DEG
            out.append(o)
    return [*out, np.array([6.0, 1.0, 0.0, -1.0]), np.array([-4.0, 3.0, 5.0, -2.0])]


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tolerances", default="0,1,2", help="offset_tolerance_deg values, comma-separated")
    args = ap.parse_args(argv)
    lib = load_library("able_bodied")
    for tol in (float(v) for v in args.tolerances.split(",")):
        unlearnt, wrong, total = [], 0, 0
        for mode in MODES:
            for o in cases():
                x = np.tile(lib.mode(mode).samples, (STRIDES, 1)) + o
                t = np.arange(len(x)) / lib.sample_rate_hz
                est = Estimator(lib, EstimatorConfig(offset_tolerance_deg=tol))
                trace = run_estimator(est, t, x)
                total += 1
                if np.max(np.abs(est.sensor_offset_deg - o)) > 1.0:
                    unlearnt.append(f"{mode} {o.tolist()} -> {np.round(est.sensor_offset_deg, 1).tolist()}")
                tail = trace.ready & (t > t[-1] - 5.0)
                wrong += bool(np.mean(np.asarray(trace.modes)[tail] != mode) > 0.05)
        print(f"offset_tolerance_deg {tol:g}: offset not learnt in {len(unlearnt)} of {total} cases; "
              f"mode wrong in the last 5 s in {wrong}")
        for line in unlearnt:
            print("    " + line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
