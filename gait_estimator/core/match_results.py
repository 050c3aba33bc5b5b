"""What the matchers return: one step's estimate (``StepResult``), a run of steps in bulk
(``StepBlock``) and a whole sequence (``MatchTrace``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class StepResult:
    """The estimate after one sample.

    Attributes:
        mode_index: Index of the best mode in the library.
        mode: Name of the best mode.
        phase: Gait phase of the best mode, [0, 1), 0 = right heel strike.
        sse: Per-mode match error (the score of the mode's best row and shift), shape (M,): SSE
            in deg^2 (the paper), or deg^2 per window sample with ``normalize``; channel-weighted.
        phases: Per-mode phase at that mode's best shift, shape (M,).
        ready: True once the window of every row is full.
        window: Samples in each mode's comparison window so far (of its best row), shape (M,).
        variant: Per mode, index of the best time scale in ``matcher.time_scales``, shape (M,);
            None when the matcher has only one scale.
        column: Per mode, the best kernel column j* of that row, shape (M,); None if not kept.
    """

    mode_index: int
    mode: str
    phase: float
    sse: np.ndarray
    phases: np.ndarray
    ready: bool
    window: np.ndarray
    variant: np.ndarray | None = None
    column: np.ndarray | None = None


@dataclass(frozen=True)
class MatchTrace:
    """Step results for a whole sequence of samples (T steps, M modes)."""

    mode_names: list[str]
    mode_index: np.ndarray  # (T,) int64
    phase: np.ndarray  # (T,) float64
    sse: np.ndarray  # (T, M) float64, deg^2 (per window sample with normalize)
    phases: np.ndarray  # (T, M) float64
    ready: np.ndarray  # (T,) bool

    @property
    def modes(self) -> list[str]:
        return [self.mode_names[i] for i in self.mode_index]



@dataclass(frozen=True)
class StepBlock:
    """The results of a run of matcher steps in bulk (``IncrementalMatcher.run_steps``; G steps,
    M modes): what ``StepResult`` holds per step, with the column of one mode only."""

    mode_names: list[str]
    n_scales: int
    sse: np.ndarray  # (G, M) every mode's score
    phases: np.ndarray  # (G, M) every mode's phase
    variant: np.ndarray  # (G, M) int64: every mode's best time scale (index)
    window: np.ndarray  # (G, M) int64: every mode's window's samples so far
    best: np.ndarray  # (G,) int64: the best mode
    column: np.ndarray  # (G,) int64: the reported mode's best kernel column (``run_steps``; default the best mode)
    ready: np.ndarray  # (G,) bool

    @classmethod
    def empty(cls, mode_names: Sequence[str], n_scales: int, steps: int) -> StepBlock:
        """Room for ``steps`` steps."""
        m = len(mode_names)
        variant, window = np.empty((2, steps, m), dtype=np.int64)
        return cls(list(mode_names), n_scales, np.empty((steps, m)), np.empty((steps, m)), variant, window,
                   np.empty(steps, dtype=np.int64), np.empty(steps, dtype=np.int64), np.empty(steps, dtype=bool))

    def rows(self, start: int, stop: int) -> StepBlock:
        """Steps ``start`` .. ``stop`` - 1 (views)."""
        s = slice(start, stop)
        return replace(self, sse=self.sse[s], phases=self.phases[s], variant=self.variant[s], window=self.window[s],
                       best=self.best[s], column=self.column[s], ready=self.ready[s])

    def result(self, g: int, reported: int | None = None) -> StepResult:
        """Step ``g`` as a ``StepResult``, ``column`` that of the ``reported`` mode (default the best;
        the other modes' column is 0)."""
        b = int(self.best[g])
        column = np.zeros(len(self.mode_names), dtype=np.int64)
        column[b if reported is None else reported] = self.column[g]
        return StepResult(b, self.mode_names[b], float(self.phases[g, b]), self.sse[g], self.phases[g],
                          bool(self.ready[g]), self.window[g], self.variant[g] if self.n_scales > 1 else None, column)
