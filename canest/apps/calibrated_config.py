"""A calibration written as a complete config: the user's config with the fitted values in place.

canest has no overlay mechanism (a config is one file, :func:`canest.config.load_config`),
so ``canest calibrate --out`` writes a copy of the config with the calibrated
values and a comment on each saying what it was and how sure the fit is:
the axle cornering stiffnesses and the steering ratio in ``vehicle``, the
effective wheel radius in ``vehicle.wheel_radius`` (and, for wheel speeds the
DBC gives as a linear speed, in their ``scale``: the radius does not reach
those) with how well it is now known (``wheel_radius_uncertainty``,
:data:`RADIUS_DRIFT`), the sensor offsets as each signal's ``offset`` (SI,
added after scaling: the bias subtracted). A road's bank is no property of the car and is
only reported in the header. DBC paths relative to the config are rewritten
relative to the new file; the result is loaded as ``canest check`` loads it
before it is written, and never replaces a file.
"""
from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import yaml

from canest.calibration import CONFIDENCE, RADIUS_DRIFT, Fit
from canest.apps.init import write_new
from canest.codec.dbc import load_database
from canest.config import BUILTIN_PREFIX, load_config
from canest.codec.opendbc_dbcs import PREFIX as OPENDBC_PREFIX
from canest.errors import ConfigError, OutputFileError
from canest.estimation.inputs import WHEEL_SPEEDS
from canest.settings import Config
from canest.signals import LINEAR_SPEED_UNITS, normal_unit

SENSOR_OFFSETS = {"steering_wheel_angle": "steering_offset", "yaw_rate": "gyro_bias", "ay": "ay_bias",
                  "yaw_rate_2": "gyro_bias_2"}  # the last where the fit has it and the config maps the signal


def calibrated_values(config: Config, fit: Fit) -> dict:
    """key path -> (new value, comment) for every config value the calibration sets."""
    v = config.vehicle

    def scaled(name, base):
        return (round(base * fit.value(name), 6),
                f"calibrated: was {base:g}, 95 % CI +-{base * fit.half_width(name):.4g}")

    values = {
        ("vehicle", "cornering_stiffness_front"): scaled("front", v.cornering_stiffness_front),
        ("vehicle", "cornering_stiffness_rear"): scaled("rear", v.cornering_stiffness_rear),
        ("vehicle", "steering_ratio"): scaled("ratio", v.steering_ratio),
        ("vehicle", "wheel_radius"): scaled("speed", v.wheel_radius),
        ("vehicle", "wheel_radius_uncertainty"): (
            round(math.hypot(fit.half_width("speed") / CONFIDENCE / fit.value("speed"), RADIUS_DRIFT), 4),
            f"calibrated: was {v.wheel_radius_uncertainty:g}; the fit's std and {RADIUS_DRIFT:g} of drift "
            "between drives"),
    }
    for signal, name in SENSOR_OFFSETS.items():
        if name not in fit.names or signal not in config.signals:
            continue
        old = config.signals[signal].offset
        values[("input", "signals", signal, "offset")] = (
            round(old - fit.value(name), 9),
            f"calibrated (SI): was {old:g}, sensor bias {fit.value(name):.4g} +-{fit.half_width(name):.2g}")
    database = load_database(config.input_dbc, f"{config.path}: input.dbc")
    for wheel in WHEEL_SPEEDS:
        spec = config.signals[wheel]
        unit = database.get_message_by_name(spec.message).get_signal_by_name(spec.signal).unit
        if normal_unit(_entry(config, wheel).get("unit", unit) or "") in LINEAR_SPEED_UNITS:
            scale = _entry(config, wheel).get("scale", 1.0)
            values[("input", "signals", wheel, "scale")] = (
                round(scale * fit.value("speed"), 9), f"calibrated: was {scale:g} (effective wheel radius)")
    return values


def _entry(config: Config, signal: str) -> dict:
    entry = _raw(config)["input"]["signals"][signal]
    return {"signal": entry} if isinstance(entry, str) else entry


def _raw(config: Config) -> dict:
    return yaml.safe_load(Path(config.path).read_text(encoding="utf-8"))


def _moved_dbc(given: str, source: Path, target: Path) -> str:
    """A DBC path of the config at ``source`` as the config at ``target`` must say it."""
    if given.startswith((BUILTIN_PREFIX, OPENDBC_PREFIX)) or os.path.isabs(given):
        return given
    return os.path.relpath((source.parent / given).resolve(), target.resolve().parent)


def calibrated_text(config: Config, fit: Fit, out: Path, header: list) -> str:
    """The config file's text with the calibrated values, each with its comment, under ``header`` lines."""
    raw = _raw(config)
    values = calibrated_values(config, fit)
    for section in ("input", "output"):
        raw[section]["dbc"] = _moved_dbc(raw[section]["dbc"], Path(config.path), out)
    for key_path, (value, _) in values.items():
        node = raw
        for key in key_path[:-1]:
            if isinstance(node.get(key), str):  # the short form `signal: MSG.SIG`
                node[key] = {"signal": node[key]}
            node = node[key]
        node[key_path[-1]] = value
    lines = yaml.safe_dump(raw, sort_keys=False, default_flow_style=False).splitlines()
    for key_path, (_, comment) in values.items():
        index = _line_of(lines, key_path)
        lines[index] += f"  # {comment}"
    return "\n".join([*(f"# {line}" for line in header), *lines]) + "\n"


def _line_of(lines: list, key_path: tuple) -> int:
    """The index of the line holding ``key_path`` in block-style YAML of two-space indentation."""
    depth = 0
    for index, line in enumerate(lines):
        if line.startswith("  " * depth + f"{key_path[depth]}:"):
            if depth == len(key_path) - 1:
                return index
            depth += 1
    raise AssertionError(f"{'.'.join(key_path)} not in the YAML just written")


def write_calibrated(config: Config, fit: Fit, out, header: list) -> None:
    """The calibrated config into the new file ``out``, loaded first as ``canest check`` loads it."""
    out = Path(out)
    text = calibrated_text(config, fit, out, header)
    check_new(out)
    with tempfile.NamedTemporaryFile("w", suffix=".yaml", dir=out.resolve().parent, prefix=".calibrate-",
                                     encoding="utf-8", delete=False) as handle:
        handle.write(text)
    try:
        load_config(handle.name)
    except ConfigError as exc:
        raise ConfigError(f"{out}: the calibrated config does not load (a fitted value out of its range?): "
                          f"{str(exc).replace(handle.name, 'the config')}") from None
    finally:
        Path(handle.name).unlink(missing_ok=True)
    write_new(out, text, "calibrate")


def check_new(out) -> None:
    """An OutputFileError (73) now, before the fit, when ``out`` exists or its folder does not."""
    out = Path(out)
    if os.path.lexists(out):
        raise OutputFileError(f"{out}: exists; calibrate never replaces a file: choose another --out or move it away")
    if not out.resolve().parent.is_dir():
        raise OutputFileError(f"{out}: cannot create: no folder {out.resolve().parent}; create it or write elsewhere")


def bank_lines(fit: Fit, logs: list) -> list:
    """The header lines of each log's road bank (the road's, not the car's: not a config value)."""
    return [f"  road bank of {log}: {math.degrees(fit.value(f'bank[{i}]')):+.2f} deg "
            f"+-{math.degrees(fit.half_width(f'bank[{i}]')):.2f} (not a config value)" for i, log in enumerate(logs)]
