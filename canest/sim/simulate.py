"""Drive the plant through a maneuver and produce CAN frames plus the truth.

The plant integrates at ``PLANT_DT``; the driver acts every ``CONTROL_DT``;
every mapped input message is sent at its cycle time (the config's
``cycle_time``, else the DBC's ``GenMsgCycleTime``) with a random phase,
encoded through the config's signal map; the truth is sampled every ``TRUTH_DT``. Times are seconds on the log's clock, starting at
``start_time``.
"""
from __future__ import annotations

import csv
import heapq
import math
from dataclasses import dataclass

import can
import numpy as np

from canest.codec.encode import InputEncoder
from canest.errors import SimulationError
from canest.settings import Config
from canest.models.attitude import per_si, tilted_reading
from canest.signals import WHEELS
from canest.sim.maneuvers import Driver, make_maneuver
from canest.sim.mismatch import PlantMismatch, true_vehicle
from canest.sim.plant import PSI, R, VX, VY, W, X, Y, TwoTrackPlant
from canest.sim.sensors import SensorModel
from canest.sim.wind import PRESSURE_CENTRE, Crosswind

PLANT_DT = 0.001
CONTROL_DT = 0.01
TRUTH_DT = 0.01
DEFAULT_CYCLE = 0.01

TRUTH_COLUMNS = ("t", "vx", "vy", "beta", "yaw_rate", "ax", "ay", "delta", "steering_wheel_angle",
                 *(f"{q}_{w}" for q in ("fx", "fy", "fz", "mu", "alpha", "kappa", "w", "torque") for w in WHEELS))


@dataclass
class Simulation:
    frames: list  # can.Message, in time order
    truth: dict  # column -> np.ndarray, see TRUTH_COLUMNS

    def write_log(self, path) -> None:
        """The frames as a CAN log, its format chosen by python-can from the suffix."""
        with can.Logger(str(path)) as writer:
            for frame in self.frames:
                writer.on_message_received(frame)

    def write_truth(self, path) -> None:
        """The truth as a CSV with a header of TRUTH_COLUMNS."""
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(list(self.truth))
            writer.writerows(zip(*self.truth.values()))


def _true_inputs(state, outputs, swa, torque, tilt) -> dict:
    """What perfect sensors read: the accelerometers on the body, tilted with its ``tilt`` (pitch and roll
    gradients, rad per m/s^2)."""
    ax, ay = tilted_reading(outputs.ax, tilt[0]), tilted_reading(outputs.ay, tilt[1])
    values = {"steering_wheel_angle": swa, "ax": ax, "ay": ay, "yaw_rate": state[R],
              "ax_2": ax, "ay_2": ay, "yaw_rate_2": state[R]}
    for i, w in enumerate(WHEELS):
        values[f"wheel_speed_{w}"] = state[W][i]
        values[f"motor_torque_{w}"] = torque[i]
    return values


def simulate(config: Config, maneuver: str, speed_kmh: float, mu, *, duration=None, amplitude_deg=None,
             seed: int = 0, noise_scale: float = 1.0, outliers: float = 0.0, start_time: float = 0.0,
             channel: str = "vcan0", progress=None, mu_jump=None, vibration: float = 0.0,
             mismatch: PlantMismatch = PlantMismatch(), crosswind: float = 0.0) -> Simulation:
    """Simulate one run; ``mu`` is a scalar or four per-wheel friction coefficients.

    ``mismatch``: how the simulated car differs from ``config`` (:mod:`canest.sim.mismatch`); the frames are
    encoded through ``config``, so a replay with it runs on a wrong config.

    ``mu_jump = (t, mu)``: the road's friction changes to ``mu`` (scalar or four) at ``t`` s into the run (a
    SimulationError if the drive is over by then).
    ``vibration``: scale of the IMU's body vibration and road spikes (:mod:`canest.sim.sensors`; 0 none).
    ``crosswind``: scale of the gusts' side force (:mod:`canest.sim.wind`; 0 none, 1 a gusty day's).
    """
    rng = np.random.default_rng(seed)
    speed = speed_kmh / 3.6
    plan = make_maneuver(maneuver, speed, amplitude_deg, duration, seed)
    if mu_jump is not None and not 0.0 <= mu_jump[0] < plan.duration:  # it would never happen
        raise SimulationError(f"--mu-jump: the friction jump at {mu_jump[0]:g} s is not within the drive's "
                              f"{plan.duration:g} s: jump earlier or drive longer (--duration)")
    vehicle = true_vehicle(config.vehicle, mismatch)
    plant = TwoTrackPlant(vehicle, mu, mismatch.tire(), mismatch.bank_acceleration, mismatch.grade_acceleration,
                          PRESSURE_CENTRE)
    wind = Crosswind(seed, crosswind, PLANT_DT)
    tilt = (per_si(vehicle.accelerometer_pitch_gradient), per_si(vehicle.accelerometer_roll_gradient))
    driver = Driver(vehicle, plan, speed)
    sensors = SensorModel(rng, noise_scale, outliers, mismatch.sensor_errors(), vibration=vibration)
    encoder = InputEncoder(config)
    state = plant.initial_state(speed)
    state[X] = plan.start_x
    cycles = {fid: plan.checks.cycle_time or (plan.message.cycle_time / 1000.0 if plan.message.cycle_time else
                                             DEFAULT_CYCLE) for fid, plan in encoder.decoder_plans.items()}
    schedule = [(float(rng.uniform(0, cycle)), frame_id, cycle) for frame_id, cycle in cycles.items()]
    heapq.heapify(schedule)
    steps = int(round(plan.duration / PLANT_DT))
    control_every = int(round(CONTROL_DT / PLANT_DT))
    truth_every = int(round(TRUTH_DT / PLANT_DT))
    frames, rows = [], []
    swa, torque = 0.0, np.zeros(4)
    for k in range(steps + 1):
        t = k * PLANT_DT
        if mu_jump is not None and k == int(round(mu_jump[0] / PLANT_DT)):
            plant.mu[:] = mu_jump[1]
        if k % control_every == 0:
            swa = driver.steering_wheel_angle(t, state[X], state[Y], state[PSI], state[VX], CONTROL_DT)
            torque = driver.motor_torques(t, state[VX], state[W], CONTROL_DT)
        delta = swa / vehicle.steering_ratio
        plant.side_force = wind.side_force(state[VX])
        slope, outputs = plant.derivatives(state, delta, torque)
        if k % truth_every == 0:
            rows.append(_truth_row(t + start_time, state, outputs, delta, swa, plant.mu, torque))
        if schedule[0][0] <= t:
            true_values = _true_inputs(state, outputs, swa, torque, tilt)
            while schedule[0][0] <= t:
                due, frame_id, cycle = heapq.heappop(schedule)
                measured = {name: sensors.measure(name, value, t) for name, value in true_values.items()}
                frames.append(encoder.encode(frame_id, measured, start_time + t, channel))
                heapq.heappush(schedule, (due + cycle, frame_id, cycle))
        if not np.all(np.isfinite(state)) or state[VX] < 0.5:
            raise SimulationError(f"the simulated car left the plant's valid range at t={t:.3f} s (vx={state[VX]:.2f} "
                                  "m/s, at least 0.5 m/s and finite): ask for a speed of at least 2 km/h, or a gentler "
                                  "maneuver (--amplitude) or more grip (--mu)")
        state = plant.step(state, delta, torque, PLANT_DT, slope)
        if progress is not None and k % 1000 == 0:
            progress(k / steps)
    truth = {name: np.array([row[i] for row in rows]) for i, name in enumerate(TRUTH_COLUMNS)}
    return Simulation(frames, truth)


def _truth_row(t, state, outputs, delta, swa, mu, torque) -> tuple:
    return (t, state[VX], state[VY], math.atan2(state[VY], state[VX]), state[R], outputs.ax, outputs.ay, delta, swa,
            *outputs.fx, *outputs.fy, *outputs.fz, *mu, *outputs.alpha, *outputs.kappa, *state[W], *torque)
