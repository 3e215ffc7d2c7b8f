"""The per-tick core: one filter step per tick, whatever the model.

Per tick (:meth:`Estimator.step`, handed the resampler's sample):

1. read the held inputs (zero-order hold, stale and fresh flags);
2. initialize the filter once wheel speeds and the gyro are present
   (vx from the wheels, yaw rate from the gyro, sideslip 0; the model's
   binding sets its other states);
3. choose the mode: ``low_speed`` below ``min_speed`` (left again above
   ``min_speed + speed_hysteresis``) or when reversing, else ``normal``;
4. predict with the model (its low-speed transition at low speed);
5. judge every fresh channel against the prior under the configured noise
   (:mod:`canest.estimation.validity`), then update with them
   (:mod:`canest.estimation.channels`): the lateral ones (ay, ax) only while
   the lateral model holds;
6. publish values, standard deviations (covering the model's error) and
   validity with its cause. A non-finite state or covariance, or a diverging
   filter, resets it (counted in ``resets``).

Divergence test: the normalized innovation squared (NIS) of a consistent
filter averages the number of measurements. Over the last
``DIVERGENCE_WINDOW`` updates its mean stays below 3 on every maneuver the
simulator drives within the tires' grip (measured on the single-track model:
0.3 DLC, 1.3 sine 80 km/h, 2.9 sine on mu 0.3) and reaches hundreds when the
car spins and no model can follow. Above ``DIVERGENCE_NIS`` the filter is
reset and sideslip stays invalid (mode ``degraded``) for ``DIVERGENCE_HOLD`` s.

A model binds to the core by a subclass (one per model, named in the model
catalog) overriding the hooks ``_initial_state``, ``_control``, ``_derived``,
``_update`` and ``_extra_values``.
"""
from __future__ import annotations

import logging
import math
import time
from collections import deque

import numpy as np

from canest.estimation import channels as ch
from canest.estimation import validity
from canest.estimation.estimate import OUTPUT_STATES, Estimate
from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs
from canest.estimation.reference_speed import ReferenceSpeed
from canest.estimation.steering_zero import steering_zero
from canest.filters import Transition, make_filter
from canest.filters.base import central_difference_jacobian
from canest.models.wheel_force import WheelAcceleration
from canest.models.wheels import WheelGeometry
from canest.settings import Config
from canest.signals import INPUT_GROUPS

TORQUES = INPUT_GROUPS["motor_torques"]

log = logging.getLogger("canest.estimator")

DIVERGENCE_WINDOW = 50  # updates
DIVERGENCE_NIS = 30.0
DIVERGENCE_HOLD = 1.0  # s
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

    def __init__(self, config: Config, model):
        self.config = config
        self.vehicle = config.vehicle
        self.est = config.estimator
        self.model = model
        self.dt = 1.0 / self.est.rate_hz
        names = [noise_key(n) for n in model.state_names]
        self.Q = np.diag(np.array([self.est.process_noise[n] for n in names]) ** 2 * self.dt)  # per tick
        self.p0 = np.diag(np.array([self.est.initial_std[n] for n in names]) ** 2)
        self.r_std = np.array([self.est.measurement_noise[noise_key(n)] for n in model.measurement_names])
        self.yaw, self.beta, self.vx = (model.state_names.index(n) for n in ("yaw_rate", "beta", "vx"))
        self.filter = None
        self.low_speed = False
        self.resets = 0
        self.step_times = None  # set to a list to record the seconds of each predict + update
        self.last_mode = "initializing"
        self.recent_nis = deque(maxlen=DIVERGENCE_WINDOW)
        self.suspect_until = -math.inf
        self.transitions = {
            False: transition_of(model.transition, getattr(model, "transition_jacobian", None)),
            True: transition_of(getattr(model, "transition_low_speed", model.transition),
                                getattr(model, "transition_low_speed_jacobian", None)),
        }
        self.latency_compensation = self.est.latency_compensation
        self.consistency = validity.Consistency(model.measurement_names)
        self.geometry = WheelGeometry(config.vehicle)
        self.reference_speed = ReferenceSpeed(self.vehicle.wheel_radius, self.vehicle.tire.longitudinal_stiffness,
                                              self.est.measurement_noise["vx_reference"])
        self.reference_wheel_acceleration = WheelAcceleration()
        self.holds = validity.Holds()
        # a model that estimates friction covers saturation itself; the others are judged by the linear regime
        self.regime = None if getattr(model, "parameters", 0) else validity.LinearRegime(config.vehicle, self.dt)
        self.kinematic = validity.KinematicCheck(self.dt)
        self.gyros = [n for n in validity.OBSERVED_BY["yaw_rate"] if n in model.measurement_names]  # the measured ones
        self.steering_zero = steering_zero(config)

    def reset(self) -> None:
        """Forget the state: the next tick with inputs initializes a new filter."""
        self.filter = None
        self.recent_nis.clear()
        self.consistency.reset()
        self.reference_wheel_acceleration.reset()
        self.kinematic.reset()
        if self.regime is not None:
            self.regime.reset()

    def _diverged(self, t: float) -> bool:
        self.recent_nis.append(self.filter.nis)
        mean_nis = sum(self.recent_nis) / DIVERGENCE_WINDOW
        if len(self.recent_nis) < DIVERGENCE_WINDOW or mean_nis <= DIVERGENCE_NIS:
            return False
        log.warning("filter diverged (mean NIS %.0f over %d updates): reset", mean_nis, DIVERGENCE_WINDOW)
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
        without wheel speeds and ax. Motor torques, where mapped, tell which wheels transmit force."""
        if not inputs.has(*WHEEL_SPEEDS, "ax"):
            return None
        speeds = np.array([inputs.values[name] for name in WHEEL_SPEEDS])
        ax, ay = inputs.current("ax"), inputs.current("ay")
        torques = np.array([inputs.values.get(name, 0.0) for name in TORQUES])
        usage = torques / (self.vehicle.wheel_radius * np.maximum(self.geometry.loads(ax, ay), 1.0))
        beta, vx = self.filter.x[self.beta], self.filter.x[self.vx]
        return self.reference_speed.update(t, ax + inputs.current("yaw_rate") * vx * math.tan(beta), speeds,
                                           self.reference_wheel_acceleration.update(t, speeds), usage)

    def _derived(self, inputs: TickInputs, t: float, lateral_ok: bool) -> dict:
        """Channels computed from the inputs this tick: name -> (value, standard deviation, age).

        Here ``vx_wheel``, for models that measure it: the reference speed (wheels while they roll
        freely, else integrated ax), so vx never follows spinning or locked wheels; the plain
        wheel mean where ax is missing."""
        if "vx_wheel" not in self.model.measurement_names:
            return {}
        reference = self._reference_speed(inputs, t)
        if not (inputs.has(*WHEEL_SPEEDS) and inputs.any_fresh(*WHEEL_SPEEDS)):
            return {}
        age = sum(inputs.ages[w] for w in WHEEL_SPEEDS) / len(WHEEL_SPEEDS)
        speed, std = reference or (inputs.wheel_speed(self.vehicle.wheel_radius), self.est.measurement_noise["vx_wheel"])
        return {"vx_wheel": (speed, max(std, self.est.measurement_noise["vx_wheel"]), age)}

    def _channels(self, inputs: TickInputs, t: float, lateral_ok: bool) -> ch.Channels:
        derived = self._derived(inputs, t, lateral_ok)
        return ch.assemble(self.model.measurement_names, self.r_std, inputs, derived, lateral_ok)

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

    def _judge(self, channels: ch.Channels, u: np.ndarray, x_prior: np.ndarray, P_prior: np.ndarray) -> None:
        """Record each usable channel's consistency with the prior under the configured noise."""
        rows = np.flatnonzero(channels.mask)
        if rows.size:
            measurement = ch.rows_measurement(self.model, rows, channels.ages, False)
            d = validity.normalized_innovations(measurement, x_prior, P_prior, u, channels.z[rows], channels.std[rows])
            self.consistency.push(rows, d)

    def step(self, sample) -> Estimate:
        """One tick on the resampler's ``sample``."""
        t = sample.t
        inputs = TickInputs(sample)
        missing = inputs.missing_groups()
        if not inputs.any_present():
            self.reset()  # nothing to estimate from: restart cleanly when inputs return, do not extrapolate
            return self._publish(t, "no_input", missing, inputs)
        if self.filter is None and not self._start(inputs):
            return self._publish(t, "initializing", missing, inputs)
        self._choose_mode()
        u = self._control(inputs, t)
        started = time.perf_counter()
        self.filter.predict(self.transitions[self.low_speed], u, self.dt, self.Q)
        lateral_ok = not self.low_speed and inputs.has("steering_wheel_angle", "ay")
        channels = self._channels(inputs, t, lateral_ok)
        self._judge(channels, u, self.filter.x.copy(), self.filter.P.copy())
        diverged = self._update(channels, inputs, u, lateral_ok, t)
        if self.step_times is not None:
            self.step_times.append(time.perf_counter() - started)
        if diverged or not (np.all(np.isfinite(self.filter.x)) and np.all(np.isfinite(self.filter.P))):
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
                      lateral_ok: bool) -> None:
        """Add model-specific values, ``_std``, validity and causes (none for the single-track model)."""

    def _publish(self, t, mode, missing, inputs: TickInputs, lateral_ok: bool = False) -> Estimate:
        self.last_mode = mode
        if self.filter is None:
            names = OUTPUT_STATES + self.extra_states
            values = {name: math.nan for name in names}
            values.update({f"{name}_std": math.nan for name in names})
            cause = "no_input" if mode == "no_input" else "initializing"
            return Estimate(t, values, {}, mode, self.est.filter, missing=missing, resets=self.resets,
                            causes={name: cause for name in validity.GROUPS})
        x, P = self.filter.x, self.filter.P
        std = np.sqrt(np.maximum(np.diag(P), 0.0))
        ratio = {state: self.consistency.ratio(state) for state in validity.OBSERVED_BY}
        std[self.yaw] *= validity.inflation(ratio["yaw_rate"])
        std[self.vx] *= validity.inflation(ratio["vx"])
        std[self.beta] = math.hypot(std[self.beta] * validity.inflation(ratio["beta"]),
                                    validity.sideslip_model_std(self.vehicle, inputs.current("ay"),
                                                                  getattr(self.model, "linear_tires", False)))
        vx, beta = x[self.vx], x[self.beta]
        values = {
            "vx": vx, "vy": vx * math.tan(beta), "beta": beta, "yaw_rate": x[self.yaw],
            "vx_std": std[self.vx], "vy_std": math.hypot(vx * std[self.beta] / math.cos(beta) ** 2,
                                                         math.tan(beta) * std[self.vx]),
            "beta_std": std[self.beta], "yaw_rate_std": std[self.yaw],
        }
        causes = {
            "yaw_rate": validity.judge(any(inputs.has(n) for n in self.gyros), inputs.saturated("yaw_rate"),
                                       ratio["yaw_rate"]),
            "vx": self._vx_cause(inputs, ratio["vx"], std[self.vx]),
            "beta": self._lateral_cause(mode, inputs, lateral_ok, ratio["beta"], t),
        }
        causes = {state: self.holds.apply(state, cause, t) for state, cause in causes.items()}
        valid = {name: causes[name] == "valid" for name in causes}
        valid["vy"] = valid["beta"] and valid["vx"]
        self._extra_values(values, valid, causes, std, inputs, lateral_ok)
        return Estimate(t, values, valid, mode, self.est.filter, self.filter.nis, missing, self.resets, causes)

    def _vx_cause(self, inputs: TickInputs, ratio: float, vx_std: float) -> str:
        cause = validity.judge(inputs.has(*WHEEL_SPEEDS) or inputs.has("ax"),
                               any(inputs.saturated(w) for w in WHEEL_SPEEDS), ratio)
        if cause == "valid" and vx_std > validity.VX_VALID_STD:
            return "uncertain"
        return cause

    def _lateral_cause(self, mode: str, inputs: TickInputs, lateral_ok: bool, ratio: float, t: float) -> str:
        """Why sideslip (and the lateral forces) are not valid, or "valid"."""
        if mode == "low_speed":
            return "low_speed"
        if mode == "degraded" and t < self.suspect_until:
            return "after_reset"
        if not self.steering_zero.learned:
            return "initializing"
        present = lateral_ok and inputs.has(*WHEEL_SPEEDS)
        saturated = any(inputs.saturated(n) for n in ("ay", "steering_wheel_angle", "yaw_rate"))
        cause = validity.judge(present, saturated, ratio)
        if cause != "valid":
            self.kinematic.reset()
            return cause
        x, yaw_rate = self.filter.x, inputs.values["yaw_rate"]
        moving_as_measured = self.kinematic.inside(x[self.beta], inputs.values["ay"], yaw_rate, x[self.vx])
        in_regime = self.regime is None or self.regime.inside(self._road_wheel_angle(inputs), x[self.vx], yaw_rate)
        return "valid" if moving_as_measured and in_regime else "model_regime"
