"""The judge of one estimator: which published states are valid, why not, and how far to widen their std.

It owns the tests of :mod:`canest.estimation.validity` for one model (the
channel consistency, the holds, the linear-regime and kinematic sideslip
checks) and answers the tick core (:mod:`canest.estimation.core`) three
questions: is a directly measured state diverging (reset), what standard
deviations to publish, and the cause of each state's bit.
"""
from __future__ import annotations

import math

import numpy as np

from canest.estimation import channels as ch
from canest.estimation import validity
from canest.estimation.inputs import WHEEL_SPEEDS
from canest.estimation.lags import FadingMaximum

# the input behind each derived channel (a channel not listed is fed by the input of its own name)
SOURCES = {"vx_wheel": WHEEL_SPEEDS, "vx_reference": WHEEL_SPEEDS, "yaw_acceleration": ("yaw_rate",)}
DIVERGENCE_NIS = 30.0  # windowed mean NIS of a directly measured state above which the filter is reset
MEASURED_DIRECTLY = ("yaw_rate", "vx")


def steered_wheels_std(delta: float, vy_std: float) -> float:
    """vx's error (m/s) from a lateral velocity error of ``vy_std`` (m/s) through the steered wheels: every model
    measures the wheels' mean speed along their headings, ``0.5 vx (1 + cos delta) + 0.5 (vy + a r) sin delta``
    (:meth:`canest.models.single_track.SingleTrackModel.measure`), so the vx read from them moves by
    ``-tan(delta / 2)`` per m/s of vy. ``vy_std`` is the error the filter's covariance does not hold (its own it
    couples into vx itself): on the step steer on 0.35 dici-gfckf's sideslip was 6 deg off (its bit clear), and its
    vx 0.04-0.05 m/s low with a std of 0.034 for 1.5 s (road wheels at 2.8 deg: 0.06 m/s per 6 deg at 22 m/s)."""
    return abs(math.tan(0.5 * delta) * vy_std)


def lateral_velocity_of(vx: float, beta: float, beta_std: float) -> float:
    """A sideslip std ``beta_std`` (rad) as the lateral velocity's (m/s): ``vy = vx tan(beta)`` moves by
    ``vx / cos(beta)^2`` per rad."""
    return abs(vx) * beta_std / math.cos(beta) ** 2


class StateJudge:
    def __init__(self, model, vehicle, dt: float, gyro_bias_std: float = 0.0, ay_noise: float = 0.0):
        self.model = model
        self.ay_noise = ay_noise  # m/s^2, the configured: the ay offset it admits (:meth:`sideslip_offset_std`)
        self.vehicle = vehicle
        self.consistency = validity.Consistency(model.measurement_names)
        self.friction_consistency = validity.Consistency(model.measurement_names)  # under the configured noise
        self.yaw_rate_consistency = validity.Consistency(model.measurement_names)  # the gyros as held (:meth:`record`)
        self.holds = validity.Holds()
        # a model that estimates friction covers saturation itself (dckf's sideslip: not at a tire's limit,
        # :meth:`_lateral_cause`); the others are judged by the linear regime
        self.regime = None if getattr(model, "parameters", 0) else validity.LinearRegime(vehicle, dt)
        self.kinematic = validity.KinematicCheck(dt)
        self.lateral_drift = validity.LateralDrift(dt, ay_noise)
        self.sideslip_known = False  # the sideslip was valid on the last tick
        self.reference_gap = FadingMaximum(dt, validity.HOLD)  # m/s, vx's from the reference (:meth:`widen`)
        # |v r| (m/s^2), or a tire curve's rear slip angle (rad), held (:meth:`sideslip_model_std`)
        self.excitation = FadingMaximum(dt, validity.MODEL_ERROR_MEMORY)
        self.kinematic_offsets = (0.0, 0.0)  # ay, yaw rate (:meth:`use_kinematic_offsets`)
        # speed scale, gyro bias: the config's claim until the online calibration applies its own
        # (:meth:`use_correction_std`)
        self.claimed_std = (vehicle.wheel_radius_uncertainty, gyro_bias_std)
        self.correction_std = self.claimed_std
        self.gyros = [n for n in validity.OBSERVED_BY["yaw_rate"] if n in model.measurement_names]  # the measured ones
        self.linear_tires = getattr(model, "linear_tires", False)
        self.sources = [SOURCES.get(name, (name,))[0] for name in model.measurement_names]  # input behind each channel

    def use_vehicle(self, vehicle) -> None:
        """Judge with ``vehicle``'s cornering stiffnesses (the online calibration's): the sideslip's model error and
        the linear regime's steady yaw rate."""
        self.vehicle = vehicle
        if self.regime is not None:
            self.regime.understeer = vehicle.understeer_gradient

    def reset(self) -> None:
        self.consistency.reset()
        self.friction_consistency.reset()
        self.yaw_rate_consistency.reset()
        self.reference_gap.reset()
        self.excitation.reset()
        self.kinematic.reset()
        if self.regime is not None:
            self.regime.reset()

    def record(self, channels: ch.Channels, measured_std: np.ndarray, held_std: np.ndarray, u: np.ndarray,
               x_prior: np.ndarray, P_prior: np.ndarray, returning=frozenset()) -> None:
        """Each usable channel's consistency with the prior: under the noise its samples show where above the
        configured (``measured_std``, what the filter takes: :meth:`canest.estimation.core.Estimator._measured`)
        for every state but friction, under the configured noise for friction (:meth:`ratios`); the yaw rate's
        under ``held_std``, which adds a gyro's noise as its value at the tick carries it
        (:meth:`canest.estimation.core.Estimator._held_gyro_noise`), as the yaw rate's published std does.

        Only the yaw rate's: its std takes the gyro's measured noise (:meth:`widen`), and judged under the
        configured noise a vibrating gyro raised its ratio and its std counted the vibration twice (ckf's yaw rate
        on the drawn cars with a vibrating IMU: NEES 0.71, where svd-fckf's, whose adapted Q keeps the ratio below
        1, was 1.04 and valid but wrong on 0.51 % of its valid ticks). The sideslip's and the lateral forces'
        stds take no gyro noise of their own: judged alike, dici-gfckf's forces were valid but wrong on 0.39 % of
        those ticks, 0.12 before.

        A channel whose input comes back after a gap (``returning``: inputs stale on the previous tick)
        starts a new window and its first innovation is not judged: it measures how far the state drifted
        while nothing observed it, which this very update corrects."""
        mask = channels.mask
        if returning:
            back = [i for i, source in enumerate(self.sources) if source in returning]
            self.consistency.restart(back)
            self.friction_consistency.restart(back)
            self.yaw_rate_consistency.restart(back)
            mask = mask.copy()
            mask[back] = False
        rows = np.flatnonzero(mask)
        if rows.size:
            measurement = ch.rows_measurement(self.model, rows, channels.ages, False)
            squared, spread = validity.innovation_terms(measurement, x_prior, P_prior, u, channels.z[rows])
            self.consistency.push(rows, squared / (spread + measured_std[rows] ** 2))
            self.friction_consistency.push(rows, squared / (spread + channels.std[rows] ** 2))
            self.yaw_rate_consistency.push(rows, squared / (spread + held_std[rows] ** 2))

    def divergence(self) -> float:
        """The worst windowed mean NIS of a directly measured state over a full window (0 before one is full)."""
        ratios = [self.consistency.ratio(state, validity.WINDOW) for state in MEASURED_DIRECTLY]
        return max((r for r in ratios if r == r), default=0.0)

    def ratios(self) -> dict:
        """Each state's consistency ratio; friction's under the configured noise (module
        :mod:`canest.estimation.two_track`, "a noisy IMU"), the yaw rate's under its gyros' held noise
        (:meth:`record`)."""
        ratios = {state: self.consistency.ratio(state) for state in validity.OBSERVED_BY
                  if state not in ("friction", "yaw_rate")}
        return {**ratios, "friction": self.friction_consistency.ratio("friction"),
                "yaw_rate": self.yaw_rate_consistency.ratio("yaw_rate")}

    def sideslip_model_std(self, steady_ay: float, rear_slip: float | None = None) -> float:
        """The sideslip's model error (rad) at ``|steady_ay|`` (``v r``), or for a model with a tire curve at its
        rear slip angle (then ``steady_ay`` is not used), each held as a leaky maximum with time constant
        ``validity.MODEL_ERROR_MEMORY`` s (:func:`validity.sideslip_model_std`). Held because the filter's
        sideslip error lags the excitation: on a vibrating IMU, whose kinematic check cannot catch it, ckf's
        sideslip was 1.3 deg off with a std of 0.4 after the peak of the sine on 0.85 (5.4 m/s^2 on its way down
        from 6.5), the term following ay down."""
        if rear_slip is None:
            return validity.sideslip_model_std(self.vehicle, self.excitation.update(abs(steady_ay)))
        return validity.sideslip_model_std(self.vehicle, steady_ay, self.excitation.update(abs(rear_slip)))

    def sideslip_offset_std(self) -> float:
        """The sideslip error (rad) of the ay offset the online calibration learned and does not apply
        (:meth:`use_kinematic_offsets`) beyond what ay's configured noise admits (:func:`validity.sideslip_offset_std`):
        a side force no model's process noise holds, so every model's published std takes it."""
        unadmitted = max(0.0, abs(self.kinematic_offsets[0]) - self.ay_noise)
        return validity.sideslip_offset_std(self.vehicle, unadmitted)

    def drift(self, inputs, vx: float, beta: float, beta_std: float, vx_measured: bool,
              ay_density: float = 0.0, kinematic_ay: float | None = None) -> float:
        """This tick's bound on vx's drift from an unmodelled lateral velocity (0 without ay or a gyro);
        ``beta_std``: the sideslip's std, the filter's with the model's error; ``vx_measured``: the wheels
        measured vx this tick; ``ay_density``: the noise density of the ay the kinematic identity takes
        (``kinematic_ay``, None: the input's) where it is louder than configured."""
        if not inputs.has("ay", "yaw_rate"):
            self.lateral_drift.reset()
            return 0.0
        ay, yaw_rate = self._kinematic_inputs(inputs, kinematic_ay)
        return self.lateral_drift.update(ay, yaw_rate, vx, beta, vx_measured, self.sideslip_known,
                                         lateral_velocity_of(vx, beta, beta_std), ay_density)

    def lateral_std(self, drift: float) -> float:
        """The vx error (m/s) a lateral velocity the model misses may have caused since the wheels last measured vx:
        :meth:`drift`'s bound and the sideslip std's integral (:attr:`validity.LateralDrift.spread`) in
        quadrature. The reference speed integrated the same ``r vy`` over that time."""
        return math.hypot(drift, self.lateral_drift.spread)

    def lateral_velocity_std(self, vx: float, beta: float, beta_std: float) -> float:
        """The lateral velocity's error (m/s) beside the filter's covariance: ``beta_std`` (rad, the published std's
        part beyond the covariance's) as vy's (:func:`lateral_velocity_of`), and, in quadrature, where the
        sideslip is not known, the kinematic lateral velocity's change since it was less the model's, beyond what the
        admitted ay offset explains (:attr:`canest.estimation.validity.LateralDrift.unexplained`): its published
        std does not bound it then."""
        return math.hypot(lateral_velocity_of(vx, beta, beta_std), self.lateral_drift.unexplained)

    def use_kinematic_offsets(self, ay: float, yaw_rate: float) -> None:
        """Offsets still in the inputs' ay and yaw rate that the kinematic identity ``ay - c = v (r - b) + dvy/dt``
        has learned (the online calibration's, not applied to the inputs): the kinematic checks take them out."""
        self.kinematic_offsets = (ay, yaw_rate)

    def use_correction_std(self, speed: float | None, gyro_bias: float | None) -> None:
        """The error of the wheel-speed scale (relative) and the gyro bias (rad/s) the online calibration applied to
        the inputs, which :meth:`widen` adds to vx's and the yaw rate's std; ``None``: not applied, the config's
        claim (``vehicle.wheel_radius_uncertainty``, ``estimator.gyro_bias_std``) holds."""
        self.correction_std = tuple(claimed if applied is None else applied
                                    for applied, claimed in zip((speed, gyro_bias), self.claimed_std))

    def _kinematic_inputs(self, inputs, ay: float | None = None) -> tuple:
        """ay and yaw rate as the kinematic identity holds them: the inputs less :meth:`use_kinematic_offsets`';
        ``ay``: the lateral acceleration to take instead of the input's (both accelerometers',
        :meth:`canest.estimation.core.Estimator._kinematic_ay`)."""
        ay_offset, yaw_offset = self.kinematic_offsets
        return (inputs.values["ay"] if ay is None else ay) - ay_offset, inputs.values["yaw_rate"] - yaw_offset

    def widen(self, std: np.ndarray, index: dict, ratios: dict, beta_model_std: float,
              lateral: float = 0.0, gyro_noise: float = 1.0, walk: float = 0.0, walk_apart: bool = False,
              reference_gap: float = 0.0, vx: float = 0.0, beta_floor: float = 0.0) -> np.ndarray:
        """The published std: each state's by its channels' consistency, the yaw rate's also by its gyro's noise as
        measured over what the covariance took (``gyro_noise``, :meth:`canest.estimation.core.Estimator._gyro_noise`,
        :mod:`canest.estimation.measured_noise`; never narrowed by it), vx
        with its lateral drift (``lateral``, :meth:`lateral_std`) and the reference speed's random walk, the error every
        tick it was updated shares (``walk``, :meth:`canest.estimation.reference_speed.ReferenceSpeed.integration_std`):
        in quadrature where the covariance holds only the error beside it (``walk_apart``: a model integrating ax that
        took the reference this tick, whose channel leaves the walk out), else never below it, and never below
        ``reference_gap`` (its distance from the reference beyond the reference's std, ``ReferenceSpeed.disagreement``),
        a leaky maximum fading over ``validity.HOLD`` s (it alternates tick by tick while vx and the reference cross:
        vx's bit flickered between valid and uncertain); sideslip with its model error (``beta_model_std``,
        :meth:`sideslip_model_std`), and never below ``beta_floor`` (the model error of a model whose covariance
        holds it as a relaxing noise only) nor its last mismatch with the kinematic sideslip change. vx (its
        value ``vx``) and the yaw rate add the error of the wheel-speed scale and the gyro bias in quadrature
        (:meth:`use_correction_std`: the config's claim, or the applied correction's)."""
        std = std.copy()
        speed_std, gyro_bias_std = self.correction_std
        yaw_rate = std[index["yaw_rate"]] * (validity.inflation(ratios["yaw_rate"]) * max(gyro_noise, 1.0))
        std[index["yaw_rate"]] = math.hypot(yaw_rate, gyro_bias_std) if gyro_bias_std else yaw_rate
        vx_std = math.hypot(std[index["vx"]] * validity.inflation(ratios["vx"]), lateral)
        vx_std = max(math.hypot(vx_std, walk) if walk_apart else max(vx_std, walk),
                     self.reference_gap.update(reference_gap))
        std[index["vx"]] = math.hypot(vx_std, abs(vx) * speed_std) if speed_std else vx_std
        std[index["beta"]] = max(math.hypot(std[index["beta"]] * validity.inflation(ratios["beta"]), beta_model_std),
                                 beta_floor, self.kinematic.mismatch)
        return std

    def causes(self, inputs, ratios: dict, vx_std: float, lateral: dict, t: float, drift: float = 0.0,
               walk_unknown: bool = False) -> dict:
        """Cause per state (held for ``validity.HOLD``); ``lateral`` describes the sideslip's situation, ``drift``
        is :meth:`drift`, ``walk_unknown``: the reference speed was updated with an ax whose noise is not measured
        yet."""
        causes = {
            "yaw_rate": validity.judge(any(inputs.has(n) for n in self.gyros), inputs.saturated("yaw_rate"),
                                       ratios["yaw_rate"]),
            "vx": self._vx_cause(inputs, ratios["vx"], vx_std, drift, walk_unknown),
            "beta": self._lateral_cause(inputs, ratios["beta"], **lateral),
        }
        causes = {state: self.holds.apply(state, cause, t) for state, cause in causes.items()}
        self.sideslip_known = causes["beta"] == "valid"
        return causes

    @staticmethod
    def _vx_cause(inputs, ratio: float, vx_std: float, drift: float, walk_unknown: bool) -> str:
        """As every measured state's, then "model_regime" for a drift beyond ``DRIFT_LIMIT``, "initializing" while the
        reference speed takes an ax whose noise is not yet measured (the first half second: the random walk of its
        integration, which a vibrating IMU makes 0.4 m/s, is unknown, and an anchor does not bring back a filter
        that took it), and "uncertain" for a std beyond ``VX_VALID_STD`` (the only cause that leaves vy valid)."""
        cause = validity.judge(inputs.has(*WHEEL_SPEEDS) or inputs.has("ax"),
                               any(inputs.saturated(w) for w in WHEEL_SPEEDS), ratio)
        if cause == "valid" and drift > validity.DRIFT_LIMIT:
            return "model_regime"
        if cause == "valid" and walk_unknown:
            return "initializing"
        if cause == "valid" and vx_std > validity.VX_VALID_STD:
            return "uncertain"
        return cause

    def _lateral_cause(self, inputs, ratio: float, low_speed: bool, after_reset: bool, zero_learned: bool,
                       ay_noise_known: bool, lateral_ok: bool, beta: float, vx: float, delta: float, ay_density: float,
                       at_limit_of_unbounded_friction: bool, frictions_pressed: bool,
                       kinematic_ay: float | None = None) -> str:
        """Why sideslip (and the lateral forces) are not valid, or "valid" (a steering zero still being learned, or
        an ay whose noise its samples do not show yet, ``ay_noise_known`` false: "initializing"; the filter took it
        at its configured noise, and on a vibrating IMU the 3-DOF filters' sideslip had a NEES of 3.1 over the
        first half second of the drawn cars' grid, 0.6 after it); ``at_limit_of_unbounded_friction``: a tire
        works at its limit at a friction whose error no covariance bounds
        (:meth:`canest.estimation.two_track.FrictionEstimator._at_limit_of_unbounded_friction`), "model_regime";
        ``frictions_pressed``: the update pressed a friction the sideslip rests on against its physical range (the
        model cannot explain the data), "at_bound", held as every failed test is (it flickers tick by tick while a
        slide is read as a split of frictions: jckf's sideslip on a drawn car's step steer on 0.35 was 2 deg off
        with a std of 0.6, flagged valid between such ticks)."""
        if low_speed:
            return "low_speed"
        if after_reset:
            return "after_reset"
        if not (zero_learned and ay_noise_known):
            return "initializing"
        present = lateral_ok and inputs.has(*WHEEL_SPEEDS)
        saturated = any(inputs.saturated(n) for n in ("ay", "steering_wheel_angle", "yaw_rate"))
        cause = validity.judge(present, saturated, ratio)
        if cause != "valid":
            self.kinematic.reset()
            return cause
        moving_as_measured = self.kinematic.inside(beta, *self._kinematic_inputs(inputs, kinematic_ay), vx,
                                                  ay_density)
        in_regime = self.regime is None or self.regime.inside(delta, vx, inputs.values["yaw_rate"])
        in_regime = in_regime and not at_limit_of_unbounded_friction
        if not (moving_as_measured and in_regime and self.lateral_drift.allows_return(vx)):
            return "model_regime"
        return "at_bound" if frictions_pressed else "valid"
