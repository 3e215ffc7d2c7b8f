"""Parameters appended to a filter's state (the road frictions): bounds, freezing and a variance cap.

Shared by the double CKF (:mod:`canest.filters.dual`) and the joint CKF
(:mod:`canest.filters.joint`), which both estimate the last ``count`` entries of
the state as random-walk parameters:

* after each measurement update a parameter whose mean left ``bounds`` (the
  physical range, e.g. friction 0.1-1.3) is projected back as a truncated
  Gaussian: mean and variance become those of the normal truncated to the
  range (one-sided formulas with the scaled complementary error function,
  stable far outside the range), and its row and column of P are scaled by
  the ratio of the standard deviations (a congruence: P stays positive
  definite, correlations are kept). Only violated bounds are enforced:
  truncating every update a wide prior near a bound (0.9 +- 0.3 below 1.3)
  would walk the mean into the range's middle, 0.05 per update. Clipping the mean alone left a friction on its
  bound with the variance of a free estimate, flagged valid. ``pressed`` says
  which parameters the update pushed within one standard deviation of a bound
  (moved towards it and ended within it; the estimator clears their
  validity). A parameter held (frozen, or its rise refused) or moved away from
  the bound is not pressed: near ice a low friction's own uncertainty
  (0.3 +- 0.2 above the bound 0.1) is not the data pushing it;
* parameters in ``frozen`` (set by the estimator: not observable this tick)
  get a zero gain, so they keep their value; so do those outside
  ``may_rise`` (set by the estimator where the data can only bound a
  parameter from below: :mod:`canest.estimation.two_track`) whose update
  would raise them. The Joseph update keeps the covariance honest for any
  gain: a refused update leaves the parameter's variance as it was.
  Clipping the mean of such an update instead kept the variance the refused
  evidence had shrunk, and ratcheted the mean down (noise lowering it was
  kept, noise raising it clipped): on the honesty grid's DLC on friction 0.85
  the joint filter's frictions fell from 0.90 to 0.66 in 0.3 s while their
  std fell from 0.30 to 0.13, flagged valid 0.2-0.3 below the truth;
* a parameter's variance grows with its random walk but never beyond its
  initial value, the widest a prior on the road can be: each time update
  rescales the row and column of a parameter above it (a congruence
  ``D P D`` with positive diagonal ``D``, which keeps P positive definite).
"""
from __future__ import annotations

import numpy as np

from canest.filters.special import erfcx

SQRT_2_OVER_PI = np.sqrt(2.0 / np.pi)


class ParameterBlock:
    def __init__(self, size: int, P0: np.ndarray, count: int, bounds=(-np.inf, np.inf)):
        if not 0 < count < size:
            raise ValueError(f"parameters must be between 1 and {size - 1} (the state has {size} entries), got {count}")
        self.index = slice(size - count, size)
        self.bounds = tuple(float(b) for b in bounds)
        self.variance_cap = np.diag(P0)[self.index].copy()
        self.frozen = np.zeros(count, dtype=bool)
        self.may_rise = np.ones(count, dtype=bool)
        self.pressed = np.zeros(count, dtype=bool)

    def project(self, values: np.ndarray, P: np.ndarray, prior: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(values, P) with each parameter truncated to ``bounds``; ``prior``: the values before the update.

        ``P``'s last entries are the parameters (the joint covariance, or the parameters' own)."""
        count = self.frozen.size
        std = np.sqrt(np.maximum(np.diag(P)[-count:], 1e-300))
        low, high = self.bounds
        self.pressed = ((values < low + std) & (values < prior)) | ((values > high - std) & (values > prior))
        mean, new_std = values.astype(float), std
        below, above = mean < low, mean > high
        mean[below], new_std[below] = truncated(mean[below], std[below], low, 1.0)
        mean[above], new_std[above] = truncated(mean[above], std[above], high, -1.0)
        scale = np.ones(P.shape[0])
        scale[-count:] = new_std / std
        return mean, P * np.outer(scale, scale)

    def gain_mask(self, step: np.ndarray) -> np.ndarray:
        """Which entries of a state (parameters last) may take their ``step`` (the unconstrained ``K y``): all but
        the frozen parameters and those the step would raise beyond ``may_rise``."""
        mask = np.ones(step.size, dtype=bool)
        rising = step[step.size - self.frozen.size:] > 0.0
        mask[step.size - self.frozen.size:] = ~self.frozen & (self.may_rise | ~rising)
        return mask

    def cap_variance(self, P: np.ndarray) -> np.ndarray:
        """P (whose last entries are the parameters) with each parameter's variance at most its cap."""
        ratio = self.variance_cap / np.maximum(np.diag(P)[-self.frozen.size:], 1e-300)
        scale = np.ones(P.shape[0])
        scale[-self.frozen.size:] = np.sqrt(np.minimum(1.0, ratio))
        return P * np.outer(scale, scale)


def truncated(mean: np.ndarray, std: np.ndarray, bound: float, side: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std of N(mean, std^2) truncated to ``x >= bound`` (side 1) or ``x <= bound`` (side -1).

    With ``a = side (bound - mean) / std`` and the inverse Mills ratio
    ``l = phi(a) / (1 - Phi(a)) = sqrt(2/pi) / erfcx(a / sqrt(2))``:
    mean ``+ side std l``, variance ``std^2 (1 + a l - l^2)``.
    """
    if not np.isfinite(bound):
        return mean, std
    a = side * (bound - mean) / std
    ratio = SQRT_2_OVER_PI / erfcx(a / np.sqrt(2.0))
    variance_factor = np.maximum(1.0 + a * ratio - ratio**2, 1e-12)
    return mean + side * std * ratio, std * np.sqrt(variance_factor)
