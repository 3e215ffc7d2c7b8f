"""A starting config from a DBC (a file or one of opendbc's) and, for a car opendbc describes, its parameters.

:func:`starting_config` finds the usual inputs in the DBC
(:mod:`canest.config.discover`), lists each choice and its runners-up in
YAML comments for the user to confirm, takes the vehicle block from
opendbc's car parameters where a car is named (each number's source in a
comment) and from canest's built-in config for the rest, and loads the result
as ``canest check`` would before anything is written. A DBC that lacks an
input every model needs is a :class:`~canest.errors.DbcError` naming those
inputs and what they cost; nothing is written then. :func:`write_new` never
replaces a file.
"""
from __future__ import annotations

import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from canest.codec.dbc import parse_dbc_text
from canest.codec.opendbc_dbcs import opendbc_name_of
from canest.codec.raw_range import raw_style
from canest.config import DEFAULT_CONFIG, load_config
from canest.config.discover import candidates
from canest.config.opendbc_cars import CAR_SOURCES, PREFIX, car_parameters, dbc_text
from canest.errors import ConfigError, DbcError, InputFileError, OutputFileError
from canest.estimation.catalog import BASE_INPUTS, losses, unmet
from canest.io.outputs import OutputFile, is_stdio, open_stdout
from canest.limits import VEHICLE
from canest.signals import INPUT_GROUPS, LINEAR_SPEED_UNITS, normal_unit

CONFIG_LOG = logging.getLogger("canest.config")  # the config loader's warnings (a tolerated DBC problem)
ORDER = (*BASE_INPUTS, *INPUT_GROUPS["motor_torques"])  # the inputs init looks for, in the config's order
UNMEASURED_RADIUS = 0.1  # vehicle.wheel_radius_uncertainty of the built-in car's radius on another car: 10 % (1 std)


@dataclass(frozen=True)
class DbcSource:
    """A DBC's text, what the config's ``input.dbc`` says for it, and how messages name it."""

    text: str
    reference: str
    label: str


def dbc_source(given: str, out) -> DbcSource:
    """``opendbc:NAME`` or a DBC path; a path is written relative to the config's folder (absolute for stdout).

    A file of opendbc's own (its package folder, canest's cache of generated DBCs) is written ``opendbc:NAME``:
    those folders move with an install or a cache clean, the name does not."""
    if given.startswith(PREFIX):
        return DbcSource(dbc_text(given[len(PREFIX):]), given, given)
    name = opendbc_name_of(given)
    if name:
        return DbcSource(dbc_text(name), PREFIX + name, PREFIX + name)
    path = Path(given)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise InputFileError(f"{path}: DBC file not found") from None
    except IsADirectoryError:
        raise InputFileError(f"{path}: that is a folder; name a DBC file") from None
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read: {exc.strerror}; check that this user may read it") from None
    folder = Path.cwd() if is_stdio(out) or out is None else Path(out).resolve().parent
    inside = path.resolve().is_relative_to(folder)  # beside the config: a relative path moves with both
    return DbcSource(text, os.path.relpath(path.resolve(), folder) if inside else str(path.resolve()), str(path))


def parse_dbc(source: DbcSource):
    """The DBC's cantools database, read leniently and repaired where cantools refuses it (canest's loader judges it
    again when the config loads)."""
    try:
        return parse_dbc_text(source.text, source.label)[0]
    except DbcError as exc:
        raise DbcError(f"{exc}; fix the DBC or name another") from None


def _number(value: float) -> str:
    return f"{value:.6g}" if abs(value) < 1e5 else f"{value:.1f}"


def vehicle_lines(name: str, car: str | None) -> list:
    """The ``vehicle:`` block: opendbc's numbers for ``car`` (each with its source), canest's defaults otherwise."""
    defaults = load_config(DEFAULT_CONFIG).vehicle
    known = car_parameters(car) if car else {}
    lines = ["vehicle:", f"  name: {name}"]
    for key in VEHICLE:
        if key in known:
            lines.append(f"  {key}: {_number(known[key])}    # opendbc {car}: {CAR_SOURCES[key]}")
        else:
            lines.append(f"  {key}: {_number(getattr(defaults, key))}    # canest's default (built-in "
                         f"{DEFAULT_CONFIG.name}): measure or look up yours")
    lines.append(f"  wheel_radius_uncertainty: {UNMEASURED_RADIUS}    # relative: wheel_radius is another car's until "
                 "you measure yours (README \"Your car\"); then say how well you know it (0.02: a tire size's)")
    return lines


def signal_lines(found: dict, database) -> list:
    """``input.signals`` entries, each with why it was taken and the runners-up, for the user to confirm.

    A signal whose DBC range is raw-style (:mod:`canest.codec.raw_range`) gets ``range: none``."""
    lines = []
    for canonical in ORDER:
        if canonical not in found:
            continue
        best, *others = found[canonical]
        notes = [f"ASSUMED unit {best.unit}: the DBC gives none" if best.assumed else f"unit {best.unit}"]
        keys = {"unit": best.unit} if best.assumed else {}
        signal = database.get_message_by_name(best.message).get_signal_by_name(best.signal)
        if raw_style(signal):
            notes.append(f"range none: the DBC's [{signal.minimum:g}|{signal.maximum:g}] is raw counts")
            keys["range"] = "none"
        if canonical.startswith("wheel_speed_") and normal_unit(best.unit) in LINEAR_SPEED_UNITS:
            notes.append("a linear speed: rad/s through vehicle.wheel_radius")
        if others:
            notes.append("else: " + ", ".join(o.reference for o in others))
        entry = "{" + ", ".join(f"{k}: {v}" for k, v in {"signal": best.reference, **keys}.items()) + "}" \
            if keys else best.reference
        lines.append(f"    {canonical}: {entry}    # CONFIRM: {'; '.join(notes)}")
    return lines


def config_text(source: DbcSource, database, found: dict, name: str, car: str | None) -> str:
    header = [
        f"# A starting config written by `canest init` from {source.label}"
        + (f" and opendbc's car {car}" if car else "") + ".",
        "# Every input below was found by its name and unit: CONFIRM each (right signal, sign: ISO 8855, a left turn",
        "# and a left yaw positive; `sign: -1` flips one), then run `canest check --config THIS` and replay a log.",
        "# If replay rejects a message's frames (rejected_fd_mismatch: the DBC declares CAN FD, the car sends",
        "# classic), add under input: `messages: {MESSAGE: {fd: false}}`. README \"Your car\" walks through it.",
    ]
    missing = losses(set(found))
    if missing:
        header += ["# Inputs not found, and what they cost:"] + [f"#   {line}" for line in missing]
    body = [
        "", *vehicle_lines(name, car), "",
        "input:", f"  dbc: {source.reference}", "  bus: {interface: socketcan, channel: can0}", "  signals:",
        *signal_lines(found, database), "",
        "output:", "  dbc: builtin:canest_estimates.dbc", "  bus: {interface: socketcan, channel: can1}", "",
        "estimator:", "  filter: ckf", "  rate_hz: 100",
    ]
    return "\n".join(header + body) + "\n"


def lacking(source: DbcSource, found: dict) -> None:
    """A DbcError naming the inputs every model needs that the DBC lacks (None if it has them all)."""
    missing = unmet(BASE_INPUTS, found)
    if missing:
        costs = [line for line in losses(set(found)) if any(f"{name}," in line or f"{name})" in line
                                                             for name in missing)]
        raise DbcError(f"{source.label}: no signal found for {', '.join(missing)} ({'; '.join(costs)}); "
                       "a signal of another name or unit can be mapped by hand in input.signals (README "
                       "\"Your car\"); nothing written")


class _ScratchNamed(logging.Filter):
    """Rewrites the scratch folder's paths in the config loader's warnings to the names the user gave."""

    def __init__(self, names: dict):
        super().__init__()
        self.names = names

    def rename(self, text: str) -> str:
        for scratch, given in self.names.items():
            text = text.replace(scratch, given)
        return text

    def filter(self, record) -> bool:
        record.msg, record.args = self.rename(record.getMessage()), None
        return True


def validated(text: str, source: DbcSource) -> None:
    """Load ``text`` as ``canest check`` does, in a scratch folder holding the DBC; an error or warning names
    the DBC as given, never the scratch folder."""
    with tempfile.TemporaryDirectory(prefix="canest-init-") as folder:
        dbc = Path(folder) / "input.dbc"
        dbc.write_text(source.text, encoding="utf-8")
        config = Path(folder) / "config.yaml"
        config.write_text(text.replace(f"  dbc: {source.reference}\n", f"  dbc: {dbc}\n", 1), encoding="utf-8")
        scratch = _ScratchNamed({str(config): "the config", str(dbc): source.label})
        CONFIG_LOG.addFilter(scratch)
        try:
            load_config(config)
        except ConfigError as exc:
            raise type(exc)(f"{source.label}: the config init would write does not load: "
                            f"{scratch.rename(str(exc))}") from None
        finally:
            CONFIG_LOG.removeFilter(scratch)


def starting_config(given_dbc: str | None, car: str | None = None, out=None) -> tuple:
    """(the config's text, the inputs found) for the DBC ``given_dbc`` (or ``car``'s own when None)."""
    params_dbc = car_parameters(car)["dbc"] if car and given_dbc is None else None
    source = dbc_source(given_dbc or f"{PREFIX}{params_dbc}", out)
    database = parse_dbc(source)
    found = candidates(database)
    lacking(source, found)
    name = (car or Path(source.label.removeprefix(PREFIX)).stem).lower().replace("_", "-")
    text = config_text(source, database, found, name, car)
    validated(text, source)
    return text, found


def write_new(path, text: str, command: str = "init") -> None:
    """``text`` into a new file ``path`` (``-``: standard output); an existing file is never replaced
    (``command`` says who in the error).

    Staged beside the name and linked under it, which fails if the name exists (no race with another writer)."""
    if is_stdio(path):
        with open_stdout() as handle:
            handle.write(text)
        return
    if os.path.isdir(path):
        raise OutputFileError(f"{path}: that is a folder; name the new file in it")
    if os.path.lexists(path):
        raise OutputFileError(f"{path}: exists; {command} never replaces a file: choose another --out or move it away")
    output = OutputFile(path)
    try:
        with open(output.write_path, "w", encoding="utf-8") as handle:
            handle.write(text)
        os.link(output.write_path, output.target)
    except FileExistsError:
        raise OutputFileError(f"{path}: exists; {command} never replaces a file: choose another --out or move it "
                              "away") from None
    except OSError as exc:
        raise output.error(exc) from None
    finally:
        output.discard()

