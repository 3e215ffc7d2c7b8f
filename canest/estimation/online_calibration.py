"""Online self-calibration: the car's parameters and sensor biases learned while it drives, slowly and bounded.

In the spirit of openpilot's ``paramsd`` (steer ratio, stiffness factor, angle
offset and roll learned by a small Kalman filter, bounded, saved): a Kalman
filter over the parameters below, each a random walk of small process noise
(``drift``: it may wander that much in an hour), the measurement noise per
block widened for the errors' correlation in time: after two minutes of
bends, 5 s of a 0.25 m/s^2 ay error move the learned ay offset by 0.09, a
third of it, tested), updated at ``BLOCK`` s from the *raw* inputs' block means (10 ticks
averaged: their noise shrinks, and the learner costs a few microseconds a
tick). Each update is one identity of :mod:`canest.models.identities`, used
only when the drive excites it and the car is steady enough for it to hold:

- ``kinematic`` (speed above ``MIN_SPEED``, steady yaw rate): ``ay_m = s v_w (r_m - b_r) + c`` (``v_w`` the
  wheels' speed without their motors' slip, :mod:`canest.estimation.calibration_blocks`)
  observes the speed scale ``speed`` (the effective wheel radius over the configured one), the gyro bias
  ``gyro_bias`` and the lateral offset ``ay_bias`` (the accelerometer's bias plus the mean bank's
  ``-g sin(bank)``: no sensor here tells them apart);
- ``steering`` (above ``MIN_STEER_SPEED``, |v r| below ``LINEAR_AY``, steady steering and yaw rate):
  ``delta_sw = offset + R (k L r / v + u v r)`` observes ``steering_offset`` and, in bends, ``ratio`` (``k``,
  a factor on the configured ratio ``R``) and ``u = k K_us``, reported as ``understeer`` (``K_us``, the
  stiffnesses' balance): linear in what it learns, so no linearization point can mislead it;
- ``longitudinal`` (moving, |v r| small): ``ax_m = s dv_w/dt + b_ax`` observes ``ax_bias`` (bias plus the
  mean grade's ``g sin(grade)``); it *considers* the speed scale (Schmidt, :meth:`_update`) but does not learn
  it: a car pitches as it accelerates (nose up, about 2 deg per g), so its accelerometer reads ``ax`` a few
  percent high, and a speed scale learned from it holds that. On the real Ford log (an ACC speed-up from 30
  to 80 km/h, looped to 80 s) this identity alone learned the scale as 1.033 +- 0.008, applied, vx ran 3 %
  above the car's own speed signal; the kinematic one alone 1.008 +- 0.022. The simulator's IMU does not
  pitch, so there both agree;
- ``standstill`` (wheels still): ``r_m = b_r``;
- ``gyros`` (a second gyro mapped, steady yaw rate, any speed): ``r_m - r_m2 = b_r - b_r2`` observes the second
  gyro's bias ``gyro_bias_2`` (an airbag unit's), the first's *considered* (:meth:`_gyros_update`).

A scalar update whose innovation exceeds ``GATE`` standard deviations is left
out (a transient or a pothole, not evidence). Each parameter's mean is held in
its physical bounds. A parameter counts as *converged* once its standard
deviation is below ``converged`` and ``MIN_EVIDENCE`` s of blocks excited it.
The *applied* value (what corrects the inputs the estimator sees) follows the
learned one, by at most ``rate`` per second, once ``APPLY_EVIDENCE`` s of blocks
excited it: the learned mean is the best estimate the drive gives (the prior
shrinks it), so it is applied before it is certain (:meth:`_follow`); the gyro
bias waits for convergence, the second gyro's for its difference to the first's.
The correction acts on the inputs, so every model gains from it: wheel speeds
times ``speed``, yaw rates less ``gyro_bias`` and ``gyro_bias_2``, steering
angle over ``ratio``. ``ax_bias`` is learned and reported, not applied:
it holds the road's grade, which changes faster than a calibration may follow;
the reference speed learns ax's offset from the wheels within a second
(:mod:`canest.estimation.longitudinal_offset`). ``understeer`` is learned and
reported but not applied: it fixes only the balance of the two cornering
stiffnesses. Nor are the steering offset and the lateral offset ``ay_bias``
applied: a road's bank shows as both, and applied as offsets its side force
becomes a force the model's tires carry, consistent with every channel and
wrong (:meth:`_follow`); the estimator's kinematic checks take them
(:meth:`_kinematic_offsets`).

The output-error fit of each 30 s window of driving, run in a worker
(:mod:`canest.estimation.stiffness_window`, :meth:`_window_update`), is a second source: the only one of
``front`` and ``rear``, the two cornering stiffnesses (factors on the configured ones, applied to the model, not
the inputs: :attr:`stiffness`, ``Estimator.use_stiffness``; the identities move them only through their
covariance with what they measure), and the strongest of the ratio, the offsets, the gyro bias and the speed
scale, which it fits alongside them.
"""
from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import replace
from types import MappingProxyType

import numpy as np

from canest.calibration import MAX_YAW_ACCELERATION, MODEL_ERROR, RADIUS_DRIFT, STIFFNESS_MODEL_ERROR, STIFFNESSES
from canest.estimation.calibration_blocks import Block, BlockMeans
from canest.estimation.calibration_state import CalibrationStore
from canest.estimation.inputs import WHEEL_SPEEDS
from canest.estimation.learned_parameters import (APPLIED, AX, AY, FRONT, GYRO, GYRO_2, NAMES, OFFSET, RATIO, REAR,
                                                  SPEED, STIFFNESS, UNDERSTEER, parameters)
from canest.estimation.stiffness_window import StiffnessWindow
from canest.models import identities
from canest.params import VehicleParams
from canest.settings import Config

log = logging.getLogger("canest.calibration")

BLOCK = 0.1  # s: one learner update per block of ticks (10 Hz)
HISTORY = 4  # blocks kept for the rates (0.4 s)
MIN_SPEED = 5.0  # m/s
MIN_STEER_SPEED = 8.0  # m/s: slower, the slip angles leave the linear single-track model
LINEAR_AY = 2.5  # m/s^2
MIN_BEND_AY = 0.5  # m/s^2: a bend that excites the steering ratio and the understeer gradient
MAX_STEERING_RATE = math.radians(5.0)  # rad/s at the steering wheel over the history: steady
MAX_AX = 2.0  # m/s^2: harder braking slips the wheels and pitches the body
STANDSTILL = 0.05  # m/s
GATE = 4.0  # innovation standard deviations
MIN_EVIDENCE = 30.0  # s of excited blocks before a parameter counts as converged
APPLY_EVIDENCE = 10.0  # s of excited blocks before a parameter is applied (the gyro bias: once converged)
REOPEN_AFTER = 3  # window fits gated in a row before the stiffnesses are relearned
# std of a window fit's parameter beyond its interval: the linear model's error, measured over 4 windows of each of
# 3 roads (seeds 3 and 7, flat and banked 3 deg): the linear tires read the plant's 2-3 % soft (with the fit's
# steering held over each step; taken over the step, the rear reads 1-8 % soft, README "Online calibration"); the
# offsets, ratio and speed scattered 1.5-3 of their own std about the truth
FIT_FLOOR = {"front": 0.03, "rear": 0.03, "ratio": 0.02, "steering_offset": math.radians(0.15),
             "gyro_bias": math.radians(0.04), "ay_bias": 0.015, "speed": 0.002}
NOISE = {"kinematic": 0.1, "steering": math.radians(0.5), "longitudinal": 0.1,  # per block, widened for the
         "standstill": math.radians(0.05), "gyros": math.radians(0.1)}  # errors' correlation in time and the
# identities' model error; the gyros': a block's mean of two gyros' noise (0.1 and 0.2 deg/s a sample, the second's
# frames every 20 ms)
SPREAD_UPDATES = 20  # an identity's innovations averaged into its measured noise (:class:`InnovationSpread`)
SPREAD_WARMUP = 10  # innovations of an identity seen before it learns: its spread must be known first
CONSECUTIVE = 1.5  # blocks: two innovations this close in time are consecutive (:class:`InnovationSpread`)
MAX_CORRELATION = 0.95  # of an identity's consecutive innovations, as measured (:meth:`_noise`)
SECONDS_PER_HOUR = 3600.0
NEEDED = ("yaw_rate", "ay", "steering_wheel_angle", *WHEEL_SPEEDS)


class OnlineCalibration:
    """The learner (module docstring): :meth:`correct` learns from a tick's raw sample and returns it corrected."""

    def __init__(self, vehicle: VehicleParams, names: tuple, dt: float, store=None, enabled: bool = True,
                 gyro_bias_std: float = 0.0):
        self.vehicle = vehicle
        self.specs = parameters(vehicle, gyro_bias_std)
        self.x = np.array([p.start for p in self.specs])
        self.P = np.diag([p.std**2 for p in self.specs])
        self.low = np.array([p.low for p in self.specs])
        self.high = np.array([p.high for p in self.specs])
        self.Q = np.diag([(p.drift**2) * BLOCK / SECONDS_PER_HOUR for p in self.specs])
        self.evidence = np.zeros(len(self.specs))  # s of blocks that excited each parameter
        self.excited = np.zeros(len(self.specs), dtype=bool)  # by an update of the current block
        self.prior_std = np.array([p.std for p in self.specs])
        self.applied = self.x.copy()
        self.correcting = np.zeros(len(self.specs), dtype=bool)  # applied once (or restored): :attr:`correction_std`
        self._report = None  # built by report() once per block
        self.index = {name: i for i, name in enumerate(names)}
        self.second_gyro = self.index.get("yaw_rate_2")
        self.enabled = enabled and all(name in self.index for name in NEEDED)
        ticks = max(1, round(BLOCK / dt))
        self.block_period = ticks * dt  # s: BLOCK at tick rates that divide it
        self.blocks = BlockMeans(names, vehicle, ticks) if self.enabled else None
        self.history = deque(maxlen=HISTORY + 1)
        self.store = store
        self.last_save = None
        self.updates = {**{kind: 0 for kind in NOISE}, "window": 0, "gated": 0}
        self.window = StiffnessWindow(vehicle, names, dt) if self.enabled else None
        self.gated_fits = 0  # window fits gated in a row
        self.kinematic_offsets = (0.0, 0.0)  # ay, yaw rate: :meth:`_kinematic_offsets`, once per block
        self.spread = self._new_spreads()  # :meth:`_noise`
        self.block_time = 0.0  # s, the end of the block being learned from
        if store is not None and self.enabled:
            saved = store.load(self.specs)
            if saved is not None:
                self.restore(saved)

    # -- learning --------------------------------------------------------------------------------------------

    @property
    def values(self) -> np.ndarray:
        """The parameters as reported and saved: the state, but the understeer gradient ``K_us = u / k``."""
        values = self.x.copy()
        values[UNDERSTEER] = self.x[UNDERSTEER] / self.x[RATIO]
        return values

    @property
    def std(self) -> np.ndarray:
        """Standard deviations of :attr:`values` (``K_us``'s by the delta method from ``u`` and ``k``)."""
        std = np.sqrt(np.maximum(np.diag(self.P), 0.0))
        k, u = self.x[RATIO], self.x[UNDERSTEER]
        J = np.array([-u / (k * k), 1.0 / k])
        both = [RATIO, UNDERSTEER]
        std[UNDERSTEER] = math.sqrt(max(float(J @ self.P[np.ix_(both, both)] @ J), 0.0))
        return std

    @property
    def published_std(self) -> np.ndarray:
        """:attr:`std` as reported, the stiffnesses' and the steering ratio's with the linear tires' model error
        in quadrature (:data:`canest.calibration.MODEL_ERROR` of the value: a floor on the posterior, where the
        window fits' ``FIT_FLOOR`` averages away over windows), and the understeer gradient's with the stiffnesses'
        error carried through ``K_us = m (b / C_f - a / C_r) / L``: ``e m / L hypot(b / C_f, a / C_r)`` (the
        steering identity that learns it holds the same linear tires; without it, on ten roads after 120 s, its
        error was 4.2 of its std in RMS). :attr:`converged` judges the evidence alone."""
        std = self.std
        for name, error in MODEL_ERROR.items():
            i = NAMES.index(name)
            std[i] = math.hypot(std[i], error * self.x[i])
        v = self.vehicle
        front, rear = v.cornering_stiffness_front * self.x[FRONT], v.cornering_stiffness_rear * self.x[REAR]
        tires = STIFFNESS_MODEL_ERROR * v.mass / v.wheelbase * math.hypot(v.cg_to_rear / front, v.cg_to_front / rear)
        std[UNDERSTEER] = math.hypot(std[UNDERSTEER], tires)
        return std

    @property
    def converged(self) -> np.ndarray:
        """Per parameter: std below its threshold after ``MIN_EVIDENCE`` s of excitation."""
        return (self.std < np.array([p.converged for p in self.specs])) & (self.evidence >= MIN_EVIDENCE)

    def _update(self, z: float, h: float, H: np.ndarray, noise: float, kind: str, learns=None,
                gate: bool = True) -> None:
        """One scalar Kalman update (Joseph form), left out beyond ``GATE`` (unless ``gate`` is False: a caller
        that gated the update as a whole); counts the excited parameters.

        ``learns`` (indices; default all) are the parameters the update may move: the others are *considered*
        (Schmidt-Kalman): their uncertainty widens the innovation's variance and their covariance with the learned
        ones is kept, so a later update of them corrects what was learned against their error, but this update's
        model error cannot leak into them. The Joseph form keeps P symmetric positive semi-definite for any gain,
        the zeroed rows included."""
        PH = self.P @ H
        predicted, innovation = float(H @ PH), z - h
        if not math.isfinite(innovation):
            return
        R = self._noise(kind, noise)
        spread = self.spread.get(kind)
        if spread is not None:  # measured after R was taken: an innovation never widens its own gate
            spread.add(innovation, predicted, GATE * math.sqrt(predicted + (R or noise * noise)), self.block_time)
        if R is None:
            return
        S = predicted + R
        if gate and innovation * innovation > GATE * GATE * S:
            self.updates["gated"] += 1
            return
        K = PH / S
        if learns is not None:
            considered = np.ones(len(K), dtype=bool)
            considered[list(learns)] = False
            K[considered] = 0.0
        self.x = np.clip(self.x + K * innovation, self.low, self.high)
        A = np.eye(len(self.x)) - np.outer(K, H)
        self.P = A @ self.P @ A.T + np.outer(K, K) * R
        self.excited |= (np.abs(H) * self.prior_std > 0.3 * math.sqrt(R)) & (K != 0.0)
        self.updates[kind] += 1

    def _new_spreads(self) -> dict:
        return {kind: InnovationSpread(self.block_period) for kind in NOISE}

    def _noise(self, kind: str, noise: float) -> float | None:
        """The variance of one ``kind`` update's noise: the configured ``noise``, or what its earlier innovations
        show when larger (:class:`InnovationSpread`: their mean square less what the parameters' uncertainty
        explained, widened by their correlation; a whitened stiffness fit keeps its own). None for the first
        ``SPREAD_WARMUP`` innovations of an identity, which only measure it: a spread that started at the
        configured noise and grew over the first updates let them, trusted as if quiet, learn the ax offset 0.16
        m/s^2 off at 30 s with a std of 0.03. Evidence counts a block against this noise, not the configured one.

        The configured noise is a real ESC's (the Ford log's kinematic innovations: 0.08 m/s^2 per block, 0.1
        widened for their correlation); an IMU whose ay vibrates as the issue's real car's (the simulator's
        ``vibration 1``: 1.4 m/s^2 in a 10 Hz band, 0.77 m/s^2 in a block's mean) gave innovations eight times
        the configured noise, half the updates were gated as outliers, and the rest, trusted as if quiet,
        learned the speed scale 1.085 (true 1.03), the ratio 0.63 (1.08) and the front stiffness at its bound.
        On a quiet IMU and a flat road the measured noise stays below the configured one. On a banked road the
        steering identity's errors are the tires' curve under the bank's side force, slow (consecutive
        innovations correlated 0.7): counted as independent, they made the ratio 12-17 % and the understeer
        gradient 42-47 % wrong at 60 s, two to five std off (seeds 5, 7); measured and widened, -6 to -9 % and
        +28 to +35 %, seed 7 still four std off (README "Online calibration")."""
        if kind not in self.spread:
            return noise * noise
        measured = self.spread[kind].noise()
        return None if measured is None else max(noise * noise, measured)

    def _learn(self, block: Block) -> None:
        self.P = self.P + self.Q
        self.history.append(block)
        if len(self.history) <= HISTORY:
            return
        first, span = self.history[0], HISTORY * BLOCK
        steady_yaw = abs(block.yaw_rate - first.yaw_rate) / span < MAX_YAW_ACCELERATION
        self._gyros_update(block, steady_yaw)
        if block.wheel_speed < STANDSTILL and first.wheel_speed < STANDSTILL:
            H = np.zeros(len(self.x))
            H[GYRO] = 1.0
            self._update(block.yaw_rate, self.x[GYRO], H, NOISE["standstill"], "standstill")
            return
        if block.wheel_speed < MIN_SPEED:
            return
        speed_rate = (block.wheel_speed - first.wheel_speed) / span
        turning = self.x[SPEED] * block.wheel_speed * (block.yaw_rate - self.x[GYRO])  # v r: ay without its vibration
        if block.ax is not None and abs(turning) < 1.0 and abs(block.ax) < MAX_AX:
            mean_ax = sum(b.ax for b in list(self.history)[1:]) / HISTORY
            H = np.zeros(len(self.x))
            H[SPEED], H[AX] = speed_rate, 1.0
            self._update(mean_ax, self.x[SPEED] * speed_rate + self.x[AX], H, NOISE["longitudinal"], "longitudinal",
                         learns=(AX,))
        steady = steady_yaw and abs(block.steering_wheel_angle - first.steering_wheel_angle) / span < MAX_STEERING_RATE
        if not steady or abs(block.ax or 0.0) > MAX_AX:
            return
        s, bias = self.x[SPEED], self.x[GYRO]
        H = np.zeros(len(self.x))
        H[SPEED], H[GYRO], H[AY] = block.wheel_speed * (block.yaw_rate - bias), -s * block.wheel_speed, 1.0
        h = identities.measured_ay(block.wheel_speed, block.yaw_rate, s, bias, self.x[AY])
        self._update(block.ay, h, H, NOISE["kinematic"], "kinematic")
        if block.wheel_speed >= MIN_STEER_SPEED:
            self._steering_update(block)

    def _gyros_update(self, block: Block, steady: bool) -> None:
        """``r_m - r_m2 = b_r - b_r2``: two gyros on one body read one yaw rate, so their difference is their
        biases'. Only while the yaw rate is ``steady``: the two gyros' frames sample it apart in time (the second's
        every 20 ms), which in a swerve is a difference of several deg/s. The first gyro's bias is *considered*
        (:meth:`_update`), not learned: the identities of the car's motion learn it, and the second gyro's error
        (an airbag unit's, noisier) must not move it; the covariance kept makes every later correction of the
        first bias carry the second along. The second gyro's bias so learned lets the estimator's models weigh
        both gyros (:mod:`canest.models.single_track`): unlearned, a second gyro 2 deg/s off made the two disagree
        beyond their noise, and the yaw rate read ``inconsistent`` for the whole drive (README "Online
        calibration")."""
        if block.yaw_rate_2 is None or not steady:
            return
        H = np.zeros(len(self.x))
        H[GYRO], H[GYRO_2] = 1.0, -1.0
        self._update(block.yaw_rate - block.yaw_rate_2, self.x[GYRO] - self.x[GYRO_2], H, NOISE["gyros"], "gyros",
                     learns=(GYRO_2,))

    def _steering_update(self, block: Block) -> None:
        """``delta_sw = offset + R (k L r / v + u v r)``, ``u = k K_us``, ``r = r_m - b_r``, ``v = s v_w``, while
        ``|v r| < LINEAR_AY`` (the linear single-track model; ``v r`` at the parameters this block's kinematic update
        left).

        ``v r`` is the steady bend's lateral acceleration (the kinematic identity's ``ay_m - c``), taken from the
        wheels and the gyro rather than the accelerometer: an ay that vibrates (0.77 m/s^2 in a block's mean on
        the simulator's ``vibration 1``) is a noisy regressor beside ``r / v``, nearly collinear with it in
        steady bends, and the fit put the whole steering on the clean one: understeer to 0, the ratio to its
        bound 2.0 (true 1.08) in 120 s; with ``v r``, 1.08 and K_us within 2 %. It is the flat road's tire force:
        on a banked road the tires carry ``g sin(bank)`` less, so the learned offset is the offset of the
        *equivalent flat road*, off by ``k R K_us g sin(bank)``; with it, the corrected inputs (steering, yaw
        rate, ay less ``c``) agree with the estimator's flat-road model (which no learned value could do for the
        true offset and a bank it lacks).

        The state holds ``u = k K_us`` instead of ``K_us``: the identity is then linear in the parameters it
        learns (``offset + R (k L r / v + u v r)``). In ``k`` and ``K_us`` it is bilinear, and a linearization at
        a wrong ``K_us`` sent the ratio 29 % off on a banked road. Speed and gyro bias are *considered*
        (:meth:`_update`), not learned here: the kinematic identity learns them in any steady driving, and this
        one's model error would leak into them (on a banked road the equivalent flat road's offset moved the gyro
        bias from 0.5 to 1.2 deg/s in 30 s). Taken as known instead (before), their error in the first minute (a
        gyro bias 0.5 deg/s is 1.2 deg of steering at 20 m/s) was learned as ratio and understeer, whose growing
        confidence then gated out every bend: ratio -28 %, understeer of the wrong sign after 120 s. Ratio and
        understeer are learned only in bends (``|v r| >= MIN_BEND_AY``): on a straight their columns are the
        speed and bias errors' noise, not the steering's geometry. Below it they are considered, not taken as
        known: a gentle bend (``v r`` 0.2-0.4 m/s^2, as a car drifting on a banked road's straight with its
        steering held) puts ``R (dk L r / v + du v r)`` into the offset, 1.8 deg at the prior's ratio and
        understeer (bank 3 deg, seeds 8 and 9). Taken as known, the offset learned it with a std that left it out
        (-0.86 +- 0.20 deg, converged, against the equivalent flat road's -2.4 at 120 s), gated out every window
        fit's right offset and ratio (whitened -7) and, in one-sided bends, moved the ratio to 0.85 (true 1.08);
        considered, their uncertainty widens the offset's innovations and their covariance with it is kept, so the
        first bend that teaches them (or a window fit whose offset row is taken) corrects it. Only while the block
        turns by more than the gyro bias's std, though: below it ``r`` is mostly the bias's error, which the bias's
        own column considers, and the product of the two errors built a covariance that the first bend turned into
        a wrong correction (the synthetic drive of ``tests/test_online_calibration.py``: offset 1.41 -> 0.97 deg at
        the first bend, true 1.5). A drift within that std is still taken as known: 0.34 deg/s under the prior's
        0.5 left the offset 1.8 std off at 30 s, 1.5 at 120 s (the synthetic drive with that drift; with the
        threshold halved, the synthetic drive above left it 2 std off)."""
        p = self.vehicle
        s, bias, offset, k, u = (self.x[i] for i in (SPEED, GYRO, OFFSET, RATIO, UNDERSTEER))
        ratio, L = p.steering_ratio, p.wheelbase
        v, r = s * block.wheel_speed, block.yaw_rate - bias
        ay = v * r
        if abs(ay) >= LINEAR_AY:  # beyond the linear single-track model
            return
        h = identities.steady_steering_wheel_angle(v, r, ay, offset, k * ratio, L, u / k)
        H = np.zeros(len(self.x))
        H[SPEED] = ratio * r * (u * block.wheel_speed - k * L / (s * v))
        H[GYRO] = -ratio * (k * L / v + u * v)
        H[OFFSET] = 1.0
        bend = abs(ay) >= MIN_BEND_AY
        if bend or abs(r) > math.sqrt(self.P[GYRO, GYRO]):  # turning, not only the gyro bias's error
            H[RATIO], H[UNDERSTEER] = ratio * L * r / v, ratio * ay
        self._update(block.steering_wheel_angle, h, H, NOISE["steering"], "steering",
                     (OFFSET, RATIO, UNDERSTEER) if bend else (OFFSET,))

    def _window_update(self, fit) -> None:
        """The window fit's parameters as one measurement (:mod:`canest.estimation.stiffness_window`).

        Its covariance (the fit's intervals, each widened by its :data:`FIT_FLOOR`) is whitened by its Cholesky
        factor, so scalar updates make the joint one (checked against the joint update to 1e-16); the stiffnesses
        come first, so the first two rows are theirs alone. The gates, on the innovation whitened by its whole
        covariance (the learner's and the fit's) in the same order: the stiffness pair's normalized innovation
        squared above ``GATE`` squared leaves the fit out whole (a row gated alone would let the second row,
        conditioned on the first, move the learned value away from the fit); any other row beyond ``GATE``
        leaves out the rest (the sensors' offsets, ratio and speed, which a changing bank moves) and keeps the
        stiffnesses. Windows never overlap, so each fit used is new evidence: it counts the window's seconds.
        ``REOPEN_AFTER`` fits whose stiffnesses were gated in a row (new tires, a new load) reopen them to their
        prior, and the next fit is taken.

        The identities see the same driving, so the fit's sensor rows count part of their evidence twice; the
        fit's is the larger part by far (the gyro bias from one 30 s window: +-0.03 deg/s, the kinematic
        identity's +-0.2 after 30 s), which makes the overlap small.

        A parameter the window tells no better than the learner's prior (its fit std above the prior's) is left
        out (its marginal: the rows of the others): such a fit knows only a combination of it with others (at a
        constant speed the gyro bias and ``c`` are one sum, the steering offset a third), which would move it by
        the learner's error in the others. On a 45 s sine steer at 80 km/h the fit's steering offset, gyro bias
        and ``c`` had stds of 42 deg, 8 deg/s and 3.1 m/s^2, and taken whole they carried the steering
        identity's offset error (5 std) into the gyro bias and ``c`` (5 std each, the gyro bias 0.8 deg/s off)."""
        told = [i for i, name in enumerate(fit.names)
                if name in STIFFNESSES or fit.covariance[i, i] <= self.prior_std[NAMES.index(name)] ** 2]
        names = [fit.names[i] for i in told]
        index = [NAMES.index(name) for name in names]
        R = fit.covariance[np.ix_(told, told)] + np.diag([FIT_FLOOR[name] ** 2 for name in names])
        innovation = fit.values[told] - self.x[index]
        whitened = np.linalg.solve(np.linalg.cholesky(self.P[np.ix_(index, index)] + R), innovation)
        if whitened[:2] @ whitened[:2] > GATE * GATE:
            self.updates["gated"] += 1
            self.gated_fits += 1
            if self.gated_fits >= REOPEN_AFTER:
                self._reopen_stiffness()
            return
        self.gated_fits = 0
        used = len(index) if np.all(np.abs(whitened[2:]) <= GATE) else 2
        if used < len(index):
            self.updates["gated"] += 1
        whiten = np.linalg.inv(np.linalg.cholesky(R))
        rows = np.zeros((len(index), len(self.x)))
        rows[:, index] = whiten
        learns = index[:used]
        for z, H in zip((whiten @ fit.values[told])[:used], rows[:used]):
            self._update(float(z), float(H @ self.x), H, 1.0, "window", learns=learns, gate=False)
        self.evidence[learns] += fit.seconds

    def _reopen_stiffness(self) -> None:
        log.warning("%d windows in a row disagreed with the learned cornering stiffnesses: relearning them",
                    self.gated_fits)
        both = list(STIFFNESS)
        self.P[both, :] = 0.0
        self.P[:, both] = 0.0
        self.P[both, both] = self.prior_std[both] ** 2
        self.evidence[both] = 0.0
        self.gated_fits = 0

    def _follow(self) -> None:
        """Move each applied parameter toward its learned value, rate-limited, once ``APPLY_EVIDENCE`` s excited it.

        Not waiting for convergence: the learned mean is the drive's best estimate, and the wait cost the most.
        On the wrong car of README "Online calibration" (flat road, seed 3) the ratio's std was still 0.084 at
        60 s (threshold 0.03) and the speed scale lacked the 30 s of bends, so after 60 s the yaw rate RMSE was
        0.134 deg/s and vx 0.39 m/s with nothing of them applied; applied after 10 s of evidence, 0.109 and
        0.059 (0.023 once the speed scale was learned without the drive slip; the true parameters give 0.101 and
        0.028).

        The gyro bias waits for its convergence: the kinematic identity tells it from the lateral offset ``c``
        only through the speed's changes (``v b`` against a constant), which a real road's changing bank and an
        IMU's misalignment times ax also produce. On the real Ford log (20 s, 8 to 22 m/s, no standstill) it
        learned -0.17 +- 0.09 deg/s within 15 s, applied from 10 s it moved the yaw rate off the car's own signal
        by 0.1 deg/s RMS; on the simulated roads it converges within 60 s, so waiting costs nothing there.

        The second gyro's applied bias heads for the first's *applied* bias less the learned difference of the two
        (:meth:`_goal`), once that difference is known within ``converged`` after ``APPLY_EVIDENCE`` s: the second
        gyro is made to agree with the first as corrected, whatever the first's own bias (the config's claim, or its
        correction's error, covers that one). Its absolute value waits for the first's, which an IMU that vibrates
        as a real car's held unconverged all of a 120 s road (README "Online calibration"), while the difference
        was known within 0.01 deg/s.

        The steering offset and the lateral offset ``c`` are learned, published and taken by the estimator's
        kinematic checks (:meth:`_kinematic_offsets`), never applied to the inputs: a road's bank shows as both
        (``c`` holds its ``-g sin(bank)``, the offset its steering, :meth:`_steering_update`), and applied as
        offsets a bank's side force becomes a force the model's tires carry with every channel consistent. On the
        road banked 3 deg of README "Online calibration", both applied from the window fit's convergence (35 s)
        made the sideslip RMSE after 60 s 0.183 deg with a std of 0.054 (NEES 7.2, flagged valid); not applied,
        0.092 (NEES 1.5); on the flat road 0.036 and 0.076 (NEES 0.10 and 1.10); without any calibration 0.121
        and 0.098. The offset alone applied: banked 0.056, flat 0.101 (NEES 2.2)."""
        ready = self.evidence >= APPLY_EVIDENCE
        ready[GYRO] = self.converged[GYRO]
        ready[GYRO_2] &= self.gyro_difference_std < self.specs[GYRO_2].converged
        for i in APPLIED:
            if ready[i]:
                self.correcting[i] = True
                step = self.specs[i].rate * BLOCK
                self.applied[i] += min(step, max(-step, self._goal(i) - self.applied[i]))

    def _goal(self, i: int) -> float:
        """Where parameter ``i``'s applied value heads: its learned value; the second gyro's bias, the first's
        applied bias less the learned difference of the two (:meth:`_follow`)."""
        if i == GYRO_2:
            return float(self.applied[GYRO] - (self.x[GYRO] - self.x[GYRO_2]))
        return float(self.x[i])

    @property
    def gyro_difference_std(self) -> float:
        """The std of the learned difference of the two gyros' biases (rad/s)."""
        P = self.P
        return math.sqrt(max(float(P[GYRO, GYRO] + P[GYRO_2, GYRO_2] - 2.0 * P[GYRO, GYRO_2]), 0.0))

    # -- the estimator's side ----------------------------------------------------------------------------------

    def correct(self, sample):
        """Learn from the raw ``sample`` (one tick), then return a copy with the applied corrections."""
        if not self.enabled:
            return sample
        fit = self.window.add(sample)
        if fit is not None:
            self._window_update(fit)
            self._report = None
        block = self.blocks.add(sample)
        if block is not None:
            self.block_time = sample.t
            self._report = None
            self.excited[:] = False
            self._learn(block)
            self.evidence += BLOCK * self.excited
            self._follow()
            self.kinematic_offsets = self._kinematic_offsets()
            self._maybe_save(sample.t)
        return self.apply(sample)

    def apply(self, sample):
        """A copy of ``sample`` with the applied corrections (module docstring)."""
        a, index = self.applied, self.index
        values = sample.values.copy()
        for wheel in self.blocks.wheels:
            values[wheel] *= a[SPEED]
        values[index["yaw_rate"]] -= a[GYRO]
        if self.second_gyro is not None:
            values[self.second_gyro] -= a[GYRO_2]
        swa = index["steering_wheel_angle"]
        values[swa] = float(identities.road_wheel_angle(values[swa], 0.0, a[RATIO]))
        return replace(sample, values=values)

    def _kinematic_offsets(self) -> tuple:
        """(ay, yaw rate) offsets the kinematic identity learned beyond the applied ones, once the lateral offset
        ``c`` has converged, else (0, 0). ``c`` is never applied to the inputs (a bank, :meth:`_follow`) and the
        gyro bias waits for its own convergence; the estimator's kinematic checks (``ay - c = v (r - b) +
        dvy/dt``, any bank) need them as soon as they are known. Without them, on the flat road of README "Online
        calibration" (c 0.2 m/s^2, the steering offset not converged in 120 s) the gyro bias applied alone left
        ``c / v`` in the kinematic sideslip rate, and the sideslip's std (never below the kinematic mismatch) grew
        from 0.05 to 1 deg against an error of 0.08."""
        if not self.converged[AY]:
            return 0.0, 0.0
        return float(self.x[AY]), float(self.x[GYRO] - self.applied[GYRO])

    @property
    def correction_std(self) -> tuple:
        """(speed scale, gyro bias): the error of each correction applied to the inputs, ``None`` until it is first
        applied (the config's value and its claimed uncertainty hold until then): its learned std and the distance
        the rate-limited applied value has still to follow, in quadrature. The gyro bias's is the first gyro's:
        the second is corrected to agree with it (:meth:`_follow`), within its difference's std, which is below
        0.15 deg/s when applied and weighs a fifth for the built-in car. The inputs carry it whole, and no
        consistency test sees it: the reference speed and the filter share the scaled wheels, and the filter's
        prior follows the gyro with its bias. Without it, on the wrong car's banked road of
        ``tests/test_online_calibration.py`` (the scale applied at 35 s), vx after the scale was applied was within
        2 std on 64 % of its valid ticks (NEES 9.5, valid but wrong 2.3 %)."""
        return tuple(math.hypot(math.sqrt(max(self.P[i, i], 0.0)), self.x[i] - self.applied[i])
                     if self.correcting[i] else None for i in (SPEED, GYRO))

    @property
    def stiffness(self) -> tuple:
        """The applied factors on the configured front and rear cornering stiffnesses (the model's, not an input's)."""
        return float(self.applied[FRONT]), float(self.applied[REAR])

    @property
    def stiffness_error(self) -> float | None:
        """The relative error of the applied cornering stiffnesses, the larger axle's: its published std (the
        window fits' evidence and the linear tires' model error, :data:`canest.calibration.STIFFNESS_MODEL_ERROR`)
        and the distance the rate-limited applied factor has still to follow, in quadrature, over the applied
        factor. ``None`` until a stiffness is first applied: the config's ``cornering_stiffness_uncertainty``
        holds until then. It takes that claim's place in the sideslip's model error of a model with linear tires
        (``Estimator.use_stiffness``), as :attr:`correction_std` takes the wheel radius's and the gyro bias's: a
        claim of 0.3 for textbook values, kept after the stiffnesses are learned, leaves the published sideslip
        std wider than the model's error (README "Online calibration")."""
        if not self.correcting[list(STIFFNESS)].any():
            return None
        report = self.report()  # built once per block
        return float(max(math.hypot(report[f"calib_{NAMES[i]}_std"], report[f"calib_{NAMES[i]}"] - self.applied[i])
                         / self.applied[i] for i in STIFFNESS))

    def report(self) -> MappingProxyType:
        """Per parameter: ``calib_<name>`` (the learned value), ``_std``, ``_applied``, ``_learned`` (driving excited
        it, or a saved state brought evidence) and ``_converged``. Read-only and shared by the ticks of one block:
        it changes only when a block updates the learner (10 Hz), so it is built once per block."""
        if self._report is None:
            self._report = MappingProxyType(self._build_report())
        return self._report

    def _build_report(self) -> dict:
        values, std, converged = self.values, self.published_std, self.converged
        out = {}
        for i, name in enumerate(NAMES):
            out[f"calib_{name}"] = float(values[i])
            out[f"calib_{name}_std"] = float(std[i])
            out[f"calib_{name}_applied"] = float(self.applied[i])
            out[f"calib_{name}_learned"] = bool(self.evidence[i] > 0.0)
            out[f"calib_{name}_converged"] = bool(converged[i])
        return out

    # -- persistence ---------------------------------------------------------------------------------------------

    def state(self) -> dict:
        """What :class:`canest.estimation.calibration_state.CalibrationStore` saves."""
        values, variances = self.values, self.std ** 2
        return {name: {"value": float(values[i]), "variance": float(variances[i]), "evidence": float(self.evidence[i]),
                       "applied": float(self.applied[i])} for i, name in enumerate(NAMES)}

    def restore(self, saved: dict) -> None:
        """Take a checked saved state (:meth:`CalibrationStore.load` inflated its variances, and the speed scale's
        takes :data:`canest.calibration.RADIUS_DRIFT` more); a parameter it lacks keeps its prior."""
        for i, name in enumerate(NAMES):
            if name in saved:
                entry = saved[name]
                self.x[i], self.evidence[i] = entry["value"], entry["evidence"]
                if i in APPLIED:  # a file of a canest that applied more keeps only what this one applies
                    self.applied[i] = entry["applied"]
                    self.correcting[i] = self.applied[i] != self.specs[i].start
        variances = np.array([saved[name]["variance"] if name in saved else spec.std**2
                              for name, spec in zip(NAMES, self.specs)])
        if "speed" in saved:  # the tires' radius moved since (pressure, temperature): the published vx carries it
            variances[SPEED] += RADIUS_DRIFT**2
        self.spread = self._new_spreads()  # the noise is this drive's, measured anew
        k, understeer = self.x[RATIO], self.x[UNDERSTEER]
        self.x[UNDERSTEER] = k * understeer  # the state's u = k K_us, its variance as if k and K_us were independent:
        variances[UNDERSTEER] = k * k * variances[UNDERSTEER] + understeer**2 * variances[RATIO]  # K_us's std grows
        self.P = np.diag(variances)
        self._report = None

    def _maybe_save(self, t: float) -> None:
        if self.store is None:
            return
        if self.last_save is None:
            self.last_save = t
        elif t - self.last_save >= self.store.interval:
            self.store.save(self.state())
            self.last_save = t

    def close(self) -> None:
        """Save now (at shutdown) and stop the stiffness window's worker."""
        if self.store is not None and self.enabled:
            self.store.save(self.state())
        if self.window is not None:
            self.window.close()


def make_calibration(config: Config, names: tuple) -> OnlineCalibration:
    """The learner the config asks for (``estimator.online_calibration``, saving to ``estimator.state_file``);
    a disabled one (inputs passed through) when it is off or an input it needs is not mapped."""
    est = config.estimator
    store = CalibrationStore(est.state_file) if est.state_file else None
    return OnlineCalibration(config.vehicle, names, 1.0 / est.rate_hz, store, est.online_calibration,
                             est.gyro_bias_std)


class InnovationSpread:
    """One identity's innovations: their mean square beyond what the parameters' uncertainty explained, times the
    information lost to their correlation in time, the AR(1) factor ``(1 + rho) / (1 - rho)`` of consecutive
    innovations (as :mod:`canest.models.output_error` widens its intervals) taken about their mean: the
    parameters' error at the start is an innovation that stays (on the banked road ``c`` of -0.31 made
    consecutive innovations correlate 0.97 and held the speed scale at the configured 1.0 for 50 s), not noise
    that repeats. Only the innovations of consecutive blocks are paired: an identity that skipped blocks (a bend
    not steady, a block dropped) would pair across the gap errors that had time to decorrelate, reading the
    correlation low. Means over all innovations until ``SPREAD_UPDATES`` were seen, then moving ones: a
    longer memory kept the start's large innovations (the parameters still at their prior) for 20 s and slowed
    every identity on the banked road. Gated innovations count too (a noisier IMU must widen the gate),
    clipped at the gate (a pothole must not). The longitudinal identity's ax, a mean over ``HISTORY`` blocks
    that ``HISTORY`` updates in a row share, shows its correlation here as well (AR(1) reads its lag-1
    correlation 0.75 as a factor of 7 where the shared blocks make 4: it learns the ax offset slower than it
    could)."""

    def __init__(self, block_period: float = BLOCK):
        self.block_period = block_period  # s between consecutive blocks
        self.seen = 0
        self.pairs = 0  # of consecutive innovations
        self.mean = 0.0  # of the innovations
        self.square = 0.0  # mean of innovation^2
        self.predicted = 0.0  # mean of their predicted variances
        self.lagged = 0.0  # mean of the products of consecutive innovations
        self.last = None
        self.last_time = -math.inf

    def add(self, innovation: float, predicted: float, limit: float, time: float) -> None:
        """One innovation (clipped to +-``limit``) whose variance the parameters' uncertainty predicted, from the
        block that ended at ``time`` (s)."""
        innovation = min(max(innovation, -limit), limit)
        self.seen = min(self.seen + 1, SPREAD_UPDATES)
        weight = 1.0 / self.seen
        self.mean += weight * (innovation - self.mean)
        self.square += weight * (innovation * innovation - self.square)
        self.predicted += weight * (predicted - self.predicted)
        if 0.0 < time - self.last_time <= CONSECUTIVE * self.block_period:
            self.pairs = min(self.pairs + 1, SPREAD_UPDATES)
            self.lagged += (innovation * self.last - self.lagged) / self.pairs
        self.last, self.last_time = innovation, time

    def noise(self) -> float | None:
        """The measured noise variance, None before ``SPREAD_WARMUP`` innovations were seen."""
        if self.seen < SPREAD_WARMUP:
            return None
        variance = self.square - self.mean * self.mean
        rho = (self.lagged - self.mean * self.mean) / variance if variance > 0.0 and self.pairs else 0.0
        rho = min(max(rho, 0.0), MAX_CORRELATION)
        return (self.square - self.predicted) * (1.0 + rho) / (1.0 - rho)
