"""Filters, chosen by name in the config (``estimator.filter``).

Each filter class takes ``(x0, P0, factorization=..., **options)`` and offers
``predict(transition, u, dt, Q)`` and ``update(z, measurement, u, R)`` with the
models of :mod:`canest.filters.base`. Adding a filter is adding a class and
one line here.
"""
from canest.filters.adaptive import AdaptiveSvdFifthDegreeCKF, LimitedMemoryRandomWeightedEKF
from canest.filters.base import Measurement, Transition
from canest.filters.dici import DICIGeneralizedFifthDegreeCKF
from canest.filters.dual import DoubleCubatureKalmanFilter
from canest.filters.ekf import DualExtendedKalmanFilter, ExtendedKalmanFilter
from canest.filters.joint import JointCubatureKalmanFilter
from canest.filters.robust import MaximumCorrentropySCKF
from canest.filters.sigma import (
    FACTORIZATIONS,
    CubatureKalmanFilter,
    FifthDegreeCubatureKalmanFilter,
    GeneralizedFifthDegreeCKF,
    UnscentedKalmanFilter,
)
from canest.filters.sqrt import SquareRootCubatureKalmanFilter

FILTERS = {cls.name: cls for cls in (
    ExtendedKalmanFilter,
    DualExtendedKalmanFilter,
    LimitedMemoryRandomWeightedEKF,
    UnscentedKalmanFilter,
    CubatureKalmanFilter,
    SquareRootCubatureKalmanFilter,
    MaximumCorrentropySCKF,
    FifthDegreeCubatureKalmanFilter,
    AdaptiveSvdFifthDegreeCKF,
    GeneralizedFifthDegreeCKF,
    DICIGeneralizedFifthDegreeCKF,
    DoubleCubatureKalmanFilter,
    JointCubatureKalmanFilter,
)}

__all__ = ["FILTERS", "FACTORIZATIONS", "Measurement", "Transition"]
