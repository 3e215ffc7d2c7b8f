"""The catalog of vehicle models: one row per model, everything the rest of canest asks about it.

In the spirit of openpilot's ``car_kf.py`` (states, observations and filter
in one place): a row names the model class, its binding to the inputs (the
estimator subclass), its default filter and the inputs it needs. Which
filters run on it follows from what each filter ``needs`` and what the model
offers (:func:`canest.filters.fits`), so no table of pairs can disagree with
the code. The config loader, compare, batch and the pipeline ask only this
module.

To add a model: its file in ``canest/models/``, its binding in
``canest/estimation/``, one row in :data:`CATALOG` (and output DBC signals if
it publishes new states).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from canest.estimation.derived_ax import NAME as DERIVED_AX, NOTE as DERIVED_AX_NOTE, derives_ax
from canest.estimation.single_track import SingleTrackEstimator
from canest.estimation.tire_force import TireForceEstimator
from canest.estimation.two_track import FrictionEstimator
from canest.filters import FILTERS, fits
from canest.models.single_track import SingleTrackModel
from canest.models.tire_force import TireForceModel
from canest.models.two_track import TwoTrackModel
from canest.estimation.estimate import OUTPUT_STATES
from canest.signals import INPUT_GROUPS, WHEELS

BASE_INPUTS = ("steering_wheel_angle", "ax", "ay", "yaw_rate", *(f"wheel_speed_{w}" for w in WHEELS))


def derived_inputs(mapped) -> dict:
    """{input: how it is derived} for the required inputs not mapped that the estimator computes from mapped ones:
    ax is required unless the wheel speeds are mapped (:mod:`canest.estimation.derived_ax`)."""
    return {DERIVED_AX: DERIVED_AX_NOTE} if derives_ax(mapped) else {}


def unmet(needed, mapped) -> list:
    """The inputs of ``needed`` neither mapped nor derived from mapped ones."""
    derived = derived_inputs(mapped)
    return [name for name in needed if name not in mapped and name not in derived]


@dataclass(frozen=True)
class ModelEntry:
    """One model: its class, its binding, its default filter and the inputs it (and a filter need) requires."""

    name: str
    model: type
    estimator: type
    default_filter: str
    required_inputs: tuple
    inputs_per_need: dict = field(default_factory=dict)  # a filter need -> the inputs it adds (e.g. a second IMU)
    optional_groups: dict = field(default_factory=dict)  # an input group used when mapped -> what replaces it if not

    @property
    def filters(self) -> tuple:
        """The filters that run on this model, in the order of :data:`canest.filters.FILTERS`."""
        return tuple(name for name in FILTERS if fits(name, self.model))

    def inputs_for(self, filter_name: str) -> tuple:
        """Inputs the model and the filter ``filter_name`` need together."""
        extra = [inputs for need, inputs in self.inputs_per_need.items() if need in FILTERS[filter_name].needs]
        return self.required_inputs + tuple(name for group in extra for name in group)

    @property
    def restricts_filters(self) -> bool:
        """True if only some filters run on it (it has parameter states): a misfit then asks for another filter."""
        return bool(getattr(self.model, "parameters", 0))


SECOND_GYRO = "the yaw rate from the first gyro alone"  # what a model reading a second gyro where mapped does without
CATALOG = {entry.name: entry for entry in (
    ModelEntry("single_track", SingleTrackModel, SingleTrackEstimator, "ckf", BASE_INPUTS,
               optional_groups={"imu_2": SECOND_GYRO}),
    ModelEntry("tire_force", TireForceModel, TireForceEstimator, "ckf", BASE_INPUTS,
               {"sensor_sets": INPUT_GROUPS["imu_2"]},
               {"motor_torques": "longitudinal forces from ax and vehicle.drive"}),
    ModelEntry("two_track", TwoTrackModel, FrictionEstimator, "jckf", BASE_INPUTS + INPUT_GROUPS["motor_torques"],
               optional_groups={"imu_2": SECOND_GYRO}),
)}
DEFAULT_MODEL = "single_track"


def model_for(filter_name: str, preferred: str = DEFAULT_MODEL) -> str:
    """``preferred`` if the filter runs on it, else the first catalog model it runs on."""
    if fits(filter_name, CATALOG[preferred].model):
        return preferred
    return next(name for name, entry in CATALOG.items() if fits(filter_name, entry.model))


def misfit(filter_name: str, model: str) -> str | None:
    """None if the pair runs; else what to change, naming the allowed choices."""
    entry = CATALOG[model]
    if fits(filter_name, entry.model):
        return None
    if entry.restricts_filters:
        return (f"filter '{filter_name}' and model '{model}' do not fit: use filter '{entry.default_filter}' "
                f"(model '{model}' runs with {', '.join(entry.filters)})")
    models = [name for name, other in CATALOG.items() if fits(filter_name, other.model)]
    return (f"filter '{filter_name}' and model '{model}' do not fit: use model '{models[0]}' "
            f"(filter '{filter_name}' runs on {', '.join(models)})")


def states_of(entry: ModelEntry) -> tuple:
    """The states a model publishes: the output states and those its binding adds (forces, frictions)."""
    return OUTPUT_STATES + tuple(entry.estimator.extra_states)


def losses(mapped) -> list:
    """What each input group not (fully) in ``mapped`` costs, one line per group: the models and filters of the
    catalog that need it, what models that use it when mapped take instead, and the states that are then not
    estimated (none lost: an empty list); first, how each input the estimator derives is derived."""
    derived = derived_inputs(mapped)
    lines = list(derived.values())
    for group, inputs in INPUT_GROUPS.items():
        missing = unmet(inputs, mapped)
        if not missing:
            continue
        models = [name for name, entry in CATALOG.items() if set(missing) & set(entry.required_inputs)]
        filters = sorted({(filter_name, name) for name, entry in CATALOG.items() if name not in models
                          for filter_name in entry.filters if set(missing) & set(entry.inputs_for(filter_name))})
        left = [CATALOG[name] for name in CATALOG if name not in models]
        lost = list(dict.fromkeys(state for name in models for state in states_of(CATALOG[name])
                                  if not any(state in states_of(entry) for entry in left)))
        costs = []
        if models:
            costs.append(("no model runs" if not left else f"model {', '.join(models)} unavailable"))
        if filters:
            costs.append(f"filter {', '.join(f'{f} (on {m})' for f, m in filters)} unavailable")
        costs += [f"model {name}: {entry.optional_groups[group]}" for name, entry in CATALOG.items()
                  if group in entry.optional_groups]
        costs.append(f"{', '.join(lost)} not estimated" if lost else "every state still estimated")
        lines.append(f"no {group} ({', '.join(missing)}): {'; '.join(costs)}")
    return lines


def make_estimator(config):
    """The estimator of the configured model."""
    return CATALOG[config.estimator.model].estimator(config)
