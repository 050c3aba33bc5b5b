"""The incremental matcher's step compiled with numba (optional; ``matcher.py`` falls back to numpy).

One call does what ``IncrementalMatcher._step_numpy`` does with a dozen numpy calls: the
running-sum update of every row (mode x time scale), the window sums, the offset adjustment,
normalisation, the per-row argmin and the per-mode choice of the best time scale. Row layout and
conventions are documented in ``matcher.py``; results equal the numpy path to rounding (tested).

``AVAILABLE`` is False when numba is not installed or ``GAIT_ESTIMATOR_NO_NUMBA`` is set; the
first use compiles (about 2 s) and caches the machine code next to this file or in
``NUMBA_CACHE_DIR``.
"""

from __future__ import annotations

import hashlib
import os
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from .shift_means import SHIFT_BLOCK
from .stride_track import stride_step

try:  # pragma: no cover - depends on the environment
    if os.environ.get("GAIT_ESTIMATOR_NO_NUMBA"):
        raise ImportError("disabled by GAIT_ESTIMATOR_NO_NUMBA")
    from numba import njit, prange

    AVAILABLE = True
except ImportError:  # pragma: no cover - depends on the environment
    AVAILABLE = False
    prange = range

    def njit(*args, **kwargs):  # type: ignore[no-redef]
        def wrap(fn):
            return fn

        return wrap


@njit(cache=True, nogil=True, inline="always")
def _offset_penalty(s0, s1, s2, s3, w, m0, m1, m2, m3, tau):  # pragma: no cover - compiled
    """W * sum_c g(S_c / W - mu_c), g(x) = x^2 - max(|x - o_c| - tau_c, 0)^2 with tau = tau[0]
    and the sensor offset o = tau[1]: the part of the SSE explained by a per-channel offset
    within tau_c of o_c between window and kernel means."""
    total = 0.0
    for c in range(4):
        if c == 0:
            x = s0 / w - m0
        elif c == 1:
            x = s1 / w - m1
        elif c == 2:
            x = s2 / w - m2
        else:
            x = s3 / w - m3
        a = abs(x - tau[1, c]) - tau[0, c]
        total += x * x - (a * a if a > 0.0 else 0.0)
    return total * w


class StepState(NamedTuple):
    """The matcher state a compiled step reads and updates (its arrays in place), built by
    ``IncrementalMatcher`` when one of them is replaced. The steps take it as a plain tuple
    (``tuple(state)``), which numba types as fast as separate arguments (a named tuple costs a
    microsecond more per call), and unpack it in this order (``step_rows``)."""

    e: np.ndarray
    kern: np.ndarray
    ksq: np.ndarray
    lens: np.ndarray
    ring: np.ndarray
    ring_sq: np.ndarray
    psum_ring: np.ndarray
    psum: np.ndarray
    decay: bool
    lam: np.ndarray
    lam_w: np.ndarray
    wsum: np.ndarray
    wsums: np.ndarray
    offset: bool
    mu: np.ndarray
    mu_anchor: np.ndarray
    mu_range: np.ndarray
    mu_blocks: np.ndarray
    tau: np.ndarray
    normalize: bool
    n_scales: int
    readable: np.ndarray
    active: np.ndarray
    slot: np.ndarray
    out_col: np.ndarray
    out_score: np.ndarray


def step_rows(
    state: tuple, count: int, d0: float, d1: float, d2: float, d3: float, dsq: float,
    out_sse: np.ndarray, out_phase: np.ndarray, out_variant: np.ndarray, out_column: np.ndarray, out_window: np.ndarray,
) -> int:  # pragma: no cover - compiled
    """One matcher step over the rows ``active``; returns the best mode. See the module docstring.

    state: a ``StepState`` as a plain tuple, of which e (R, Nmax): running sums, updated in place;
    kern (R, 4, Nmax) float64 or float32; ksq (R, Nmax) = ||k_j||^2;
    lens (R,): row lengths (= windows); ring (Wmax, 4) and ring_sq (Wmax,): the last Wmax samples and
    their squared norms; psum_ring (Wmax, 4): prefix sums of the samples at those slots, psum (4,)
    the prefix sum before this sample; count: samples before this one; d0..d3: the (weighted)
    sample, as scalars (the caller builds no array), dsq = ||d||^2; decay: the matcher keeps
    age-weighted window sums, with per row lam (R,) the weight factor per sample of age, lam_w =
    lam^N, wsum the weight sum of a full window (N without decay) and wsums (R, 4) the
    age-weighted window sums, updated in place; offset: apply the offset penalty (mu (R, 4)
    kernel means, mu_anchor (R, 4, B) the per-shift age-weighted means of the kernel at every
    16th shift (the others follow: ``shift_means.expand_shift_means``), mu_range (R, 2, 4) their
    minimum and maximum over the shifts, mu_blocks (R, 2, 4, B) the same per block of 16 shifts, tau (2, 4):
    tolerances and sensor offsets; with decay the window's weight W_a and age-weighted sums stand
    for W and the sums);
    normalize: divide by the window's weight;
    readable (R,) bool: the rows a mode may be read at (at least one per mode); active: the rows
    updated and read out (the readable ones, or all); the others keep their sums. slot (R,): the
    row of e, kern, ksq, wsums, mu, mu_anchor, mu_range and mu_blocks that holds a row (the row
    tables; every active row has one); lens, lam, lam_w, wsum, out_col and out_score are per row.
    Writes per active row out_col/out_score, per mode out_sse/out_phase/out_variant/out_column/out_window.
    """
    (e, kern, ksq, lens, ring, ring_sq, psum_ring, psum, decay, lam, lam_w, wsum, wsums, offset, mu, mu_anchor,
     mu_range, mu_blocks, tau, normalize, n_scales, readable, active, slot, out_col, out_score) = state  # StepState
    wmax = ring.shape[0]
    i = count
    p0, p1, p2, p3 = psum[0] + d0, psum[1] + d1, psum[2] + d2, psum[3] + d3
    for a in prange(active.shape[0]):  # rows are independent (threads in step_rows_parallel)
        r = active[a]
        p = slot[r]
        n = lens[r]
        full = i >= n
        r0 = r1 = r2 = r3 = rsq = 0.0
        if full:
            s = (i - n) % wmax
            r0, r1, r2, r3, rsq = ring[s, 0], ring[s, 1], ring[s, 2], ring[s, 3], ring_sq[s]
        lw = lam_w[r]  # weight of the sample leaving the window (1 without decay)
        o0, o1, o2, o3, osq = r0 * lw, r1 * lw, r2 * lw, r3 * lw, rsq * lw
        base = dsq - osq
        er = e[p]
        k0, k1, k2, k3 = kern[p, 0], kern[p, 1], kern[p, 2], kern[p, 3]
        last = er[n - 1]
        # In place, from the last column down: e[j] takes the old e[j-1] before it is overwritten.
        aged = decay and lam[r] < 1.0  # age weights in effect (lam = 1: uniform, the paper's update)
        if full and not aged:
            # e[j] = e[j-1] + ||d||^2 - ||old||^2 - 2 k_j . (d - old)
            c0, c1, c2, c3 = -2.0 * (d0 - o0), -2.0 * (d1 - o1), -2.0 * (d2 - o2), -2.0 * (d3 - o3)
            for j in range(n - 1, 0, -1):
                er[j] = er[j - 1] + base + c0 * k0[j] + c1 * k1[j] + c2 * k2[j] + c3 * k3[j]
            er[0] = last + base + c0 * k0[0] + c1 * k1[0] + c2 * k2[0] + c3 * k3[0]
        elif full:
            _aged_update(er, n, lam[r], lw, base, d0 - o0, d1 - o1, d2 - o2, d3 - o3, k0, k1, k2, k3, ksq[p])
        else:
            # filling: nothing leaves the window; e[j] = lam e[j-1] + ||d - k_j||^2   (lam = 1 without decay)
            c0, c1, c2, c3 = -2.0 * d0, -2.0 * d1, -2.0 * d2, -2.0 * d3
            g = lam[r]
            kq = ksq[p]
            for j in range(n - 1, -1, -1):
                prev = er[j - 1] if j > 0 else last
                er[j] = g * prev + base + kq[j] + c0 * k0[j] + c1 * k1[j] + c2 * k2[j] + c3 * k3[j]

        if decay:  # the weighted window sums age too: S = lam S + d - lam^N old
            _age_sums(wsums, p, lam[r], d0 - o0, d1 - o1, d2 - o2, d3 - o3)

        # Read-out of row r: score = (e - offset penalty) / window weight, its argmin over j.
        filled = i + 1 >= n
        if aged:
            weff = wsum[r] if filled else (1.0 - lam[r] ** (i + 1)) / (1.0 - lam[r])
        else:
            weff = float(n if filled else i + 1)
        scale = 1.0 / weff if normalize else 1.0
        use_offset = offset and filled
        s0 = s1 = s2 = s3 = 0.0
        if use_offset:
            s0, s1, s2, s3 = _row_sums(decay, wsums, p, p0, p1, p2, p3, psum_ring, i, n)
        per_shift = use_offset and aged  # the kernel part's weighted mean depends on the shift
        wp = wsum[r]
        const = 0.0
        if use_offset and not per_shift:
            const = _offset_penalty(s0, s1, s2, s3, wp, mu[p, 0], mu[p, 1], mu[p, 2], mu[p, 3], tau)
        if per_shift:  # _offset_penalty per column, with the window means and tau hoisted out of the loop
            best, bj = _argmin_per_shift(er, n, wp, s0 / wp, s1 / wp, s2 / wp, s3 / wp, tau, mu_anchor[p], k0, k1, k2, k3,
                                         lam[r], mu_range[p], mu_blocks[p], out_col[r] + 1)
        else:
            best, bj = _argmin(er, n)
            best -= const
        out_col[r] = bj
        out_score[r] = best * scale

    # Per mode: the time scale (row) with the lowest score; phase of its best column.
    n_modes = lens.shape[0] // n_scales
    best_mode = 0
    for m in range(n_modes):
        rb = -1
        vb = 0
        for v in range(n_scales):  # row v * M + m: mode m at scale v
            r = v * n_modes + m
            if readable[r] and (rb < 0 or out_score[r] < out_score[rb]):
                rb, vb = r, v
        n = lens[rb]
        j = out_col[rb]
        ph = (float(j + 1) % n) / n
        if ph >= 1.0:
            ph = 0.0
        out_sse[m] = out_score[rb]
        out_phase[m] = ph
        out_variant[m] = vb
        out_column[m] = j
        out_window[m] = n if i + 1 >= n else i + 1
        if out_score[rb] < out_sse[best_mode]:
            best_mode = m

    # The new sample enters the ring (after every row has read its stale sample).
    slot = i % wmax
    ring[slot, 0], ring[slot, 1], ring[slot, 2], ring[slot, 3] = d0, d1, d2, d3
    ring_sq[slot] = dsq
    psum_ring[slot, 0], psum_ring[slot, 1], psum_ring[slot, 2], psum_ring[slot, 3] = p0, p1, p2, p3
    psum[0], psum[1], psum[2], psum[3] = p0, p1, p2, p3
    return best_mode


def compiled_copy(fn: Callable[..., Any], name: str, parallel: bool = False, **callees: Any) -> Any:
    """A compiled copy of ``fn`` (or of a compiled function's source) as a function of its own
    ``name`` (so that its cache does not collide with ``fn``'s), ``parallel``: prange over numba's
    threads; ``callees``: global names that refer to other functions in the copy (then a snapshot
    of the module's globals, else the module's own, which later definitions still enter)."""
    fn = getattr(fn, "py_func", fn)  # a compiled function: its Python source
    twin = types.FunctionType(fn.__code__, {**fn.__globals__, **callees} if callees else fn.__globals__, name)
    twin.__qualname__ = f"{name}_{_source_tag(twin)}"
    return njit(cache=True, nogil=True, parallel=parallel)(twin)


def _source_tag(fn: Callable[..., Any]) -> str:
    """A hash of the files that define ``fn`` and the compiled functions it calls, at any depth:
    numba's cache checks only the file of the function compiled, so a copy is cached under a name
    that changes with every file its code comes from."""
    files, seen, todo = set(), set(), [fn]
    while todo:
        f = todo.pop()
        f = getattr(f, "py_func", f)
        if f in seen:
            continue
        seen.add(f)
        files.add(f.__code__.co_filename)
        todo += [g for n in f.__code__.co_names if hasattr(g := f.__globals__.get(n), "py_func")]
    digest = hashlib.blake2s(digest_size=4)
    for path in sorted(files):
        digest.update(Path(path).read_bytes())
    return digest.hexdigest()


step_rows, step_rows_parallel = (  # serial (prange runs as range) and with the rows over threads
    njit(cache=True, nogil=True)(step_rows),
    compiled_copy(step_rows, "step_rows_parallel", parallel=True),
)


@njit(cache=True, nogil=True, inline="always")
def _argmin(v, n):  # pragma: no cover - compiled
    """(min, first index of the min) of v[:n] ((inf, 0) if no value is below inf; nan never wins):
    the scan's four interleaved lanes have no dependence on each other, so they overlap."""
    b0 = b1 = b2 = b3 = np.inf
    j0 = j1 = j2 = j3 = 0
    q = n - n % 4
    for j in range(0, q, 4):
        v0, v1, v2, v3 = v[j], v[j + 1], v[j + 2], v[j + 3]
        if v0 < b0:
            b0, j0 = v0, j
        if v1 < b1:
            b1, j1 = v1, j + 1
        if v2 < b2:
            b2, j2 = v2, j + 2
        if v3 < b3:
            b3, j3 = v3, j + 3
    for j in range(q, n):
        if v[j] < b0:
            b0, j0 = v[j], j
    best, bj = np.inf, 0
    for lb, lj in ((b0, j0), (b1, j1), (b2, j2), (b3, j3)):
        if lb < best or (lb == best and lb < np.inf and lj < bj):
            best, bj = lb, lj
    return best, bj


@njit(cache=True, nogil=True, inline="always")
def _shift_score(e, j, wp, a0, a1, a2, a3, t0, t1, t2, t3, f0, f1, f2, f3, m0, m1, m2, m3):  # pragma: no cover
    """e[j] minus the offset penalty at column j with the kernel part's means m* (at that shift)."""
    x0, x1, x2, x3 = a0 - m0, a1 - m1, a2 - m2, a3 - m3
    g0 = max(abs(x0 - f0) - t0, 0.0)
    g1 = max(abs(x1 - f1) - t1, 0.0)
    g2 = max(abs(x2 - f2) - t2, 0.0)
    g3 = max(abs(x3 - f3) - t3, 0.0)
    return e[j] - wp * (x0 * x0 - g0 * g0 + x1 * x1 - g1 * g1 + x2 * x2 - g2 * g2 + x3 * x3 - g3 * g3)


@njit(cache=True, nogil=True, inline="always")
def _penalty_bound(a, lo, hi, t, f):  # pragma: no cover - compiled
    """The largest offset penalty of one channel (``_shift_score``'s g(x) = x^2 - max(|x - f| - t, 0)^2)
    over window-vs-kernel mean differences x = a - m with m in [lo, hi]: g is convex (a parabola
    between two tangent lines), so its largest value is at an end."""
    x0, x1 = a - hi, a - lo
    g0, g1 = max(abs(x0 - f) - t, 0.0), max(abs(x1 - f) - t, 0.0)
    return max(x0 * x0 - g0 * g0, x1 * x1 - g1 * g1)


@njit(cache=True, nogil=True, inline="always")
def _scan_block(e, lo, hi, wp, a0, a1, a2, a3, t0, t1, t2, t3, f0, f1, f2, f3, anchor, k0, k1, k2, k3, lam, best,
                bj):  # pragma: no cover - compiled
    """(best, bj) after scoring the shifts lo .. hi - 1 of one block (``_argmin_per_shift``), the
    kernel part's means from the block's first (anchor) on: m_j = lam m_{j-1} + (1 - lam) k_j."""
    c = 1.0 - lam
    q = lo // SHIFT_BLOCK
    m0, m1, m2, m3 = anchor[0, q], anchor[1, q], anchor[2, q], anchor[3, q]
    v = _shift_score(e, lo, wp, a0, a1, a2, a3, t0, t1, t2, t3, f0, f1, f2, f3, m0, m1, m2, m3)
    if v < best or (v == best and lo < bj):
        best, bj = v, lo
    for j in range(lo + 1, hi):
        m0, m1, m2, m3 = lam * m0 + c * k0[j], lam * m1 + c * k1[j], lam * m2 + c * k2[j], lam * m3 + c * k3[j]
        v = _shift_score(e, j, wp, a0, a1, a2, a3, t0, t1, t2, t3, f0, f1, f2, f3, m0, m1, m2, m3)
        if v < best or (v == best and j < bj):
            best, bj = v, j
    return best, bj


@njit(cache=True, nogil=True, inline="always")
def _argmin_per_shift(e, n, wp, a0, a1, a2, a3, tau, anchor, k0, k1, k2, k3, lam, mu_range, mu_blocks,
                      guess):  # pragma: no cover
    """(min, first index of the min) over j < n of the scores e[j] - penalty(j) (``_shift_score``;
    a*: the window means; the kernel part's means per shift: anchor (4, B) those of every 16th
    shift, the others m_j = lam m_{j-1} + (1 - lam) k_j (``shift_means.expand_shift_means``)
    from the kernel k* (n,); mu_range (2, 4) their range, mu_blocks (2, 4, B) per block of 16
    shifts). A score is at least e[j] - wp * (the largest penalty any shift of its block can
    have), so starting from the block of column ``guess`` (the last step's best, moved on by
    one), only the blocks whose smallest e[j] is within that bound (over all shifts, then over
    the block's) of the best score so far are scored: the result is the exhaustive scan's
    (test_matcher compares it with the numpy read-out)."""
    t0, t1, t2, t3 = tau[0, 0], tau[0, 1], tau[0, 2], tau[0, 3]
    f0, f1, f2, f3 = tau[1, 0], tau[1, 1], tau[1, 2], tau[1, 3]
    bound = wp * (_penalty_bound(a0, mu_range[0, 0], mu_range[1, 0], t0, f0)
                  + _penalty_bound(a1, mu_range[0, 1], mu_range[1, 1], t1, f1)
                  + _penalty_bound(a2, mu_range[0, 2], mu_range[1, 2], t2, f2)
                  + _penalty_bound(a3, mu_range[0, 3], mu_range[1, 3], t3, f3))
    first = (guess if 0 <= guess < n else 0) // SHIFT_BLOCK * SHIFT_BLOCK  # where the last step's best shift moved to
    best, bj = _scan_block(e, first, min(first + SHIFT_BLOCK, n), wp, a0, a1, a2, a3, t0, t1, t2, t3, f0, f1, f2, f3, anchor,
                           k0, k1, k2, k3, lam, np.inf, first)
    slack = 1e-9 * (abs(best) + abs(bound))  # rounding of the scores and the bound
    for lo in range(0, n, SHIFT_BLOCK):  # one test per block of shifts
        if lo == first:
            continue
        hi = min(lo + SHIFT_BLOCK, n)
        low = e[lo]
        for j in range(lo + 1, hi):
            low = min(low, e[j])
        if low - bound > best + slack:
            continue
        q = lo // SHIFT_BLOCK  # the bound over this block's shifts only
        near = wp * (_penalty_bound(a0, mu_blocks[0, 0, q], mu_blocks[1, 0, q], t0, f0)
                     + _penalty_bound(a1, mu_blocks[0, 1, q], mu_blocks[1, 1, q], t1, f1)
                     + _penalty_bound(a2, mu_blocks[0, 2, q], mu_blocks[1, 2, q], t2, f2)
                     + _penalty_bound(a3, mu_blocks[0, 3, q], mu_blocks[1, 3, q], t3, f3))
        if low - near > best + 1e-9 * (abs(best) + abs(near)):
            continue
        best, bj = _scan_block(e, lo, hi, wp, a0, a1, a2, a3, t0, t1, t2, t3, f0, f1, f2, f3, anchor, k0, k1, k2, k3,
                               lam, best, bj)
    return best, bj


@njit(cache=True, nogil=True, inline="always")
def _aged_update(er, n, a, lw, base, x0, x1, x2, x3, k0, k1, k2, k3, kq):  # pragma: no cover - compiled
    """Running sums of one whole-stride row with age weights, in place from the last column down:
    e[j] = a e[j-1] + base + (1 - lw) ||k_j||^2 - 2 k_j . x, with base = ||d||^2 - lw ||old||^2,
    x = d - lw old and lw = a^N (0 while the window fills: nothing leaves it)."""
    kc = 1.0 - lw
    c0, c1, c2, c3 = -2.0 * x0, -2.0 * x1, -2.0 * x2, -2.0 * x3
    last = er[n - 1]
    for j in range(n - 1, 0, -1):
        er[j] = a * er[j - 1] + base + kc * kq[j] + c0 * k0[j] + c1 * k1[j] + c2 * k2[j] + c3 * k3[j]
    er[0] = a * last + base + kc * kq[0] + c0 * k0[0] + c1 * k1[0] + c2 * k2[0] + c3 * k3[0]


@njit(cache=True, nogil=True, inline="always")
def _age_sums(ws, r, a, x0, x1, x2, x3):  # pragma: no cover - compiled
    """Age-weighted window sums of row r, in place: S = a S + x, x = d - lw old."""
    ws[r, 0] = a * ws[r, 0] + x0
    ws[r, 1] = a * ws[r, 1] + x1
    ws[r, 2] = a * ws[r, 2] + x2
    ws[r, 3] = a * ws[r, 3] + x3


@njit(cache=True, nogil=True, inline="always")
def _row_sums(decay, wsums, r, p0, p1, p2, p3, psum_ring, i, w):  # pragma: no cover - compiled
    """The window sums of the row (slot r of wsums) after this sample (p: prefix sums including it): the age-weighted
    sums with decay, else a difference of two prefix sums."""
    if decay:
        return wsums[r, 0], wsums[r, 1], wsums[r, 2], wsums[r, 3]
    s0, s1, s2, s3 = p0, p1, p2, p3
    if i >= w:
        q = (i - w) % psum_ring.shape[0]
        s0 -= psum_ring[q, 0]
        s1 -= psum_ring[q, 1]
        s2 -= psum_ring[q, 2]
        s3 -= psum_ring[q, 3]
    return s0, s1, s2, s3


_stride_step = njit(cache=True, nogil=True, inline="always")(stride_step)


@njit(cache=True, nogil=True, inline="always")
def report_step(hook, g, best, sse, phases, window, ready):  # pragma: no cover - compiled
    """The mode and phase reported at step ``g`` of ``run_steps``: the ``best`` mode and its phase
    (``hook`` unused). A copy of ``run_steps`` with another function here (``StepHook``) decides
    there from ``hook`` and the step's per-mode ``sse``, ``phases``, ``window`` and ``ready``."""
    return best, phases[best]


def run_steps(  # pragma: no cover - compiled
    state, count, samples, squares, start, stop,
    out_sse, out_phase, out_variant, out_window, best, best_column, column, track, near, mid_lo, mid_hi, ready_from,
    hook,
):
    """Matcher steps ``start`` .. ``stop`` - 1 of ``samples`` (G, 4) (weighted; ``squares`` their
    squared norms) through step_rows (``run_steps_parallel``: step_rows_parallel, the rows of each
    step over numba's threads), the matcher's ``state`` (``step_rows``) in place from ``count`` samples on. Per step:
    every mode's score, phase, variant and window into out_sse/out_phase/out_variant/out_window
    (G, M), the best mode, and the column of the reported mode (``report_step`` with ``hook``).

    The walking calibrations' stride tracker (``stride_track.stride_step``, as
    ``WalkingCalibration._confident_stride_end`` runs it, without its confidence test) runs
    along on the reported mode and its phase: ``track`` = (valid, mode, phase,
    passed_mid, began_in_mode) as floats, ``near`` (M, M) the near copies; the steps stop after a
    heel strike that ends a whole stride, where the calibrations may act, with ``track`` as it was
    before that step. Returns the step after the last done and whether it ended such a stride."""
    for g in range(start, stop):
        i = count + g - start
        d0, d1, d2, d3, dsq = samples[g, 0], samples[g, 1], samples[g, 2], samples[g, 3], squares[g]
        b = step_rows(state, i, d0, d1, d2, d3, dsq, out_sse[g], out_phase[g], out_variant[g], column, out_window[g])
        m, phase = report_step(hook, g, b, out_sse[g], out_phase[g], out_window[g], i + 1 >= ready_from)
        best[g], best_column[g] = b, column[m]
        if track.shape[0] == 0:
            continue
        same = track[0] > 0.0 and (int(track[1]) == m or near[int(track[1]), m])
        ends, midway, began = _stride_step(same, track[2], track[3] > 0.0, track[4] > 0.0, phase, (mid_lo, mid_hi))
        if ends:  # the tracker's state stays the one before this step
            return g + 1, True
        if i + 1 >= ready_from:
            track[0], track[1], track[2] = 1.0, m, phase
            track[3] = 1.0 if midway else 0.0
            track[4] = 1.0 if began else 0.0
        else:
            track[0] = 0.0
    return stop, False


run_steps, run_steps_parallel = (
    compiled_copy(run_steps, "run_steps"),
    compiled_copy(run_steps, "run_steps_parallel", step_rows=step_rows_parallel),
)


def step_loops(report: Any, name: str) -> tuple[Any, Any]:
    """Copies of ``run_steps`` named after ``name`` (rows on one thread, over threads) that call
    ``report`` (compiled, ``report_step``'s arguments and results) in ``report_step``'s place."""
    return (compiled_copy(run_steps, name, report_step=report),
            compiled_copy(run_steps, f"{name}_parallel", step_rows=step_rows_parallel, report_step=report))


class StepHook(NamedTuple):
    """A decision inside the compiled steps (``IncrementalMatcher.run_steps``): ``loops`` the copies
    of ``run_steps`` (``step_loops``) that make it, ``args`` their ``hook`` argument."""

    loops: tuple[Any, Any]
    args: tuple


MATCHER_REPORTS = StepHook((run_steps, run_steps_parallel), ())
"""No decision inside the steps: the best mode is reported."""
