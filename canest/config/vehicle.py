"""The ``vehicle`` section: mass, geometry, stiffnesses, drive layout and the tire coefficients, each within its
physical range."""
from __future__ import annotations

from canest import limits
from canest.params import TireModelParams, VehicleParams
from canest.yamldoc import Document, suggestion

DEFAULT_DRIVE = "front"
DEFAULT_DRIVE_FRONT_SHARE = 0.5  # with drive: all
DEFAULT_BRAKE_FRONT_SHARE = VehicleParams.brake_front_share


def read_tire(doc: Document) -> TireModelParams:
    key_path = ("vehicle", "tire")
    section = doc.section(key_path, required=False)
    doc.reject_unknown(key_path, section, limits.TIRE)
    defaults = TireModelParams()
    return TireModelParams(**{name: doc.number(key_path, section, name, allowed, getattr(defaults, name))
                              for name, allowed in limits.TIRE.items()})


def read_drive(doc: Document, section: dict) -> dict:
    """``drive`` (front | rear | all), ``drive_front_share`` (all only) and ``brake_front_share`` as axle shares."""
    key_path = ("vehicle",)
    drive = doc.text(key_path, section, "drive", DEFAULT_DRIVE)
    if drive not in limits.DRIVE_LAYOUTS:
        raise doc.error(key_path + ("drive",), f"unknown drive '{drive}'; {suggestion(drive, limits.DRIVE_LAYOUTS)}")
    share = limits.DRIVE_LAYOUTS[drive]
    if share is not None and "drive_front_share" in section:
        raise doc.error(key_path + ("drive_front_share",), f"only with drive: all (drive: {drive} puts "
                                                           f"{share:.0%} of the drive force on the front axle)")
    if share is None:
        share = doc.number(key_path, section, "drive_front_share", limits.DRIVE["drive_front_share"],
                           DEFAULT_DRIVE_FRONT_SHARE)
    brake = doc.number(key_path, section, "brake_front_share", limits.DRIVE["brake_front_share"],
                       DEFAULT_BRAKE_FRONT_SHARE)
    return {"drive_front_share": share, "brake_front_share": brake}


def read_vehicle(doc: Document) -> VehicleParams:
    section = doc.section(("vehicle",))
    doc.reject_unknown(("vehicle",), section, [*limits.VEHICLE, *limits.DRIVE, *limits.ATTITUDE, "drive", "name",
                                               "tire", "cornering_stiffness_uncertainty",
                                               "wheel_radius_uncertainty"])
    values = {name: doc.number(("vehicle",), section, name, allowed) for name, allowed in limits.VEHICLE.items()}
    uncertainty = doc.number(("vehicle",), section, "cornering_stiffness_uncertainty", limits.STIFFNESS_UNCERTAINTY,
                             VehicleParams.cornering_stiffness_uncertainty)
    radius_uncertainty = doc.number(("vehicle",), section, "wheel_radius_uncertainty", limits.RADIUS_UNCERTAINTY,
                                    VehicleParams.wheel_radius_uncertainty)
    attitude = {name: doc.number(("vehicle",), section, name, allowed, getattr(VehicleParams, name))
                for name, allowed in limits.ATTITUDE.items()}
    return VehicleParams(name=doc.text(("vehicle",), section, "name", doc.path.stem), tire=read_tire(doc),
                         cornering_stiffness_uncertainty=uncertainty,
                         wheel_radius_uncertainty=radius_uncertainty, **read_drive(doc, section), **attitude, **values)
