"""Per-shift age-weighted kernel means (the offset penalty with recency weighting): the mean of
the kernel part the window is compared with at each shift, kept for every SHIFT_BLOCK-th shift and
derived for the others."""

from __future__ import annotations

import numpy as np

from .channels import N_CHANNELS

SHIFT_BLOCK = 16
"""Shifts per block of the per-shift kernel means: each block's first mean is kept, the others follow
from it (``expand_shift_means``); the compiled read-out bounds the penalty per block."""


def expand_shift_means(anchors: np.ndarray, k: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """The per-shift age-weighted kernel means (g, 4, n) from their values at every SHIFT_BLOCK-th
    shift ``anchors`` (g, 4, B), the kernels ``k`` (g, 4, n) and the rows' age weight factors
    ``lam`` (g,): within a block m_j = lam m_{j-1} + (1 - lam) k_j (the window slides by one
    sample), in the float operations ``compiled._argmin_per_shift`` does them in."""
    g, _, n = k.shape
    b = anchors.shape[2]
    kb = np.zeros((g, N_CHANNELS, b * SHIFT_BLOCK))
    kb[:, :, :n] = k
    kb = kb.reshape(g, N_CHANNELS, b, SHIFT_BLOCK)
    out = np.empty_like(kb)
    a = np.asarray(lam, dtype=np.float64).reshape(-1, 1, 1)
    c = 1.0 - a
    m = np.array(anchors[:, :, :b], dtype=np.float64)
    out[..., 0] = m
    for q in range(1, SHIFT_BLOCK):
        m = a * m + c * kb[..., q]
        out[..., q] = m
    return out.reshape(g, N_CHANNELS, b * SHIFT_BLOCK)[:, :, :n]


def weighted_shift_means(k: np.ndarray, w: int, lam: float, wsum: float) -> np.ndarray:
    """Per column j of kernels ``k`` (g, 4, n), sum_{t<w} lam^t k_{(j-t) mod n} / wsum, (g, 4, n):
    by FFT at every SHIFT_BLOCK-th shift, the others by ``expand_shift_means`` (lam 1: by prefix
    sums)."""
    n = k.shape[2]
    if lam == 1.0:  # mean of k over columns j-w+1 .. j (circular), exactly
        c = np.cumsum(np.concatenate([k, k], axis=2), axis=2)
        j = np.arange(n) + n
        return (c[:, :, j] - c[:, :, j - w]) / w
    weights = np.zeros(n)
    weights[:w] = lam ** np.arange(w)
    conv = np.fft.irfft(np.fft.rfft(k, n=n) * np.fft.rfft(weights), n=n)  # sum_t w_t k_{j-t}
    anchors = (conv / wsum)[:, :, ::SHIFT_BLOCK]
    return expand_shift_means(anchors, k, np.full(k.shape[0], lam))
