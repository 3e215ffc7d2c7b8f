"""Validity by consistency, and published standard deviations that cover the model's error.

A validity bit means "consistent with what the car measures, within the
published std", never merely "inputs present". Each tick, before the
measurement update, every usable channel's innovation at the filter's prior
is normalized by what the sensor's noise and the prior spread explain:

    d_c = (z_c - h_c(x-))^2 / ((H P- H^T)_cc + R_c)          (R_c never adapted or reweighted by a filter)

``R_c`` is the configured noise, or an accelerometer's noise as its own
samples show it where that is larger (:mod:`canest.estimation.measured_noise`:
the scatter of the signal, no model, no innovation; the R every filter takes
for it). A vibrating body shakes ay by 1.4 m/s^2 where 0.11 is configured:
judged by the configured noise the sideslip was never valid on such an IMU
(issue 17's real car's ay jumped so). Friction alone keeps the configured noise (its
one-sided gate turns a noisy IMU into a falling estimate:
:mod:`canest.estimation.two_track`).

A consistent estimator gives d_c about 1 on average. :class:`Consistency`
keeps the last ``WINDOW`` values per channel; a state is *inconsistent* when
the mean over the channels that observe it exceeds ``INCONSISTENT`` (a
generous bound: coloured road noise and model error raise the mean of a
healthy filter to 2-3; a yaw rate of the wrong sign gives thousands at once).
A gyro that disagrees with the published yaw rate clears the yaw-rate bit
whatever the filter did with the gyro (the maximum-correntropy and adaptive
filters can reweight a channel to silence): the test never sees a filter's
adapted or reweighted R.

Published standard deviations get these terms beyond the filter's covariance:

- the consistency ratio: where a state's channels show ``mean d = k > 1``,
  the prior spread explains only ``1/k`` of what is measured, so the state's
  standard deviation is scaled by ``sqrt(k)`` (innovation-driven, as a
  covariance-matching adaptive filter would scale Q, but on the published
  value only, so every filter's estimate stays what its paper gives);
- the yaw rate's gyro noise as its samples show it, over the noise the
  filter's covariance took for it (the configured, or an adaptive filter's
  learned R: :mod:`canest.estimation.measured_noise`, a factor never below 1): a
  vibrating gyro's coloured noise, which the prior follows, hides from the
  innovations;
- the sideslip's model error: a rear cornering stiffness off by a relative
  ``e`` moves the steady-state sideslip by ``e m a |ay| / (L C_r)`` (rear
  slip angle ``alpha_r = F_yr / C_r`` with ``F_yr = m ay a / L``), added in
  quadrature, at ``|v r|`` for ``ay`` (the steady-state ay; a vibrating ay would shake the term), held as a
  leaky maximum over ``MODEL_ERROR_MEMORY`` (:meth:`canest.estimation.judge.StateJudge.sideslip_model_std`). A user's
  stiffness is uncertain by ``e_0``
  (``vehicle.cornering_stiffness_uncertainty``: 0.3 for textbook values; for linear tires, once the online
  calibration applies learned stiffnesses, their error,
  :attr:`canest.estimation.online_calibration.OnlineCalibration.stiffness_error`, takes its place:
  ``Estimator.use_stiffness``); a model with linear tires adds
  ``e_2 (ay / g)^2``, because every tire's secant stiffness falls with the
  square of its slip at first (the cubic term of any tire curve:
  ``sin(C atan(B a)) ~ C B a - k a^3``): ``e_2`` (:data:`DEGRESSIVE_STIFFNESS`)
  makes ``e`` 0.6 at 0.65 g, the error of the simulator's Magic Formula
  tires on dry road (sideslip 1.8 deg off at 6.3 m/s^2). Models with a tire
  curve (tire force, two track) have that growth in their dynamics, and their
  term is ``e |alpha_r|`` at the estimate (the rear slip angle
  ``atan((vy - b r) / vx)``): a curve that scales the slip by the stiffness,
  ``F = F(B alpha)``, puts a relative stiffness error into the slip angle at a
  given force whole, and with the yaw rate measured the sideslip's error is
  the rear slip angle's. It equals the linear term at small slip and grows
  past it near the limit, where ``F / C_r`` had left jckf's and dckf's
  sideslip valid but wrong on 0.7 and 1.2 % of the ticks of cars drawn as
  wrong as their config admits (``tools/honesty.py --car drawn``); for the
  friction models, while the car has shown no tire's limit, the term also
  holds half the sideslip their rear tires' saturation makes beyond linear tires
  (:meth:`canest.models.two_track.TwoTrackModel.rear_saturation_slip`), and once it has shown one, the
  rear slip angle's move when the frictions are one std off: near the peak a friction a little lower needs
  the peak's slip angle for the same force, which the filter's linearization does not see
  (:meth:`canest.estimation.two_track.FrictionEstimator._friction_slip`; published with the sideslip, left
  out of vx's drift bound below). The joint friction filter (jckf) takes no ``e |alpha_r|``: its covariance
  holds the frictions, which bend the curves the sideslip rests on, and the stiffness's error with them
  (:meth:`canest.estimation.two_track.FrictionEstimator._covariance_holds_stiffness_error`);
- the sideslip is never published more certain than its remembered mismatch
  with the kinematic sideslip (:class:`KinematicCheck`), and vx's std grows
  by ``|r|`` times the lateral velocity's std while the wheels do not measure
  vx (:class:`LateralDrift`);
- vx is never published more certain than the random walk the ax noise put
  into the reference speed since the wheels last anchored it: a filter takes
  that reference every tick as a new measurement, but its walk is one error
  they all share (on a vibrating IMU ckf's vx NEES was 4.6, its error at the
  anchors 0.12 m/s where the reference's was 0.035;
  :meth:`canest.estimation.reference_speed.ReferenceSpeed.integration_std`);
- nor more certain than its distance from the reference speed beyond the
  reference's std (with the lateral drift above, which it integrates too):
  the least error the estimate has while the reference is within one std
  (:meth:`canest.estimation.reference_speed.ReferenceSpeed.disagreement`),
  a leaky maximum fading over ``HOLD`` s, where the wheels' forces drive vx: such a
  model follows its own course between anchors, with a prior too small for
  the reference to pull it back (dckf's frictions, drifting on a vibrating
  launch on 0.35, ran its vx 1.3-1.9 m/s ahead with a std of 0.23, valid,
  while the reference was 0.4 off with a std of 0.3). A model integrating ax
  shares the reference's integration, ax and ``r vy`` alike: their
  difference tells nothing there;
- vx and the yaw rate carry the error of the wheel radius and the gyro bias,
  in quadrature: the config's claim (``vehicle.wheel_radius_uncertainty``,
  ``estimator.gyro_bias_std``) until the online calibration applies its own
  correction, then that correction's error
  (:attr:`canest.estimation.online_calibration.OnlineCalibration.correction_std`):
  one error every tick shares, which no consistency test sees (the reference
  speed takes the same scaled wheels; the filter's prior follows the gyro).

Sideslip also needs the model inside its valid regime. A model with fixed
tire friction (the single-track model's linear tires, the tire-force
model's nominal friction) explains a saturated car by a wrong sideslip with
small innovations ("consistent but wrong"). As an ESC does, :class:`LinearRegime`
compares the gyro with the linear steady-state yaw rate of the steering,
``r_ref = vx delta / (L + K_us vx^2)`` (understeer gradient
``K_us = m (b C_r - a C_f) / (L C_f C_r)``), lagged by the yaw response
``REGIME_LAG``: beyond ``REGIME_TOLERANCE`` (absolute plus relative) the tires
saturate and the sideslip is ``model_regime``. A model that estimates friction
explains saturation itself, unless its frictions' error is bounded by no
covariance (dckf): then its sideslip is ``model_regime`` while a tire works at
its limit (:meth:`canest.estimation.two_track.FrictionEstimator._at_limit_of_unbounded_friction`).

And sideslip must move as the car says it moves: over the last
``KINEMATIC_WINDOW`` s the model's sideslip change must agree with the
kinematic one, the integral of ``ay / vx - r`` (gyro and accelerometer
only, no model; biases drift it by ~0.1 deg/s, so a short window), within
``KINEMATIC_TOLERANCE`` (absolute plus relative; and, for an ay louder than
configured, its integrated noise) (:class:`KinematicCheck`).
A car sliding into a slow spin on low friction keeps small innovations while
the model's sideslip stays near zero; the kinematic sideslip sees the slide.
A window sees only its last half second, and a steady slide passes it: a
sideslip that lost its bit comes back only while the kinematic lateral
velocity's change since it was last valid agrees with the model's
(:meth:`LateralDrift.allows_return`).

vx, integrated from ax while the wheels do not roll freely
(``dvx/dt = ax + r vy``), drifts by ``r`` times the lateral velocity the
model does not see: on the simulator's DLC on friction 0.35 the car slides
to 20-80 deg of sideslip while the model's stays near 0, and the reference
speed's integrated ``ax`` drove vx 2-4 m/s above the truth with std 0.07
(47 % of that drive's vx ticks valid but wrong). :class:`LateralDrift` bounds that drift from the
kinematic lateral velocity (``dvy/dt = ay - r vx``, gyro and accelerometer,
no model) since the sideslip was last valid, integrated since the wheels last
measured vx: the vx std grows by it (in quadrature) and above ``DRIFT_LIMIT``
vx is ``model_regime`` (the car slides).

A state stays invalid for ``HOLD`` s after a test last failed
(:class:`Holds`): the innovations of a model out of its regime come in
bursts, and a bit that flickers back between them is not a promise. (An
input returning after a gap does not fail a test: its first innovation
measures the gap's drift, which that update corrects; see the judge.)

Why a bit is clear is published too (:data:`CAUSES`, CAN ``CE_ValidityCause``).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np


from canest.estimation.estimate import CAUSE_GROUPS as GROUPS, CAUSES
from canest.estimation.lags import FirstOrderLag

__all__ = ["CAUSES", "GROUPS", "Consistency", "Holds", "KinematicCheck", "LateralDrift", "LinearRegime", "RoadOffset",
           "inflation", "judge", "innovation_terms", "sideslip_model_std", "sideslip_offset_std", "understeer_std"]

WINDOW = 50  # channel samples
MIN_SAMPLES = 10  # before this many samples a channel's mean is not judged
INCONSISTENT = 9.0  # windowed mean of d above which a state is inconsistent with what is measured
DEGRESSIVE_STIFFNESS = 0.7  # growth of that error with (ay / g)^2: the tire curve's first nonlinear term
GRAVITY = 9.81
VX_VALID_STD = 0.5  # m/s: a published vx less certain than this is "uncertain"
HOLD = 1.0  # s a failed test keeps a state invalid
HELD_CAUSES = ("inconsistent", "model_regime", "at_bound", "after_reset")
REGIME_LAG = 0.15  # s, first-order lag of the steady-state yaw rate (a passenger car's yaw response)
REGIME_TOLERANCE = (0.035, 0.2)  # rad/s plus a share of the reference: ESC's yaw-rate deviation band
KINEMATIC_WINDOW = 0.5  # s
KINEMATIC_TOLERANCE = (math.radians(0.5), 0.25)  # rad plus a share of the kinematic change
KINEMATIC_MEMORY = 2.0  # s, time constant of the sideslip's remembered mismatch with the kinematic one
KINEMATIC_BIAS_ALLOWANCE = math.radians(0.25)  # rad of that mismatch the sensors' biases explain
MODEL_ERROR_MEMORY = 1.0  # s, time constant of the leaky maximum the sideslip's model error is taken at
KINEMATIC_NOISE_GATE = 2.0  # standard deviations of ay's integrated noise the kinematic change may be off by
KINEMATIC_MISMATCH_GATE = 1.0  # standard deviations of that noise the remembered mismatch is taken beyond (a std floor)
DRIFT_LIMIT = 0.5  # m/s of possible vx drift above which the car slides (vx "model_regime"; as VX_VALID_STD)
RETURN_TOLERANCE = math.radians(0.5)  # rad, as a lateral velocity at vx: what a sideslip coming back may have missed
RETURN_MEMORY = 5.0  # s after the sideslip was last known within which its return is tested (an unlearned offset)
OFFSET_MEMORY = 30.0  # s, time constant over which the road's lateral offset is learned from the sideslip's known ticks
# The channels that observe each published state (any model; a model without the channel just lacks it).
OBSERVED_BY = {
    "yaw_rate": ("yaw_rate", "yaw_rate_2"),
    "vx": ("vx_wheel", "vx_reference"),
    "beta": ("ay", "ay_2", "yaw_rate", "yaw_rate_2", "yaw_acceleration"),
    # friction shows in the body's forces: what the tires transmit, longitudinally, laterally and in yaw
    "friction": ("ax", "ay", "yaw_rate", "yaw_acceleration"),
}


class Consistency:
    """Per measurement channel, the last ``WINDOW`` normalized innovations squared (module docstring: ``d_c``)."""

    def __init__(self, names):
        self.names = tuple(names)
        self.windows = {name: deque(maxlen=WINDOW) for name in self.names}

    def reset(self) -> None:
        for window in self.windows.values():
            window.clear()

    def restart(self, rows) -> None:
        """Forget the windows of channels ``rows``."""
        for row in rows:
            self.windows[self.names[row]].clear()

    def push(self, rows, d: np.ndarray) -> None:
        for row, value in zip(rows, d):
            self.windows[self.names[row]].append(float(value))

    def ratio(self, state: str, min_samples: int = MIN_SAMPLES) -> float:
        """The largest windowed mean of d over the channels observing ``state`` (nan: none has ``min_samples``)."""
        means = [sum(w) / len(w) for name in OBSERVED_BY[state] if len(w := self.windows.get(name, ())) >= min_samples]
        return max(means) if means else math.nan


def innovation_terms(measurement, x_prior, P_prior, u, z) -> tuple:
    """Per row, the innovation squared and the prior spread ``(H P- H^T)_cc``: ``d`` is their ratio with a noise's
    variance added to the spread."""
    predicted = measurement.h(x_prior[None, :], u)[0]
    H = measurement.jacobian(x_prior, u)
    return (z - predicted) ** 2, np.maximum(np.einsum("ij,jk,ik->i", H, P_prior, H), 0.0)


def judge(present: bool, saturated: bool, ratio: float) -> str:
    """The cause of a measured state: a saturated input, no input, inconsistent channels, or valid."""
    if saturated:
        return "saturated"
    if not present:
        return "no_input"
    if ratio > INCONSISTENT:
        return "inconsistent"
    return "valid"


def inflation(ratio: float) -> float:
    """The factor on a published std from its channels' consistency ratio (never below 1)."""
    return math.sqrt(ratio) if ratio > 1.0 else 1.0


def sideslip_model_std(vehicle, ay: float, rear_slip: float | None = None) -> float:
    """Sideslip error (rad) of a rear cornering stiffness off by its relative uncertainty: from the estimate's
    ``rear_slip`` angle (rad) for a model with a tire curve, else at ``ay`` for linear tires, whose secant stiffness
    also falls with ``(ay / g)^2`` (module docstring)."""
    if rear_slip is not None:
        return vehicle.cornering_stiffness_uncertainty * abs(rear_slip)
    uncertainty = vehicle.cornering_stiffness_uncertainty + DEGRESSIVE_STIFFNESS * (ay / GRAVITY) ** 2
    return uncertainty * vehicle.mass * vehicle.cg_to_front * abs(ay) / (vehicle.wheelbase * vehicle.cornering_stiffness_rear)


def sideslip_offset_std(vehicle, ay_offset: float) -> float:
    """The sideslip error (rad) an offset in ay the model does not take can cause: ``m |c| / (C_f + C_r)``, the
    steady single track's sideslip for a side force ``m c`` its tires carry. The online calibration learns the
    offset ``c`` but never applies it: a bias and a road's bank (``-g sin(bank)``, a side force the model's
    dynamics lack) look the same. An upper bound (the gyro holds part of it). The judge takes it for the part of
    ``c`` beyond ay's configured noise: on a road banked 3 deg with an ay bias of 0.2 (c = -0.31 m/s^2) the
    sideslip was within 2 std on 92 % of its valid ticks, NEES 2.06, with the configured 0.11 m/s^2 (a crown's
    bias, not a bank's) alone; 100 %, 0.43 with it."""
    return vehicle.mass * abs(ay_offset) / (vehicle.cornering_stiffness_front + vehicle.cornering_stiffness_rear)


def understeer_std(vehicle) -> float:
    """The understeer gradient's std (s^2/m) when each axle's cornering stiffness is off by the relative
    ``cornering_stiffness_uncertainty``, independently: ``K_us = (m / L) (b / C_f - a / C_r)`` moves by
    ``(m / L) b / C_f`` per relative error of ``C_f`` and ``(m / L) a / C_r`` per one of ``C_r``."""
    return vehicle.cornering_stiffness_uncertainty * vehicle.mass / vehicle.wheelbase * math.hypot(
        vehicle.cg_to_rear / vehicle.cornering_stiffness_front, vehicle.cg_to_front / vehicle.cornering_stiffness_rear)


class LinearRegime:
    """Whether the measured yaw rate follows the linear steady-state yaw rate of the steering (tires not saturated).

    ``understeer_std`` (s^2/m, :func:`understeer_std`; 0: the ESC band alone) widens the band by the share of the
    reference that one std of the understeer gradient moves: ``r = vx delta / (L + K vx^2)`` moves by
    ``r vx^2 / (L + K vx^2)`` per unit of ``K``, about a fifth of ``r`` per std at 80 km/h for the built-in car
    (0.15 claimed)."""

    def __init__(self, vehicle, dt: float, understeer_std: float = 0.0):
        self.wheelbase = vehicle.wheelbase
        self.understeer = vehicle.understeer_gradient
        self.understeer_std = understeer_std
        self.reference = FirstOrderLag(dt, REGIME_LAG)

    def reset(self) -> None:
        self.reference.reset()

    def inside(self, delta: float, vx: float, yaw_rate: float) -> bool:
        denominator = max(self.wheelbase + self.understeer * vx * vx, 0.1 * self.wheelbase)
        reference = self.reference.update(vx * delta / denominator)
        absolute, relative = REGIME_TOLERANCE
        relative += self.understeer_std * vx * vx / denominator
        return abs(yaw_rate - reference) <= absolute + relative * abs(reference)


class Holds:
    """Keep a state invalid for ``HOLD`` s after a test of :data:`HELD_CAUSES` last failed, with that cause (also
    over vx's ``uncertain``, which clears its bit but not vy's: a held vx is not only wide)."""

    def __init__(self):
        self.until = {}
        self.cause = {}

    def reset(self) -> None:
        self.until.clear()
        self.cause.clear()

    def apply(self, state: str, cause: str, t: float) -> str:
        if cause in HELD_CAUSES:
            self.until[state], self.cause[state] = t + HOLD, cause
            return cause
        if cause in ("valid", "uncertain") and t < self.until.get(state, -math.inf):
            return self.cause[state]
        return cause


class KinematicCheck:
    """Whether the model's sideslip changed as ``integral(ay / vx - r)`` did over the last ``KINEMATIC_WINDOW`` s.

    :attr:`mismatch` (rad) is how far the model's sideslip moved away from the kinematic one, remembered over
    ``KINEMATIC_MEMORY`` s (a leaky integral of the difference of their rates), beyond what the sensors' biases
    explain (``KINEMATIC_BIAS_ALLOWANCE``: the simulated IMU's alone hold the difference at 0.26 deg at
    80 km/h): evidence of the sideslip's error that the published std is never below. A slide building up on
    0.35 outran jckf's sideslip by 0.8 deg per window, inside the tolerance, until it was 2 deg off with a std
    of 0.62, flagged valid; in a lane change the difference swings both ways and cancels.

    ay's noise integrates into both: a vibrating ay (1.4 m/s^2, correlated over 15 ms) puts 0.45 deg of noise
    into the kinematic change per half second at 80 km/h, and the window's 0.5 deg failed a model that follows
    the car exactly. For an ay louder than configured (``ay_density`` 0 otherwise) the tolerance takes
    ``KINEMATIC_NOISE_GATE`` standard deviations of that integrated noise (from ay's measured density), in
    quadrature: independent of the biases and of the model's share (their sum let the sideslip on the vibrating
    honesty grid be valid on 28-58 % of the ticks and wrong on 0.1-1.0 % of them; in quadrature 10-29 % and
    0.0-0.3 %). The mismatch's allowance takes ``KINEMATIC_MISMATCH_GATE`` (one) standard deviation of it: the
    mismatch is a std floor, not a test, and what it shows beyond one std of its noise is as likely an error as
    the std itself says one is. At two, a vibrating ay hid 1.3 deg of the leaky difference at 80 km/h, and
    dici-gfckf's sideslip in a slide's onset on 0.35 (drawn car, seed 2) was 1.4-1.9 deg off with a std of
    0.45, flagged valid, while the window's test still passed (the honesty grid's drawn cars with a vibrating
    IMU: valid but wrong 0.20 -> 0 %; within 2 std 98.3 -> 98.6 %, NEES 0.57 -> 0.54; the 3-DOF filters'
    within 2 std as before, NEES 0.61 -> 0.60). A quiet ay's density is 0: there it changes nothing."""

    def __init__(self, dt: float):
        self.dt = dt
        self.history = deque(maxlen=max(2, int(round(KINEMATIC_WINDOW / dt)) + 1))
        self.leak = math.exp(-dt / KINEMATIC_MEMORY)
        self.reset()

    def reset(self) -> None:
        self.history.clear()
        self.kinematic = 0.0
        self.kinematic_noise = 0.0  # variance (rad^2) the ay noise put into ``kinematic`` since the reset
        self.difference = 0.0
        self.difference_noise = 0.0  # variance of that noise in the leaky ``difference``
        self.mismatch = 0.0

    def inside(self, beta: float, ay: float, yaw_rate: float, vx: float, ay_density: float = 0.0) -> bool:
        """The check on this tick's inputs; ``ay_density`` (m^2/s^3): ay's noise density as its samples show it
        (:attr:`canest.estimation.measured_noise.MeasuredNoise.density`), whose integral the tolerance takes at
        ``KINEMATIC_NOISE_GATE`` standard deviations and the mismatch's allowance at ``KINEMATIC_MISMATCH_GATE``."""
        rate = (ay / vx - yaw_rate) * self.dt
        noise = ay_density * self.dt / (vx * vx)
        if self.history:
            self.difference = self.leak * self.difference + (beta - self.history[-1][0]) - rate
            self.difference_noise = self.leak * self.leak * self.difference_noise + noise
            allowance = math.hypot(KINEMATIC_BIAS_ALLOWANCE, KINEMATIC_MISMATCH_GATE * math.sqrt(self.difference_noise))
            self.mismatch = max(0.0, abs(self.difference) - allowance)
        self.kinematic += rate
        self.kinematic_noise += noise
        self.history.append((beta, self.kinematic, self.kinematic_noise))
        if len(self.history) < self.history.maxlen:
            return True
        (beta_then, kinematic_then, noise_then), (beta_now, kinematic_now, noise_now) = self.history[0], \
            self.history[-1]
        change = kinematic_now - kinematic_then
        absolute, relative = KINEMATIC_TOLERANCE
        gate = KINEMATIC_NOISE_GATE * math.sqrt(noise_now - noise_then)
        return abs((beta_now - beta_then) - change) <= math.hypot(absolute + relative * abs(change), gate)


class RoadOffset:
    """The road's lateral offset (m/s^2): the rate at which the kinematic lateral velocity, ``integral(ay - r vx)``,
    leaves the model's ``vx tan(beta)`` while the sideslip is known: a bank's gravity, an ay bias, a gyro bias times
    vx, none of them a lateral velocity of the car's.

    Learned over the ticks the sideslip was known (each stretch of them adds its change of that difference and
    its time) as a leaky mean over ``OFFSET_MEMORY`` s, so a road whose bank changes is followed. The measured
    rate's error is the model's lateral velocity error at each stretch's two ends (its std,
    ``lateral_std``, at both) and ay's integrated noise beyond the configured, at ``KINEMATIC_NOISE_GATE``
    standard deviations, over the stretches' time; combined with the prior the config gives (0, the configured
    ay noise: the offset it admits), a few seconds of known sideslip learn little and a long drive learns the
    road. :attr:`rate` and :attr:`std` are that combination: with nothing learned 0 and the configured noise."""

    def __init__(self, dt: float, prior_std: float):
        self.dt = dt
        self.prior_std = prior_std
        self.leak = math.exp(-dt / OFFSET_MEMORY)
        self.reset()

    def reset(self) -> None:
        self.change = 0.0  # m/s, the difference's change over the known ticks (a leaky sum)
        self.time = 0.0  # s, those ticks' time (a leaky sum)
        self.variance = 0.0  # m^2/s^2, the variance of ``change``'s error: the stretches' ends and ay's noise
        self.last = None  # (difference, lateral_std) on the last tick, if the sideslip was known on it

    def update(self, difference: float, known: bool, lateral_std: float, ay_density: float) -> None:
        """One tick: ``difference`` (m/s) the kinematic lateral velocity less the model's, ``known`` the sideslip,
        ``lateral_std`` (m/s) the model's lateral velocity std, ``ay_density`` (m^2/s^3) ay's noise density beyond
        the configured (:class:`KinematicCheck`)."""
        self.change *= self.leak
        self.time *= self.leak
        self.variance *= self.leak * self.leak
        if known and self.last is not None:
            self.change += difference - self.last[0]
            self.time += self.dt
            self.variance += ay_density * self.dt
        elif known:  # a stretch begins: its start's error
            self.variance += lateral_std * lateral_std
        elif self.last is not None:  # a stretch ended: its end's error
            self.variance += self.last[1] * self.last[1]
        self.last = (difference, lateral_std) if known else None

    def _measured_variance(self) -> float:
        ended = self.variance + (self.last[1] ** 2 if self.last is not None else 0.0)  # an open stretch's end
        return KINEMATIC_NOISE_GATE ** 2 * ended / (self.time * self.time)

    @property
    def rate(self) -> float:
        """The offset (m/s^2), the measured rate shrunk towards 0 as its error is to the prior."""
        if self.time <= 0.0 or self.prior_std <= 0.0:
            return 0.0
        prior = self.prior_std ** 2
        return self.change / self.time * prior / (prior + self._measured_variance())

    @property
    def std(self) -> float:
        """The offset's error (m/s^2): the prior's and the measurement's, combined."""
        if self.time <= 0.0 or self.prior_std <= 0.0:
            return self.prior_std
        prior, measured = self.prior_std ** 2, self._measured_variance()
        return math.sqrt(prior * measured / (prior + measured))


class LateralDrift:
    """The vx error (m/s) an unmodelled lateral velocity can have caused since the wheels last measured vx.

    ``vx`` follows ``dvx/dt = ax + r vy``; with the model's ``vy = vx tan(beta)`` wrong by ``e`` the error
    grows at ``r e``. ``e`` is the kinematic lateral velocity's change, ``integral(ay - r vx)``, less the
    model's, since the model's sideslip was last known (valid); the drift is ``|integral(r e)|`` since the
    wheels last measured vx (``vx_measured``: the reference speed rolled freely). A filter restart moves the
    model's sideslip, not the car's: the car's lateral velocity stays anchored where the model last knew it,
    so ``e`` takes in the restarted model's jump (continuing ``e`` instead let mcsckf's vx, restarted four times
    in a slide with the sideslip 7 deg off, run 0.9 m/s off against a drift bound of 0.3, flagged valid).

    While the sideslip is known, its error is what its std says, and a systematic one (a stiffness off, see
    :func:`sideslip_model_std`): vx's error grows at ``r`` times the lateral velocity's std, linearly.
    :attr:`spread` is that bound, ``integral(|r| std(vy))`` since the wheels last measured vx (the step steer
    on 0.85 drove ckf's vx 0.4 m/s high in 4 s with a std of 0.11, a sideslip 0.9 deg off within its std).

    :attr:`unexplained` is the lateral velocity's error while the sideslip is not known, for what the error does
    beside the drift (vx read through the steered wheels, :func:`canest.estimation.judge.steered_wheels_std`):
    ``|e|`` beyond what an ay offset of ``ay_bias`` (the configured ay noise: the offset it admits) integrates to
    over that time. Taken whole, ``e`` drifts with every ay bias for as long as the sideslip stays unknown: a drawn
    car's ay bias of -0.21 m/s^2 in a 180 s slalom at 20 km/h (its sideslip valid on 9 % of the ticks) took ckf's
    vx std to 0.6 m/s against errors below 0.1, and vx ``uncertain``. Remembered for 5 s only instead (a leaky
    ``e``), dici-gfckf's vx in the step steer on 0.35, its sideslip 3-4 deg off for 5 s, fell out of its std
    again (within 2 std on 93 % of the ticks).

    :meth:`allows_return` keeps a sideslip that was not known from coming back while :attr:`unexplained` is beyond
    ``RETURN_TOLERANCE`` at vx and ``KINEMATIC_NOISE_GATE`` standard deviations of ay's integrated noise (from its
    measured density) since then, for at most ``RETURN_MEMORY`` s: the kinematic window test
    (:class:`KinematicCheck`) sees only its last half second, and a steady slide passes it. On a drawn car's
    step steer on 0.35 in gusts, jckf's sideslip came back 1.7 s after the slide began, 3.3 deg off with a std
    of 1.0: its model had moved 1.7 deg, the car's lateral velocity 0.5 m/s more.
    """

    def __init__(self, dt: float, ay_bias: float = 0.0):
        self.dt = dt
        self.road = RoadOffset(dt, ay_bias)
        self.reset()

    def reset(self) -> None:
        self.road.reset()
        self.kinematic = 0.0
        self.known = None  # (kinematic, model) lateral velocity when the sideslip was last known
        self.ever_known = False  # the sideslip was known since the reset: the anchor is a valid one
        self.drift = 0.0
        self.spread = 0.0
        self.mismatch = 0.0  # m/s, ``e`` of the last update
        self.unknown_for = 0.0  # s since the sideslip was last known
        self.unknown_noise = 0.0  # m^2/s^2, the variance ay's noise put into ``e`` over that time

    def update(self, ay: float, yaw_rate: float, vx: float, beta: float, vx_measured: bool,
               sideslip_known: bool, lateral_std: float = 0.0, ay_density: float = 0.0) -> float:
        """The drift bound ``|integral(r e)|`` (m/s); :attr:`spread` grows by ``|r| lateral_std dt`` (m/s);
        ``ay_density`` (m^2/s^3): ay's noise density as its samples show it (:meth:`allows_return`)."""
        self.kinematic += (ay - yaw_rate * vx) * self.dt
        model = vx * math.tan(beta)
        if sideslip_known or self.known is None:
            self.known = (self.kinematic, model)
        self.road.update(self.kinematic - model, sideslip_known, lateral_std, ay_density)
        self.ever_known = self.ever_known or sideslip_known
        self.unknown_for = 0.0 if sideslip_known else self.unknown_for + self.dt
        self.unknown_noise = 0.0 if sideslip_known else self.unknown_noise + ay_density * self.dt
        self.mismatch = (self.kinematic - self.known[0]) - (model - self.known[1])
        self.drift = 0.0 if vx_measured else self.drift + yaw_rate * self.mismatch * self.dt
        self.spread = 0.0 if vx_measured else self.spread + abs(yaw_rate) * lateral_std * self.dt
        return abs(self.drift)

    @property
    def unexplained(self) -> float:
        return max(0.0, abs(self.mismatch) - self.road.prior_std * self.unknown_for)

    @property
    def unexplained_by_road(self) -> float:
        """``|e|`` less the road's learned offset (:class:`RoadOffset`) integrated over the time unknown, beyond that
        offset's error integrated alike: what :meth:`allows_return` tests. vx's std keeps :attr:`unexplained`: a
        model's slow slide during the known ticks reads as road offset too, and taken there it left dici-gfckf's
        vx in the step steer on 0.35 (its sideslip 3-6 deg off) within 2 std on 87 % of its valid ticks, 94 %
        without it."""
        road = self.road
        return max(0.0, abs(self.mismatch - road.rate * self.unknown_for) - road.std * self.unknown_for)

    def allows_return(self, vx: float) -> bool:
        """Whether a sideslip not known may be known again: its lateral velocity's error beyond the road's learned
        offset (:attr:`unexplained_by_road`) is within
        ``RETURN_TOLERANCE`` at ``vx`` and the noise gate, in quadrature. Tested only against an anchor that was
        known (not a start's) and for ``RETURN_MEMORY`` s: a road offset beyond the learned one (a bank that
        changed while the sideslip was unknown) would otherwise hold the bit shut for good. Before the offset was
        learned (:class:`RoadOffset`) the Ford's log, whose ay runs 0.25 m/s^2 off the kinematic identity against
        a configured 0.15, had its sideslip valid on 50 ticks of 2090 without that limit, then never again."""
        if not self.ever_known or self.unknown_for > RETURN_MEMORY:
            return True
        gate = KINEMATIC_NOISE_GATE * math.sqrt(self.unknown_noise)
        return self.unexplained_by_road <= math.hypot(RETURN_TOLERANCE * abs(vx), gate)
