"""Putting an irregular sample stream onto the uniform clock the kernels were built at."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


class UniformResampler:
    """Linear interpolation of a time-stamped stream onto t0 + k / rate_hz.

    The first sample after construction or ``reset`` starts the grid (t0 = its stamp); every
    later sample emits the grid points in (previous stamp, its stamp]. A grid point within
    ``snap`` grid intervals of a sample's stamp is that sample itself (value and stamp), so a
    stream already at the rate (up to stamp rounding, e.g. to nanoseconds) passes through
    unchanged.

    Args:
        rate_hz: Output rate (Hz), e.g. the kernel library's sample rate.
        snap: Fraction of the grid interval within which a grid point takes the sample as it is.
    """

    def __init__(self, rate_hz: float, snap: float = 0.01) -> None:
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"resampling rate must be a positive number of Hz, got {rate_hz!r}")
        self.rate_hz = float(rate_hz)
        self.snap = float(snap)
        self.reset()

    def reset(self) -> None:
        self._t0: float | None = None
        self._k = 0
        self._prev_t = 0.0
        self._prev_x: tuple[float, ...] = ()

    def push(self, time_s: float, sample: Sequence[float]) -> list[tuple[float, tuple[float, ...]]]:
        """Add one sample (any number of channels; stamps strictly increasing); returns the grid
        samples it completes, each channel interpolated in Python floats (no numpy call: this
        runs for every live sample)."""
        x = tuple(map(float, sample))
        if self._t0 is None:
            self._t0, self._k = time_s, 1
            self._prev_t, self._prev_x = time_s, x
            return [(time_s, x)]
        if time_s <= self._prev_t:
            raise ValueError(f"stamps must increase: {time_s} after {self._prev_t}")
        out = []
        snap = self.snap / self.rate_hz
        while True:
            t = self._t0 + self._k / self.rate_hz
            if t > time_s + snap:
                break
            if t >= time_s - snap:
                out.append((time_s, x))
            else:
                a = (t - self._prev_t) / (time_s - self._prev_t)
                out.append((t, tuple(p + a * (v - p) for p, v in zip(self._prev_x, x, strict=True))))
            self._k += 1
        self._prev_t, self._prev_x = time_s, x
        return out


    def push_many(self, time_s: np.ndarray, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The bulk form of ``push`` for samples (T, C) whose stamps (T,) increase after the last
        one: the grid times (G,) and values (G, C) they complete, in the float operations of
        ``push``, and per sample how many grid points it and the samples before it emitted (T,)."""
        t, x = time_s, samples
        first_t, first_x, lead = np.zeros(0), np.zeros((0, x.shape[1])), 0
        if self._t0 is None:  # the first sample starts the grid
            self._t0, self._k, self._prev_t, self._prev_x = float(t[0]), 1, float(t[0]), tuple(x[0].tolist())
            first_t, first_x, lead = t[:1], x[:1], 1
            t, x = t[1:], x[1:]
        snap = self.snap / self.rate_hz
        upper = t + snap
        tk = np.zeros(0)
        if t.size:
            count = max(0, math.floor((float(upper[-1]) - self._t0) * self.rate_hz) - self._k + 3)
            tk = self._t0 + (self._k + np.arange(count)) / self.rate_hz
            tk = tk[tk <= upper[-1]]
        src = np.searchsorted(upper, tk, side="left")  # the first sample with t + snap >= t_k emits it
        prev_t = np.concatenate([[self._prev_t], t[:-1]])
        prev_x = np.concatenate([np.asarray(self._prev_x, dtype=np.float64).reshape(1, -1), x[:-1]])
        snapped = tk >= t[src] - snap if tk.size else np.zeros(0, dtype=bool)
        a = (tk - prev_t[src]) / (t[src] - prev_t[src])
        p, v = prev_x[src], x[src]
        grid_x = np.where(snapped[:, None], v, p + a[:, None] * (v - p))
        grid_t = np.where(snapped, t[src], tk)
        emitted = np.searchsorted(src, np.arange(t.size), side="right")
        if t.size:
            self._k += tk.size
            self._prev_t, self._prev_x = float(t[-1]), tuple(x[-1].tolist())
        emitted = np.concatenate([[lead] if lead else [], emitted + lead]).astype(np.int64)
        return np.concatenate([first_t, grid_t]), np.concatenate([first_x, grid_x]), emitted
