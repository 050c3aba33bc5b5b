"""Which slot of a matcher's row tables holds which row (mode x time scale).

The row tables (kernels, per-shift means, running sums) have one slot per row unless the compiled
step keeps only the rows in use: the scale band's, and a few more read now and then.
"""

from __future__ import annotations

import numpy as np


class RowSlots:
    """The map row -> slot (``slot``, -1: none) and slot -> row (``owner``, -1: free); slot r
    holds row r until the tables are first repacked (``identity``)."""

    def __init__(self, n_rows: int) -> None:
        self.slot = np.arange(n_rows)
        self.owner = np.arange(n_rows)
        self.identity = True

    def at(self, rows: np.ndarray | slice) -> np.ndarray | slice:
        """The slots of ``rows`` (which have one)."""
        return rows if self.identity else self.slot[rows]

    def held(self) -> np.ndarray:
        """The rows that have a slot, in slot order."""
        return self.owner[self.owner >= 0]

    def spare(self, pinned: np.ndarray, fresh: np.ndarray, wanted: int) -> np.ndarray | None:
        """``wanted`` slots to give to rows without one: free ones and those whose row is not
        ``pinned`` ((R,) bool), the rows not ``fresh`` ((R,) bool: state exact at this step)
        first; None if there are not that many."""
        row = np.maximum(self.owner, 0)
        used = self.owner >= 0
        keep = used & pinned[row]
        late = used & ~keep & fresh[row]
        order = np.concatenate([np.flatnonzero(~keep & ~late), np.flatnonzero(late)])
        return order[:wanted] if order.size >= wanted else None

    def assign(self, rows: np.ndarray, slots: np.ndarray) -> None:
        """Give ``slots`` to ``rows``; their former rows lose them."""
        gone = self.owner[slots]
        self.slot[gone[gone >= 0]] = -1
        self.owner[slots] = rows
        self.slot[rows] = slots

    def repack(self, keep: np.ndarray, slots: int) -> None:
        """After the tables were rebuilt with ``slots`` slots holding the rows ``keep`` in the
        first ones: every other row has none."""
        self.slot[:] = -1
        self.slot[keep] = np.arange(keep.size)
        self.owner = np.full(slots, -1)
        self.owner[: keep.size] = keep
        self.identity = False
