"""Mode and phase matching: the paper's Algorithms 1 (naive) and 2 (incremental).

Every step takes one sample d_i (4 angles, degrees, CHANNELS order). For every mode m and every
kernel column j (0-based) the matcher keeps

    e[m, j] = sum_{t=0}^{W-1} || d_{i-t} - k^m_{(j-t) mod N_m} ||^2        (SSE, deg^2)

where W = min(samples seen, N_m): the window ends at the newest sample, aligned with kernel
column j. Until W = N_m for every mode (``ready``) the sums run over the samples seen so far, as
in the reference implementation, whose running sums start from zero.

The best mode is argmin_m min_j e[m, j] (ties: the earlier mode); its best column j* gives the
phase ((j* + 1) mod N_m) / N_m in [0, 1). That is the paper's phi = j*/N_m with its 1-based j*,
and the reference implementation's output, except that we wrap its 1.0 to 0.0.

Options beyond the paper (all off by default, which reproduces the reference exactly):

* ``window_fraction`` f in (0, 1]: match only the newest W_m = max(2, round(f N_m)) samples
  against the corresponding part of every kernel shift (shorter delay after a mode change);
* ``channel_weights`` w (4,), >= 0: e = sum_c w_c (d_c - k_c)^2, so 0 drops a channel (e.g.
  unilateral sensing with the prosthesis-side thigh and shank only); implemented by scaling
  kernels and samples by sqrt(w);
* ``subsample``: parabolic interpolation of e around j* for a phase finer than 1/N_m.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .channels import N_CHANNELS
from .kernels import KernelLibrary


@dataclass(frozen=True)
class StepResult:
    """The estimate after one sample.

    Attributes:
        mode_index: Index of the best mode in the library.
        mode: Name of the best mode.
        phase: Gait phase of the best mode, [0, 1), 0 = right heel strike.
        sse: Per-mode minimum SSE over all shifts, deg^2, shape (M,).
        phases: Per-mode phase at that mode's best shift, shape (M,).
        ready: True once the window of every mode is full.
        window: Samples in each mode's comparison window so far, min(steps, W_m), shape (M,).
    """

    mode_index: int
    mode: str
    phase: float
    sse: np.ndarray
    phases: np.ndarray
    ready: bool
    window: np.ndarray


@dataclass(frozen=True)
class MatchTrace:
    """Step results for a whole sequence of samples (T steps, M modes)."""

    mode_names: list[str]
    mode_index: np.ndarray  # (T,) int64
    phase: np.ndarray  # (T,) float64
    sse: np.ndarray  # (T, M) float64, deg^2
    phases: np.ndarray  # (T, M) float64
    ready: np.ndarray  # (T,) bool

    @property
    def modes(self) -> list[str]:
        return [self.mode_names[i] for i in self.mode_index]


class _MatcherBase:
    """Shared state: padded kernels, the ring buffer of recent samples, result assembly.

    Args:
        library: The kernels to match against (degrees).
        window_fraction: Fraction of each stride compared, (0, 1]; 1.0 = the paper.
        channel_weights: Weight of each channel (CHANNELS order), >= 0, not all 0; None = all 1.
        subsample: Refine the phase between kernel columns by parabolic interpolation.
    """

    def __init__(
        self,
        library: KernelLibrary,
        window_fraction: float = 1.0,
        channel_weights: Sequence[float] | None = None,
        subsample: bool = False,
    ) -> None:
        self.library = library
        self.mode_names = library.mode_names
        self.lengths = library.lengths
        self.n_modes = len(library)
        self.max_length = int(self.lengths.max())
        self.window_fraction = check_window_fraction(window_fraction)
        self.channel_weights = check_channel_weights(channel_weights)
        self.subsample = bool(subsample)
        self.windows = np.maximum(2, np.rint(self.window_fraction * self.lengths)).astype(np.int64)
        self.windows = np.minimum(self.windows, self.lengths)
        self.max_window = int(self.windows.max())
        self.active_channels = int(np.count_nonzero(self.channel_weights))
        self._scale = np.sqrt(self.channel_weights)
        self._weighted = bool(np.any(self.channel_weights != 1.0))
        m, n = self.n_modes, self.max_length
        kernels = np.zeros((m, N_CHANNELS, n))  # channel-major: one (4, Nmax) matrix per mode
        for i, mode in enumerate(library.modes):
            kernels[i, :, : mode.length] = (mode.samples * self._scale).T
        self._kernels = kernels
        self._valid = np.arange(n)[None, :] < self.lengths[:, None]  # (M, Nmax)
        self._ring = np.zeros((self.max_window, N_CHANNELS))
        self._count = 0
        self._all = np.arange(self.n_modes)

    @property
    def steps(self) -> int:
        """Samples consumed since construction or the last reset()."""
        return self._count

    @property
    def ready(self) -> bool:
        """True once every mode's window holds W_m samples (W_m = N_m by default)."""
        return self._count >= self.max_window

    def reset(self) -> None:
        """Forget all samples; the next step starts a fresh (incomplete) window."""
        self._ring[:] = 0.0
        self._count = 0

    def _checked(self, sample: np.ndarray) -> np.ndarray:
        d = np.asarray(sample, dtype=np.float64).reshape(N_CHANNELS)
        if not np.isfinite(d).all():
            raise ValueError(f"sample has non-finite values: {d.tolist()}")
        return d * self._scale if self._weighted else d

    def _push(self, d: np.ndarray) -> None:
        self._ring[self._count % self.max_window] = d
        self._count += 1

    def _result(self, e: np.ndarray) -> StepResult:
        best_cols = e.argmin(axis=1)
        sse = e[self._all, best_cols]
        if self.subsample:
            lens = self.lengths
            before = e[self._all, (best_cols - 1) % lens]
            after = e[self._all, (best_cols + 1) % lens]
            curvature = before - 2.0 * sse + after
            with np.errstate(divide="ignore", invalid="ignore"):
                offset = np.where(curvature > 0, 0.5 * (before - after) / curvature, 0.0)
            position = best_cols + 1 + np.clip(offset, -0.5, 0.5)
            phases = np.mod(position, lens) / lens
            phases[phases >= 1.0] = 0.0
        else:
            phases = ((best_cols + 1) % self.lengths) / self.lengths
        best = int(sse.argmin())
        window = np.minimum(self._count, self.windows)
        return StepResult(best, self.mode_names[best], float(phases[best]), sse, phases, self.ready, window)

    def _window_sse(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Naive SSE of the current window against kernel shifts (rows[b], cols[b]), shape (B,)."""
        w = self.max_window
        t = np.arange(w)
        data = self._ring[(self._count - 1 - t) % w]  # (Wmax, 4): d_{i-t}
        lens = self.lengths[rows][:, None]
        diff = data[None, :, :] - self._kernels[rows[:, None], :, (cols[:, None] - t[None, :]) % lens]
        sq = np.einsum("btc,btc->bt", diff, diff)
        sq[t[None, :] >= np.minimum(self._count, self.windows[rows][:, None])] = 0.0
        return sq.sum(axis=1)

    def full_sse(self) -> np.ndarray:
        """e[m, j] recomputed from the buffered samples (the naive sum), (M, Nmax); padding inf."""
        rows, cols = np.nonzero(self._valid)
        out = np.full(self._valid.shape, np.inf)
        for lo in range(0, rows.size, _CHUNK):
            r, c = rows[lo : lo + _CHUNK], cols[lo : lo + _CHUNK]
            out[r, c] = self._window_sse(r, c)
        return out

    def run(self, samples: np.ndarray) -> MatchTrace:
        """Step through ``samples`` (T, 4), degrees; returns every step's result."""
        x = np.asarray(samples, dtype=np.float64)
        t = x.shape[0]
        mode_index = np.empty(t, dtype=np.int64)
        phase = np.empty(t)
        sse = np.empty((t, self.n_modes))
        phases = np.empty((t, self.n_modes))
        ready = np.empty(t, dtype=bool)
        for i in range(t):
            r = self.step(x[i])
            mode_index[i], phase[i], sse[i], phases[i], ready[i] = r.mode_index, r.phase, r.sse, r.phases, r.ready
        return MatchTrace(list(self.mode_names), mode_index, phase, sse, phases, ready)

    def step(self, sample: np.ndarray) -> StepResult:  # pragma: no cover - abstract
        raise NotImplementedError


_CHUNK = 2048  # columns per naive recomputation, bounds its temporary memory


def check_window_fraction(value: float) -> float:
    """Validate ``window_fraction``: a number in (0, 1]."""
    f = float(value)
    if not (0.0 < f <= 1.0):
        raise ValueError(f"window_fraction must be in (0, 1], got {value!r}")
    return f


def check_channel_weights(value: Sequence[float] | None) -> np.ndarray:
    """Validate ``channel_weights``: 4 finite numbers >= 0, not all 0 (None = all 1)."""
    if value is None:
        return np.ones(N_CHANNELS)
    w = np.asarray(value, dtype=np.float64).reshape(-1)
    if w.size != N_CHANNELS:
        raise ValueError(f"channel_weights needs {N_CHANNELS} values (CHANNELS order), got {w.size}")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise ValueError(f"channel_weights must be finite, >= 0 and not all 0, got {w.tolist()}")
    return w


class NaiveMatcher(_MatcherBase):
    """Paper Algorithm 1: every step recomputes every shift from the window, O(N^2 M).

    The executable specification the incremental matcher is tested against; use
    IncrementalMatcher for anything real. Takes the same options.
    """

    def step(self, sample: np.ndarray) -> StepResult:
        """Consume one sample (4,), degrees, CHANNELS order; return the estimate."""
        self._push(self._checked(sample))
        return self._result(self.full_sse())

    def state_bytes(self) -> int:
        return self._kernels.nbytes + self._ring.nbytes + self._valid.nbytes


class IncrementalMatcher(_MatcherBase):
    """Paper Algorithm 2 with O(N M) time and memory per step, vectorised across modes.

    With W_m = N_m (the paper):

        e[m, j] <- e[m, j-1] + ||d_i - k_j||^2 - ||d_{i-N_m} - k_j||^2
                 = e[m, j-1] + ||d_i||^2 - ||d_{i-N_m}||^2 - 2 k_j . (d_i - d_{i-N_m})

    With a shorter window the stale sample d_{i-W_m} leaves paired with kernel column j - W_m:

        e[m, j] <- e[m, j-1] + ||d_i - k_j||^2 - ||d_{i-W_m} - k_{j-W_m}||^2

    The stale sample comes from a ring buffer of the last W_max samples instead of the paper's
    N x N cache of squared terms (which would take O(N^2 M) memory). One step is a batched
    (1 x 4) @ (4 x N_max) product per mode (8 channels with a shorter window) plus a few passes
    over the (M, N_max) array.

    Resynchronisation: rounding errors of the running sums are bounded by recomputing
    ``resync_block`` entries from the window every few steps, so that every entry is recomputed
    from scratch at least once per ``resync_period`` steps (sweeping the diagonals along which
    errors travel).

    Args:
        library: The kernels to match against.
        window_fraction, channel_weights, subsample: see the module docstring.
        resync_period: Steps within which every column is recomputed from scratch (0 = never).
        resync_block: Columns recomputed at one resynchronisation.
    """

    def __init__(
        self,
        library: KernelLibrary,
        window_fraction: float = 1.0,
        channel_weights: Sequence[float] | None = None,
        subsample: bool = False,
        resync_period: int = 1 << 20,
        resync_block: int = 64,
    ) -> None:
        super().__init__(library, window_fraction, channel_weights, subsample)
        m, n = self.n_modes, self.max_length
        self._ksq = np.einsum("mcj,mcj->mj", self._kernels, self._kernels)  # ||k_j||^2, (M, Nmax)
        self._partial = bool(np.any(self.windows < self.lengths))
        if self._partial:
            # k_{j-W_m} for every column j: the kernel column the stale sample was compared with.
            j = np.arange(n)[None, :]
            src = np.where(self._valid, (j - self.windows[:, None]) % self.lengths[:, None], j)
            lagged = self._kernels[self._all[:, None], :, src].transpose(0, 2, 1)  # (M, 4, Nmax)
            self._stacked = np.concatenate([self._kernels, lagged], axis=1)  # (M, 8, Nmax)
            self._kconst = self._ksq - np.einsum("mcj,mcj->mj", lagged, lagged)
        self._last = self.lengths - 1
        padded = self.lengths < n
        self._pad_rows = np.flatnonzero(padded)
        self._pad_cols = self.lengths[padded]
        self._ring_sq = np.zeros(self.max_window)
        self._e = np.empty((m, n))
        self._next = np.empty((m, 1, n))  # matmul output; becomes e after the update
        total = int(self._valid.sum())
        self._resync_block = max(1, min(int(resync_block), total))
        if resync_period > 0:
            rounds = math.ceil(m * n / self._resync_block)
            self._resync_every = max(1, int(resync_period) // rounds)
        else:
            self._resync_every = 0
        self.reset()

    def reset(self) -> None:
        super().reset()
        self._ring_sq[:] = 0.0
        self._e[:] = np.where(self._valid, 0.0, np.inf)
        self._resync_cursor = 0

    def step(self, sample: np.ndarray) -> StepResult:
        """Consume one sample (4,), degrees, CHANNELS order; return the estimate."""
        d = np.asarray(sample, dtype=np.float64).reshape(N_CHANNELS)
        dsq = float(d @ d)
        if not math.isfinite(dsq):  # also catches overflow of ||d||^2, i.e. |angle| > 1e154
            raise ValueError(f"sample has non-finite values: {d.tolist()}")
        if self._weighted:
            d = d * self._scale
            dsq = float(d @ d)
        i = self._count
        w = self.max_window
        stale = (i - self.windows) % w
        if i >= w:  # every window is full: d_{i-W_m} leaves every mode's window
            old = self._ring[stale]
            base = dsq - self._ring_sq[stale]
            full = None
        else:  # windows still filling: nothing leaves them yet
            full = i >= self.windows
            old = self._ring[stale] * full[:, None]
            base = dsq - self._ring_sq[stale] * full
        self._push(d)
        self._ring_sq[i % w] = dsq
        nxt3 = self._next
        if self._partial:
            vec = np.concatenate([-2.0 * np.broadcast_to(d, old.shape), 2.0 * old], axis=1)  # (M, 8)
            np.matmul(vec[:, None, :], self._stacked, out=nxt3)
        else:
            np.matmul((-2.0 * (d[None, :] - old))[:, None, :], self._kernels, out=nxt3)
        nxt = nxt3.reshape(self._e.shape)
        e = self._e
        first = nxt[:, 0] + e[self._all, self._last]  # circular: column 0 follows column N_m - 1
        nxt.ravel()[1:] += e.ravel()[:-1]  # e[m, j-1]: the window and the kernel slide together
        nxt[:, 0] = first
        nxt[self._pad_rows, self._pad_cols] = np.inf
        nxt += base[:, None]
        if full is None:
            if self._partial:
                nxt += self._kconst
        else:  # ||k_j||^2 stays until the window is full, then ||k_j||^2 - ||k_{j-W}||^2
            nxt[~full] += self._ksq[~full]
            if self._partial:
                nxt[full] += self._kconst[full]
        self._e, self._next = nxt, e.reshape(nxt3.shape)
        if self._resync_every and self._count % self._resync_every == 0:
            self._resync()
        return self._result(self._e)

    def _resync(self) -> None:
        # Errors travel with the diagonal e[m, j] -> e[m, j + 1], so the sweep runs over the
        # diagonals r = (j - steps) mod N_m, which stay put, not over the columns j.
        lo = self._resync_cursor
        hi = min(lo + self._resync_block, self._valid.size)
        flat = lo + np.flatnonzero(self._valid.ravel()[lo:hi])
        rows, diag = np.divmod(flat, self.max_length)
        if flat.size:
            cols = (diag + self._count) % self.lengths[rows]
            self._e[rows, cols] = self._window_sse(rows, cols)
        self._resync_cursor = 0 if hi >= self._valid.size else hi

    def resync_all(self) -> None:
        """Recompute every column from the window now (O(N^2 M); not needed in normal use)."""
        self._e[:] = self.full_sse()

    def running_sse(self) -> np.ndarray:
        """The running e[m, j] (M, Nmax), padding inf; a copy."""
        return self._e.copy()

    def state_bytes(self) -> int:
        """Bytes of numpy state this matcher keeps between steps."""
        arrays = [self._kernels, self._ksq, self._ring, self._ring_sq, self._e, self._next, self._valid]
        if self._partial:
            arrays += [self._stacked, self._kconst]
        return int(sum(a.nbytes for a in arrays))
