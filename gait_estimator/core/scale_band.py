"""Which rows (mode x time scale) the matcher reads out: the scale band, and the modes searched at
every scale while the band is narrow (``ScaleBand``; rows scale-major, row s * M + m)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

SEARCH_EVERY = 16
"""Steps between two choices of the modes read at every time scale."""
SEARCH_MARGIN = 0.1
"""Relative score by which a mode must fit better than a searched one to take its place."""


class ScaleBand:
    """The time scales every mode is read at (``allowed``), the ``search`` modes that fit best read
    at every scale besides (``searched``), and the rows that makes (``readable``, ``rows``)."""

    def __init__(self, n_modes: int, n_scales: int) -> None:
        self.n_modes, self.n_scales = n_modes, n_scales
        self.allowed = np.ones(n_scales, dtype=np.bool_)
        self.search = 0
        self.searched = np.zeros(n_modes, dtype=np.bool_)
        self._inside = np.zeros(0, dtype=np.int64)  # the searched modes' indices, and the others'
        self._outside = np.arange(n_modes)
        self.readable = np.ones(n_modes * n_scales, dtype=np.bool_)  # per row; updated in place
        self.rows = np.arange(n_modes * n_scales)

    def set(self, allowed: Sequence[bool] | np.ndarray | None, search: int, row_score: np.ndarray) -> None:
        """Read every mode at the scales flagged in ``allowed`` (S,) (None = all), and the
        ``search`` modes that fit best (by ``row_score``, (R,), the last step's) at every scale."""
        a = np.ones(self.n_scales, dtype=np.bool_) if allowed is None else np.asarray(allowed, dtype=np.bool_).reshape(-1)
        if a.size != self.n_scales or not a.any():
            raise ValueError(f"scale band needs {self.n_scales} flags, at least one true, got {a.tolist()}")
        if search < 0:
            raise ValueError(f"search must be >= 0 modes, got {search}")
        self.allowed[:] = a
        self.search = 0 if a.all() else min(int(search), self.n_modes)
        self._set_searched(np.zeros(self.n_modes, dtype=np.bool_))
        if self.search:
            self.choose(np.where(self.readable, row_score, np.inf).reshape(self.n_scales, self.n_modes).min(axis=0))
        self._update_rows()

    def after_step(self, steps: int, score: np.ndarray) -> bool:
        """Every SEARCH_EVERY ``steps``, choose the searched modes again from the step's per-mode
        ``score`` (M,); True if the rows changed."""
        if self.search and steps % SEARCH_EVERY == 0 and self.choose(score):
            self._update_rows()
            return True
        return False

    def choose(self, score: np.ndarray) -> bool:
        """Choose the searched modes from the last step's per-mode scores (each mode's best over
        the rows it is read at): the best ones, a mode replacing a searched one only if it fits
        better by SEARCH_MARGIN (near ties do not swap rows in and out); True if they changed."""
        if self._inside.size == self.search:  # full: the loop below would stop at the best other mode
            if self._outside.size == 0:
                return False
            others = score[self._outside]  # a short list is cheaper in Python floats (cold numpy calls cost)
            best_other = min(others.tolist()) if others.size <= 64 else float(np.minimum.reduce(others))
            if not best_other < (1.0 - SEARCH_MARGIN) * max(score[self._inside].tolist()):
                return False
        chosen = self.searched.copy()
        for m in np.argsort(score, kind="stable"):  # ends at the first mode that does not enter
            if chosen[m]:
                continue
            if chosen.sum() < self.search:
                chosen[m] = True
                continue
            worst = int(np.flatnonzero(chosen)[score[chosen].argmax()])
            if not score[m] < (1.0 - SEARCH_MARGIN) * score[worst]:
                break
            chosen[worst], chosen[m] = False, True
        changed = bool(np.any(chosen != self.searched))
        self._set_searched(chosen)
        return changed

    def _set_searched(self, chosen: np.ndarray) -> None:
        self.searched[:] = chosen
        self._inside, self._outside = np.flatnonzero(chosen), np.flatnonzero(~chosen)

    def _update_rows(self) -> None:
        self.readable[:] = (self.allowed[:, None] | self.searched[None, :]).ravel()
        self.rows = np.flatnonzero(self.readable)
