"""The per-tick core: one filter step per tick, whatever the model.

Per tick (:meth:`Estimator.step`, handed the resampler's sample):

1. read the held inputs (zero-order hold, stale and fresh flags);
2. initialize the filter once wheel speeds and the gyro are present
   (vx from the wheels, yaw rate from the gyro, sideslip 0; the model's
   binding sets its other states);
3. choose the mode: ``low_speed`` below ``min_speed`` (left again above
   ``min_speed + speed_hysteresis``) or when reversing, else ``normal``;
4. predict with the model (its low-speed transition at low speed);
5. judge every fresh channel against the prior under the noise the filter takes
   (friction's: the configured; :mod:`canest.estimation.validity`), then update with them
   (:mod:`canest.estimation.channels`): the lateral ones (ay, ax) only while
   the lateral model holds, an accelerometer channel's noise never below
   what its samples show (:mod:`canest.estimation.measured_noise`: a
   vibrating body);
6. publish values, standard deviations (covering the model's error) and
   validity with its cause. A non-finite state or covariance, or a diverging
   filter, resets it (counted in ``resets``).

Divergence test: divergence means the states the car measures directly have
left their sensors, not that the lateral model is out of its regime. Over a
full window (:data:`canest.estimation.validity.WINDOW` samples) the mean
normalized innovation squared of the gyro channel or of the speed channel,
under the configured noise, must stay below ``DIVERGENCE_NIS`` (a consistent
filter averages 1); above it the filter is reset and sideslip stays invalid
(mode ``degraded``) for ``DIVERGENCE_HOLD`` s. The lateral channels (ay) judge
sideslip's validity but never reset the filter: the whole filter's NIS reset
it 70 times on a real drive of healthy hard cornering, where only the linear
tires' error grew.

A model binds to the core by a subclass (one per model, named in the model
catalog) overriding the hooks ``_initial_state``, ``_control``, ``_derived``,
``_update`` and ``_extra_values``.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import replace

import numpy as np

from canest.estimation import channels as ch
from canest.estimation import validity
from canest.estimation.derived_ax import derived_ax
from canest.estimation.estimate import OUTPUT_STATES, Estimate
from canest.estimation.gyro_hold import GyroHold
from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs
from canest.estimation.judge import DIVERGENCE_NIS, StateJudge, lateral_velocity_of, steered_wheels_std
from canest.estimation.measured_noise import MeasuredNoise
from canest.estimation.reference_speed import TORQUES, ReferenceSpeed, tick_usage
from canest.estimation.steering_zero import steering_zero
from canest.filters import Transition, make_filter
from canest.filters.base import central_difference_jacobian
from canest.models.wheel_force import DriveLayout, WheelAcceleration
from canest.models.wheels import WheelGeometry
from canest.settings import Config

GYROS = ("yaw_rate", "yaw_rate_2")  # measurement channels read straight from a gyro
ACCELEROMETERS = ("ax", "ay", "ax_2", "ay_2")  # measurement channels read straight from an accelerometer
LATERAL_ACCELEROMETERS = ("ay", "ay_2")  # their R carries the model's lateral error (estimator.lateral_model_error)

log = logging.getLogger("canest.estimator")

DIVERGENCE_HOLD = 1.0  # s
# s: the densities of ax's and ay's noise, which integrations over seconds take (the reference speed's walk, the
# kinematic sideslip), are read from means over this span (canest.estimation.measured_noise), long enough to see a
# body's vibration as an integration does (the simulator's, correlated over 15 ms: 0.19-0.25 m/s/sqrt(s) read for
# 0.24; over 30 ms spans 0.15-0.17), short enough that a clean drive's own ax reads below vx_from_ax
INTEGRATED_NOISE_SPAN = 0.1
PER_WHEEL_KEYS = {"fy_": "lateral_force", "w_": "wheel_speed", "wheel_speed_": "wheel_speed", "mu_": "friction"}


def noise_key(name: str) -> str:
    """The noise config key of a model state or measurement: the four wheels of a quantity share one key."""
    return next((key for prefix, key in PER_WHEEL_KEYS.items() if name.startswith(prefix)), name)


def transition_of(f, jacobian) -> Transition:
    """A :class:`Transition` with the model's Jacobian, or central differences of ``f`` where it has none."""
    if jacobian is None:
        def jacobian(x, u, dt):
            return central_difference_jacobian(lambda X: f(X, u, dt), x)
    return Transition(f, jacobian)


class Estimator:
    """The model-independent tick logic; a binding subclass names the model and fills the hooks."""

    extra_states: tuple = ()  # published beyond OUTPUT_STATES, each with its _std
    covariance_has_tire_error = False  # its Q carries the tire curve's error above min_speed (:meth:`_publish`)

    def __init__(self, config: Config, model):
        self.config = config
        self.vehicle = config.vehicle
        self.est = config.estimator
        self.model = model
        self.dt = 1.0 / self.est.rate_hz
        names = [noise_key(n) for n in model.state_names]
        driven = [getattr(model, "vx_noise_key", "vx") if name == "vx" else name for name in names]
        self.Q = np.diag(np.array([self.est.process_noise[n] for n in driven]) ** 2 * self.dt)  # per tick
        self.p0 = np.diag(np.array([self.est.initial_std[n] for n in names]) ** 2)
        self.derived_ax = derived_ax(config)
        noise = {**self.est.measurement_noise, **self.derived_ax.noise}
        self.r_std = np.array([noise[noise_key(n)] for n in model.measurement_names])
        self.yaw, self.beta, self.vx = (model.state_names.index(n) for n in ("yaw_rate", "beta", "vx"))
        self.filter = None
        self.low_speed = False
        self.resets = 0
        self.step_times = None  # set to a list to record the CPU seconds (this thread's) of each predict + update
        self.last_mode = "initializing"
        self.suspect_until = -math.inf
        self.transitions = {
            False: transition_of(model.transition, getattr(model, "transition_jacobian", None)),
            True: transition_of(getattr(model, "transition_low_speed", model.transition),
                                getattr(model, "transition_low_speed_jacobian", None)),
        }
        self.latency_compensation = self.est.latency_compensation
        self.judge = StateJudge(model, config.vehicle, self.dt, self.est.gyro_bias_std,
                                self.est.measurement_noise["ay"])
        self.stale_before = self.stale_now = frozenset()  # inputs stale on the previous and on this tick
        self.geometry = WheelGeometry(config.vehicle)
        self.layout = DriveLayout(config.vehicle)  # which wheels ax drives or brakes, for a car without torques
        self.reference_speed = ReferenceSpeed(self.vehicle.wheel_radius, self.vehicle.tire.longitudinal_stiffness,
                                              self._anchored_std(model), self.vehicle.drive_front_share)
        self.reference_wheel_acceleration = WheelAcceleration()
        self.gyro_holds = {row: (name, GyroHold()) for row, name in enumerate(model.measurement_names)
                           if name in GYROS}
        # the sensors' noise as their samples show it, kept through a filter reset (:mod:`measured_noise`)
        self.ax_noise = MeasuredNoise(INTEGRATED_NOISE_SPAN)
        self.ay_noise = MeasuredNoise(INTEGRATED_NOISE_SPAN)
        self.ay_pair_noise = MeasuredNoise(INTEGRATED_NOISE_SPAN)  # both accelerometers' mean (:meth:`_kinematic_ay`)
        self.ay_row = model.measurement_names.index("ay") if "ay" in model.measurement_names else None
        self.input_noise = {name: MeasuredNoise() for name in model.measurement_names
                            if name in ACCELEROMETERS + GYROS}
        self.lateral_rows = [row for row, name in enumerate(model.measurement_names) if name in LATERAL_ACCELEROMETERS]
        self.accelerometer_rows = [(row, self.input_noise[name]) for row, name in enumerate(model.measurement_names)
                                   if name in ACCELEROMETERS]
        self.integrates_ax = getattr(model, "vx_noise_key", "vx") == "vx_from_ax"
        self.steering_zero = steering_zero(config)
        # factors on the configured cornering stiffnesses and their uncertainty in use (:meth:`use_stiffness`)
        self.stiffness = (1.0, 1.0, config.vehicle.cornering_stiffness_uncertainty)

    def use_stiffness(self, front: float, rear: float, error: float | None = None) -> None:
        """Run the model and judge the sideslip with the configured cornering stiffnesses times ``front`` and
        ``rear`` (the online calibration's applied factors); the filter's state is kept.

        ``error`` (relative, :attr:`OnlineCalibration.stiffness_error`; ``None``: nothing learned) takes the place
        of the config's ``cornering_stiffness_uncertainty`` for a model with linear tires, whose term it is: the
        linear stiffness's error, beside the degressive term (:func:`validity.sideslip_model_std`). A model with
        a tire curve keeps the claim: there the same number also stands for the curve's shape, the longitudinal
        slip stiffness and the nominal friction (the forces' process noise, the frictions' stiffness term), none
        of which the learner measures, and on a vibrating IMU 0.05 left jckf's sideslip and dici-gfckf's forces
        valid but wrong (README "How far to trust the output")."""
        p = self.config.vehicle
        uncertainty = error if error is not None and self.judge.linear_tires else p.cornering_stiffness_uncertainty
        if (front, rear, uncertainty) == self.stiffness:  # a tire curve's model is not rebuilt for an unused error
            return
        self.stiffness = (front, rear, uncertainty)
        self.vehicle = replace(p, cornering_stiffness_front=front * p.cornering_stiffness_front,
                               cornering_stiffness_rear=rear * p.cornering_stiffness_rear,
                               cornering_stiffness_uncertainty=uncertainty)
        self.model.use_vehicle(self.vehicle)
        self.judge.use_vehicle(self.vehicle)
        self.steering_zero.use_vehicle(self.vehicle)

    def use_kinematic_offsets(self, ay: float, yaw_rate: float) -> None:
        """The online calibration's learned ay and yaw-rate offsets not applied to the inputs (ay's never, a bank;
        the gyro bias's until it converged), for the kinematic checks (:meth:`StateJudge.use_kinematic_offsets`)."""
        self.judge.use_kinematic_offsets(ay, yaw_rate)

    def use_correction_std(self, speed: float | None, gyro_bias: float | None) -> None:
        """The error of the online calibration's applied wheel-speed scale (relative) and gyro bias (rad/s), which
        the published vx and yaw rate carry (:meth:`StateJudge.use_correction_std`)."""
        self.judge.use_correction_std(speed, gyro_bias)

    def reset(self) -> None:
        """Forget the state: the next tick with inputs initializes a new filter."""
        self.filter = None
        self.judge.reset()
        self.reference_wheel_acceleration.reset()
        for _, hold in self.gyro_holds.values():
            hold.reset()

    def _diverged(self, t: float) -> bool:
        """True when the gyro or the speed channel disagrees with the prior beyond ``DIVERGENCE_NIS``, windowed."""
        worst = self.judge.divergence()
        if worst <= DIVERGENCE_NIS:
            return False
        log.warning("filter diverged (mean NIS %.0f of a directly measured state over %d samples): reset", worst,
                    validity.WINDOW)
        self.suspect_until = t + DIVERGENCE_HOLD
        return True

    def _initial_state(self, inputs: TickInputs) -> np.ndarray:
        """Yaw rate from the gyro, vx from the wheels, every other state 0."""
        x0 = np.zeros(len(self.model.state_names))
        x0[self.yaw] = inputs.values["yaw_rate"]
        x0[self.vx] = inputs.wheel_speed(self.vehicle.wheel_radius)
        return x0

    def _start(self, inputs: TickInputs) -> bool:
        if not inputs.has("yaw_rate", *WHEEL_SPEEDS):
            return False
        x0 = self._initial_state(inputs)
        est = self.est
        self.filter = make_filter(est.filter, x0, self.p0, self.model, est.factorization, est.filter_options)
        self.low_speed = x0[self.vx] < self.est.min_speed
        return True

    def _process_noise(self, t: float) -> np.ndarray:
        """Q of the prediction at tick ``t``: the configured one; where vx integrates the measured ax (the model's
        ``vx_noise_key``), vx's never below the measured ax noise's density (:data:`INTEGRATED_NOISE_SPAN`) and enough
        to bring vx's variance up to the random walk of the reference speed the filter took since the wheels last
        anchored it (:meth:`_shared_walk`): its prediction integrates that very ax, so the walk is its error too,
        yet every tick's reference taken as a new measurement had shrunk its variance below it, and an anchor
        could not pull it back (ckf on a vibrating IMU: 0.12 m/s off at the anchors, where the reference was
        0.035 off, with a std of 0.05). The reference channel's std then leaves the walk out (:meth:`_derived`):
        the innovation ``reference - prior`` cancels it, and the posterior keeps it whole, so the covariance
        after the update holds the error beside the walk, and the published std adds the walk in quadrature
        (:meth:`StateJudge.widen`). Only ever added to the diagonal: Q stays positive semidefinite. A binding
        whose model error scales with its state adds to this one."""
        if not self.integrates_ax:
            return self.Q
        Q = self.Q.copy()
        density = self.ax_noise.density
        if density is not None:
            Q[self.vx, self.vx] = max(Q[self.vx, self.vx], density * self.dt)
        Q[self.vx, self.vx] = max(Q[self.vx, self.vx], self._shared_walk(t) ** 2 - self.filter.P[self.vx, self.vx])
        return Q

    def _shared_walk(self, t: float) -> float:
        """The reference speed's random walk (m/s) at its update on the tick before ``t`` (0 without one there: ax
        missing, a gap; while the wheels are missing it integrates ax on), at ax's noise density as measured
        now: in the first half second nothing is measured yet, and a vibrating ax had walked the reference 0.4
        m/s off unseen (the small vibrating grid's ckf: vx 0.41 m/s off with a std of 0.033 when the wheels
        anchored it)."""
        previous = self.reference_speed.last_t
        if previous is None or not 0.0 < t - previous <= 1.5 * self.dt:
            return 0.0
        return self.reference_speed.integration_std(previous, self.ax_noise.density or 0.0)

    def _anchored_std(self, model) -> float:
        """The reference speed's std while the wheels anchor it: the wheel-speed mean's noise (``vx_wheel``) where the
        model measures vx by it, ``vx_reference``'s where the model measures each wheel itself beside the reference
        (the two-track model): there the reference is those wheels read a second time, and at the wheels' own
        noise it counted their errors twice (jckf's vx on the honesty grid: RMSE 0.026 -> 0.032 m/s, within 2 std
        98.1 -> 86.7 %, with ``vx_reference`` 0.05 -> 0.018)."""
        name = "vx_reference" if "vx_reference" in model.measurement_names else "vx_wheel"
        return self.est.measurement_noise[name]

    def _road_wheel_angle(self, inputs: TickInputs) -> float:
        return self.steering_zero.angle(inputs) / self.vehicle.steering_ratio

    def _control(self, inputs: TickInputs, t: float) -> np.ndarray:
        """The model input ``u`` of this tick."""
        raise NotImplementedError

    def _choose_mode(self) -> None:
        vx = self.filter.x[self.vx]
        if self.low_speed:
            self.low_speed = vx < self.est.min_speed + self.est.speed_hysteresis
        else:
            self.low_speed = vx < self.est.min_speed

    def _reference_speed(self, inputs: TickInputs, t: float):
        """(speed, std) of the slip-aware reference speed (:mod:`canest.estimation.reference_speed`), or None
        without wheel speeds and ax (without the wheels alone it integrates ax on, :meth:`ReferenceSpeed.coast`).
        Motor torques, where mapped, tell which wheels transmit force, else ax and the drive layout."""
        if not inputs.has("ax"):
            return None
        beta, vx, yaw_rate = self.filter.x[self.beta], self.filter.x[self.vx], inputs.current("yaw_rate")
        vy = vx * math.tan(beta)
        acceleration = inputs.current("ax") + yaw_rate * vy
        if not inputs.has(*WHEEL_SPEEDS):  # the speed the wheels left, integrated until they are back
            self.reference_speed.coast(t, acceleration, self.ax_noise.density or 0.0)
            return None
        speeds = [inputs.values[name] for name in WHEEL_SPEEDS]
        usage = tick_usage(inputs, self.geometry, self.vehicle, self.layout)
        accelerations = self.reference_wheel_acceleration.update(t, speeds).tolist()
        delta = self._road_wheel_angle(inputs)
        front_excess = vx * (math.cos(delta) - 1.0) + (vy + self.vehicle.cg_to_front * yaw_rate) * math.sin(delta)
        return self.reference_speed.update(t, acceleration, speeds, accelerations, usage, front_excess,
                                           self.ax_noise.density, inputs.has(*TORQUES), vx * yaw_rate)

    def _derived(self, inputs: TickInputs, t: float, lateral_ok: bool) -> dict:
        """Channels computed from the inputs this tick: name -> (value, standard deviation, age).

        Here ``vx_wheel``, for models that measure it: the reference speed (wheels while they roll
        freely, else integrated ax), so vx never follows spinning or locked wheels; the plain
        wheel mean where ax is missing. Its std less the ax noise's walk where the model integrates ax (the
        prior holds it, :meth:`_process_noise`)."""
        if "vx_wheel" not in self.model.measurement_names:
            return {}
        reference = self._reference_speed(inputs, t)
        if not (inputs.has(*WHEEL_SPEEDS) and inputs.any_fresh(*WHEEL_SPEEDS)):
            return {}
        age = sum(inputs.ages[w] for w in WHEEL_SPEEDS) / len(WHEEL_SPEEDS)
        speed, std = reference or (inputs.wheel_speed(self.vehicle.wheel_radius), self.est.measurement_noise["vx_wheel"])
        if reference and self.integrates_ax:  # the walk is in the prior (:meth:`_process_noise`), not beside it
            std = math.sqrt(max(std**2 - self.reference_speed.integration_std(t) ** 2, 0.0))
        return {"vx_wheel": (speed, max(std, self.est.measurement_noise["vx_wheel"]), age)}

    def _channels(self, inputs: TickInputs, t: float, lateral_ok: bool) -> ch.Channels:
        derived = self._derived(inputs, t, lateral_ok)
        for row, (name, hold) in self.gyro_holds.items():  # a fresh gyro sample at the tick, not as held
            if inputs.has(name) and inputs.any_fresh(name):
                derived.setdefault(name, (hold.at(t, inputs.values[name], inputs.ages[name]), self.r_std[row], 0.0))
        channels = ch.assemble(self.model.measurement_names, self.r_std, inputs, derived, lateral_ok)
        return ch.with_lateral_model_error(channels, self.lateral_rows, self.est.lateral_model_error)

    def _apply(self, channels: ch.Channels, u: np.ndarray, t: float, mask=None) -> bool:
        """One measurement update with the usable channels (within ``mask``); True if the filter has diverged."""
        use = channels.mask if mask is None else channels.mask & mask
        if not use.any():
            return False
        compensate = self.latency_compensation and not self.low_speed
        z, measurement, R = ch.rows_of(channels, self.model, compensate, use)
        self.filter.update(z, measurement, u, R)
        return self._diverged(t)

    def _update(self, channels: ch.Channels, inputs: TickInputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        """Measurement update with the fresh samples; True if the filter has diverged."""
        return self._apply(channels, u, t)

    def step(self, sample) -> Estimate:
        """One tick on the resampler's ``sample``."""
        t = sample.t
        inputs = TickInputs(sample)
        self.derived_ax.add_to(inputs)
        for name, noise in (("ax", self.ax_noise), ("ay", self.ay_noise), *self.input_noise.items()):
            if inputs.has(name) and inputs.fresh[name]:
                noise.add(t - inputs.ages[name], inputs.values[name])
        if inputs.has("ay", "ay_2") and inputs.any_fresh("ay", "ay_2"):
            self.ay_pair_noise.add(t, 0.5 * (inputs.values["ay"] + inputs.values["ay_2"]))
        self.stale_before, self.stale_now = self.stale_now, frozenset(n for n, stale in inputs.stale.items() if stale)
        missing = inputs.missing_groups()
        if not inputs.any_present():
            self.reset()  # nothing to estimate from: restart cleanly when inputs return, do not extrapolate
            return self._publish(t, "no_input", missing, inputs)
        if self.filter is None and not self._start(inputs):
            return self._publish(t, "initializing", missing, inputs)
        self._choose_mode()
        u = self._control(inputs, t)
        started = time.thread_time() if self.step_times is not None else 0.0
        self.filter.predict(self.transitions[self.low_speed], u, self.dt, self._process_noise(t))
        lateral_ok = not self.low_speed and inputs.has("steering_wheel_angle", "ay")
        channels = self._channels(inputs, t, lateral_ok)
        measured = self._measured(channels)
        self.judge.record(channels, measured.std, self._judged_std(measured, inputs), u, self.filter.x.copy(),
                          self.filter.covariance.copy(), self.stale_before)
        diverged = self._update(measured, inputs, u, lateral_ok, t)
        if self.step_times is not None:
            self.step_times.append(time.thread_time() - started)
        finite = all(np.all(np.isfinite(a)) for a in (self.filter.x, self.filter.P, self.filter.covariance))
        if diverged or not finite:
            self.suspect_until = max(self.suspect_until, t + DIVERGENCE_HOLD)
            self.resets += 1
            self.reset()
            self._start(inputs)  # restart from the measurements at once, so vx and yaw rate stay published
            return self._publish(t, "degraded", missing, inputs)
        lateral_ok = lateral_ok and t >= self.suspect_until
        if self.low_speed:
            mode = "low_speed"
        elif not lateral_ok:
            mode = "degraded"
        else:
            mode = "normal"
        return self._publish(t, mode, missing, inputs, lateral_ok)

    def _extra_values(self, values: dict, valid: dict, causes: dict, std: np.ndarray, inputs: TickInputs,
                      ratios: dict) -> None:
        """Add model-specific values, ``_std``, validity and causes (none for the single-track model); ``ratios``:
        this tick's consistency ratio per state (:meth:`StateJudge.ratios`)."""

    def _at_limit_of_unbounded_friction(self) -> bool:
        """A tire works at its limit at an estimated friction whose error no covariance bounds (the sideslip
        rests on it: :meth:`canest.estimation.judge.StateJudge.causes`); never for a model without frictions."""
        return False

    def _frictions_pressed(self) -> bool:
        """The last update pressed a friction the sideslip rests on against its physical range: the model cannot
        explain the data, and the sideslip is ``at_bound`` (:meth:`canest.estimation.judge.StateJudge.causes`;
        :meth:`canest.estimation.two_track.FrictionEstimator._frictions_pressed`); never for a model without
        frictions."""
        return False

    def _covariance_holds_stiffness_error(self) -> bool:
        """The filter's covariance already holds what a cornering stiffness off by its uncertainty does to the
        sideslip, which then takes no stiffness term (:func:`validity.sideslip_model_std`); only where frictions are
        estimated in that covariance (:meth:`canest.estimation.two_track.FrictionEstimator._covariance_holds_stiffness_error`)."""
        return False

    def _sideslip_saturation_std(self) -> float:
        """The sideslip's std (rad) from tire saturation the measurements have not shown (none for a model without
        frictions: :meth:`canest.estimation.two_track.FrictionEstimator._sideslip_saturation_std`)."""
        return 0.0

    def _sideslip_friction_std(self) -> float:
        """The sideslip's std (rad) from the frictions' error near the tires' peak (none for a model without
        frictions: :meth:`canest.estimation.two_track.FrictionEstimator._friction_slip`). Published, and left out of
        vx's lateral drift (:meth:`_publish`)."""
        return 0.0

    def _rear_slip(self, x: np.ndarray) -> float:
        """The rear wheels' mean slip angle (rad) at the estimate ``x`` (they do not steer: any road wheel angle)."""
        vx = x[self.vx]
        v_long, v_lat = self.geometry.wheel_velocities(np.array([x[self.yaw]]), np.array([vx]),
                                                       np.array([vx * math.tan(x[self.beta])]), 0.0)
        return float(self.geometry.slip_angles(v_long, v_lat)[0, 2:].mean())

    def _measured(self, channels: ch.Channels) -> ch.Channels:
        """The channels as the filter takes them: an accelerometer channel's std never below its noise as its samples
        show it (:mod:`canest.estimation.measured_noise`); the consistency test takes them too, except friction's
        (:meth:`canest.estimation.judge.StateJudge.record`)."""
        std = channels.std.copy()
        for row, noise in self.accelerometer_rows:
            measured = noise.std
            if measured is not None:
                std[row] = max(std[row], measured)
        return ch.Channels(channels.mask, channels.z, std, channels.ages)

    def _held_gyro_noise(self, inputs: TickInputs) -> dict:
        """Per present gyro row whose noise is measured, the noise its value at the tick carries (rad/s): its measured
        noise (:mod:`canest.estimation.measured_noise`) times its hold's factor (:meth:`GyroHold.noise_factor`: the
        sample brought forward along a slope whose noise leans on that sample; 1.12 at 5 ms, 1.19 at 8 ms)."""
        held = {}
        for row, (name, hold) in self.gyro_holds.items():
            measured = self.input_noise[name].std
            if measured is not None and inputs.has(name):
                held[row] = measured * hold.noise_factor(inputs.ages[name])
        return held

    def _judged_std(self, channels: ch.Channels, inputs: TickInputs) -> np.ndarray:
        """The noise the yaw rate's consistency test judges each channel under
        (:meth:`canest.estimation.judge.StateJudge.record`): what the filter takes (``channels``), and a gyro's as
        its value at the tick carries it, never below the configured (:meth:`_held_gyro_noise`)."""
        std = channels.std.copy()
        for row, held in self._held_gyro_noise(inputs).items():
            std[row] = max(std[row], held)
        return std

    def _gyro_noise(self, inputs: TickInputs) -> float:
        """The largest ratio of a present gyro's noise as its value at the tick carries it (:meth:`_held_gyro_noise`)
        to the noise the filter's published covariance took for it (1 while none is measured): the configured one,
        or an adaptive filter's learned R where larger (``noise_taken``, :mod:`canest.filters.adaptive`), which
        holds a vibrating gyro already. Over the configured noise, lmrwekf's yaw rate counted the vibration twice:
        on the drawn cars with a vibrating IMU within 2 std on 99.8 % of its valid ticks, NEES 0.31 (now 98.7 %,
        0.60; svd-fckf's 97.8 % / 0.68 -> 97.6 % / 0.74, the other filters' unchanged).

        The largest, not the two gyros' average as a filter weighing them by their configured noise would take
        it: the filters weigh them otherwise (svd-fckf by its adapted R, dici-gfckf by covariance intersection),
        and with the average their yaw rate on the drawn cars with a vibrating IMU was valid but wrong on 0.20 and
        0.12 % of the ticks (0.07 and 0.08 % with the largest; ckf's within 2 std on 98.4 instead of 99.0 %)."""
        return max((held / math.sqrt(self.filter.noise_taken(row, self.r_std[row] ** 2))
                    for row, held in self._held_gyro_noise(inputs).items()), default=1.0)

    def _ay_noise_known(self, inputs: TickInputs) -> bool:
        """ay, which every filter's lateral update takes, has its noise measured from its samples
        (:mod:`canest.estimation.measured_noise`), or is not sent (a second IMU's ay, which only dici-gfckf takes,
        is left out: a flaky one would hold back a sideslip that never reads it)."""
        noise = self.input_noise.get("ay")
        return noise is None or not inputs.has("ay") or noise.std is not None

    def _ay_density(self, inputs: TickInputs) -> float:
        """ay's noise density as its samples show it over :data:`INTEGRATED_NOISE_SPAN`, where its noise is above the
        configured at this ay (0 until then, and for a quiet ay: the kinematic check's tolerance is set for it,
        and spans of 0.1 s read part of a quiet drive's own ay as noise; taken, they let dici-gfckf's sideslip on a
        drawn car be valid but wrong on 0.3 % of its ticks). "Configured at this ay" is the channel's std with the
        model's error (:func:`canest.estimation.channels.lateral_std`): what those spans read beyond a quiet
        sensor's noise is mostly a bend's own ay (0.13 m/s^2 in the spin of the DLC on 0.35 on a quiet IMU)."""
        noise = self.input_noise.get("ay")
        loud = noise is not None and noise.std is not None and noise.std > ch.lateral_std(
            self.r_std[self.ay_row], self.est.lateral_model_error, inputs.values["ay"])
        return (self.ay_noise.density or 0.0) if loud else 0.0

    def _kinematic_ay(self, inputs: TickInputs) -> tuple:
        """The lateral acceleration the kinematic sideslip identity integrates (:class:`validity.KinematicCheck`,
        :class:`validity.LateralDrift`) and its noise density as :meth:`_ay_density` gives it: ``(None, density)``
        for the input's ay, or the two accelerometers' mean and the density read from that mean's own samples,
        where ay is louder than configured and the mean is quieter than ay. Two accelerometers on one body read
        one ay; their vibrations may be correlated (a real body shakes both) or not (the simulator draws them
        apart), and the mean's density, read like ay's (:mod:`canest.estimation.measured_noise`, no model), holds
        whichever is true: it never assumes the independence that would make it ``1/2`` of the pair's mean
        density. A vibrating ay (1.4 m/s^2) left the check a noise gate of 0.82 of its 1.26 deg tolerance in the
        onset of a slide on 0.35, where dici-gfckf's sideslip was 1.3-1.9 deg off with a std of 0.36, flagged
        valid."""
        density = self._ay_density(inputs)
        pair = self.ay_pair_noise.density
        if density and inputs.has("ay_2") and pair is not None and pair < density:
            return 0.5 * (inputs.values["ay"] + inputs.values["ay_2"]), pair
        return None, density

    def _publish(self, t, mode, missing, inputs: TickInputs, lateral_ok: bool = False) -> Estimate:
        self.last_mode = mode
        if self.filter is None:
            names = OUTPUT_STATES + self.extra_states
            values = {name: math.nan for name in names}
            values.update({f"{name}_std": math.nan for name in names})
            cause = "no_input" if mode == "no_input" else "initializing"
            return Estimate(t, values, {}, mode, self.est.filter, missing=missing, resets=self.resets,
                            causes={name: cause for name in validity.GROUPS})
        # The sideslip's model error (a cornering stiffness off by its uncertainty) enters vx's drift bound always:
        # integrated over seconds it is systematic, which a process noise relaxing within a tire's relaxation
        # length does not carry. Where the covariance has that noise (the tire-force model's), the sideslip's std
        # is never below the term: the covariance holds the error as the relaxing noise, whose steady states average
        # out, and a car whose stiffness is off holds it steadily (dici-gfckf's sideslip on drawn cars with a
        # vibrating IMU was valid but wrong on 3.1 % of its valid ticks, 1.2 deg off in a step steer with a std of
        # 0.36: 0.97 % as a floor, nearly all in a slide's onset on 0.35). Added in quadrature to that covariance it
        # counted the error twice (on the quiet drawn cars NEES 0.48, as a floor 0.57, neither 0.94).
        x = self.filter.x
        ratios = self.judge.ratios()
        index = {"yaw_rate": self.yaw, "vx": self.vx, "beta": self.beta}
        vx, beta = x[self.vx], x[self.beta]
        reference = self.reference_speed  # vx is measured unless the reference integrated ax this tick
        std = covariance_std = np.sqrt(np.maximum(np.diag(self.filter.covariance), 0.0))
        if self._covariance_holds_stiffness_error():
            stiffness_std = 0.0
        else:
            rear_slip = None if self.judge.linear_tires else self._rear_slip(x)  # linear tires: the ay term
            stiffness_std = self.judge.sideslip_model_std(vx * x[self.yaw], rear_slip)
        offset_std = self.judge.sideslip_offset_std()  # a learned ay offset not applied: no model's Q holds it
        beta_model_std = math.hypot(stiffness_std, offset_std, self._sideslip_saturation_std())
        kinematic_ay, ay_density = self._kinematic_ay(inputs)
        drift = self.judge.drift(inputs, vx, beta, math.hypot(std[self.beta], beta_model_std),
                                 reference.last_t != t or reference.anchored_at == t, ay_density, kinematic_ay)
        carried = self.covariance_has_tire_error and not self.low_speed  # the model's Q has the tire error
        # vx driven by the wheels' forces can leave the reference; one integrating ax shares its integration (ax and
        # r vy alike), and their difference tells nothing
        lateral_std = self.judge.lateral_std(drift)
        gap = 0.0 if self.integrates_ax else reference.disagreement(t, vx, lateral_std)
        # the frictions' error near the peak is published, not integrated into vx's drift bound: there it took jckf's
        # vx valid share on the drawn cars 92.5 -> 84.7 % while vx stayed within 2 std on 99 % of its ticks either way
        published_model_std = math.hypot(offset_std if carried else beta_model_std, self._sideslip_friction_std())
        std = self.judge.widen(std, index, ratios, published_model_std, lateral_std,
                               self._gyro_noise(inputs), reference.integration_std(t),
                               self.integrates_ax and reference.wheels_t == t, gap, vx,
                               beta_model_std if carried else 0.0)
        delta = self._road_wheel_angle(inputs)
        beyond_covariance = math.sqrt(max(std[self.beta] ** 2 - covariance_std[self.beta] ** 2, 0.0))
        std[self.vx] = math.hypot(std[self.vx], steered_wheels_std(
            delta, self.judge.lateral_velocity_std(vx, beta, beyond_covariance)))
        values = {
            "vx": vx, "vy": vx * math.tan(beta), "beta": beta, "yaw_rate": x[self.yaw],
            "vx_std": std[self.vx], "vy_std": math.hypot(lateral_velocity_of(vx, beta, std[self.beta]),
                                                         math.tan(beta) * std[self.vx]),
            "beta_std": std[self.beta], "yaw_rate_std": std[self.yaw],
        }
        lateral = {"low_speed": mode == "low_speed", "after_reset": mode == "degraded" and t < self.suspect_until,
                   "zero_learned": self.steering_zero.learned, "ay_noise_known": self._ay_noise_known(inputs),
                   "lateral_ok": lateral_ok, "beta": beta, "vx": vx,
                   "delta": delta, "ay_density": ay_density, "kinematic_ay": kinematic_ay,
                   "at_limit_of_unbounded_friction": self._at_limit_of_unbounded_friction(),
                   "frictions_pressed": self._frictions_pressed()}
        walk_unknown = self.ax_noise.density is None and reference.last_t == t
        causes = self.judge.causes(inputs, ratios, std[self.vx], lateral, t, drift, walk_unknown)
        valid = {name: causes[name] == "valid" for name in causes}
        # vy = vx tan(beta) holds vx's std in its own (tan(beta) vx_std): a vx only "uncertain" (a wide std, such as
        # an unlearned wheel radius's) leaves vy valid; a vx that is wrong, missing or saturated does not
        valid["vy"] = valid["beta"] and causes["vx"] in ("valid", "uncertain")
        self._extra_values(values, valid, causes, std, inputs, ratios)
        return Estimate(t, values, valid, mode, self.est.filter, self.filter.nis, missing, self.resets, causes)
