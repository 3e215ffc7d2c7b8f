"""Binding of the 7-DOF two-track model (:mod:`canest.models.two_track`) to the tick core:
four road frictions. It runs with the joint CKF (``jckf``, the default) or
the DCKF paper's double CKF (``dckf``). Beyond the paper's measurements it
gives the filter two derived channels: the yaw acceleration from the gyro
(Theil-Sen slope over ``YAW_ACCELERATION_WINDOW`` samples; its std grows by
the slope of the gyro's noise beyond the configured), which with ay
splits the lateral force between the axles, and a reference speed that does
not follow slipping wheels (:mod:`canest.estimation.reference_speed`), which makes the
slip ratio, and so a spinning wheel's friction, observable.

Friction is observable only while a tire works near its limit: a wheel is
excited when its force sensitivity ``|dF/dmu|``, at its friction
``LOWER_FRICTION_STDS`` standard deviations below the estimate, reaches
``estimator.friction_excitation`` (N per unit mu). While no wheel is
excited the frictions are frozen (value held; variance growing up to its
initial value, :mod:`canest.filters.parameters`); while any is, all four
update, so evidence from the excited wheels reaches the others through
their correlation. The CAN flags ``Mu..Observable`` say which wheels were
excited this tick; ``Mu..Valid`` that the standard deviation is below
``MU_VALID_STD`` (excitation was seen recently enough), the estimate is
not within ``MU_VALID_STD`` of the highest friction a road has (an estimate
pressed against that bound says the data only bound friction from below),
and a tire's limit showed in what the car measures within the last
``LIMIT_MEMORY`` s: the measured yaw rate left the ESC band around the
linear steady-state yaw rate of the steering
(:class:`canest.estimation.validity.LinearRegime`), or a wheel slipped
beyond the linear slip its force needs (``SLIP_TOLERANCE``). Why: the
cubature points sit 3.3 standard deviations from the mean (11 states), the
lowest at a friction where a gentle curve already saturates its tire, and
their evidence alone moves the mean: on the simulator's country road (exact
car, dry 0.85, ay up to 2.4 m/s^2) the frictions fell from 0.90 to 0.25-0.35
in the first curves and were flagged valid on 2-26 % of the ticks of 30 s
drives (seeds 0, 1, 3), 72-100 % of those wrong. A car whose yaw response
stays linear and whose wheels do not slip has not shown where its limit is,
whatever the filter makes of it (a low road met that gently is estimated,
not promised).
The published standard deviation adds, to the filter's, the error a wrong
slip stiffness puts into the frictions (:class:`FrictionModelError`) and the
range the estimate spanned over the last ``SETTLE_WINDOW`` (a road's friction
does not change within a second: what the estimate did meanwhile is its
error, e.g. a plunge from the prior in a step steer, or a slide the model
reads as a friction split). And a friction is never published more certain
than its distance from the four wheels' mean: on one road that split is the
error of the wheels that make it (a stiffness the model lacks, read as
friction: on a car whose rear stiffness is x0.77, as wrong as a config
admitting 15 % may be, the step steer on 0.85 split the rear frictions to
0.88 and 0.62 in four seconds, the low one flagged valid with a std of 0.07).
The filter cannot tell that from a road of split friction, where the bits of
the wheels that differ clear as "uncertain": a split is published, never
promised.

Friction may always fall but rises only on a wheel at its limit at the
estimated friction (:meth:`FrictionEstimator._update`): below it the data
bound friction from below only.

A noisy IMU: that one-sided rule turns an accelerometer's noise into a
falling friction (every update that lowers it is taken, every one that
raises it below the limit refused). On a vibrating IMU (ay shaken by 1.4
m/s^2 where 0.15 was configured) jckf's frictions on a dry road fell to
0.15-0.2 and, judged by the accelerometers' measured noise as the other
states are, were valid but wrong on 3-7 % of their valid ticks. So friction
is judged under the configured noise: an IMU that vibrates beyond it makes
the frictions ``inconsistent``.

A divergence reset restarts the states but keeps the frictions: it says the
states were wrong, not the road.

Four frictions from three body measurements (ax, ay, r) are not separately
observable: a tire with too much friction and its neighbour with too little
explain the same accelerations. The four wheels usually share one road, so
their prior and random walk are correlated (``estimator.friction_correlation``,
default 0.9): evidence on one wheel moves all four, and a split-mu road still
shows as a slowly growing difference.

The lateral channels (ax, ay, yaw acceleration) are skipped at low speed, as
the single-track binding skips ay.
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from canest.estimation import validity
from canest.estimation.core import Estimator
from canest.estimation.inputs import WHEEL_SPEEDS, TickInputs
from canest.estimation.reference_speed import tick_usage
from canest.estimation.roll_lag import accelerations
from canest.estimation.tire_force import TORQUES, torques
from canest.models import two_track
from canest.models.two_track import TwoTrackModel
from canest.models.wheel_force import WheelAcceleration
from canest.signals import WHEELS

FRICTIONS = tuple(f"mu_{w}" for w in WHEELS)
MU_VALID_STD = 0.15
LOWER_FRICTION_STDS = 3.0  # the excitation gate tests each friction this many standard deviations below its estimate
YAW_ACCELERATION_WINDOW = 7
EVIDENCE_MEMORY = 2.0  # s of excited driving over which the frictions' model error is averaged
SETTLE_WINDOW = 1.0  # s over which the range a friction spanned is part of its std
LIMIT_MEMORY = 5.0  # s after a tire's limit last showed in what the car measures that a friction may be valid
LIMIT_PERSISTENCE = 0.1  # s on end a limit must show for: one outlier of the gyro or a wheel is not a limit
# std of a sideslip resting on a saturation not shown, per unit of the sideslip that saturation makes: linear tires
# and the estimate's saturated ones explain the measurements alike, and half their distance puts either within 2 std
UNSHOWN_SATURATION_STD = 0.5
SLIP_TOLERANCE = (0.015, 0.5)  # slip ratio plus a share of the linear slip: a wheel's slip beyond is past linear


class FrictionModelError:
    """The error a wrong slip stiffness puts into the friction estimates (a considered parameter, not estimated).

    Near its limit a tire's force ``F(mu, C)`` depends on its friction and on its slip stiffness: a stiffness off by
    a relative ``e`` (``vehicle.cornering_stiffness_uncertainty``), read as friction, moves ``mu`` by
    ``e |dF/d ln C| / |dF/d mu|`` at the same force. The filter weighs each excited tick's evidence by its
    information ``(dF/d mu)^2 / R``, so the estimate's error is the information-weighted mean of those ratios,
    pooled over the four wheels (one road): ``e sum(S_mu S_C) / sum(S_mu^2)``, older evidence forgotten over
    ``EVIDENCE_MEMORY`` s of excitation. Deep in saturation ``S_C`` is zero (the force is the peak); in the linear
    range ``S_mu`` is, and the ratio says friction was not measured.
    """

    def __init__(self, uncertainty: float, dt: float):
        self.uncertainty = uncertainty
        self.decay = math.exp(-dt / EVIDENCE_MEMORY)
        self.information = self.cross = 0.0

    def add(self, friction_sensitivity: np.ndarray, stiffness_sensitivity: np.ndarray) -> None:
        """One excited tick's evidence: both sensitivities per wheel at the estimate (N per unit mu, N)."""
        self.information = self.decay * self.information + float(np.sum(friction_sensitivity**2))
        self.cross = self.decay * self.cross + float(np.sum(friction_sensitivity * stiffness_sensitivity))

    @property
    def std(self) -> float:
        return self.uncertainty * self.cross / self.information if self.information > 0.0 else 0.0


class FrictionEstimator(Estimator):
    extra_states = FRICTIONS

    def __init__(self, config):
        super().__init__(config, TwoTrackModel(config.vehicle, config.vehicle.tire))
        self.observable = np.zeros(len(FRICTIONS), dtype=bool)
        self.yaw_acceleration = WheelAcceleration(YAW_ACCELERATION_WINDOW)
        # the rows of the derived yaw acceleration and of the gyro it is derived from (:meth:`_measured`)
        self.yaw_acceleration_row, self.gyro_row = map(self.model.measurement_names.index,
                                                       ("yaw_acceleration", "yaw_rate"))
        self.last_friction = None
        self.model_error = FrictionModelError(config.vehicle.cornering_stiffness_uncertainty, self.dt)
        self.recent = deque(maxlen=max(1, round(SETTLE_WINDOW / self.dt)))  # the frictions over SETTLE_WINDOW
        # the limit's yaw test: a yaw rate a stiffness error within the claim explains is no limit (_note_limit)
        self.regime = validity.LinearRegime(config.vehicle, self.dt, validity.understeer_std(config.vehicle))
        self.limit_ticks = 0  # ticks on end on which a tire's limit showed in the measurements
        self.since_limit = math.inf  # ticks since it last showed for LIMIT_PERSISTENCE on end
        self.persistence, self.memory = max(1, round(LIMIT_PERSISTENCE / self.dt)), round(LIMIT_MEMORY / self.dt)
        self.reference = None  # (speed, std) of this tick's reference speed, :meth:`_derived`
        self.saturation_std = 0.0  # rad: the sideslip's std from a saturation not shown, :meth:`_update`
        self.friction_std = 0.0  # rad: the sideslip's std from the frictions' error near the peak, :meth:`_update`
        self.pressed_in_episode = False  # pressed since the tire's limit, still showing, showed: _note_pressed
        correlation = self.est.friction_correlation
        mixing = correlation * np.ones((4, 4)) + (1.0 - correlation) * np.eye(4)
        for matrix in (self.Q, self.p0):  # the four wheels are on one road: correlated prior and random walk
            matrix[two_track.MU, two_track.MU] = matrix[two_track.MU.start, two_track.MU.start] * mixing

    def reset(self) -> None:
        """Forget the state but remember the frictions: a divergence says the states were wrong, not the road."""
        if self.filter is not None and np.all(np.isfinite(self.filter.x[two_track.MU])):
            self.last_friction = self.filter.x[two_track.MU].copy()
        super().reset()
        self.yaw_acceleration.reset()
        self.regime.reset()  # a non-finite vx would stay in its lag; the limit seen (since_limit) stays: a fact
        self.limit_ticks = 0
        self.saturation_std = self.friction_std = 0.0
        self.pressed_in_episode = False

    def _initial_state(self, inputs: TickInputs) -> np.ndarray:
        """Wheel speeds as measured; friction as before a reset, else at the tire's nominal value (dry)."""
        x0 = super()._initial_state(inputs)
        x0[two_track.W] = [inputs.values[name] for name in WHEEL_SPEEDS]
        x0[two_track.MU] = self.vehicle.tire.nominal_friction if self.last_friction is None else self.last_friction
        return x0

    def _control(self, inputs: TickInputs, t: float) -> np.ndarray:
        """u = (delta, ax, ay, ax's offset, motor torque per wheel): the offset from the wheels' acceleration (a
        road's grade, :mod:`canest.estimation.longitudinal_offset`) slows vx beside the tires' forces."""
        return np.array([self._road_wheel_angle(inputs), *accelerations(inputs), self.reference_speed.offset.value,
                         *torques(inputs)])

    def _derived(self, inputs: TickInputs, t: float, lateral_ok: bool) -> dict:
        """The gyro's yaw acceleration (body moment balance, eq 5) and the reference speed (vx without slip).

        Both are computed at the tick: age 0."""
        derived = {}
        if inputs.has("yaw_rate") and inputs.any_fresh("yaw_rate"):
            rate = self.yaw_acceleration.update(t, [inputs.values["yaw_rate"]])[0]
            if lateral_ok and self.yaw_acceleration.samples == YAW_ACCELERATION_WINDOW:
                derived["yaw_acceleration"] = (rate, self.est.measurement_noise["yaw_acceleration"], 0.0)
        self.reference = reference = self._reference_speed(inputs, t)
        if reference is not None:
            derived["vx_reference"] = (*reference, 0.0)
        return derived

    def _measured(self, channels):
        """As every model's (the accelerometers' noise as their samples show it), and the yaw acceleration's std
        with the slope that the gyro's noise beyond its configured puts into it (:meth:`_yaw_acceleration_noise`).
        Friction's consistency keeps the configured (:meth:`canest.estimation.judge.StateJudge.record`)."""
        measured = super()._measured(channels)
        row = self.yaw_acceleration_row
        measured.std[row] = math.hypot(measured.std[row], self._yaw_acceleration_noise())
        return measured

    def _yaw_acceleration_noise(self) -> float:
        """The std (rad/s^2) a gyro noisier than configured puts into the yaw acceleration, its slope over
        ``YAW_ACCELERATION_WINDOW`` samples: the excess ``sqrt(s^2 - r^2)`` of the gyro's noise as its samples show
        it (``s``, :mod:`canest.estimation.measured_noise`) over the configured ``r``, through the slope's gain
        (:meth:`canest.models.wheel_force.WheelAcceleration.noise_gain`; 0 while the gyro's noise is not measured).
        The configured yaw acceleration noise (0.1 rad/s^2) is a quiet gyro's slope noise and the moment balance's
        error; a body vibrating the gyro by 0.3 deg/s, correlated over 15 ms, adds 0.12 over 7 samples at 100 Hz,
        which the filter had taken as 2.4 times as certain as it was."""
        gyro = self.input_noise.get("yaw_rate")
        if gyro is None or gyro.std is None:
            return 0.0
        configured = self.r_std[self.gyro_row]
        return math.sqrt(max(gyro.std**2 - configured**2, 0.0)) * self.yaw_acceleration.noise_gain()

    def _update(self, channels, inputs: TickInputs, u: np.ndarray, lateral_ok: bool, t: float) -> bool:
        """Open or close the friction gate and say which frictions may rise, then update as every model does.

        One-sided evidence: a tire below its limit at the estimated friction
        says only that friction is at least what it uses; a force above what
        the model predicts there is the model's error (its slip or cornering
        stiffness), not friction. Read as friction it pushed the 0.85 launch to
        the upper bound 1.3 (the plant's unloaded front tire is 11 % stiffer
        in slip than the model's). So friction rises only on a tire at its
        limit at the estimate (sensitivity at the estimate itself above
        ``friction_excitation``) and can always fall (README "Tire forces and
        road friction"); a refused rise leaves the friction and its variance
        as they were (:class:`canest.filters.parameters.ParameterBlock`).
        """
        self._note_limit(inputs, u, lateral_ok, t)
        states = np.stack([self._plausibly_lower_friction(), self.filter.x])
        sensitivity = self.model.friction_sensitivity(states, u)
        excited, at_limit = sensitivity >= self.est.friction_excitation
        self.observable = excited & lateral_ok & inputs.has(*TORQUES)
        self.filter.parameters.frozen = np.full(4, not self.observable.any())
        if self.observable.any():
            self.model_error.add(sensitivity[1], self.model.stiffness_sensitivity(self.filter.x, u))
        self.filter.parameters.may_rise = at_limit
        diverged = self._apply(channels, u, t)
        self._note_pressed()
        shown = self._limit_recent()
        self.saturation_std = 0.0 if shown else UNSHOWN_SATURATION_STD * self._saturation_slip(u)
        self.friction_std = self._friction_slip(u) if shown else 0.0
        return diverged

    def _note_limit(self, inputs: TickInputs, u: np.ndarray, lateral_ok: bool, t: float) -> None:
        """Count the ticks since a tire's limit last showed in the measurements for ``LIMIT_PERSISTENCE`` s on end
        (one outlier is not a limit): the measured yaw rate left the ESC band around the linear steady-state yaw
        rate of the steering (:class:`canest.estimation.validity.LinearRegime` at the understeer gradient of the
        stiffnesses in use, the band widened by one std of it, :func:`canest.estimation.validity.understeer_std`;
        judged with the lateral model on and the steering zero learned, its lag restarted where not, so that it
        never resumes from a stale steady yaw rate) or a wheel slipped beyond the linear slip its force needs
        (:meth:`_slipping`). Without the widening a car with front x1.2 and rear x0.8 of the config's stiffnesses
        (1.3 times the claimed 0.15 each, towards oversteer) held its yaw rate 50 % above the linear one in a
        curve at 3.3 m/s^2 on a dry road, read as a limit: its frictions, fallen to 0.25-0.35, were valid and
        wrong until the online calibration's first window fit applied the learned stiffnesses. Two std let the
        vibrating drawn cars' sideslip be valid but wrong on 0.10 % of its ticks (none with one)."""
        judged = lateral_ok and self.steering_zero.learned and inputs.has("yaw_rate")
        if not judged:
            self.regime.reset()
        yaw_off_linear = judged and not self.regime.inside(u[two_track.DELTA], self.filter.x[two_track.VX],
                                                           inputs.values["yaw_rate"])
        self.limit_ticks = self.limit_ticks + 1 if yaw_off_linear or self._slipping(inputs, u, t) else 0
        self.since_limit = 0 if self.limit_ticks >= self.persistence else self.since_limit + 1

    def _note_pressed(self) -> None:
        """Note whether this update pressed a friction against its bound while the car showed a tire's limit
        (:meth:`_limit_recent`), or one did earlier in a limit that still shows (shown within ``LIMIT_PERSISTENCE``
        s): the model could not explain that slide, and the sideslip it left need not be right when the frictions
        come free of the bound in the same slide (:meth:`_frictions_pressed`)."""
        pressed = bool(self.filter.parameters.pressed.any()) and self._limit_recent()
        showing = self.since_limit <= self.persistence
        self.pressed_in_episode = pressed or (self.pressed_in_episode and showing)

    def _saturation_slip(self, u: np.ndarray) -> float:
        """How much of the estimate's sideslip its rear tires' saturation makes (rad,
        :meth:`canest.models.two_track.TwoTrackModel.rear_saturation_slip`): a sideslip resting on a friction the
        car has not confirmed may be off by that much (:meth:`_sideslip_saturation_std`)."""
        return self.model.rear_saturation_slip(self.filter.x, u) if self._judgeable() else 0.0

    def _friction_slip(self, u: np.ndarray) -> float:
        """The rear slip angle's std (rad) from the frictions' error: its moves when all four frictions are one
        covariance std lower and higher (never below ice), in root mean square (two sigma points of a Gaussian
        error; exact where the move is linear in it). Each move is the rear axle's force at the estimate carried
        by tires of those frictions (:meth:`canest.models.two_track.TwoTrackModel.rear_axle_slips`), less the
        estimate's slip angle; with the yaw rate measured the sideslip moves with it. Near the peak of the curve a
        friction a little lower needs the peak's slip angle, which the filter's linearization does not see: after
        a slide on 0.35, on a car with its rear stiffness drawn x1.3, jckf's rear frictions sat at 0.42 and 0.47
        (std 0.11, 0.09), its rear tires at 87 and 72 % of them where the car's were at their limit, and its
        sideslip 1.9 deg off with a std of 0.5, valid; one std lower moves the rear slip angle by 1.3-1.8 deg. In
        the linear range the force needs the same slip angle at any friction and the term vanishes."""
        if not self._judgeable():
            return 0.0
        x = self.filter.x
        frictions = x[two_track.MU]
        std = np.sqrt(np.maximum(np.diag(self.filter.P)[two_track.MU], 0.0))
        here = abs(self._rear_slip(x))
        shifted = np.maximum(frictions + np.array([[-1.0], [1.0]]) * std, two_track.LOWEST_FRICTION)
        moves = self.model.rear_axle_slips(x, u, shifted) - here
        return float(np.sqrt(np.mean(moves**2)))

    def _judgeable(self) -> bool:
        """The estimate's sideslip is published and finite: at ``min_speed`` or above (else not published), every
        state finite (else reset next)."""
        x = self.filter.x
        return bool(x[two_track.VX] >= self.est.min_speed and np.all(np.isfinite(x)))

    def _covariance_holds_stiffness_error(self) -> bool:
        """The joint filter's (``parameters_valid``: jckf's) covariance holds the frictions beside the states, and
        their spread moves the tire curves the sideslip rests on: what a stiffness off by its uncertainty does to
        the sideslip is inside it, and the frictions take that error where the tires bend. The stiffness term on
        top counted it twice: jckf's sideslip within 2 std / NEES with -> without it, on the honesty grid
        99.9 % / 0.21 -> 94.6 % / 1.06, on the drawn cars (stiffnesses x0.77-1.25 of the config's) 98.2 % / 0.39
        -> 93.3 % / 1.21, with a vibrating IMU 99.9 % / 0.41 -> 97.4 % / 0.70, nothing valid but wrong either
        way (half the term: NEES 0.36 / 0.55 / 0.54). The dual filter's (dckf's) state covariance takes the
        frictions as known, and its sideslip, valid only off the tires' limit, needs the term: without it
        86.5 % / 1.53 on the drawn cars (90.4 % / 1.11 with it)."""
        return self.filter.parameters_valid

    def _sideslip_saturation_std(self) -> float:
        """The sideslip's std where it rests on tire saturation the car has not shown: while no tire's limit showed
        in the last ``LIMIT_MEMORY`` s (:meth:`_note_limit`) the measurements fit linear tires as well as the
        estimate's saturated ones, so the sideslip its rear tires' saturation makes (:meth:`_saturation_slip`, this
        tick's update) is not measured; ``UNSHOWN_SATURATION_STD`` of it puts either within 2 std. On a gentle
        country road the frictions fall towards the friction the car uses (README "Tire forces and road
        friction", "Still weak") and the sideslip with them. Not held over a second as the stiffness term is
        (:meth:`canest.estimation.judge.StateJudge.sideslip_model_std`): it is the estimate's own, without lag."""
        return self.saturation_std

    def _sideslip_friction_std(self) -> float:
        """The sideslip's std from the frictions' error once a tire's limit showed (:meth:`_friction_slip`, this
        tick's update): the tires may work near their peak there."""
        return self.friction_std

    def _limit_recent(self) -> bool:
        """A tire's limit showed in the measurements in the last ``LIMIT_MEMORY`` s (:meth:`_note_limit`)."""
        return self.since_limit <= self.memory

    def _slipping(self, inputs: TickInputs, u: np.ndarray, t: float) -> bool:
        """A wheel's slip ratio against its own centre's speed (the reference speed, updated by the wheels this
        tick, moved to each wheel by the yaw rate, the sideslip and the steering) is beyond the linear slip its
        usage needs (``Fx / Fz`` over the tire's slip stiffness) by more than ``SLIP_TOLERANCE``, the reference's
        own std (per unit speed: an integrated ax on a grade) in quadrature: spinning or locking. Braking takes
        the brake balance's share of ``m ax`` where larger than the motor torques' (friction brakes the torques
        do not show)."""
        if (self.reference is None or self.reference_speed.wheels_t != t or self.reference[0] < self.est.min_speed
                or not inputs.has("yaw_rate")):
            return False
        speed, std = self.reference
        usage = np.array(self.reference_speed.usage)  # this tick's: the reference was updated by the wheels at t
        if inputs.current("ax") < 0.0:
            usage = np.minimum(usage, tick_usage(inputs, self.geometry, self.vehicle, self.layout, use_torques=False))
        beta = self.filter.x[two_track.BETA]
        v_long, _ = self.geometry.wheel_velocities(np.array([inputs.current("yaw_rate")]), np.array([speed]),
                                                   np.array([speed * math.tan(beta)]), u[two_track.DELTA])
        slip = self.geometry.slip_ratios(np.array([inputs.values[name] for name in WHEEL_SPEEDS]), v_long[0])
        linear = usage / self.vehicle.tire.longitudinal_stiffness
        absolute, relative = SLIP_TOLERANCE
        return bool(np.any(np.abs(slip - linear) > math.hypot(absolute, std / speed) + relative * np.abs(linear)))

    def use_stiffness(self, front: float, rear: float, error: float | None = None) -> None:
        """As every model (:meth:`Estimator.use_stiffness`), and the limit's yaw test takes the understeer gradient
        of the stiffnesses in use, and its std."""
        super().use_stiffness(front, rear, error)
        self.regime.understeer = self.vehicle.understeer_gradient
        self.regime.understeer_std = validity.understeer_std(self.vehicle)

    def _frictions_pressed(self) -> bool:
        """A friction pressed against its bound while the car showed a tire's limit (:meth:`_limit_recent`), on this
        tick or earlier in the limit still showing (:meth:`_note_pressed`): the sideslip then rests on the
        frictions. Where it showed none, the sideslip's std holds the saturation the estimate assumes
        (:meth:`_sideslip_saturation_std`), and a vibrating IMU presses the frictions on 14-30 % of the ticks of any
        drive (its noise makes them fall, module docstring). Until the limit stops showing, not only for this
        tick: the exact car's step steer on 0.35 (vibrating IMU, seed 1) pressed jckf's frictions until 3.9 s of a
        slide that lasted to 5.5 s, and the sideslip, freed with them at 4.9 s (the hold's second), climbed back
        slower than the car's: 2.1-2.9 deg off with a std of 0.6-1.0, flagged valid (0.54 % of the vibrating
        grid's valid sideslip ticks wrong; none since)."""
        return self.pressed_in_episode

    def _at_limit_of_unbounded_friction(self) -> bool:
        """A tire at its limit at the estimated friction (``may_rise``, :meth:`_update`) in a filter whose covariance
        does not bound the frictions' error (``parameters_valid`` false: dckf, whose frictions carry the bias of
        step 3, :mod:`canest.filters.dual`). There the friction sets the sideslip, and that bias with it: on a
        drawn car of the honesty grid (rear stiffness x1.25) the step steer on 0.85 left dckf's rear frictions at
        0.45-0.55, then one at 0.11, and its sideslip 2-3.5 deg off with a std of 0.9-1.2, valid on 28 % of that
        drive's ticks (within 2 std on 31 % of those). ``may_rise`` is the last update's (a fresh filter's is
        all true: on a reset's tick the sideslip is ``after_reset`` first)."""
        return not self.filter.parameters_valid and bool(self.filter.parameters.may_rise.any())

    def _plausibly_lower_friction(self) -> np.ndarray:
        """The state with each friction ``LOWER_FRICTION_STDS`` standard deviations lower (not below ice).

        A tire says something about its friction if it works near its limit at
        a friction the estimate still allows. Testing at the estimate itself
        never opens the gate for an overestimated friction (measured: at 1
        standard deviation three of the joint filter's four estimates never left
        0.90 on the 50 km/h sine on friction 0.35; at 3 they are within 0.1
        after 0.3-0.8 s; README "Tire forces and road friction").
        """
        x = self.filter.x.copy()
        std = np.sqrt(np.maximum(np.diag(self.filter.P)[two_track.MU], 0.0))
        x[two_track.MU] = np.maximum(x[two_track.MU] - LOWER_FRICTION_STDS * std, two_track.LOWEST_FRICTION)
        return x

    def _extra_values(self, values: dict, valid: dict, causes: dict, std: np.ndarray, inputs: TickInputs,
                      ratios: dict) -> None:
        """Per wheel: friction is valid once excitation made it certain (std below ``MU_VALID_STD``) and a tire's
        limit showed in the measurements within ``LIMIT_MEMORY`` s (:meth:`_note_limit`; else "not_excited"), the
        channels that show the tires' forces (ax, ay, yaw rate and acceleration) agree with the filter under the
        configured noise (module docstring, "a noisy IMU"; :mod:`canest.estimation.validity`; its std widened by their
        consistency ratio; not before they have been judged, nor in the second after a reset: the frictions
        outlive a divergence reset and may be what diverged), the update has not pressed it against a bound of
        the physical range (the data then say only that the model cannot explain them: the sideslip loses its
        bit too, for a second, once the car showed a tire's limit: :meth:`_frictions_pressed`), and the
        filter's covariance bounds its parameters' error (``parameters_valid``: not the dual filter's,
        "uncertain"). The published std adds :class:`FrictionModelError`'s and the range the
        estimate spanned over ``SETTLE_WINDOW`` in quadrature, and is never below the friction's distance from
        the four wheels' mean (module docstring, "one road"); above ``MU_VALID_STD`` through them the cause is
        "uncertain" (through the filter's own, "not_excited")."""
        ratio = ratios["friction"]
        frictions, filter_stds = self.filter.x[two_track.MU], std[two_track.MU] * validity.inflation(ratio)
        self.recent.append(frictions.copy())
        movement = np.ptp(self.recent, axis=0)
        spread = np.sqrt(filter_stds**2 + self.model_error.std**2 + movement**2)
        friction_stds = np.maximum(spread, np.abs(frictions - frictions.mean()))  # never more certain than its split
        pressed = self.filter.parameters.pressed
        every_wheel = ("after_reset" if causes["beta"] == "after_reset"
                       else "inconsistent" if ratio > validity.INCONSISTENT
                       else "uncertain" if not self.filter.parameters_valid
                       else "not_excited" if math.isnan(ratio) or not self._limit_recent()
                       else None)  # what holds for all four alike
        wheel_causes = []
        for name, mu, mu_std, filter_std, observable, at_bound in zip(FRICTIONS, frictions, friction_stds,
                                                                       filter_stds, self.observable, pressed):
            values[name], values[f"{name}_std"] = mu, mu_std
            cause = "at_bound" if at_bound else every_wheel or ("not_excited" if filter_std >= MU_VALID_STD
                                                                else "uncertain" if mu_std >= MU_VALID_STD
                                                                else "valid")
            valid[name] = cause == "valid"
            valid[f"{name}_observable"] = bool(observable)
            wheel_causes.append(cause)
        valid["friction"] = any(valid[name] for name in FRICTIONS)
        valid["friction_observable"] = bool(self.observable.any())
        causes["friction"] = "valid" if valid["friction"] else min(wheel_causes, key=validity.CAUSES.index)
