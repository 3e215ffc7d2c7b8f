"""Parameters appended to a filter's state (the road frictions): bounds, freezing and a variance cap.

Shared by the double CKF (:mod:`canest.filters.dual`) and the joint CKF
(:mod:`canest.filters.joint`), which both estimate the last ``count`` entries of
the state as random-walk parameters:

* after each measurement update the parameters are clipped to ``bounds``
  (the projection of the mean onto the physical range, e.g. friction 0.1-1.3)
  and to ``ceiling``, a per-update upper limit the estimator may set (where
  the data can only bound a parameter from below: :mod:`canest.estimation.bindings`);
* parameters in ``frozen`` (set by the estimator: not observable this tick)
  get a zero gain, so they keep their value; the Joseph update keeps the
  covariance honest for any gain;
* a parameter's variance grows with its random walk but never beyond its
  initial value, the widest a prior on the road can be: each time update
  rescales the row and column of a parameter above it (a congruence
  ``D P D`` with positive diagonal ``D``, which keeps P positive definite).
"""
from __future__ import annotations

import numpy as np


class ParameterBlock:
    def __init__(self, size: int, P0: np.ndarray, count: int, bounds=(-np.inf, np.inf)):
        if not 0 < count < size:
            raise ValueError(f"parameters must be between 1 and {size - 1} (the state has {size} entries), got {count}")
        self.index = slice(size - count, size)
        self.bounds = tuple(float(b) for b in bounds)
        self.variance_cap = np.diag(P0)[self.index].copy()
        self.frozen = np.zeros(count, dtype=bool)
        self.ceiling = np.full(count, np.inf)

    def clip(self, values: np.ndarray) -> np.ndarray:
        low, high = self.bounds
        return np.clip(values, low, np.maximum(np.minimum(self.ceiling, high), low))

    def gain_mask(self, size: int) -> np.ndarray:
        """Which of ``size`` trailing-aligned state entries may move: all but the frozen parameters."""
        mask = np.ones(size, dtype=bool)
        mask[size - self.frozen.size:] = ~self.frozen
        return mask

    def cap_variance(self, P: np.ndarray) -> np.ndarray:
        """P (whose last entries are the parameters) with each parameter's variance at most its cap."""
        ratio = self.variance_cap / np.maximum(np.diag(P)[-self.frozen.size:], 1e-300)
        scale = np.ones(P.shape[0])
        scale[-self.frozen.size:] = np.sqrt(np.minimum(1.0, ratio))
        return P * np.outer(scale, scale)
