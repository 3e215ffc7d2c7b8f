"""The ``estimator`` section: filter and model (a pair the model catalog accepts), noise, options; the inputs they need."""
from __future__ import annotations

import dataclasses
import inspect
import math
from pathlib import Path

import numpy as np

from canest import limits
from canest.estimation import catalog
from canest.filters import FACTORIZATIONS, FILTERS, make_filter, model_options
from canest.settings import EstimatorConfig
from canest.yamldoc import Document, suggestion

VX_NOISE_SPLIT = ("vx_from_ax", "vx_from_wheel_states")  # vx noises told apart from vx's: a config's vx alone sets them
NOISE_KEYS = {name: tuple(getattr(EstimatorConfig(), name)) for name in ("process_noise", "measurement_noise", "initial_std")}


def read_estimator(doc: Document) -> EstimatorConfig:
    key_path = ("estimator",)
    section = doc.section(key_path, required=False)
    defaults = EstimatorConfig()
    doc.reject_unknown(key_path, section, [f.name for f in dataclasses.fields(EstimatorConfig)])
    values = {name: doc.number(key_path, section, name, allowed, getattr(defaults, name))
              for name, allowed in limits.ESTIMATOR.items()}
    for name, keys in NOISE_KEYS.items():
        given = doc.section(key_path + (name,), required=False)
        doc.reject_unknown(key_path + (name,), given, keys)
        values[name] = {**getattr(defaults, name), **{k: doc.number(key_path + (name,), given, k, limits.NOISE)
                                                       for k in given}}
        if name == "process_noise" and "vx" in given:
            # a vx noise written before vx_from_ax and vx_from_wheel_states existed is meant for every model: it
            # keeps that meaning where they are not given
            values[name].update({key: values[name]["vx"] for key in VX_NOISE_SPLIT if key not in given})
    compensation = _flag(doc, section, "latency_compensation", defaults.latency_compensation)
    online_calibration = _flag(doc, section, "online_calibration", defaults.online_calibration)
    state_file = _state_file(doc, section)

    name = doc.text(key_path, section, "filter", defaults.filter)
    if name not in FILTERS:
        raise doc.error(key_path + ("filter",), f"unknown filter '{name}'; {suggestion(name, FILTERS)}")
    model = doc.text(key_path, section, "model", catalog.model_for(name))
    if model not in catalog.CATALOG:
        raise doc.error(key_path + ("model",), f"unknown model '{model}'; {suggestion(model, catalog.CATALOG)}")
    if "filter" not in section and "model" in section:
        name = catalog.CATALOG[model].default_filter
    problem = catalog.misfit(name, model)
    if problem:
        raise doc.error(key_path + ("model",), problem)
    if compensation and not hasattr(catalog.CATALOG[model].model, "derivatives"):
        raise doc.error(key_path + ("latency_compensation",), f"model '{model}' has no derivatives to back-date by")
    factorization = doc.text(key_path, section, "factorization", defaults.factorization)
    if factorization is not None and factorization not in FACTORIZATIONS:
        raise doc.error(key_path + ("factorization",), f"must be one of {', '.join(FACTORIZATIONS)}")
    options = doc.section(key_path + ("filter_options",), required=False)
    for key, value in options.items():
        if isinstance(value, float) and not math.isfinite(value):
            raise doc.error(key_path + ("filter_options", key), f"must be a finite number, got {value}")
    config = EstimatorConfig(filter=name, model=model, factorization=factorization, filter_options=options,
                             latency_compensation=compensation, online_calibration=online_calibration,
                             state_file=state_file, **values)
    _check_filter_options(doc, config)
    return config


def _flag(doc: Document, section: dict, key: str, default: bool) -> bool:
    value = section.get(key, default)
    if not isinstance(value, bool):
        raise doc.error(("estimator", key), f"must be true or false, got {value!r}")
    return value


def _state_file(doc: Document, section: dict) -> str | None:
    """``estimator.state_file``: the online calibration's state, relative to the config's directory; not a directory."""
    given = doc.text(("estimator",), section, "state_file")
    if given is None:
        return None
    if not given.strip():
        raise doc.error(("estimator", "state_file"), "must name a file, got an empty text")
    path = Path(doc.path).parent / Path(given).expanduser()
    if path.is_dir():
        raise doc.error(("estimator", "state_file"), f"{path} is a directory; name a file in it, e.g. "
                                                     f"{path / 'calibration.json'}")
    return str(path)


def _check_filter_options(doc: Document, est: EstimatorConfig) -> None:
    """Each option one the filter takes (not one the catalog or ``factorization`` sets), a positive number where the
    filter's default is one (every such option is a width, a window, a floor or a rate); then the filter built once
    on a dummy state of the model's size, so a wrong option fails at load time, naming the key."""
    model = catalog.CATALOG[est.model].model
    parameters = inspect.signature(FILTERS[est.filter]).parameters
    set_elsewhere = {"x0", "P0", "factorization", *model_options(est.filter, model)}
    options = [name for name in parameters if name not in set_elsewhere]
    for key, value in est.filter_options.items():
        where = ("estimator", "filter_options", key)
        if key not in options:
            raise doc.error(where, f"{est.filter} has no option '{key}'; " + (
                suggestion(key, options, "its options") if options else "it takes none"))
        default = parameters[key].default
        if _positive_number(default) and not _positive_number(value):
            raise doc.error(where, f"must be a number above 0 (default {default:g}), got {value!r}")
    n = len(model.state_names)
    try:
        make_filter(est.filter, np.zeros(n), np.eye(n), model, est.factorization, est.filter_options)
    except (TypeError, ValueError, ArithmeticError) as exc:
        raise doc.error(("estimator", "filter_options"), f"{est.filter}: {exc}") from None


def _positive_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0


def check_model_inputs(doc: Document, est: EstimatorConfig, specs: dict) -> None:
    """Every input the model needs, and those the filter adds (the DICI-GFCKF's second IMU); an input the estimator
    derives from mapped ones (ax from the wheel speeds) need not be mapped."""
    entry = catalog.CATALOG[est.model]
    for reason, needed in (("the estimator", catalog.BASE_INPUTS),
                           (f"model '{est.model}'", entry.required_inputs),
                           (f"filter '{est.filter}'", entry.inputs_for(est.filter))):
        missing = catalog.unmet(needed, specs)
        if missing:
            raise doc.error(("input", "signals"), f"{reason} needs {', '.join(missing)}")
