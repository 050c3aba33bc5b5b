"""The matchers: the paper's Algorithms 1 (naive) and 2 (incremental).

Row layout, options and the read-out are documented in ``matching.py`` (their shared part); the
incremental step's compiled form is in ``compiled.py``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np

from . import compiled
from .channels import N_CHANNELS
from .kernels import KernelLibrary
from .match_results import MatchTrace, StepBlock, StepResult
from .matching import (
    ROW_TABLES,
    _MatcherBase,
    check_channel_weights,
    check_offset_tolerance,
    check_recency_half_life,
    check_time_scales,
)
from .scale_band import SEARCH_EVERY

__all__ = [
    "BACKENDS", "PARALLEL_MIN_ROWS", "IncrementalMatcher", "MatchTrace", "NaiveMatcher", "StepBlock", "StepResult",
    "check_channel_weights", "check_offset_tolerance", "check_recency_half_life", "check_time_scales",
]

BACKENDS = ("auto", "numba", "numpy")
"""Incremental step implementations: ``numba`` (compiled), ``numpy``; ``auto`` = numba if installed."""
PARALLEL_MIN_ROWS = 64
"""From this many rows (modes x time scales) on, the compiled step reads the kernels as float32
(the same values: every path uses float32-representable kernel values) and spreads the rows over
threads (numba's ``parallel``) when the process may use more than one CPU."""


class NaiveMatcher(_MatcherBase):
    """Paper Algorithm 1: every step recomputes every shift from the window, O(N^2 M).

    The executable specification the incremental matcher is tested against; use
    IncrementalMatcher for anything real. Takes the same options.
    """

    def step(self, sample: Sequence[float] | np.ndarray) -> StepResult:
        d0, d1, d2, d3, _ = self._weighted_values(sample)
        self._ring[self._count % self.max_window] = d0, d1, d2, d3
        self._count += 1
        e = self.full_sse()
        sums = (self.age_weighted_sums() if self._decay else self.window_sums()) if self._offset else None
        result = self._result(self._scores(e, sums))
        self._search_step(result.sse)
        return result

    def state_bytes(self) -> int:
        return self._kernels.nbytes + self._ring.nbytes



class IncrementalMatcher(_MatcherBase):
    """Paper Algorithm 2 with O(N M) time and memory per step, vectorised across rows.

        e[r, j] <- e[r, j-1] + ||d_i - k_j||^2 - ||d_{i-n} - k_j||^2
                 = e[r, j-1] + ||d_i||^2 - ||d_{i-n}||^2 - 2 k_j . (d_i - d_{i-n})

    The stale sample comes from a ring buffer of the last N_max samples instead of the paper's
    N x N cache of squared terms (which would take O(N^2 M) memory). Window sums for the offset
    penalty come from a ring of prefix sums (two lookups per row). The ``numba`` backend does a
    step in one compiled pass; the ``numpy`` backend in a batched (1 x 4) @ (4 x N_max) product
    per row plus a few passes over the (R, N_max) array.

    Scale band: the compiled step updates only the rows at the time scales of the band
    (``set_scale_band``); a row outside it keeps the sums of the sample it left the band at and is
    rebuilt exactly from the window (FFT) when it is needed again: when it re-enters the band, or
    when ``mode_row_scores`` reads it. The numpy step updates every row.

    Row tables: with more than one time scale the compiled step keeps kernels, per-shift means and
    running sums only for the rows in use (the band's, and one mode's rows more), each in a slot
    (``RowSlots``); a row that needs one again takes a free slot and is built from its mode's
    kernel, with the numbers it had.

    Resynchronisation: rounding errors of the running sums are bounded by recomputing
    ``resync_block`` entries from the window every few steps, so that every entry is recomputed
    from scratch at least once per ``resync_period`` steps (sweeping the diagonals along which
    errors travel).

    Args:
        library: The kernels to match against.
        channel_weights, time_scales, offset_tolerance_deg, normalize, recency_half_life: see
            ``matching.py``.
        resync_period: Steps within which every column is recomputed from scratch (0 = never).
        resync_block: Columns recomputed at one resynchronisation.
        backend: ``auto`` (numba if installed), ``numba`` or ``numpy``.
    """

    _TABLES = (*ROW_TABLES, "_ksq", "_e", "_wsums")  # every array indexed by slot

    def __init__(
        self,
        library: KernelLibrary,
        channel_weights: Sequence[float] | None = None,
        time_scales: Sequence[float] | None = None,
        offset_tolerance_deg: float = 0.0,
        normalize: bool = False,
        recency_half_life: float = 0.0,
        resync_period: int = 1 << 20,
        resync_block: int = 64,
        backend: str = "auto",
    ) -> None:
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
        if backend == "numba" and not compiled.AVAILABLE:
            raise ValueError("backend 'numba' needs the numba package (pip install numba)")
        self.backend = "numba" if backend == "auto" and compiled.AVAILABLE else ("numpy" if backend == "auto" else backend)
        self._shift_table = self.backend != "numba"  # the compiled read-out derives the per-shift means
        super().__init__(library, channel_weights, time_scales, offset_tolerance_deg, normalize, recency_half_life)
        r, n = self.n_rows, self.max_length
        cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        large = self.backend == "numba" and self.n_rows >= PARALLEL_MIN_ROWS
        self.parallel = large and cpus > 1
        if large:  # stream float32 kernels: half the memory traffic
            self._kernels = self._kernels.astype(np.float32)
        self._state = None
        self._active = self._rows  # rows the compiled step updates (the scale band's)
        self._choose_step()
        self._synced = np.zeros(r, dtype=np.int64)  # outside the band: the step count its sums are exact at
        self._ring_sq = np.zeros(self.max_window)
        self._psum_ring = np.zeros((self.max_window, N_CHANNELS))
        self._psum = np.zeros(N_CHANNELS)
        if self.backend == "numpy":
            self._next = np.empty((r, 1, n))  # matmul output; becomes e after the update
        # The compiled step with a scale band keeps only the rows in use in the row tables
        # (``_claim``); the numpy step updates every row.
        self._pooled = self.backend == "numba" and self.n_scales > 1
        self._pad_rows = np.flatnonzero(self.lengths < n)
        self._pad_cols = self.lengths[self._pad_rows]
        self._last = self.lengths - 1
        # numba outputs, reused every step
        self._out_col = np.zeros(r, dtype=np.int64)
        self._out_score = np.zeros(r)
        if self.backend == "numba":
            self._row_score = self._out_score  # the compiled step's per-row scores (rows it reads out)
        total = int(self._valid.sum())
        self._resync_block = max(1, min(int(resync_block), total))
        if resync_period > 0:
            rounds = math.ceil(r * n / self._resync_block)
            self._resync_every = max(1, int(resync_period) // rounds)
        else:
            self._resync_every = 0
        self.reset()
        if self.backend == "numba":  # compile (or load the cached code) now, not at the first sample
            self._step_numba(0.0, 0.0, 0.0, 0.0, 0.0)
            if self.parallel:  # and the one-thread step that a narrow scale band uses
                self._compiled_step, chosen = compiled.step_rows, self._compiled_step
                self.reset()
                self._step_numba(0.0, 0.0, 0.0, 0.0, 0.0)
                self._compiled_step = chosen
            self.reset()

    def mode_row_scores(self, mode: int) -> np.ndarray:
        # Both steps read out only the rows in the scale band: score this mode's rows now.
        rows = self.mode_rows(mode)
        self._sync_rows(rows)
        p = self._slots.at(rows)
        sums = None
        if self._offset:
            sums = self._wsums[p] if self._decay else self.window_sums()[rows]
        score = self._scores(self._e[p].astype(np.float64), sums, rows)
        return np.where(self._valid[rows], score, np.inf).min(axis=1)

    def _allocate_state(self, slots: int) -> None:
        """Empty running state for ``slots`` rows of the row tables."""
        self._ksq = np.zeros((slots, self.max_length))  # ||k_j||^2
        self._wsums = np.zeros((slots, N_CHANNELS))  # recency-weighted window sums (recency_half_life)
        self._e = np.full((slots, self.max_length), np.inf)

    def _resize(self, keep: np.ndarray, slots: int) -> None:
        """Row tables with room for ``slots`` rows, holding the rows ``keep`` (which have slots) in
        the first ones; every other row loses its slot."""
        old = {name: getattr(self, name) for name in self._TABLES}
        src = self._slots.slot[keep]
        self._allocate(slots, self._kernels.dtype)
        for name, a in old.items():
            getattr(self, name)[: keep.size] = a[src]
        self._slots.repack(keep, slots)

    def _claim(self, rows: np.ndarray, pinned: np.ndarray) -> None:
        """Give those of ``rows`` without one a slot in the row tables, built from their kernels
        (their sums then need a rebuild), taking none from the ``pinned`` rows ((R,) bool)."""
        rows = rows[self._slots.slot[rows] < 0]
        if rows.size == 0:
            return
        slots = self._slots.spare(pinned, self._synced == self._count, rows.size)
        if slots is None:  # make room
            held = self._slots.held()
            self._resize(held, held.size + rows.size)
            slots = np.arange(held.size, held.size + rows.size)
        self._slots.assign(rows, slots)
        self._synced[rows] = -1
        self._build(rows)

    def _reweighted(self) -> None:
        # The compiled step rebuilds the rows of the scale band; the others when they are needed.
        self._synced[:] = -1
        self._rebuild(self._active if self.backend == "numba" else self._rows)

    def _band_changed(self) -> None:
        if self.backend != "numba":
            return
        was = np.zeros(self.n_rows, dtype=np.bool_)
        was[self._active] = True
        now = self._band.readable
        active = self._rows if now.all() else self._band.rows
        self._synced[was & ~now] = self._count  # rows leaving the band are exact now
        self._active = active
        self._state = None
        if self._pooled:
            self._claim(active, now)
            room = active.size + self.n_scales  # and one mode's rows for mode_row_scores
            if self._slots.owner.size > room + room // 4:
                held = self._slots.held()
                self._resize(np.concatenate([held[now[held]], held[~now[held]]])[:room], room)
        self._choose_step()
        self._rebuild(np.flatnonzero(now & ~was))

    def _choose_step(self) -> None:
        """Threads only for as many rows as make them pay; the step's results do not depend on them."""
        many = self._active.size >= PARALLEL_MIN_ROWS
        if compiled.AVAILABLE:
            self._compiled_step = compiled.step_rows_parallel if self.parallel and many else compiled.step_rows

    def _sync_rows(self, rows: np.ndarray) -> None:
        """Bring those of ``rows`` outside the scale band (which the compiled step does not
        update) into the row tables and up to date, before they are read."""
        if self.backend != "numba" or self._active is self._rows:
            return
        inside = np.zeros(self.n_rows, dtype=np.bool_)
        inside[self._active] = True
        if self._pooled:
            pinned = inside.copy()
            pinned[rows] = True
            self._claim(rows, pinned)
        self._rebuild(rows[~inside[rows]])

    def _rebuild(self, rows: np.ndarray) -> None:
        """Recompute the running state of those of ``rows`` not up to date exactly from the window
        (FFT), so that they are what they would be had they been updated at every step."""
        rows = rows[self._synced[rows] != self._count]
        if rows.size == 0:
            return
        p = self._slots.at(rows)
        self._e[p] = self._rows_sse_fft(rows, self._lam)
        self._wsums[p] = self.age_weighted_sums(rows)
        self._synced[rows] = self._count

    def _rows_built(self, rows: np.ndarray) -> None:
        """||k_j||^2 of ``rows`` after their kernels changed."""
        p = self._slots.at(rows)
        k = self._kernels[p].astype(np.float64)
        self._ksq[p] = np.einsum("rcj,rcj->rj", k, k)  # ||k_j||^2, (r, Nmax)

    def reset(self) -> None:
        super().reset()
        self._ring_sq[:] = 0.0
        self._psum_ring[:] = 0.0
        self._psum[:] = 0.0
        self._wsums[:] = 0.0
        held = self._slots.owner >= 0
        self._e[:] = np.inf
        self._e[held] = np.where(self._valid[self._slots.held()], 0.0, np.inf)
        self._resync_cursor = 0
        self._synced[:] = 0

    def step(self, sample: Sequence[float] | np.ndarray) -> StepResult:
        d0, d1, d2, d3, dsq = self._weighted_values(sample)
        if self.backend == "numba":
            result = self._step_numba(d0, d1, d2, d3, dsq)
        else:
            result = self._step_numpy(np.array((d0, d1, d2, d3)), dsq)
        if self._resync_every and self._count % self._resync_every == 0:
            self._resync()
        self._search_step(result.sse)
        return result

    def weighted_samples(self, samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Samples (G, 4), degrees, as ``run_steps`` takes them: times sqrt(channel weight), and
        their squared norms, in the float operations of ``step``."""
        d = np.ascontiguousarray(samples * np.asarray(self._scale_values) if self._weighted else samples)
        return d, d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2] + d[:, 3] * d[:, 3]

    def run_steps(
        self, samples: np.ndarray, squares: np.ndarray, start: int, stop: int, out: StepBlock,
        tracker: np.ndarray | None = None, near: np.ndarray | None = None, mid_stride: tuple[float, float] = (0.25, 0.75),
        hook: compiled.StepHook = compiled.MATCHER_REPORTS,
    ) -> tuple[int, bool]:
        """Steps ``start`` .. at most ``stop`` - 1 of ``samples`` (``weighted_samples``) in one
        compiled call (numba backend), each step's result into that row of ``out``: the state and
        results of ``step`` sample by sample. Stops after a step that resynchronises (done, as in
        ``step``) and, with a stride ``tracker`` (``WalkingCalibration.stride_state``, advanced in
        place; ``near`` (M, M) its near copies), after a step that ends a whole stride, the tracker
        then as before that step (``compiled.run_steps``). The tracker follows the mode ``hook``
        reports (the best one by default; ``out.column`` is that mode's column). Returns the step
        after the last done and whether it ended a stride."""
        if self.backend != "numba":
            raise ValueError("run_steps needs the numba backend")
        if self._resync_every:
            stop = min(stop, start + self._resync_every - self._count % self._resync_every)
        if self._band.search:
            stop = min(stop, start + SEARCH_EVERY - self._count % SEARCH_EVERY)
        track = np.zeros(0) if tracker is None else tracker
        near = np.zeros((self.n_modes, self.n_modes), dtype=bool) if near is None else near
        column = np.empty(self.n_modes, dtype=np.int64)
        count = self._count
        threaded = self._compiled_step is compiled.step_rows_parallel  # the rows' results do not depend on it
        done, ended = hook.loops[1 if threaded else 0](
            self._step_state(), count, samples, squares, start, stop, out.sse, out.phases, out.variant, out.window,
            out.best, out.column, column, track, near, mid_stride[0], mid_stride[1], self.max_window, hook.args,
        )
        self._count = count + done - start
        out.ready[start:done] = count + 1 + np.arange(done - start) >= self.max_window
        if self._resync_every and self._count % self._resync_every == 0:
            self._resync()
        if done > start:
            self._search_step(out.sse[done - 1])
        return done, ended

    def _step_numba(self, d0: float, d1: float, d2: float, d3: float, dsq: float) -> StepResult:
        m = self.n_modes
        sse, phases = np.empty(m), np.empty(m)
        variant, column, window = np.empty((3, m), dtype=np.int64)  # fresh arrays: results outlive the step
        b = self._compiled_step(self._state or self._step_state(), self._count, d0, d1, d2, d3, dsq,
                                sse, phases, variant, column, window)
        self._count += 1
        return StepResult(
            b, self.mode_names[b], float(phases[b]), sse, phases, self._count >= self.max_window, window,
            variant if self.n_scales > 1 else None, column,
        )

    def _step_state(self) -> tuple:
        """The compiled steps' ``compiled.StepState`` (as a plain tuple), built again after one of
        its arrays or flags was replaced (``_state`` None)."""
        if self._state is None:
            self._state = tuple(compiled.StepState(
                self._e, self._kernels, self._ksq, self.lengths, self._ring, self._ring_sq, self._psum_ring, self._psum,
                self._decay, self._lam, self._lam_w, self._wsum, self._wsums, self._offset, self._mu, self._mu_anchor,
                self._mu_seg_range, self._mu_seg_blocks, self._tau, self.normalize, self.n_scales, self._band.readable,
                self._active, self._slots.slot, self._out_col, self._out_score))
        return self._state

    def _step_numpy(self, d: np.ndarray, dsq: float) -> StepResult:
        i = self._count
        w = self.max_window
        stale = (i - self.windows) % w
        full = None if i >= w else i >= self.windows  # None: every window is full
        old, old_sq = self._ring[stale], self._ring_sq[stale]
        self._e, self._next = self._advance(
            self._e, self._next, d, dsq, old, old_sq, full, self._lam, self._lam_w, self._wsums
        )
        psum = self._psum + d  # kept always: the offset penalty may be switched on at any sample
        if self._decay:
            sums = self._wsums
        else:
            sums = psum - np.where((i >= self.windows)[:, None], self._psum_ring[stale], 0.0) if self._offset else None
        self._psum = psum
        self._psum_ring[i % w] = psum
        self._ring[i % w] = d
        self._count += 1
        self._ring_sq[i % w] = dsq
        if not (self._offset or self.normalize):
            return self._result(self._e)
        if self._band.readable.all():
            return self._result(self._scores(self._e, sums))
        # As the compiled step: read out only the rows in the scale band (mode_row_scores scores
        # a mode's other rows when they are asked for).
        rows = self._band.rows
        score = np.full(self._e.shape, np.inf)
        score[rows] = self._scores(self._e[rows], None if sums is None else sums[rows], rows)
        return self._result(score)

    def _advance(
        self, e: np.ndarray, buf: np.ndarray, d: np.ndarray, dsq: float, old: np.ndarray, old_sq: np.ndarray,
        full: np.ndarray | None, lam: np.ndarray, lam_w: np.ndarray, wsums: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """One step of the running sums e (R, Nmax) for age weights ``lam`` (and, with recency
        weighting, of the age-weighted window sums ``wsums``, in place); ``old`` (R, 4) and
        ``old_sq``: the sample each row's window loses; ``full``: which windows are full (None:
        all). Returns the new sums and the free buffer (e's memory)."""
        if self._decay:  # the leaving sample counts lambda^W
            leave = lam_w if full is None else full * lam_w
        else:
            leave = None if full is None else full.astype(np.float64)
        if leave is not None:
            old, old_sq = old * leave[:, None], old_sq * leave
        if self._decay:
            wsums *= lam[:, None]
            wsums += d - old
        np.matmul((-2.0 * (d[None, :] - old))[:, None, :], self._kernels, out=buf)
        nxt = buf.reshape(e.shape)
        if self._decay:  # every term already in the window ages by one sample (e is free after this step)
            e *= lam[:, None]
        first = nxt[:, 0] + e[self._rows, self._last]  # circular: column 0 follows column n - 1
        nxt.ravel()[1:] += e.ravel()[:-1]  # e[r, j-1]: the window and the kernel slide together
        nxt[:, 0] = first
        nxt[self._pad_rows, self._pad_cols] = np.inf
        nxt += (dsq - old_sq)[:, None]
        # ||k_j||^2 stays until the window is full, then (1 - lambda^N) ||k_j||^2
        if self._decay:
            const = (1.0 - lam_w)[:, None] * self._ksq
        else:
            const = None
        if full is None:
            if const is not None:
                nxt += const
        else:
            nxt[~full] += self._ksq[~full]
            if const is not None:
                nxt[full] += const[full]
        return nxt, e.reshape(buf.shape)

    def _resync(self) -> None:
        # Errors travel with the diagonal e[r, j] -> e[r, j + 1], so the sweep runs over the
        # diagonals q = (j - steps) mod n, which stay put, not over the columns j.
        lo = self._resync_cursor
        size = self.n_rows * self.max_length
        hi = min(lo + self._resync_block, size)
        rows, diag = np.divmod(np.arange(lo, hi), self.max_length)
        rows, diag = rows[diag < self.lengths[rows]], diag[diag < self.lengths[rows]]
        if self._active is not self._rows:  # rows the compiled step leaves are rebuilt when they come back
            inside = np.zeros(self.n_rows, dtype=np.bool_)
            inside[self._active] = True
            rows, diag = rows[inside[rows]], diag[inside[rows]]
        if rows.size:
            cols = (diag + self._count) % self.lengths[rows]
            self._e[self._slots.at(rows), cols] = self._window_sse(rows, cols)
        if hi >= size:
            self._resync_cursor = 0
            if self._count > self.max_window:  # every window sum is then a difference of two
                self._rebase_prefix_sums()
        else:
            self._resync_cursor = hi

    def _rebase_prefix_sums(self) -> None:
        """Keep the prefix sums small (their differences, the window sums, are what counts)."""
        shift = self._psum.copy()
        self._psum -= shift
        self._psum_ring -= shift

    def mean_offset(self, row: int, column: int) -> np.ndarray:
        """Mean of the current window of ``row`` minus the mean of the kernel part it is compared
        with at ``column`` (4,), degrees, both age-weighted with recency weighting (the means the
        offset penalty compares): the sensor offset under the hypothesis that the wearer walks that
        row's mode and time scale. Valid once the row's window is full."""
        self._sync_rows(np.array([row]))
        p = int(self._slots.slot[row])
        if self.recency_half_life > 0:
            return (self._wsums[p] / self._wsum[row] - self._row_shift_means(np.array([row]))[0, :, column]) * self._unscale
        w = int(self.windows[row])
        s = self.window_sums()[row]  # not from the prefix-sum ring: the longest window's start slot is overwritten
        return (s / w - self._mu[p]) * self._unscale

    def running_sse(self) -> np.ndarray:
        """The running e[r, j] (R, Nmax), padding inf (and rows not in the row tables); a copy."""
        out = np.full((self.n_rows, self.max_length), np.inf)
        held = self._slots.owner >= 0
        out[self._slots.held()] = self._e[held]
        return out

    def set_kernel(self, mode: int, samples: np.ndarray) -> None:
        """Replace the kernel of ``mode`` (N_m, 4), degrees, keeping the window: the running
        sums of its rows are recomputed exactly from the buffered samples in O(n log n) per row
        (FFT circular correlation), so the next step continues as if the kernel had always been
        this one."""
        k = np.asarray(samples, dtype=np.float64)
        if k.shape != self.library.modes[mode].samples.shape or not np.all(np.isfinite(k)):
            raise ValueError(f"new kernel for mode {self.mode_names[mode]!r} must be finite with shape "
                             f"{self.library.modes[mode].samples.shape}, got {k.shape}")
        self._set_rows(mode, k)
        rows = self.mode_rows(mode)
        rows = rows[self._slots.slot[rows] >= 0]  # the others are built from the new kernel when they are needed
        self._e[self._slots.at(rows)] = self._rows_sse_fft(rows, self._lam)
        if self._active is not self._rows:  # outside the band: the age-weighted sums too
            self._sync_rows(rows)

    def _rows_sse_fft(self, rows: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """e[r, :] for ``rows`` from the buffered window by FFT with the age weights of ``lam``
        (per row, (R,)), (len(rows), Nmax), padding inf.

        e[j] = sum_{t<W} a_t ||x_t||^2 - 2 sum_{t<W} a_t x_t . k_{(j-t) mod n} + sum_{t<W} a_t ||k_{(j-t) mod n}||^2
        with x_t = d_{i-t} and age weights a_t (lambda^t; 1 without recency weighting): two
        circular convolutions of length n.
        """
        data = self._window_data()
        out = np.full((rows.size, self.max_length), np.inf)
        # Rows of one length and age weight compare the same window part: one batch of transforms each.
        keys = np.stack([self.lengths[rows].astype(np.float64), lam[rows]], axis=1)
        _, group = np.unique(keys, axis=0, return_inverse=True)
        group = group.reshape(-1)
        for g in range(int(group.max()) + 1 if rows.size else 0):
            sel = np.flatnonzero(group == g)
            r0 = int(rows[sel[0]])
            n = int(self.lengths[r0])
            w = min(self._count, int(self.windows[r0]))
            age = np.zeros(n)
            age[:w] = lam[r0] ** np.arange(w)
            x = np.zeros((n, N_CHANNELS))
            x[:w] = data[:w]
            k = self._kernels[self._slots.at(rows[sel]), :, :n].astype(np.float64)  # (g, 4, n)
            fx = np.fft.rfft(x.T * age, n=n)  # (4, n // 2 + 1)
            cross = np.fft.irfft((fx[None] * np.fft.rfft(k, n=n)).sum(axis=1), n=n)
            ksq = np.fft.irfft(np.fft.rfft(age)[None] * np.fft.rfft((k * k).sum(axis=1), n=n), n=n)
            out[sel, :n] = float((age[:, None] * x * x).sum()) - 2.0 * cross + ksq
        return out

    def state_bytes(self) -> int:
        """Bytes of numpy state this matcher keeps between steps."""
        arrays = [self._ring, self._ring_sq, self._psum_ring, self._slots.slot, self._slots.owner, self._synced,
                  *(getattr(self, name) for name in self._TABLES), *self._samples.values()]
        if self.backend == "numpy":
            arrays.append(self._next)
        return int(sum(a.nbytes for a in arrays))
