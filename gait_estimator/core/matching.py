"""Mode and phase matching, shared part: rows, ring buffer, read-out, naive recomputation.

The matchers (``matcher.py``) are the paper's Algorithms 1 (naive) and 2 (incremental).

Every step takes one sample d_i (4 angles, degrees, CHANNELS order). The matcher keeps one *row*
per mode m and time scale s: the mode's kernel stretched to n = round(s N_m) samples (s = 1: the
kernel itself). For every row r and every column j (0-based) it keeps the running SSE

    e[r, j] = sum_{t=0}^{W-1} || d_{i-t} - k^r_{(j-t) mod n} ||^2        (deg^2)

where W = min(samples seen, n): the window (the newest n samples) ends at the newest sample, aligned
with column j. Until W = n for every row (``ready``) the sums run over the samples seen so far, as in the
reference implementation, whose running sums start from zero.

Read-out, per row: score[r, j] = e[r, j] (the paper), minus an offset penalty and divided by the
window length if asked (below); best column j* = argmin_j score. Per mode: the row (time scale)
with the lowest score. The best mode is argmin_m of that (ties: the earlier mode, then the
smaller scale, then the earlier column); its best column gives the phase ((j* + 1) mod n) / n in
[0, 1). That is the paper's phi = j*/N with its 1-based j*, and the reference implementation's
output, except that we wrap its 1.0 to 0.0.

Options (the defaults are the paper, which reproduces the reference exactly):

* ``channel_weights`` w (4,), >= 0: e = sum_c w_c (d_c - k_c)^2, so 0 drops a channel (e.g.
  unilateral sensing with the prosthesis-side thigh and shank only); implemented by scaling
  kernels and samples by sqrt(w);
* ``time_scales`` (S,): stretch factors of the kernels' stride duration; a wearer whose strides
  last s times the kernel's is matched by the rows of scale s (cadence ratio 1/s);
* ``offset_tolerance_deg`` tau >= 0: per channel, a difference of up to tau degrees between the
  window's mean and the mean of the kernel part it is compared with costs nothing (sensor
  mounting); larger differences cost only their excess. With x_c that mean difference the score
  is e - W sum_c (x_c^2 - max(|x_c| - tau, 0)^2): every SSE splits exactly into the shape part
  and W x_c^2 per channel. tau = inf matches shapes only; 0 is the paper;
* ``normalize``: compare modes and scales by mean squared error per window sample, score / W,
  instead of SSE (needed when rows of different lengths compete: the paper's SSE favours shorter
  kernels);
* ``recency_half_life`` h >= 0 (strides): weight the window's samples
  by their age, a sample t samples old by a_t = lambda_r^t with lambda_r = 2^(-1 / (h n_r)) (its
  weight halves every h strides): e[r, j] = sum_t a_t || d_{i-t} - k^r_{(j-t) mod n} ||^2, updated
  as e[r, j] <- lambda e[r, j-1] + ||d_i - k_j||^2 - lambda^n ||d_{i-n} - k_j||^2. The newest part
  of the stride counts most, so a mode change shows sooner. The offset penalty and ``normalize``
  use the weighted window: its weight W_a = sum_t a_t for W, the weighted window mean, and the
  weighted mean of the kernel part at each shift (precomputed, (R, 4, N)); the penalty is then
  the exact minimum of the weighted SSE over offsets within tau, as above. 0 = uniform weights
  (the paper); ``set_recency_half_life`` changes it at any sample;
* ``set_scale_band``: the time scales a mode may be read at (all by default; ``scale_band.py``,
  and how rows outside the band stay exact: ``IncrementalMatcher``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .channels import N_CHANNELS, Sample, sample_values
from .kernels import KernelLibrary, resample_stride
from .match_results import MatchTrace, StepResult
from .row_slots import RowSlots
from .scale_band import ScaleBand
from .shift_means import SHIFT_BLOCK, expand_shift_means, weighted_shift_means

_CHUNK = 2048  # columns per naive recomputation, bounds its temporary memory
ROW_TABLES = ("_kernels", "_mu", "_mu_seg", "_mu_anchor", "_mu_seg_range", "_mu_seg_blocks")  # arrays indexed by slot


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


def check_time_scales(value: Sequence[float] | None) -> np.ndarray:
    """Validate ``time_scales``: distinct numbers in [0.5, 2], sorted (None = (1.0,))."""
    if value is None:
        return np.ones(1)
    s = np.asarray(value, dtype=np.float64).reshape(-1)
    if s.size == 0 or not np.all(np.isfinite(s)) or np.any((s < 0.5) | (s > 2.0)):
        raise ValueError(f"time_scales must be one or more numbers in [0.5, 2], got {s.tolist()}")
    if np.unique(s).size != s.size:
        raise ValueError(f"time_scales must be distinct, got {s.tolist()}")
    return np.sort(s)


def check_recency_half_life(value: float) -> float:
    """Validate ``recency_half_life``: a finite number >= 0 (strides; 0 = uniform weights)."""
    h = float(value)
    if not (math.isfinite(h) and h >= 0):
        raise ValueError(f"recency_half_life must be a finite number >= 0 (strides; 0 = off), got {value!r}")
    return h


def check_offset_tolerance(value: float) -> float:
    """Validate ``offset_tolerance_deg``: a number >= 0 (inf allowed)."""
    t = float(value)
    if math.isnan(t) or t < 0:
        raise ValueError(f"offset_tolerance_deg must be >= 0 (inf: any offset), got {value!r}")
    return t


class _MatcherBase:
    """Shared state: the rows (padded kernels), the ring buffer of recent samples, the read-out.

    Args:
        library: The kernels to match against (degrees).
        channel_weights: Weight of each channel (CHANNELS order), >= 0, not all 0; None = all 1.
        time_scales: Stride-duration factors of the kernel variants; None = (1.0,), the paper.
        offset_tolerance_deg: Per-channel mean offset that costs nothing, degrees; 0 = the paper.
        normalize: Compare by mean squared error per window sample instead of SSE.
        recency_half_life: Age (strides) at which a sample's weight in the window halves; 0 =
            uniform weights, the paper.
    """

    _shift_table = True  # keep every shift's kernel means (else derive them from every SHIFT_BLOCK-th)

    def __init__(
        self,
        library: KernelLibrary,
        channel_weights: Sequence[float] | None = None,
        time_scales: Sequence[float] | None = None,
        offset_tolerance_deg: float = 0.0,
        normalize: bool = False,
        recency_half_life: float = 0.0,
    ) -> None:
        self.library = library
        self.mode_names = library.mode_names
        self.n_modes = len(library)
        self.channel_weights = check_channel_weights(channel_weights)
        self.time_scales = check_time_scales(time_scales)
        self.offset_tolerance_deg = check_offset_tolerance(offset_tolerance_deg)
        self.normalize = bool(normalize)
        self.recency_half_life = check_recency_half_life(recency_half_life)
        self.n_scales = int(self.time_scales.size)
        self.active_channels = int(np.count_nonzero(self.channel_weights))
        self._scale = np.sqrt(self.channel_weights)
        self._scale_values: Sample = sample_values(self._scale)
        self._unscale = np.divide(1.0, self._scale, out=np.zeros(N_CHANNELS), where=self._scale > 0)  # dropped: 0
        self._weighted = bool(np.any(self.channel_weights != 1.0))
        # row 0: tolerance, row 1: sensor offset (set_sensor_offset), in the weighted units of d and k
        tolerance = np.where(self._scale > 0, self.offset_tolerance_deg, 0.0) * self._scale  # dropped channel: 0, not inf * 0
        self._tau = np.stack([tolerance, np.zeros(N_CHANNELS)])
        self._offset = self.offset_tolerance_deg > 0
        base = library.lengths
        # Rows are scale-major: row s * M + m is mode m at time scale s (the rows of one scale, which
        # the compiled step updates once the cadence is learnt, lie next to each other in memory).
        self.lengths = np.maximum(2, np.rint(np.outer(self.time_scales, base))).astype(np.int64).reshape(-1)
        self._base_lengths = np.asarray(base, dtype=np.int64)
        self.windows = self.lengths  # every row compares its whole stride
        self.n_rows = int(self.lengths.size)
        self.max_length = int(self.lengths.max())
        self.max_window = self.max_length
        self._decay = self.recency_half_life > 0  # age weights possible (set_recency_half_life)
        self._means_half_life = self.recency_half_life  # the age weights whose kernel means mu_seg holds
        self._set_weights(self.recency_half_life)
        self._per_shift = self._decay  # the kernel part's weighted mean depends on the shift
        self._means_lam = self._lam  # the age weight factors of the per-shift means
        self._rows = np.arange(self.n_rows)
        self._all = np.arange(self.n_modes)
        self._band = ScaleBand(self.n_modes, self.n_scales)  # the rows read out
        self._row_score = np.zeros(self.n_rows)  # per row: its best score of the last step
        self._samples: dict[int, np.ndarray] = {}  # kernels that replace the library's (set_kernel)
        self._slots = RowSlots(self.n_rows)  # the slot of the row tables that holds each row
        self._allocate(self.n_rows)
        self._build(self._rows)
        self._ring = np.zeros((self.max_window, N_CHANNELS))
        self._count = 0

    # -----------------------------------------------------------------------------------------
    # Rows

    def _allocate(self, slots: int, dtype: type = np.float64) -> None:
        """Empty row tables with room for ``slots`` rows (``dtype``: the kernels')."""
        self._kernels = np.zeros((slots, N_CHANNELS, self.max_length), dtype=dtype)  # channel-major rows
        self._mu = np.zeros((slots, N_CHANNELS))
        # per-shift (weighted) kernel means of the window's part (the offset penalty may be switched
        # on at any sample): those of every SHIFT_BLOCK-th shift, and all of them unless the step
        # derives them (``_shift_table``)
        per_shift = self.max_length if self._per_shift else 1
        self._mu_seg = np.zeros((slots, N_CHANNELS, per_shift if self._shift_table or not self._per_shift else 0))
        blocks = -(-per_shift // SHIFT_BLOCK)
        self._mu_anchor = np.zeros((slots, N_CHANNELS, blocks if self._per_shift else 0))
        self._mu_seg_range = np.zeros((slots, 2, N_CHANNELS))  # per row: min and max of mu_seg over shifts
        self._mu_seg_blocks = np.zeros((slots, 2, N_CHANNELS, blocks))  # the same per block of shifts
        self._state = None  # the compiled step's state refers to the arrays replaced
        self._allocate_state(slots)

    def _allocate_state(self, slots: int) -> None:
        """Empty running state for ``slots`` rows of the row tables (the naive matcher keeps none)."""

    def _rows_built(self, rows: np.ndarray) -> None:
        """The kernels of ``rows`` were (re)built in the row tables (nothing to do for the naive matcher)."""

    def _row_kernel_values(self, rows: np.ndarray) -> np.ndarray:
        """The kernels of ``rows`` (one length, of modes of one length) (g, n, 4), weighted:
        float32-representable values (the compiled step streams a float32 copy, half the memory
        traffic); every path computes with exactly these values, in float64."""
        n = int(self.lengths[rows[0]])
        modes = [int(m) for m in rows % self.n_modes]
        stacked = np.concatenate([self._samples.get(m, self.library.modes[m].samples) for m in modes], axis=1)  # (N, 4g)
        k = resample_stride(stacked, n).reshape(n, rows.size, N_CHANNELS).transpose(1, 0, 2) * self._scale
        return np.ascontiguousarray(k.astype(np.float32).astype(np.float64))

    def _length_groups(self, rows: np.ndarray) -> list[np.ndarray]:
        """``rows`` grouped by their length and their modes' kernel length."""
        keys = self.lengths[rows] * (1 << 20) + self._base_lengths[rows % self.n_modes]
        return [rows[keys == key] for key in np.unique(keys)]

    def _build(self, rows: np.ndarray) -> None:
        """Fill the row tables' slots of ``rows`` from their modes' kernels."""
        weights = self._weights(self._means_half_life)
        for group in self._length_groups(rows):
            p = self._slots.slot[group]
            n = int(self.lengths[group[0]])
            k = self._row_kernel_values(group)
            self._kernels[p] = 0.0
            self._kernels[p, :, :n] = k.transpose(0, 2, 1)
            self._mu[p] = k.mean(axis=1)
            if self._per_shift:
                self._set_shift_means(p, self._shift_means(k, group, weights))
        self._rows_built(rows)

    def _set_rows(self, mode: int, samples: np.ndarray) -> None:
        """Use ``samples`` (N_m, 4), degrees, as the kernel of ``mode``: rebuild its rows in the tables."""
        self._samples[mode] = np.array(samples, dtype=np.float64)
        rows = self.mode_rows(mode)
        self._build(rows[self._slots.slot[rows] >= 0])

    @property
    def _valid(self) -> np.ndarray:
        """Per row and column, whether the column is in the row, (R, Nmax)."""
        return np.arange(self.max_length)[None, :] < self.lengths[:, None]

    def row_of(self, mode: int, scale: int) -> int:
        """The row of ``mode`` at time scale index ``scale``."""
        return scale * self.n_modes + mode

    def mode_rows(self, mode: int) -> np.ndarray:
        """The rows of ``mode``, (S,), ``time_scales`` order."""
        return mode + self.n_modes * np.arange(self.n_scales)

    def _weights(self, half_life: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per row: the weight factor per sample of age lambda, lambda^W (the weight of the sample
        leaving the window) and the weight sum of a full window W_a (lambda = 1: W)."""
        if half_life > 0:
            lam = 2.0 ** (-1.0 / (half_life * self.lengths))
            lam_w = lam ** self.windows
            return lam, lam_w, (1.0 - lam_w) / (1.0 - lam)
        return np.ones(self.lengths.size), np.ones(self.lengths.size), self.windows.astype(np.float64)

    def _set_weights(self, half_life: float) -> None:
        self.recency_half_life = half_life
        self._lam, self._lam_w, self._wsum = self._weights(half_life)
        self._state = None

    def set_recency_half_life(self, half_life: float) -> None:
        """Change ``recency_half_life`` (strides; 0 = uniform weights) at any sample, keeping the
        window: the running sums are recomputed from the buffered samples, so the next step
        continues as if the weights had always been these. Only for a matcher made with
        ``recency_half_life`` > 0 (its state holds the per-shift means the weights need)."""
        h = check_recency_half_life(half_life)
        if not self._decay:
            raise ValueError("set_recency_half_life needs a matcher made with recency_half_life > 0")
        if h == self.recency_half_life:
            return
        self._set_weights(h)
        if h > 0 and h != self._means_half_life:  # mu_seg: the means of the weights in use
            self._means_half_life = h
            self._means_lam = self._lam
            self._build(self._slots.held())
        self._reweighted()

    def start_uniform(self) -> None:
        """Match with uniform weights until ``set_recency_half_life`` sets the matcher's own age
        weights again (the estimator does so once its walking calibrations have read a few
        strides). Free on a fresh or reset matcher; otherwise the uniform sums are recomputed from
        the window once (as set_recency_half_life(0) does)."""
        if not self._decay:
            raise ValueError("start_uniform needs a matcher made with recency_half_life > 0")
        if self.recency_half_life == 0:
            return
        self._set_weights(0.0)
        if self._count == 0:
            self.reset()
        else:
            self._reweighted()

    def _reweighted(self) -> None:
        """Bring the running state in line with new age weights (nothing to do for the naive matcher)."""

    def _set_shift_means(self, p: np.ndarray, means: np.ndarray) -> None:
        """Slots ``p``' per-shift kernel means (g, 4, n) and their range over all shifts and over
        each block of SHIFT_BLOCK shifts."""
        n = means.shape[2]
        if self._shift_table:
            self._mu_seg[p, :, :n] = means
        self._mu_anchor[p, :, : -(-n // SHIFT_BLOCK)] = means[:, :, ::SHIFT_BLOCK]
        self._mu_seg_range[p] = np.stack([means.min(axis=2), means.max(axis=2)], axis=1)
        starts = np.arange(0, n, SHIFT_BLOCK)
        self._mu_seg_blocks[p, :, :, : starts.size] = np.stack(
            [np.minimum.reduceat(means, starts, axis=2), np.maximum.reduceat(means, starts, axis=2)], axis=1)

    def _shift_means(self, k: np.ndarray, rows: np.ndarray, weights: tuple[np.ndarray, ...]) -> np.ndarray:
        """Per column j, the (weighted) mean of the kernel part the window of each of ``rows`` (one
        length) is compared with at j: sum_{t<W} a_t k_{(j-t) mod n} / W_a, (g, 4, n) (a_t = 1
        without recency weighting); ``k`` (g, n, 4); ``weights``: ``_weights`` of the means'
        half-life."""
        r = int(rows[0])
        lam, _, wsum = weights
        return weighted_shift_means(k.transpose(0, 2, 1), int(self.windows[r]), float(lam[r]), float(wsum[r]))

    def _row_shift_means(self, rows: np.ndarray | slice) -> np.ndarray:
        """The per-shift kernel means of ``rows`` (which have slots), (r, 4, Nmax)."""
        if self._shift_table:
            return self._mu_seg[self._slots.at(rows)]
        rows = self._rows[rows]
        p = self._slots.at(rows)
        k = self._kernels[p].astype(np.float64)
        return expand_shift_means(self._mu_anchor[p], k, self._means_lam[rows])

    @property
    def sensor_offset_deg(self) -> np.ndarray:
        """The sensor offset assumed by the offset penalty (4,), degrees; zeros by default."""
        return self._tau[1] * self._unscale

    def set_sensor_offset(self, offset_deg: Sequence[float] | np.ndarray) -> None:
        """Assume the sensors read ``offset_deg`` (4,) degrees more than the kernels' (CHANNELS
        order): the offset penalty then measures window-vs-kernel mean differences from it. The
        running sums are untouched (the penalty is applied at read-out), so this may change at
        any sample; non-zero turns the penalty on even with ``offset_tolerance_deg`` 0."""
        o = np.asarray(offset_deg, dtype=np.float64).reshape(N_CHANNELS)
        if not np.all(np.isfinite(o)):
            raise ValueError(f"sensor offset must be finite, got {o.tolist()}")
        self._tau[1] = o * self._scale
        self._offset = self._offset or bool(np.any(o != 0.0))
        self._state = None

    @property
    def scale_band(self) -> np.ndarray:
        """Per time scale, whether a mode may be read at it (S,) bool; a copy."""
        return self._band.allowed.copy()

    @property
    def searched_modes(self) -> np.ndarray:
        """The modes read at every time scale besides the band's (``set_scale_band``'s
        ``search``), (M,) bool; a copy."""
        return self._band.searched.copy()

    def set_scale_band(self, allowed: Sequence[bool] | np.ndarray | None, search: int = 0) -> None:
        """Read every mode only at the time scales flagged in ``allowed`` (S,) (``time_scales``
        order; None = all), and the ``search`` modes that fit best at every scale (chosen again
        every ``SEARCH_EVERY`` steps: ``ScaleBand``). The running sums of every row are kept, so
        this may change at any sample."""
        self._band.set(allowed, search, self._row_score)
        self._band_changed()

    def _band_changed(self) -> None:
        """The rows read out changed (nothing to do for the naive matcher)."""

    def _search_step(self, score: np.ndarray) -> None:
        """After a step with per-mode ``score`` (M,): every ``SEARCH_EVERY`` steps, choose the
        searched modes again."""
        if self._band.after_step(self._count, score):
            self._band_changed()

    def mode_row_scores(self, mode: int) -> np.ndarray:
        """The best score of every row (time scale) of ``mode`` at the last step, (S,), whatever
        the scale band."""
        return self._row_score[self.mode_rows(mode)]

    def best_scale_index(self, mode: int) -> int:
        """Index in ``time_scales`` of the row of ``mode`` that scored best at the last step,
        whatever the scale band."""
        return int(self.mode_row_scores(mode).argmin())

    def best_log_scale(self, mode: int) -> float:
        """Natural log of the time scale at which ``mode`` fits best at the last step, between the
        grid's scales: the vertex of the parabola through the best row's score and its two
        neighbours' (in log scale), whatever the scale band; the grid scale itself at either end."""
        s = self.n_scales
        scores = self.mode_row_scores(mode)
        b = int(scores.argmin())
        if b == 0 or b == s - 1:
            return math.log(self.time_scales[b])
        x0, x1, x2 = (math.log(v) for v in self.time_scales[b - 1 : b + 2])
        y0, y1, y2 = (float(v) for v in scores[b - 1 : b + 2])
        a, c = x1 - x0, x1 - x2
        den = a * (y1 - y2) - c * (y1 - y0)
        if den == 0.0:  # flat: no side is better
            return x1
        return x1 - 0.5 * (a * a * (y1 - y2) - c * c * (y1 - y0)) / den

    # -----------------------------------------------------------------------------------------
    # State

    @property
    def steps(self) -> int:
        """Samples consumed since construction or the last reset()."""
        return self._count

    @property
    def ready(self) -> bool:
        """True once every row's window holds its n_r samples."""
        return self._count >= self.max_window

    def reset(self) -> None:
        """Forget all samples; the next step starts a fresh (incomplete) window."""
        self._ring[:] = 0.0
        self._count = 0

    def _weighted_values(self, sample: Sequence[float] | np.ndarray) -> tuple[float, float, float, float, float]:
        """The sample (4 angles, degrees) times sqrt(channel weight), as floats, and its squared
        norm; ValueError if it is not four finite numbers."""
        d0, d1, d2, d3 = sample_values(sample)
        dsq = d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3
        if not math.isfinite(dsq):  # also catches overflow of ||d||^2, i.e. |angle| > 1e154
            raise ValueError(f"sample has non-finite values: {[d0, d1, d2, d3]}")
        if self._weighted:
            s0, s1, s2, s3 = self._scale_values
            d0, d1, d2, d3 = d0 * s0, d1 * s1, d2 * s2, d3 * s3
            dsq = d0 * d0 + d1 * d1 + d2 * d2 + d3 * d3
        return d0, d1, d2, d3, dsq

    def _window_data(self) -> np.ndarray:
        """The buffered samples newest first: row t is d_{i-t}, (Wmax, 4) (weighted)."""
        w = self.max_window
        return self._ring[(self._count - 1 - np.arange(w)) % w]

    def window_sums(self) -> np.ndarray:
        """Per row, the sum of the samples in its current window, (R, 4) (channel-weighted)."""
        data = self._window_data()
        cum = np.concatenate([np.zeros((1, N_CHANNELS)), np.cumsum(data, axis=0)])
        return cum[np.minimum(self._count, self.windows)]

    def age_weighted_sums(self, rows: np.ndarray | None = None, lam: np.ndarray | None = None) -> np.ndarray:
        """Per row of ``rows`` (default: all), sum_t a_t d_{i-t} over its current window, (len(rows),
        4) (a_t = lam^t with the per-row ``lam`` (R,), default ``recency_half_life``'s; 1 without it)."""
        rows = self._rows if rows is None else rows
        lam = self._lam if lam is None else lam
        seen = np.arange(self.max_window)[None, :] < np.minimum(self._count, self.windows[rows])[:, None]
        age = np.where(seen, lam[rows][:, None] ** np.arange(self.max_window)[None, :], 0.0)  # (r, Wmax)
        return age @ self._window_data()

    def window_weight(self) -> np.ndarray:
        """Per row, the weight of its current window (R,): the number of samples in it, or with
        ``recency_half_life`` the sum of their age weights."""
        if self._count >= self.max_window:  # every window full
            return self._wsum
        seen = np.minimum(self._count, self.windows)
        if self.recency_half_life > 0:
            return (1.0 - self._lam ** seen) / (1.0 - self._lam)
        return seen.astype(np.float64)

    # -----------------------------------------------------------------------------------------
    # Read-out (numpy): shared by the naive matcher and the numpy incremental step

    def _scores(self, e: np.ndarray, sums: np.ndarray | None, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """score[r, j] of ``rows`` (default: all) from their running sums e (r, Nmax) and window
        sums (r, 4), age-weighted with recency weighting; see the module docstring."""
        score = e
        if self._offset:
            filled = self._count >= self.windows[rows]
            w = self._wsum[rows]
            per_shift = self.recency_half_life > 0  # mu_seg: the active weights' means
            if per_shift:
                x = sums[:, :, None] / w[:, None, None] - self._row_shift_means(rows)  # (r, 4, Nmax)
                w_ = w[:, None]
                tol, off = self._tau[0, :, None], self._tau[1, :, None]
            else:
                x = sums / w[:, None] - self._mu[self._slots.at(rows)]  # (r, 4)
                w_ = w
                tol, off = self._tau
            excess = np.maximum(np.abs(x - off) - tol, 0.0)
            penalty = w_ * (x * x - excess * excess).sum(axis=1)
            penalty = np.where(filled[:, None] if per_shift else filled, penalty, 0.0)
            score = e - (penalty if per_shift else penalty[:, None])
        if self.normalize:
            score = score / self.window_weight()[rows][:, None]
        return score

    def _result(self, score: np.ndarray) -> StepResult:
        cols = score.argmin(axis=1)
        best = score[self._rows, cols]
        self._row_score = best
        s = self.n_scales
        if s > 1:
            per_mode = best.reshape(s, self.n_modes)
            if not self._band.readable.all():
                per_mode = np.where(self._band.readable.reshape(s, self.n_modes), per_mode, np.inf)
            variant = per_mode.argmin(axis=0)
            rows = variant * self.n_modes + self._all
        else:
            variant, rows = None, self._all
        cols, sse = cols[rows], best[rows]
        lens = self.lengths[rows]
        phases = ((cols + 1) % lens) / lens
        b = int(sse.argmin())
        window = np.minimum(self._count, self.windows[rows])
        return StepResult(b, self.mode_names[b], float(phases[b]), sse, phases, self.ready, window, variant, cols)

    # -----------------------------------------------------------------------------------------
    # Naive recomputation (the specification; also used to resynchronise)

    def _window_sse(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Naive SSE of the current window against row shifts (rows[b], cols[b]), shape (B,)."""
        w = self.max_window
        t = np.arange(w)
        data = self._window_data()  # (Wmax, 4): d_{i-t}
        lens = self.lengths[rows][:, None]
        diff = data[None, :, :] - self._kernels[self._slots.at(rows)[:, None], :, (cols[:, None] - t[None, :]) % lens]
        sq = np.einsum("btc,btc->bt", diff, diff)
        sq[t[None, :] >= np.minimum(self._count, self.windows[rows][:, None])] = 0.0
        if self._decay:
            sq *= self._lam[rows][:, None] ** t[None, :]
        return sq.sum(axis=1)

    def full_sse(self) -> np.ndarray:
        """e[r, j] recomputed from the buffered samples (the naive sum), (R, Nmax); padding inf, and
        inf for rows not in the row tables."""
        rows, cols = np.nonzero(self._valid & (self._slots.slot >= 0)[:, None])
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

    def step(self, sample: Sequence[float] | np.ndarray) -> StepResult:  # pragma: no cover - abstract
        """Consume one sample (4 angles, degrees, CHANNELS order; four floats are the cheapest);
        return the estimate."""
        raise NotImplementedError
