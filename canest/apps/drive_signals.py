"""A logged drive as arrays on a regular grid: what ``canest calibrate`` fits the single-track model to.

The log is decoded and held exactly as the daemon does it (:class:`canest.codec.decode.InputDecoder`,
:class:`canest.resample.Resampler` on the :class:`canest.resample.TickClock` grid at ``STEP`` s), so the
calibration sees the signals in the config's SI units, offsets applied. A tick where any input the fit needs
is stale or saturated, or the car drives slower than ``MIN_SPEED``, is left out; the fit restarts its model
after every such gap (``starts``). The second gyro's yaw rate, where mapped, rides along (NaN where it is stale
or saturated): :mod:`canest.models.second_gyro` gives its bias.
"""
from __future__ import annotations

import logging
import math

from canest.codec.decode import InputDecoder
from canest.errors import ConfigError, LogError
from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs
from canest.estimation.leveling import AccelerometerLeveling
from canest.estimation.reference_speed import TORQUES, slip_free_speed, tick_usage
from canest.io.logfiles import open_log
from canest.models.output_error import MIN_SEGMENT, MIN_SPEED, STEP, Drive, DriveRows
from canest.models.wheels import WheelGeometry
from canest.params import VehicleParams
from canest.resample import Resampler, TickClock
from canest.settings import Config

NEEDED = ("steering_wheel_angle", "yaw_rate", "ay", *WHEEL_SPEEDS)
LOG = logging.getLogger("canest.calibrate")


def check_signals(config: Config) -> None:
    """The inputs the fit needs are mapped, else one line naming the config and what to add."""
    missing = [name for name in NEEDED if name not in config.signals]
    if missing:
        raise ConfigError(f"{config.path}: input.signals: calibration needs {', '.join(missing)}; map them")


def wheel_speed(inputs: TickInputs, geometry: WheelGeometry, vehicle: VehicleParams) -> float:
    """The four wheels' mean speed, without the slip their motors' torques need where all four are in (as the
    estimator's reference speed takes it: the radius is then fitted to the same speed the estimator uses); else the
    plain mean (the estimator's reference takes out the slip the drive layout gives ax, which in steady driving,
    where the fit's ticks are, is none)."""
    if not inputs.has(*TORQUES):
        return inputs.wheel_speed(vehicle.wheel_radius)
    return slip_free_speed([inputs.values[name] for name in WHEEL_SPEEDS],
                           tick_usage(inputs, geometry, vehicle), vehicle.wheel_radius,
                           vehicle.tire.longitudinal_stiffness)


def read_drive(config: Config, path, log_format=None, log_channel=None) -> Drive:
    """The log's usable ticks; a LogError (65) naming the log when it holds too little driving to fit.
    What the reader could not read is a warning naming the log, as in a replay."""
    decoder = InputDecoder(config)
    resampler = Resampler(config.signals, decoder.timeouts(config.estimator.timeout_cycles))
    leveling = AccelerometerLeveling(config.vehicle, resampler.names)
    clock = TickClock(STEP)
    geometry = WheelGeometry(config.vehicle)
    rows = DriveRows()
    source = open_log(path, log_format, log_channel)
    frames = iter(source)
    try:
        for msg in frames:
            for tick in clock.due(msg.timestamp):
                inputs = TickInputs(leveling.level(resampler.sample(tick)))
                if inputs.has(*NEEDED):
                    rows.add(tick, *(inputs.values[name] for name in NEEDED[:3]),
                             wheel_speed(inputs, geometry, config.vehicle),
                             inputs.values["yaw_rate_2"] if inputs.has("yaw_rate_2") else math.nan)
            values = decoder.decode(msg)
            for name, value in values or ():
                resampler.hold(name, value, msg.timestamp, name in decoder.last_saturated)
    finally:
        frames.close()
        source.stop()
    for warning in source.warnings():
        LOG.warning(warning)
    drive = rows.drive(path)
    if drive.seconds < 2 * MIN_SEGMENT:
        raise LogError(f"{path}: {drive.seconds:.1f} s of usable driving (all of steering, yaw rate, ay and "
                       f"the four wheel speeds, above {MIN_SPEED:g} m/s); calibration needs at least "
                       f"{2 * MIN_SEGMENT:g} s, better a minute of bends and straights")
    return drive
