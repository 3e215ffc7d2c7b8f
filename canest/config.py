"""YAML configuration -> typed, validated dataclasses.

Every error is a :class:`ConfigError` whose text names the file, the line and
the key (``configs/ev.yaml:42: input.signals.ax.signal: ...``) so a user can
fix it without reading code. Paths inside a config are relative to the config.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from canest import signals as sig
from canest.codec.dbc import load_database
from canest.errors import ConfigError
from canest.estimation import catalog
from canest.filters import FACTORIZATIONS, FILTERS, make_filter
from canest.params import TireModelParams, VehicleParams
from canest.settings import BusConfig, Config, EstimatorConfig, MessageChecks, SignalSpec
from canest.yamldoc import Document

BUILTIN_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_CONFIG = BUILTIN_DIR / "dici_ev.yaml"
__all__ = ["BUILTIN_DIR", "DEFAULT_CONFIG", "ConfigError", "load_config"]


VEHICLE_FIELDS = [f.name for f in dataclasses.fields(VehicleParams) if f.name not in ("name", "tire")]
TIRE_FIELDS = [f.name for f in dataclasses.fields(TireModelParams)]
ESTIMATOR_NUMBERS = ("rate_hz", "min_speed", "speed_hysteresis", "timeout_cycles", "friction_excitation",
                     "friction_correlation")
NOISE_KEYS = {name: tuple(getattr(EstimatorConfig(), name)) for name in ("process_noise", "measurement_noise", "initial_std")}


def _tire(doc: Document) -> TireModelParams:
    key_path = ("vehicle", "tire")
    section = doc.section(key_path, required=False)
    doc.reject_unknown(key_path, section, TIRE_FIELDS)
    defaults = TireModelParams()
    return TireModelParams(**{name: doc.number(key_path, section, name, getattr(defaults, name),
                                               positive=not name.endswith("curvature")) for name in TIRE_FIELDS})


def _vehicle(doc: Document) -> VehicleParams:
    section = doc.section(("vehicle",))
    doc.reject_unknown(("vehicle",), section, VEHICLE_FIELDS + ["name", "tire"])
    values = {name: doc.number(("vehicle",), section, name) for name in VEHICLE_FIELDS}
    return VehicleParams(name=str(section.get("name", doc.path.stem)), tire=_tire(doc), **values)


def _bus(doc: Document, key_path: tuple, default_channel: str) -> BusConfig:
    section = doc.section(key_path, required=False)
    options = {k: v for k, v in section.items() if k not in ("interface", "channel")}
    return BusConfig(str(section.get("interface", "socketcan")), str(section.get("channel", default_channel)), options)


def _dbc_path(doc: Document, key_path: tuple) -> Path:
    section = doc.section(key_path[:-1])
    if key_path[-1] not in section:
        raise doc.error(key_path, "missing DBC path")
    given = str(section[key_path[-1]])
    path = (doc.path.resolve().parent / given).resolve()
    if path.is_file():
        return path
    builtin = BUILTIN_DIR / Path(given).name
    if builtin.is_file():
        return builtin.resolve()
    raise doc.error(key_path, f"DBC file not found: {path}")


def _estimator(doc: Document) -> EstimatorConfig:
    key_path = ("estimator",)
    section = doc.section(key_path, required=False)
    defaults = EstimatorConfig()
    doc.reject_unknown(key_path, section, [f.name for f in dataclasses.fields(EstimatorConfig)])
    values = {name: doc.number(key_path, section, name, getattr(defaults, name)) for name in ESTIMATOR_NUMBERS}
    for name, keys in NOISE_KEYS.items():
        given = section.get(name, {})
        if not isinstance(given, dict):
            raise doc.error(key_path + (name,), "must be a mapping")
        doc.reject_unknown(key_path + (name,), given, keys)
        merged = {**getattr(defaults, name)}
        merged.update({k: doc.number(key_path + (name,), given, k) for k in given})
        values[name] = merged
    compensation = section.get("latency_compensation", defaults.latency_compensation)
    if not isinstance(compensation, bool):
        raise doc.error(key_path + ("latency_compensation",), f"must be true or false, got {compensation!r}")

    name = str(section.get("filter", defaults.filter))
    if name not in FILTERS:
        raise doc.error(key_path + ("filter",), f"unknown filter '{name}'; available: {', '.join(sorted(FILTERS))}")
    if values["friction_correlation"] >= 1.0:
        raise doc.error(key_path + ("friction_correlation",), f"must be below 1, got {values['friction_correlation']}")
    model = str(section.get("model", catalog.model_for(name)))
    if model not in catalog.CATALOG:
        raise doc.error(key_path + ("model",), f"unknown model '{model}'; available: {', '.join(catalog.CATALOG)}")
    if "filter" not in section and "model" in section:
        name = catalog.CATALOG[model].default_filter
    problem = catalog.misfit(name, model)
    if problem:
        raise doc.error(key_path + ("model",), problem)
    if compensation and not hasattr(catalog.CATALOG[model].model, "derivatives"):
        raise doc.error(key_path + ("latency_compensation",), f"model '{model}' has no derivatives to back-date by")
    factorization = section.get("factorization", defaults.factorization)
    if factorization is not None and factorization not in FACTORIZATIONS:
        raise doc.error(key_path + ("factorization",), f"must be one of {', '.join(FACTORIZATIONS)}")
    options = section.get("filter_options", {})
    if not isinstance(options, dict):
        raise doc.error(key_path + ("filter_options",), "must be a mapping of option: value")
    config = EstimatorConfig(filter=name, model=model, factorization=factorization, filter_options=options,
                             latency_compensation=compensation, **values)
    _check_filter_options(doc, config)
    return config


def _check_filter_options(doc: Document, est: EstimatorConfig) -> None:
    """Build the filter once on a dummy state of the model's size so a wrong option fails at load time, naming the key."""
    model = catalog.CATALOG[est.model].model
    n = len(model.state_names)
    try:
        make_filter(est.filter, np.zeros(n), np.eye(n), model, est.factorization, est.filter_options)
    except (TypeError, ValueError) as exc:
        raise doc.error(("estimator", "filter_options"), f"{est.filter}: {exc}") from None


def _signal_specs(doc: Document, database, dbc_path: Path, vehicle: VehicleParams) -> dict:
    key_path = ("input", "signals")
    section = doc.section(key_path)
    specs = {}
    for canonical, entry in section.items():
        where = key_path + (canonical,)
        if canonical not in sig.CANONICAL:
            raise doc.error(where, f"unknown canonical signal; known: {', '.join(sig.CANONICAL)}")
        if isinstance(entry, str):
            entry = {"signal": entry}
        if not isinstance(entry, dict) or "signal" not in entry:
            raise doc.error(where, "needs 'signal: MESSAGE.SIGNAL'")
        doc.reject_unknown(where, entry, ("signal", "unit", "sign", "scale", "offset"))
        message_name, _, signal_name = str(entry["signal"]).partition(".")
        try:
            message = database.get_message_by_name(message_name)
        except KeyError:
            raise doc.error(where + ("signal",), f"no message '{message_name}' in {dbc_path}") from None
        signal = next((s for s in message.signals if s.name == signal_name), None)
        if signal is None:
            raise doc.error(where + ("signal",), f"no signal '{signal_name}' in message '{message_name}' of {dbc_path}")
        unit = entry.get("unit", signal.unit)
        if not unit:
            raise doc.error(where, f"signal {message_name}.{signal_name} has no unit in the DBC; give 'unit'")
        if signal.unit and entry.get("unit") and signal.unit.strip() != str(unit).strip():
            raise doc.error(where + ("unit",), f"'{unit}' contradicts the DBC unit '{signal.unit}' of {message_name}.{signal_name}")
        try:
            factor = sig.si_factor(canonical, str(unit), vehicle.wheel_radius)
        except ValueError as exc:
            raise doc.error(where + ("unit",), str(exc)) from None
        sign = entry.get("sign", 1)
        if sign not in (1, -1):
            raise doc.error(where + ("sign",), "must be 1 or -1")
        scale = doc.number(where, entry, "scale", 1.0)
        offset = doc.number(where, entry, "offset", 0.0, positive=False)
        mux = None
        if signal.multiplexer_ids:
            mux = int(signal.multiplexer_ids[0])
        specs[canonical] = SignalSpec(canonical, message_name, signal_name, sign * scale * factor, offset, mux)
    return specs


def _check_model_inputs(doc: Document, est: EstimatorConfig, specs: dict) -> None:
    """Every input the model needs, and those the filter adds (the DICI-GFCKF's second IMU)."""
    entry = catalog.CATALOG[est.model]
    for reason, needed in (("the estimator", catalog.BASE_INPUTS),
                           (f"model '{est.model}'", entry.required_inputs),
                           (f"filter '{est.filter}'", entry.inputs_for(est.filter))):
        missing = [name for name in needed if name not in specs]
        if missing:
            raise doc.error(("input", "signals"), f"{reason} needs {', '.join(missing)}")


def _message_checks(doc: Document, database, dbc_path: Path, specs: dict) -> dict:
    key_path = ("input", "messages")
    section = doc.section(key_path, required=False)
    checks = {}
    for name, entry in section.items():
        where = key_path + (name,)
        try:
            message = database.get_message_by_name(name)
        except KeyError:
            raise doc.error(where, f"no message '{name}' in {dbc_path}") from None
        if not isinstance(entry, dict):
            raise doc.error(where, "must map counter/checksum/valid to signal names")
        doc.reject_unknown(where, entry, ("counter", "checksum", "valid"))
        names = {s.name for s in message.signals}
        for role, signal_name in entry.items():
            if signal_name not in names:
                raise doc.error(where + (role,), f"no signal '{signal_name}' in message '{name}' of {dbc_path}")
        checks[name] = MessageChecks(**entry)
    return checks


def load_config(path) -> Config:
    """Read and validate a config file; raise ConfigError naming file, line and key."""
    path = Path(path)
    doc = Document(path)
    doc.reject_unknown((), doc.data, ("vehicle", "input", "output", "estimator"))
    vehicle = _vehicle(doc)
    input_dbc = _dbc_path(doc, ("input", "dbc"))
    output_dbc = _dbc_path(doc, ("output", "dbc"))
    input_db = load_database(input_dbc, f"{path}: input.dbc")
    load_database(output_dbc, f"{path}: output.dbc")
    specs = _signal_specs(doc, input_db, input_dbc, vehicle)
    estimator = _estimator(doc)
    _check_model_inputs(doc, estimator, specs)
    return Config(
        path=path.resolve(),
        vehicle=vehicle,
        input_dbc=input_dbc,
        output_dbc=output_dbc,
        input_bus=_bus(doc, ("input", "bus"), "vcan0"),
        output_bus=_bus(doc, ("output", "bus"), "vcan1"),
        signals=specs,
        messages=_message_checks(doc, input_db, input_dbc, specs),
        estimator=estimator,
    )
