"""YAML configuration -> typed, validated dataclasses.

Every error is a :class:`ConfigError` whose text names the file, the line and
the key (``configs/ev.yaml:42: input.signals.ax.signal: ...``) so a user can
fix it without reading code. Nothing is accepted silently: an unknown key is
an error naming the nearest valid one, every number must lie in its physical
range (:mod:`canest.limits`), a DBC path must exist (canest's own DBCs are
named ``builtin:NAME``), and each mapped signal must decode from a frame ID
no other message of its DBC shares. Paths inside a config are relative to the
config. One module per section: :mod:`canest.config.vehicle`,
:mod:`canest.config.buses`, :mod:`canest.config.signal_map` (input signals and
messages) and :mod:`canest.config.estimator`.
"""
from __future__ import annotations

import logging
from pathlib import Path

from canest.codec.dbc import load_database, tolerated_problems
from canest.codec.opendbc_dbcs import PREFIX as OPENDBC_PREFIX, closest_names, opendbc_path
from canest.config.buses import id_clash, read_bus, same_bus
from canest.config.estimator import check_model_inputs, read_estimator
from canest.config.signal_map import read_message_checks, read_signal_specs
from canest.config.vehicle import read_vehicle
from canest.errors import ConfigError
from canest.settings import Config
from canest.yamldoc import Document

BUILTIN_DIR = Path(__file__).resolve().parent.parent / "data"
BUILTIN_PREFIX = "builtin:"
DEFAULT_CONFIG = BUILTIN_DIR / "dici_ev.yaml"
LOG = logging.getLogger(__name__)
__all__ = ["BUILTIN_DIR", "BUILTIN_PREFIX", "DEFAULT_CONFIG", "ConfigError", "load_config"]

SECTION_KEYS = {
    (): ("vehicle", "input", "output", "estimator"),
    ("input",): ("dbc", "bus", "signals", "messages"),
    ("output",): ("dbc", "bus"),
}


def _dbc_path(doc: Document, key_path: tuple) -> Path:
    """The DBC file ``key_path`` names: a path relative to the config, ``builtin:NAME`` for canest's own or
    ``opendbc:NAME`` for one of opendbc's (the optional package)."""
    given = doc.text(key_path[:-1], doc.section(key_path[:-1]), key_path[-1])
    if given is None:
        raise doc.error(key_path, "missing DBC path")
    if "\0" in given:
        raise doc.error(key_path, f"a path cannot hold a NUL character, got {given!r}")
    builtin = sorted(p.name for p in BUILTIN_DIR.glob("*.dbc"))
    if given.startswith(BUILTIN_PREFIX):
        name = given[len(BUILTIN_PREFIX):]
        if name not in builtin:
            raise doc.error(key_path, f"no built-in DBC '{name}'; built in: "
                                      f"{', '.join(BUILTIN_PREFIX + b for b in builtin)}")
        return (BUILTIN_DIR / name).resolve()
    if given.startswith(OPENDBC_PREFIX):
        name = given[len(OPENDBC_PREFIX):]
        feature = f"{doc.path}: {'.'.join(key_path)}: {given}"
        path = opendbc_path(name, feature)
        if path is None:
            raise doc.error(key_path, f"opendbc has no DBC '{name}'; {closest_names(name, feature)}")
        return path
    path = (doc.path.resolve().parent / given).resolve()
    if path.is_file():
        return path
    if path.is_dir():
        raise doc.error(key_path, f"{path} is a folder; name the DBC file in it")
    hint = f" (canest's own is '{BUILTIN_PREFIX}{path.name}')" if path.name in builtin else ""
    raise doc.error(key_path, f"DBC file not found: {path}{hint}")


def load_config(path) -> Config:
    """Read and validate a config file; raise ConfigError naming file, line and key."""
    path = Path(path)
    doc = Document(path)
    for key_path, known in SECTION_KEYS.items():
        doc.reject_unknown(key_path, doc.section(key_path), known)
    vehicle = read_vehicle(doc)
    input_dbc = _dbc_path(doc, ("input", "dbc"))
    output_dbc = _dbc_path(doc, ("output", "dbc"))
    input_db = load_database(input_dbc, f"{path}: input.dbc")
    output_db = load_database(output_dbc, f"{path}: output.dbc")
    specs = read_signal_specs(doc, input_db, input_dbc, vehicle)
    estimator = read_estimator(doc)
    check_model_inputs(doc, estimator, specs)
    tolerated = tolerated_problems(input_dbc, f"{path}: input.dbc")
    for message, problem in tolerated.items():
        LOG.warning("%s: input.dbc %s: %s (tolerated: %s)", path, input_dbc, problem,
                    f"no signal is taken from {message}" if message else "loaded without cantools' strict checks")
    input_bus, output_bus = read_bus(doc, ("input", "bus"), "vcan0"), read_bus(doc, ("output", "bus"), "vcan1")
    clash = id_clash(input_db, output_db) if same_bus(input_bus, output_bus) else None
    if clash:
        raise doc.error(("output", "bus"), clash)
    return Config(
        path=path.resolve(),
        vehicle=vehicle,
        input_dbc=input_dbc,
        output_dbc=output_dbc,
        input_bus=input_bus,
        output_bus=output_bus,
        signals=specs,
        messages=read_message_checks(doc, input_db, input_dbc, specs),
        estimator=estimator,
        tolerated=tolerated,
    )
