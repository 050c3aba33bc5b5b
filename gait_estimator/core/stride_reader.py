"""The stride-start reader: a second look at each stride from its heel strike, for mode changes.

The matcher compares a whole stride's window with every kernel, so after a mode change the
window holds mostly the old mode for a while. People change mode at a heel strike, and their
joints do not jump there: the new mode's stride starts from the pose the old one ended in and
joins its own course within part of a stride. A reading starts at a reported heel strike (the
estimator starts one after a stride the reported mode fitted as well as usual) and, for every mode
m, time scale s and join fraction f (JOIN_FRACTIONS), accumulates the squared error between the
samples since then and the start of kernel m stretched by s, at the learnt sensor offsets, the
kernel joined to the pose at the heel strike by a cosine fade over the first f of the stride:

    pred(t) = k_m(phi) + offset + w_f(phi) * (x_hs - k_m(0) - offset),   phi = t / (s * N_m)

with w_f = 1 at the heel strike and 0 from phi = f on. A mode's error is that of its best (scale,
join) row. Another mode than the one reported at the heel strike is reported once its error is
``evidence`` below every other's, the reported one's included, from REPORT_FROM of its stride on
and while it fits within the bound given at the heel strike (the estimator's READER_SWITCH_FIT of
the wearer's usual fit). Cost O(M * S * F * C) per step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from . import compiled
from .channels import N_CHANNELS
from .kernels import KernelLibrary

JOIN_FRACTIONS = (0.25, 0.65)
"""Parts of a stride (from the heel strike) over which a new mode's stride may join its own course
from the pose the previous stride ended in; each mode is read with the one that fits it best.
0.25 is the synthetic wearers' own fade; LG_2_Ramp's real mode changes are read best with 0.4-0.65
(experiments/stride_reader.py, docs/new_wearer.md)."""
REPORT_FROM = 0.25
"""The reader reports a mode only from this part of that mode's stride (at its best scale) on:
before it, every mode's prediction is still mostly the pose at the heel strike, and a walk that
stops looks like the start of a stair ascent (experiments/reader_heldout.py)."""
SUGGESTED_EVIDENCE_DEG2S = 40.0
"""The ``switch_evidence_deg2s`` docs/new_wearer.md suggests to those who opt in (the reader is off by
default): the value the guards were checked at (experiments/reader_heldout.py)."""
READ_STRIDES = 1.5
"""A reading stops this many (longest, most stretched) kernel strides after its heel strike if no
other heel strike came."""


class StrideStartReader:
    """Reads each stride from its heel strike against the start of every kernel.

    Args:
        library: Kernel library (degrees); kernels may be replaced later (``set_kernel``).
        channel_weights: Weight per channel in the squared error, CHANNELS order.
        evidence_deg2s: How much lower a mode's squared error since the heel strike (deg^2,
            weighted, summed over the library-rate samples, times the sample interval: deg^2 s)
            must be than any other's, the reported mode's included, for the reader to report it; > 0.
        allowed: Optional (M, M) bool: allowed[i, j] = mode j may follow mode i.
        backend: ``numba`` (compiled step) or ``numpy``; ``auto`` = numba if installed.
    """

    def __init__(self, library: KernelLibrary, channel_weights: np.ndarray, evidence_deg2s: float,
                 allowed: np.ndarray | None = None, backend: str = "auto") -> None:
        if not (evidence_deg2s > 0 and math.isfinite(evidence_deg2s)):
            raise ValueError(f"evidence_deg2s must be a finite number > 0, got {evidence_deg2s!r}")
        self.lengths = np.array(library.lengths, dtype=np.int64)
        self._starts = np.r_[0, np.cumsum(self.lengths)[:-1]]
        self._flat = np.concatenate([m.samples for m in library.modes]).astype(np.float64)
        self._weights = np.asarray(channel_weights, dtype=np.float64)
        self._penalty = float(evidence_deg2s) * library.sample_rate_hz
        self._allowed = allowed
        self.compiled = compiled.AVAILABLE and backend in ("auto", "numba")
        self.scales = np.ones(1)
        self._active = False
        self._steps = 0
        self._max_steps = 0.0
        self._reported = 0
        self._bias = np.zeros(len(self.lengths))
        self._joins = np.asarray(JOIN_FRACTIONS, dtype=np.float64)
        self._report_from = REPORT_FROM
        self._max_mean_error = math.inf
        self._error = np.zeros((len(self.lengths), 1))
        self._join = np.zeros((len(self.lengths), N_CHANNELS))
        self._offset = np.zeros(N_CHANNELS)
        if self.compiled:  # compile (or load the cached code) now, not at the first heel strike
            compiled.reader_step(np.zeros((len(self.lengths), self._joins.size)), self._flat, self._starts,
                                 self.lengths, self.scales, 1.0, np.zeros(N_CHANNELS), self._offset, self._join,
                                 self._weights, self._bias, self._joins)

    def set_kernel(self, mode: int, samples: np.ndarray) -> None:
        """Replace the kernel of ``mode`` (same shape), degrees."""
        s = self._starts[mode]
        self._flat[s:s + self.lengths[mode]] = samples

    def reset(self) -> None:
        """Stop reading (until the next heel strike)."""
        self._active = False

    def start(self, sample_deg: Sequence[float] | np.ndarray, reported_mode: int, sensor_offset_deg: np.ndarray,
              scales: np.ndarray, max_mean_error: float = math.inf) -> None:
        """Begin reading at a heel strike.

        Args:
            sample_deg: The pose at the heel strike (C,), degrees.
            reported_mode: The mode reported at the heel strike.
            sensor_offset_deg: The learnt sensor offsets (C,), degrees.
            scales: Stride-duration scales (S,) every mode is read at; its best one counts.
            max_mean_error: No mode is reported while its weighted squared error per sample since
                the heel strike (deg^2, summed over channels) is above this: one that fits this
                badly is no new mode (a walk that stops, say).
        """
        self._active = True
        self._max_mean_error = float(max_mean_error)
        self._steps = 0
        self.scales = np.asarray(scales, dtype=np.float64)
        self._reported = reported_mode
        self._offset = np.asarray(sensor_offset_deg, dtype=np.float64)
        self._join = np.asarray(sample_deg, dtype=np.float64) - self._flat[self._starts] - self._offset  # (M, C)
        self._error = np.zeros((len(self.lengths), self.scales.size * self._joins.size))
        self._bias = np.full(len(self.lengths), self._penalty)
        if self._allowed is not None:
            self._bias[~self._allowed[reported_mode]] = math.inf
        self._bias[reported_mode] = 0.0
        self._max_steps = READ_STRIDES * float(self.scales.max() * self.lengths.max())

    def step(self, sample_deg: Sequence[float] | np.ndarray) -> tuple[int, float, float] | None:
        """Read one library-rate sample (C,), degrees. Returns (mode, phase, time scale) while
        the reader reports another mode than the one reported at the heel strike, else None."""
        if not self._active:
            return None
        self._steps += 1
        if self._steps > self._max_steps:
            self._active = False
            return None
        x = np.asarray(sample_deg, dtype=np.float64)
        if self.compiled:
            best = int(compiled.reader_step(self._error, self._flat, self._starts, self.lengths, self.scales,
                                            float(self._steps), x, self._offset, self._join, self._weights,
                                            self._bias, self._joins))
        else:
            best = self._step_numpy(x)
        if best == self._reported:
            return None
        s = int(self._error[best].argmin()) // self._joins.size
        phase = self._steps / (self.scales[s] * self.lengths[best])
        if phase < self._report_from or not self._error[best].min() / self._steps <= self._max_mean_error:
            return None
        return best, float(phase % 1.0), float(self.scales[s])

    def _step_numpy(self, x: np.ndarray) -> int:
        """``compiled.reader_step`` in numpy: update the errors, return the winning mode."""
        pos = self._steps / self.scales  # (S,) kernel samples since the heel strike
        whole = np.floor(pos)
        frac = (pos - whole)[None, :, None]
        i0 = whole.astype(np.int64)[None, :] % self.lengths[:, None]  # (M, S)
        i1 = (i0 + 1) % self.lengths[:, None]
        rows = self._starts[:, None]
        k = (1.0 - frac) * self._flat[rows + i0] + frac * self._flat[rows + i1]  # (M, S, C)
        phi = (pos[None, :] / self.lengths[:, None])[:, :, None]  # (M, S, 1) against joins (F,)
        w = np.where(phi < self._joins, 0.5 * (1.0 + np.cos(np.pi * np.minimum(phi / self._joins, 1.0))), 0.0)
        r = (x - k - self._offset)[:, :, None, :] - w[..., None] * self._join[:, None, None, :]  # (M, S, F, C)
        self._error += ((r * r) @ self._weights).reshape(self._error.shape)
        return int(np.argmin(self._error.min(axis=1) + self._bias))
