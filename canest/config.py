"""YAML configuration -> typed, validated dataclasses.

Every error is a :class:`ConfigError` whose text names the file, the line and
the key (``configs/ev.yaml:42: input.signals.ax.signal: ...``) so a user can
fix it without reading code. Paths inside a config are relative to the config.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from canest import signals as sig
from canest.models.tire import TireModelParams

BUILTIN_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_CONFIG = BUILTIN_DIR / "dici_ev.yaml"


class ConfigError(Exception):
    """A config or DBC problem, with the file, line and key it concerns."""


@dataclass(frozen=True)
class VehicleParams:
    """Vehicle parameters in SI units. Cornering stiffnesses are per axle, positive."""

    name: str
    mass: float
    yaw_inertia: float
    cg_to_front: float
    cg_to_rear: float
    track_front: float
    track_rear: float
    cg_height: float
    wheel_radius: float
    wheel_inertia: float
    steering_ratio: float
    cornering_stiffness_front: float
    cornering_stiffness_rear: float
    tire: TireModelParams = TireModelParams()

    @property
    def wheelbase(self) -> float:
        return self.cg_to_front + self.cg_to_rear


@dataclass(frozen=True)
class BusConfig:
    """Arguments for ``can.Bus``: interface, channel and any extra keyword."""

    interface: str = "socketcan"
    channel: str = "vcan0"
    options: dict = field(default_factory=dict)

    def kwargs(self) -> dict:
        return {"interface": self.interface, "channel": self.channel, **self.options}


@dataclass(frozen=True)
class SignalSpec:
    """Where a canonical signal lives and how its DBC value becomes SI: si = factor * value + offset."""

    canonical: str
    message: str
    signal: str
    factor: float
    offset: float = 0.0
    multiplexer_value: int | None = None


@dataclass(frozen=True)
class MessageChecks:
    """Optional integrity signals of an input message."""

    counter: str | None = None
    checksum: str | None = None
    valid: str | None = None


# Models and the filters they need: the dual filter estimates the two-track model's friction
# parameters and nothing else does; the DICI-GFCKF fuses the tire-force model's two IMUs.
MODEL_FILTERS = {"two_track": ("jckf", "dckf")}
FILTER_MODELS = {"jckf": "two_track", "dckf": "two_track", "dici-gfckf": "tire_force"}
MODEL_INPUTS = {"tire_force": sig.INPUT_GROUPS["motor_torques"], "two_track": sig.INPUT_GROUPS["motor_torques"]}
FILTER_INPUTS = {"dici-gfckf": sig.INPUT_GROUPS["imu_2"]}


@dataclass(frozen=True)
class EstimatorConfig:
    filter: str = "ckf"
    model: str = "single_track"  # single_track, tire_force (7 states) or two_track (7-DOF + friction)
    factorization: str | None = None  # None: the filter's own default (svd for svd-fckf, else cholesky)
    filter_options: dict = field(default_factory=dict)
    rate_hz: float = 100.0
    min_speed: float = 3.0
    speed_hysteresis: float = 1.0
    timeout_cycles: float = 5.0
    friction_excitation: float = 1500.0  # N per unit mu: |dF/dmu| at mu - 3 std that makes a wheel excited
    friction_correlation: float = 0.9  # prior correlation of the four wheels' frictions (same road)
    latency_compensation: bool = False
    process_noise: dict = field(default_factory=lambda: {
        "yaw_rate": 0.05, "beta": 0.01, "vx": 0.3, "lateral_force": 3000.0, "wheel_speed": 5.0, "friction": 0.1})
    measurement_noise: dict = field(default_factory=lambda: {
        "ay": 0.15, "yaw_rate": 0.005, "vx_wheel": 0.15, "ax": 0.15, "ax_2": 0.3, "ay_2": 0.3, "yaw_rate_2": 0.01,
        "wheel_speed": 0.1, "yaw_acceleration": 0.1, "vx_reference": 0.05})
    initial_std: dict = field(default_factory=lambda: {
        "yaw_rate": 0.05, "beta": 0.05, "vx": 2.0, "lateral_force": 1000.0, "wheel_speed": 1.0, "friction": 0.3})


@dataclass(frozen=True)
class Config:
    path: Path
    vehicle: VehicleParams
    input_dbc: Path
    output_dbc: Path
    input_bus: BusConfig
    output_bus: BusConfig
    signals: dict  # canonical -> SignalSpec
    messages: dict  # message name -> MessageChecks
    estimator: EstimatorConfig

    def with_buses(self, input_bus: BusConfig | None = None, output_bus: BusConfig | None = None) -> "Config":
        return dataclasses.replace(self, input_bus=input_bus or self.input_bus, output_bus=output_bus or self.output_bus)


class _Document:
    """A YAML mapping with the line of every key, for error messages."""

    def __init__(self, path: Path):
        self.path = path
        try:
            node = yaml.compose(path.read_text())
        except FileNotFoundError:
            raise ConfigError(f"{path}: config file not found") from None
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: invalid YAML: {exc}") from None
        self.lines: dict = {}
        self.data = self._convert(node, ()) if node is not None else {}
        if not isinstance(self.data, dict):
            raise ConfigError(f"{path}: the top level must be a mapping of sections")

    def _convert(self, node, key_path):
        if isinstance(node, yaml.MappingNode):
            result = {}
            for key_node, value_node in node.value:
                key = key_node.value
                self.lines[key_path + (key,)] = key_node.start_mark.line + 1
                result[key] = self._convert(value_node, key_path + (key,))
            return result
        if isinstance(node, yaml.SequenceNode):
            return [self._convert(item, key_path) for item in node.value]
        return yaml.safe_load(yaml.serialize(node))

    def error(self, key_path: tuple, message: str) -> ConfigError:
        line = next((self.lines[key_path[:n]] for n in range(len(key_path), 0, -1) if key_path[:n] in self.lines), None)
        where = f"{self.path}:{line}" if line else str(self.path)
        return ConfigError(f"{where}: {'.'.join(key_path)}: {message}")

    def section(self, key_path: tuple, required: bool = True) -> dict:
        value = self.data
        for key in key_path:
            if not isinstance(value, dict) or key not in value:
                if required:
                    raise self.error(key_path, "missing section")
                return {}
            value = value[key]
        if not isinstance(value, dict):
            raise self.error(key_path, "must be a mapping")
        return value

    def number(self, key_path: tuple, section: dict, key: str, default=None, positive=True) -> float:
        if key not in section:
            if default is None:
                raise self.error(key_path + (key,), "missing value")
            return float(default)
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key_path + (key,), f"must be a number, got {value!r}")
        if positive and value <= 0:
            raise self.error(key_path + (key,), f"must be positive, got {value}")
        return float(value)

    def reject_unknown(self, key_path: tuple, section: dict, known) -> None:
        unknown = sorted(set(section) - set(known))
        if unknown:
            raise self.error(key_path + (unknown[0],), f"unknown key; known keys: {', '.join(sorted(known))}")


VEHICLE_FIELDS = [f.name for f in dataclasses.fields(VehicleParams) if f.name not in ("name", "tire")]
TIRE_FIELDS = [f.name for f in dataclasses.fields(TireModelParams)]
ESTIMATOR_NUMBERS = ("rate_hz", "min_speed", "speed_hysteresis", "timeout_cycles", "friction_excitation",
                     "friction_correlation")
NOISE_KEYS = {name: tuple(getattr(EstimatorConfig(), name)) for name in ("process_noise", "measurement_noise", "initial_std")}
MODELS = ("single_track", "tire_force", "two_track")


def _tire(doc: _Document) -> TireModelParams:
    key_path = ("vehicle", "tire")
    section = doc.section(key_path, required=False)
    doc.reject_unknown(key_path, section, TIRE_FIELDS)
    defaults = TireModelParams()
    return TireModelParams(**{name: doc.number(key_path, section, name, getattr(defaults, name),
                                               positive=not name.endswith("curvature")) for name in TIRE_FIELDS})


def _vehicle(doc: _Document) -> VehicleParams:
    section = doc.section(("vehicle",))
    doc.reject_unknown(("vehicle",), section, VEHICLE_FIELDS + ["name", "tire"])
    values = {name: doc.number(("vehicle",), section, name) for name in VEHICLE_FIELDS}
    return VehicleParams(name=str(section.get("name", doc.path.stem)), tire=_tire(doc), **values)


def _bus(doc: _Document, key_path: tuple, default_channel: str) -> BusConfig:
    section = doc.section(key_path, required=False)
    options = {k: v for k, v in section.items() if k not in ("interface", "channel")}
    return BusConfig(str(section.get("interface", "socketcan")), str(section.get("channel", default_channel)), options)


def _dbc_path(doc: _Document, key_path: tuple) -> Path:
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


def _estimator(doc: _Document) -> EstimatorConfig:
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
    from canest.filters import FACTORIZATIONS, FILTERS

    compensation = section.get("latency_compensation", defaults.latency_compensation)
    if not isinstance(compensation, bool):
        raise doc.error(key_path + ("latency_compensation",), f"must be true or false, got {compensation!r}")

    name = str(section.get("filter", defaults.filter))
    if name not in FILTERS:
        raise doc.error(key_path + ("filter",), f"unknown filter '{name}'; available: {', '.join(sorted(FILTERS))}")
    if values["friction_correlation"] >= 1.0:
        raise doc.error(key_path + ("friction_correlation",), f"must be below 1, got {values['friction_correlation']}")
    model = str(section.get("model", FILTER_MODELS.get(name, defaults.model)))
    if model not in MODELS:
        raise doc.error(key_path + ("model",), f"unknown model '{model}'; available: {', '.join(MODELS)}")
    if FILTER_MODELS.get(name, model) != model or name not in MODEL_FILTERS.get(model, (name,)):
        needed = FILTER_MODELS.get(name) or MODEL_FILTERS[model][0]
        raise doc.error(key_path + ("model",), f"filter '{name}' and model '{model}' do not fit: "
                                                f"use {'model' if name in FILTER_MODELS else 'filter'} '{needed}'")
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


def _check_filter_options(doc: _Document, est: EstimatorConfig) -> None:
    """Build the filter once on a dummy state of the model's size so a wrong option fails at load time, naming the key."""
    import numpy as np

    from canest.estimator import make_filter
    from canest.models.registry import MODELS as MODEL_CLASSES

    model = MODEL_CLASSES[est.model]
    n = len(model.state_names)
    try:
        make_filter(est, np.zeros(n), np.eye(n), **getattr(model, "filter_options", {}))
    except (TypeError, ValueError) as exc:
        raise doc.error(("estimator", "filter_options"), f"{est.filter}: {exc}") from None


def _signal_specs(doc: _Document, database, dbc_path: Path, vehicle: VehicleParams) -> dict:
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
    missing = [name for name in sig.REQUIRED if name not in specs]
    if missing:
        raise doc.error(key_path, f"the estimator needs {', '.join(missing)}")
    return specs


def _check_model_inputs(doc: _Document, est: EstimatorConfig, specs: dict) -> None:
    """The tire-force and two-track models need the motor torques; the DICI-GFCKF needs the second IMU."""
    for reason, needed in ((f"model '{est.model}'", MODEL_INPUTS.get(est.model, ())),
                           (f"filter '{est.filter}'", FILTER_INPUTS.get(est.filter, ()))):
        missing = [name for name in needed if name not in specs]
        if missing:
            raise doc.error(("input", "signals"), f"{reason} needs {', '.join(missing)}")


def _message_checks(doc: _Document, database, dbc_path: Path, specs: dict) -> dict:
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


def load_database(path: Path, owner: str):
    import cantools

    try:
        return cantools.database.load_file(str(path), strict=True)
    except Exception as exc:  # cantools raises several parser exception types
        raise ConfigError(f"{path}: cannot load DBC (referenced by {owner}): {exc}") from None


def load_config(path) -> Config:
    """Read and validate a config file; raise ConfigError naming file, line and key."""
    path = Path(path)
    doc = _Document(path)
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
