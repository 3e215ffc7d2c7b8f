"""The ``vehicle`` section: mass, geometry, stiffnesses and the tire coefficients, each within its physical range."""
from __future__ import annotations

from canest import limits
from canest.params import TireModelParams, VehicleParams
from canest.yamldoc import Document


def read_tire(doc: Document) -> TireModelParams:
    key_path = ("vehicle", "tire")
    section = doc.section(key_path, required=False)
    doc.reject_unknown(key_path, section, limits.TIRE)
    defaults = TireModelParams()
    return TireModelParams(**{name: doc.number(key_path, section, name, allowed, getattr(defaults, name))
                              for name, allowed in limits.TIRE.items()})


def read_vehicle(doc: Document) -> VehicleParams:
    section = doc.section(("vehicle",))
    doc.reject_unknown(("vehicle",), section, [*limits.VEHICLE, "name", "tire"])
    values = {name: doc.number(("vehicle",), section, name, allowed) for name, allowed in limits.VEHICLE.items()}
    return VehicleParams(name=doc.text(("vehicle",), section, "name", doc.path.stem), tire=read_tire(doc), **values)
