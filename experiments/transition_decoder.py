"""Could a decoder that changes mode only at heel strikes follow SYN-NEW's mode changes sooner?
(docs/new_wearer.md, "Offsets and cadence: mode")

A prototype, not part of the estimator: an online time-warping decoder over the states (mode m,
kernel sample j). Each library-rate step every state's cost becomes

    D[m, j] <- lambda_m * min(D[m, j - 1], D[m, j] + P_warp, D[m, j - 2] + P_warp) + ||x - k_m[j]||^2

and the first sample of every kernel (a right heel strike) may also be entered from the last
sample of any mode, at an extra P_switch from another mode. The reported mode and phase are those
of the cheapest state. lambda_m = 2^(-1 / (H N_m)) forgets with a half-life of H strides. It runs
beside the default ``Estimator`` on the synthetic wearers of ``cross_session.py`` (SYN-NEW) and
reads the estimator's learnt sensor offsets and cadence (each mode's kernel at the time scale
nearest the learnt one), so the two differ only in how they decide. Accuracy is counted per
library-rate step (not per input sample as in cross_session.py), split into the strides that
start a new mode and the others; the last line is what an estimator would score that used the
decoder in the strides that start a new mode and the estimator elsewhere, if it were told which
strides those are (an upper end of what combining the two could give, not a method).
Deterministic; about 25 s.

    python experiments/transition_decoder.py [--seeds 5] [--half-life 0.5] [--warp 1000] [--switch 50]
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from bench_common import ROUTE
from synthetic import generate, new_wearer

from gait_estimator.core.channels import Sample
from gait_estimator.core.estimator import Estimate, Estimator, run_estimator
from gait_estimator.core.matcher import IncrementalMatcher
from gait_estimator.io.library_io import load_library


class SwitchingDecoder:
    """Online (mode, kernel sample) decoder over one time-scaled row per mode of ``matcher``."""

    def __init__(self, matcher: IncrementalMatcher, half_life: float, warp: float, switch: float) -> None:
        self.matcher, self.half_life, self.warp, self.switch = matcher, half_life, warp, switch
        self.scale_index = matcher.n_scales // 2
        self._build(None)

    def _build(self, old: tuple[np.ndarray, np.ndarray, np.ndarray] | None) -> None:
        m = self.matcher
        rows = np.arange(m.n_modes) * m.n_scales + self.scale_index
        kernels = [m.row_kernel(int(r)) for r in rows]  # degrees (the default channel weights: all 1)
        self.n = np.array([k.shape[0] for k in kernels])
        self.start = np.r_[0, np.cumsum(self.n)[:-1]]
        self.end = self.start + self.n - 1
        self.k = np.concatenate(kernels)
        self.mode_of = np.repeat(np.arange(m.n_modes), self.n)
        self.j = np.arange(self.k.shape[0]) - self.start[self.mode_of]
        self.lam = 2.0 ** (-1.0 / (self.half_life * self.n[self.mode_of]))
        if old is None:
            self.cost = np.zeros(self.k.shape[0])
            return
        cost, n, start = old  # carry every mode's costs over by phase
        phase = self.j / self.n[self.mode_of]
        self.cost = cost[start[self.mode_of] + np.minimum((phase * n[self.mode_of]).astype(np.int64), n[self.mode_of] - 1)]

    def set_scale_index(self, index: int) -> None:
        if index != self.scale_index:
            old = (self.cost, self.n, self.start)
            self.scale_index = index
            self._build(old)

    def step(self, x: np.ndarray) -> tuple[int, float]:
        """Consume one sample (4,), degrees, sensor offset removed; return (mode, phase)."""
        d = self.cost
        best = d + self.warp
        best[1:] = np.minimum(best[1:], np.where(self.j[1:] >= 1, d[:-1], np.inf))
        best[2:] = np.minimum(best[2:], np.where(self.j[2:] >= 2, d[:-2] + self.warp, np.inf))
        ends = d[self.end]
        order = np.argsort(ends)
        other = np.where(np.arange(ends.size) == order[0], ends[order[1]], ends[order[0]]) + self.switch
        best[self.start] = np.minimum(best[self.start], np.minimum(ends, other))
        self.cost = self.lam * best + ((x[None, :] - self.k) ** 2).sum(axis=1)
        s = int(self.cost.argmin())
        return int(self.mode_of[s]), float(self.j[s] / self.n[self.mode_of[s]])


class EstimatorWithDecoder(Estimator):
    """The default estimator, with the decoder stepped beside it on its learnt offsets and cadence."""

    def __init__(self, *args: Any, decoder: dict[str, float], **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.decoder = SwitchingDecoder(self.matcher, **decoder)
        self.steps: list[tuple[float, bool, int, int]] = []  # time, ready, estimator mode, decoder mode

    def _step(self, time_s: float, x: Sample) -> Estimate:
        est = super()._step(time_s, x)
        m = self.matcher
        if math.isfinite(self.cadence_scale):
            self.decoder.set_scale_index(int(np.abs(np.log(m.time_scales / self.cadence_scale)).argmin()))
        mode, _ = self.decoder.step(np.asarray(x) - m.sensor_offset_deg)
        self.steps.append((time_s, est.ready, est.mode_index, mode))
        return est


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5, help="synthetic new wearers (default 5, as cross_session.py)")
    ap.add_argument("--half-life", type=float, default=0.5, help="decoder forgetting half-life, strides (0.5)")
    ap.add_argument("--warp", type=float, default=1000.0, help="cost of a held or skipped kernel sample, deg^2 (1000)")
    ap.add_argument("--switch", type=float, default=50.0, help="cost of a mode change at a heel strike, deg^2 (50)")
    args = ap.parse_args(argv)
    lib = load_library("able_bodied")
    names = lib.mode_names
    decoder = {"half_life": args.half_life, "warp": args.warp, "switch": args.switch}
    total = np.zeros((2, 3))  # [transition strides, other strides] x [steps, estimator right, decoder right]
    for seed in range(args.seeds):
        cfg = new_wearer(seed)
        syn = generate(lib, ROUTE, cfg, seed=1000 + seed, source=f"wearer {seed}")  # as cross_session.syn_new
        est = EstimatorWithDecoder(lib, decoder=decoder)
        run_estimator(est, syn.recording.time_s, syn.recording.angles_deg)
        t, ready, em, dm = (np.array(c) for c in zip(*est.steps, strict=True))
        stride = np.clip(np.searchsorted(syn.heel_strikes_s, t, side="right") - 1, 0, len(syn.stride_modes) - 1)
        truth = np.array([names.index(syn.stride_modes[k]) for k in stride])
        starts_mode = np.r_[True, np.array(syn.stride_modes[1:]) != np.array(syn.stride_modes[:-1])][stride]
        row = []
        for i, sel in enumerate((ready & starts_mode, ready & ~starts_mode)):
            counts = [sel.sum(), (em[sel] == truth[sel]).sum(), (dm[sel] == truth[sel]).sum()]
            total[i] += counts
            row.append(f"{100 * counts[1] / counts[0]:.1f} / {100 * counts[2] / counts[0]:.1f} %")
        print(f"wearer {seed}: estimator / decoder right, strides that start a new mode {row[0]}, other strides {row[1]}")
    both = total.sum(axis=0)
    print(f"all {args.seeds} wearers ({int(both[0])} library-rate steps; decoder {decoder}):")
    for name, c in (("strides that start a new mode", total[0]), ("other strides", total[1]), ("all strides", both)):
        print(f"  {name}: estimator {100 * c[1] / c[0]:.1f} %, decoder {100 * c[2] / c[0]:.1f} %")
    told = (total[0, 2] + total[1, 1]) / both[0]
    print(f"  told which strides start a new mode (the decoder there, the estimator elsewhere): {100 * told:.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
