"""``dici-gfckf``: local generalized fifth-degree CKFs fused twice by inverse covariance intersection.

DICI-GFCKF paper, section IV-B. Local filter j has its own covariance, process
noise and sensor set (eq 45: the second local filter starts with ten times the
first's covariance and runs with ten times its process noise; each uses its own
IMU with that IMU's measurement noise). Per step:

1. time update of every local filter (eqs 28-31), the points of all of them
   through one call of the model's transition;
2. ICI primary fusion of the local predictions (eqs 32-34) -> ``x-, P-``;
3. measurement update of every local filter with its own measurements, from
   cubature points of the fused prediction (eqs 35-41);
4. ICI secondary fusion of the local posteriors (eqs 42-44) -> ``x, P``.

The local filters keep their own posteriors for the next time update.

Corrections to the printed algorithm, each checked in tests/test_dici_dual.py:
eq 35 spreads the points with ``P^ICI`` where its square root is meant (as in
eq 28); eq 41 subtracts the gain term from the local prediction ``P_j,k+1/k``
while eq 40 and the cross-covariance of eq 38 start from the fused prediction;
here both use the fused prediction, which makes step 3 an exact Kalman update
of it (for a linear system the local posterior equals the Kalman filter's).
With ``fusion: ci`` covariance intersection (eqs 15-16) replaces ICI for
comparison. Positive definiteness: the locals' Joseph updates and the fused
covariance (positive definite for every weight, :mod:`canest.filters.fusion`).
"""
from __future__ import annotations

import numpy as np

from canest.filters.base import GaussianFilter, Measurement, Transition
from canest.filters.fusion import METHODS, fuse
from canest.filters.sigma import GeneralizedFifthDegreeCKF, predict_together

PAPER_SCALES = (1.0, 10.0)  # eq 45: local filter 2 has ten times the covariance and process noise of filter 1


class DICIGeneralizedFifthDegreeCKF(GaussianFilter):
    name = "dici-gfckf"
    needs = frozenset({"sensor_sets"})

    def __init__(self, x0, P0, factorization: str = "cholesky", process_scale=PAPER_SCALES,
                 initial_scale=PAPER_SCALES, fusion: str = "ici"):
        if fusion not in METHODS:
            raise ValueError(f"fusion must be one of {METHODS}, got {fusion!r}")
        if len(process_scale) != len(initial_scale) or len(process_scale) < 2:
            raise ValueError("process_scale and initial_scale need one entry per local filter (at least two)")
        super().__init__(x0, P0)
        self.fusion = fusion
        self.process_scale = tuple(float(s) for s in process_scale)
        self.locals = [GeneralizedFifthDegreeCKF(x0, np.asarray(P0) * s, factorization) for s in initial_scale]
        self.weights = None
        self._fuse()

    @property
    def sensor_sets(self) -> int:
        """How many local filters, hence sensor sets, this filter fuses."""
        return len(self.locals)

    def _fuse(self) -> None:
        fused = fuse(self.fusion, [f.x for f in self.locals], [f.P for f in self.locals])
        self.x, self.P, self.weights = fused.x, fused.P, fused.weights
        self.repairs = sum(f.repairs for f in self.locals)

    def predict(self, transition: Transition, u, dt: float, Q: np.ndarray) -> None:
        """Steps 1-2: local time updates, all local filters' cubature points through one call of the transition
        (:func:`canest.filters.sigma.predict_together`), then the primary fusion."""
        predict_together(self.locals, transition, u, dt, [Q * scale for scale in self.process_scale])
        self._fuse()

    def update(self, z, measurement: Measurement, u, R) -> None:
        """The same measurements for every local filter."""
        self.update_sets([(z, measurement, R)] * len(self.locals), u)

    def update_sets(self, sets: list, u) -> None:
        """Steps 3-4. ``sets[j]`` is ``(z, measurement, R)`` of local filter j, or None if it has nothing fresh."""
        nis = []
        for local, given in zip(self.locals, sets):
            local.x, local.P = self.x.copy(), self.P.copy()
            if given is not None:
                z, measurement, R = given
                local.update(z, measurement, u, R)
                nis.append(local.nis)
        if nis:
            first = next(local for local, given in zip(self.locals, sets) if given is not None)
            self.y, self.S, self.K = first.y, first.S, first.K
            self.nis = float(np.mean(nis))
        self._fuse()
