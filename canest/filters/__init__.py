"""Filters, chosen by name in the config (``estimator.filter``), and the factory that builds them.

Each filter class takes ``(x0, P0, factorization=..., **options)`` and offers
``predict(transition, u, dt, Q)`` and ``update(z, measurement, u, R)`` with the
models of :mod:`canest.filters.base`. Adding a filter is adding a class and
one line here.

A filter declares what it ``needs`` of a model; :func:`offered_by` says what a
model offers (class attributes, no vehicle knowledge here), :func:`fits`
matches the two, and :func:`make_filter` passes a filter what the model tells
it (the parameter count and bounds, the index of an input parameter).
"""
import inspect

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


def offered_by(model) -> frozenset:
    """What a model (class or instance) offers the filters.

    ``jacobian`` always: the model's own, or central differences of its
    vectorized functions. ``input_parameter``: a scalar parameter in ``u`` at
    ``model.input_parameter`` with ``measure_parameter_jacobian``.
    ``state_parameters``: the last ``model.parameters`` states are parameters
    within ``model.parameter_bounds``. ``sensor_sets``: ``model.sensor_sets``
    names the sensor of each measurement channel.
    """
    offered = {"jacobian"}
    if getattr(model, "input_parameter", None) is not None:
        offered.add("input_parameter")
    if getattr(model, "parameters", 0):
        offered.add("state_parameters")
    if getattr(model, "sensor_sets", None):
        offered.add("sensor_sets")
    return frozenset(offered)


def fits(name: str, model) -> bool:
    """The filter runs on the model: it gets all it needs, and parameter states only go to a filter that bounds them."""
    needs = FILTERS[name].needs
    offered = offered_by(model)
    return needs <= offered and ("state_parameters" in needs) == ("state_parameters" in offered)


def model_options(name: str, model) -> dict:
    """The constructor options the model gives the filter ``name``."""
    needs = FILTERS[name].needs
    options = {}
    if "state_parameters" in needs:
        options.update(parameters=model.parameters, parameter_bounds=model.parameter_bounds)
    if "input_parameter" in needs:
        options["parameter_index"] = model.input_parameter
    return options


def make_filter(name: str, x0, P0, model, factorization=None, options=None):
    """The filter ``name`` for ``model``; ``factorization`` only when given (else the filter's own default)."""
    kwargs = {**model_options(name, model), **(options or {})}
    if factorization is not None:
        kwargs["factorization"] = factorization
    return FILTERS[name](x0, P0, **kwargs)


def factorization_of(name: str, configured=None):
    """The factorization the filter ``name`` runs with: ``configured``, else the filter's own default; None for a
    filter that takes no square root (the EKFs)."""
    cls = FILTERS[name]
    if not cls.factorizes:
        return None
    return configured or inspect.signature(cls).parameters["factorization"].default


__all__ = ["FILTERS", "FACTORIZATIONS", "Measurement", "Transition", "factorization_of", "fits", "make_filter",
           "model_options", "offered_by"]
