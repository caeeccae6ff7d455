"""A sliding window's running sums: what the integrity monitor's long-window tests average over."""

from collections import deque

import numpy as np

__all__ = ["WindowSum"]


class WindowSum:
    """Per entry, the sum and the count of the seen values of the last ``length`` rows (added and dropped as
    rows come and go, not summed again).

    Parameters
    ----------
    length : int
        Rows kept (at least 1).

    Attributes
    ----------
    sum : ndarray, shape (C,) or None
        The seen values' sums (None before the first row or after :meth:`clear`).
    n : ndarray of int, shape (C,) or None
        How many rows saw each entry.
    """

    def __init__(self, length: int):
        self.length = max(1, int(length))
        self._rows: deque = deque()
        self.sum = None
        self.n = None

    def __len__(self) -> int:
        return len(self._rows)

    def clear(self) -> None:
        """Forget every row."""
        self._rows.clear()
        self.sum = None
        self.n = None

    def add(self, values, seen) -> None:
        """Append one row: ``values`` (C,) where ``seen`` (C,) bool, else ignored. A row of another size than the
        window's starts the window again."""
        seen = np.asarray(seen, dtype=bool).reshape(-1)
        v = np.where(seen, np.asarray(values, dtype=np.float64).reshape(-1), 0.0)
        if self.sum is None or self.sum.size != v.size:
            self.clear()
            self.sum, self.n = np.zeros(v.size), np.zeros(v.size, dtype=np.int64)
        self._rows.append((v, seen))
        self.sum += v
        self.n += seen
        if len(self._rows) > self.length:
            v0, k0 = self._rows.popleft()
            self.sum -= v0
            self.n -= k0
