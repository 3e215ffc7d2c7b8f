"""opendbc's DBC texts and car parameters, for ``canest init`` (optional package ``opendbc``).

A DBC by name: a file under ``opendbc.DBC_PATH`` or one opendbc generates in
memory (``opendbc.get_generated_dbcs()``, names ending ``_generated``); only
``import opendbc`` is needed for those. A car by its platform name
(``TOYOTA_RAV4``): the parameters openpilot's car interface derives for it
(``get_non_essential_params``: mass with 136 kg of cargo, wheelbase, centre
of gravity, steering ratio, axle cornering stiffnesses, yaw inertia), which
need ``opendbc.car`` (numpy and pycapnp).

The DBCs themselves come from :mod:`canest.codec.opendbc_dbcs`, the loader of
``input.dbc: opendbc:NAME``.
"""
from __future__ import annotations

import difflib

from canest.codec.opendbc_dbcs import INSTALL, PREFIX, closest_names, opendbc_names, opendbc_path
from canest.errors import DependencyError, UsageError


def _closest(name: str, names) -> str:
    close = difflib.get_close_matches(name, list(names), n=3, cutoff=0.5)
    return f"closest: {', '.join(close)}" if close else f"{len(names)} known, e.g. {', '.join(sorted(names)[:3])}"


def dbc_names() -> list:
    """Every DBC name opendbc ships, files and generated, sorted."""
    return opendbc_names("opendbc's DBCs")


def dbc_text(name: str) -> str:
    """The text of opendbc's DBC ``name``; a UsageError naming the closest names if opendbc has none."""
    path = opendbc_path(name, f"{PREFIX}{name}")
    if path is None:
        raise UsageError(f"--dbc {PREFIX}{name}: opendbc has no DBC of that name ({closest_names(name, PREFIX + name)})")
    return path.read_text(encoding="utf-8", errors="replace")


def _car_modules(feature: str):
    DependencyError.require("opendbc", feature, INSTALL)
    try:
        from opendbc.car import Bus
        from opendbc.car.car_helpers import interfaces
        from opendbc.car.values import PLATFORMS
    except ImportError as exc:  # opendbc.car needs numpy and pycapnp (a `pip install --no-deps opendbc` lacks them)
        raise DependencyError(f"{feature}: opendbc's car parameters need {exc.name or exc}; {INSTALL}") from None
    return Bus, interfaces, PLATFORMS


def car_parameters(name: str) -> dict:
    """What opendbc says of the car ``name``: ``dbc`` (its powertrain DBC name) and the vehicle numbers
    (canest's keys: mass, cg_to_front, cg_to_rear, steering_ratio, yaw_inertia, cornering stiffnesses)."""
    Bus, interfaces, platforms = _car_modules(f"--car {name}")
    if name not in platforms:
        raise UsageError(f"--car {name}: opendbc describes no car of that name ({_closest(name, platforms)})")
    params = interfaces[name].get_non_essential_params(name)
    to_front = round(float(params.centerToFront), 4)
    return {
        "dbc": platforms[name].config.dbc_dict.get(Bus.pt),
        "mass": round(float(params.mass), 1),
        "cg_to_front": to_front,
        "cg_to_rear": round(float(params.wheelbase) - to_front, 4),
        "steering_ratio": round(float(params.steerRatio), 3),
        "yaw_inertia": round(float(params.rotationalInertia), 1),
        "cornering_stiffness_front": round(float(params.tireStiffnessFront), 0),
        "cornering_stiffness_rear": round(float(params.tireStiffnessRear), 0),
    }


# where each of car_parameters' numbers comes from, for the config's comments
CAR_SOURCES = {
    "mass": "CarParams.mass: the platform's curb mass plus openpilot's 136 kg of cargo (STD_CARGO_KG)",
    "cg_to_front": "CarParams.centerToFront (the brand interface's share of the wheelbase)",
    "cg_to_rear": "CarParams.wheelbase - centerToFront",
    "steering_ratio": "CarParams.steerRatio",
    "yaw_inertia": "CarParams.rotationalInertia (openpilot's scale_rot_inertia of mass and wheelbase)",
    "cornering_stiffness_front": "CarParams.tireStiffnessFront (scale_tire_stiffness, the platform's "
                                 "tireStiffnessFactor), whole axle",
    "cornering_stiffness_rear": "CarParams.tireStiffnessRear, whole axle",
}
