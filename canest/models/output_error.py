"""The vehicle and sensor parameters that make the single-track model fit drives: ``canest calibrate`` fits
logs with it (:mod:`canest.apps.drive_signals` reads them), the online calibration windows of driving
(:mod:`canest.estimation.stiffness_window`).

Output error: the linear single-track model (states vy, yaw rate and the two
axles' lateral forces, which follow their slip angles over the config's tire
``relaxation_length``; RK4 at
:data:`STEP`) is driven by the measured steering
wheel angle and wheel speed of every log and predicts the measured yaw rate
and lateral acceleration; :func:`scipy.optimize.least_squares` moves the
parameters until the predictions fit, over all logs at once (scipy: the
``calibrate`` extra); a third channel
is the kinematic identity ``ay - ay_bias = v r + dvy/dt - g sin(bank)`` with the
measured yaw rate (only dvy/dt is the model's), which holds beyond the tires'
linear range too:

- ``front``, ``rear``: each axle's cornering stiffness, a factor on the config's;
- ``ratio``: the steering ratio, a factor on the config's;
- ``steering_offset``: what the steering angle sensor reads when the wheels stand straight (rad);
- ``gyro_bias``, ``ay_bias``: the yaw rate and lateral acceleration sensors' (rad/s, m/s^2);
- ``speed``: the true speed over the wheel speeds times the config's radius: the effective wheel radius's factor;
- ``bank`` of each log: the road's tilt, positive falling to the left (gravity ``g sin(bank)`` in dvy/dt, not in
  the measured ay);
- ``gyro_bias_2``, where the drives have a second gyro: not fitted, given from ``gyro_bias`` by
  :mod:`canest.models.second_gyro`.

Identifiability (what one drive can tell apart). The steady state of a bend
says ``(swa - offset) / ratio = L r / v + K_us (ay - ay_bias)`` and
``ay - ay_bias = v r - g sin(bank)``; with r and v varying over a drive this
separates the gyro bias (it enters ``L r / v`` as ``1/v``), the ratio (the
``L r / v`` term against the ``K_us ay`` term), the wheel radius (``v r``
against ay), and the understeer gradient, one combination of the two
stiffnesses; the transients of bend entries and speed changes give their
sum. But the constants are three (steering offset, ay bias, bank) and the
equations two: ``offset / ratio - K_us ay_bias`` and ``ay_bias - g sin(bank)``. No
calibration from steering, yaw rate, ay and wheel speeds can tell a constant
bank from an accelerometer bias, so the mean bank over the logs is held at 0
(a strong prior, ``MEAN_BANK_STD``): each log's bank is its difference from
the others', and the logs must share a flat road on average, e.g. the same
road driven both ways. With a single log its bank is 0 and the ay bias
carries its gravity. Every other parameter is left free (bounded to what a
car can be off by); the confidence intervals say how well the drives pinned
each down, their correlation which ones trade against each other.

Ticks turning harder than ``LINEAR_AY`` (:func:`turning_ay`) are left out of the residuals (the model runs
through them): fitting a line to the tires' curve there would read their
saturation as less stiffness and, where the drive's ay is lopsided, as a
steering offset (3-6 % and 0.3 deg on the simulator without the limit).

The 95 % intervals come from the Jacobian at the solution, each channel
weighted by its own residual RMS and widened by the residuals' correlation
in time (an AR(1) fit: neighbouring 20 ms samples are not independent errors).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from canest.calibration import BANK, CONFIDENCE, SHARED, Fit, widening
from canest.errors import DependencyError
from canest.models import second_gyro
from canest.models.wheels import GRAVITY
from canest.params import VehicleParams

STEP = 0.02  # s: 50 Hz, fast enough for a car's yaw dynamics (eigenvalues below 15 1/s at 50-100 km/h)
MIN_SPEED = 8.0  # m/s: slower, the slip angles are large and the linear single-track model does not hold
MIN_SEGMENT = 2.0  # s: shorter stretches of usable driving are left out (their start transient is all they hold)
SETTLE = 1.0  # s at the start of each stretch left out of the fit: the model starts from vy = 0
LINEAR_AY = 2.0  # m/s^2: ticks turning harder (turning_ay) are left out of the fit (the model still runs
# through them): the tires' force there falls short of linear, by the curve and by the load transfer
MEAN_BANK_STD = math.radians(0.01)  # rad: the prior that holds the logs' mean bank at 0
INSTALL = "pip install 'canest[calibrate]'"
DIFF_STEP = 1e-6  # forward-difference step, in units of each parameter's scale


@dataclass
class Drive:
    """One drive's usable ticks at ``STEP``: SI arrays of equal length, and where a new stretch starts."""

    path: str
    t: np.ndarray
    steering_wheel_angle: np.ndarray  # rad
    yaw_rate: np.ndarray  # rad/s
    ay: np.ndarray  # m/s^2
    wheel_speed: np.ndarray  # m/s: the four wheels' mean (without their drive slip where torques are mapped)
    starts: np.ndarray  # bool: the first tick of a stretch
    yaw_rate_2: np.ndarray | None = None  # rad/s: the second gyro's (NaN where stale); None: the car sends none

    @property
    def seconds(self) -> float:
        return len(self.t) * STEP


class DriveRows:
    """A :class:`Drive` collected sample by sample (every ``STEP`` s): a sample slower than ``MIN_SPEED`` is left
    out, and the next usable one after a gap starts a new stretch."""

    def __init__(self):
        self.rows = []  # (t, swa, yaw rate, ay, wheel speed, start, second gyro's yaw rate)
        self.last = None  # t of the last row

    def add(self, t: float, steering_wheel_angle: float, yaw_rate: float, ay: float, wheel_speed: float,
            yaw_rate_2: float = math.nan) -> None:
        if wheel_speed < MIN_SPEED:
            return
        start = self.last is None or t - self.last > 1.5 * STEP
        self.rows.append((t, steering_wheel_angle, yaw_rate, ay, wheel_speed, start, yaw_rate_2))
        self.last = t

    @property
    def seconds(self) -> float:
        return len(self.rows) * STEP

    def drive(self, path) -> Drive:
        """The rows as a :class:`Drive`, stretches shorter than ``MIN_SEGMENT`` left out; its ``yaw_rate_2`` None
        where no row had the second gyro's."""
        table = np.array(self.rows, dtype=float).reshape(-1, 7)
        starts = table[:, 5].astype(bool)
        ids = np.cumsum(starts)
        table = table[(np.bincount(ids)[ids] * STEP >= MIN_SEGMENT) & (ids > 0)]
        second = table[:, 6] if np.isfinite(table[:, 6]).any() else None
        return Drive(str(path), *table[:, :5].T, table[:, 5].astype(bool), second)


def turning_ay(drive: Drive) -> np.ndarray:
    """``v r`` of each tick, from the wheels and the gyro: how hard the car turns, for choosing ticks. Not the
    measured ay, which vibrates on a real body (1.0-1.5 m/s^2 RMS at 50 Hz on the simulator's ``vibration 1``):
    ticks chosen by it below ``LINEAR_AY`` held the bends' ay whose noise pulled it down, and the fit read that as
    soft tires (front x0.28 and x0.34 in two 30 s windows for a true 0.7, 95 % intervals +-0.06 and +-0.05).
    The tires' force is ``v r`` only on a flat road with the gyro bias out: a 3 deg bank moves it by 0.51
    m/s^2, a gyro bias of 0.5 deg/s by 0.2 at 80 km/h, one-sided (the measured ay carried the ay bias)."""
    return drive.wheel_speed * drive.yaw_rate


class SingleTrackFit:
    """The output-error residuals of the drives for a matrix of parameter sets (one per column, vectorized)."""

    def __init__(self, vehicle: VehicleParams, drives: list):
        self.p = vehicle
        self.drives = drives
        self.parameters = [*SHARED, *(BANK for _ in drives)]
        self.names = [*(p.name for p in SHARED), *(f"bank[{i}]" for i in range(len(drives)))]
        self.scales = np.array([p.scale for p in self.parameters])
        self.weights = {"yaw_rate": 1.0 / math.radians(0.3), "ay": 1.0 / 0.15, "kinematic": 1.0 / 0.15}
        self.settled = [self._settled(d) for d in drives]
        self.fitted = [settled & (np.abs(turning_ay(d)) < LINEAR_AY) for settled, d in zip(self.settled, drives)]

    @staticmethod
    def _settled(drive: Drive) -> np.ndarray:
        """The ticks ``SETTLE`` s or more into their stretch."""
        index = np.arange(len(drive.t))
        since_start = index - np.maximum.accumulate(np.where(drive.starts, index, 0))
        return since_start * STEP >= SETTLE

    def predict(self, drive: Drive, bank_index: int, theta: np.ndarray):
        """Predicted (yaw rate, ay, dvy/dt), each (ticks, columns), for parameter columns ``theta`` (n, columns).

        The model is linear in its state ``(vy, r, Ff, Fr)`` with the inputs constant over a tick's step (the mean
        of its two ends, :func:`_over_step`), so each tick's RK4
        step is the matrix ``Phi = sum (A dt)^j / j!`` (j to 4) and ``Gamma = dt sum (A dt)^j / (j + 1)!`` (j to 3)
        on the constant input: built for all ticks at once, then one matrix product per tick."""
        p = self.p
        front, rear, ratio, offset, gyro, ay_bias, speed = theta[:7]
        cf, cr = p.cornering_stiffness_front * front, p.cornering_stiffness_rear * rear
        a, b, m, iz, sigma = p.cg_to_front, p.cg_to_rear, p.mass, p.yaw_inertia, p.tire.relaxation_length
        delta = (drive.steering_wheel_angle[:, None] - offset) / (p.steering_ratio * ratio)
        vx = drive.wheel_speed[:, None] * speed
        ticks, columns = delta.shape
        zero, one = np.zeros((ticks, columns)), np.ones((ticks, columns))
        cf_t, cr_t = cf * one, cr * one
        delta_step, vx_step = _over_step(delta), _over_step(vx)
        matrix = np.stack([  # (ticks, columns, 4, 4)
            np.stack([zero, -vx_step, one / m, one / m], -1),
            np.stack([zero, zero, a / iz * one, -b / iz * one], -1),
            np.stack([-cf_t / sigma, -cf_t * a / sigma, -vx_step / sigma, zero], -1),
            np.stack([-cr_t / sigma, cr_t * b / sigma, zero, -vx_step / sigma], -1)], -2) * STEP
        gravity = GRAVITY * np.sin(theta[7 + bank_index]) * one
        constant = np.stack([gravity, zero, cf * vx_step * delta_step / sigma, zero], -1)
        power, phi, gamma = np.broadcast_to(np.eye(4), matrix.shape), np.eye(4) + 0.0 * matrix, 0.0 * matrix
        for j in range(1, 5):
            gamma = gamma + power / math.factorial(j)
            power = power @ matrix
            phi = phi + power / math.factorial(j)
        drift = (gamma @ constant[..., None])[..., 0] * STEP
        states = np.empty((ticks, columns, 4))
        state = None
        for k in range(ticks):
            if drive.starts[k]:
                r = drive.yaw_rate[k] - gyro
                state = np.stack([0.0 * r, r, cf * (delta[k] - a * r / vx[k]), cr * b * r / vx[k]], -1)
            states[k] = state
            state = (phi[k] @ state[..., None])[..., 0] + drift[k]
        tire_ay = (states[..., 2] + states[..., 3]) / m
        return states[..., 1] + gyro, tire_ay + ay_bias, tire_ay - states[..., 1] * vx + gravity

    def channel_errors(self, theta: np.ndarray) -> dict:
        """Per channel, the measured minus predicted values of the fitted ticks of every drive, (ticks, columns).

        ``kinematic``: the measured ay less its bias minus ``v r + dvy/dt - g sin(bank)`` with the measured yaw
        rate less its bias; only dvy/dt is the model's (small in most driving), so it holds in the tires'
        nonlinear range too and is fitted on every settled tick."""
        errors = {"yaw_rate": [], "ay": [], "kinematic": []}
        gyro, ay_bias, speed = theta[4], theta[5], theta[6]
        for i, (drive, fitted, settled) in enumerate(zip(self.drives, self.fitted, self.settled)):
            yaw, ay, vy_rate = self.predict(drive, i, theta)
            errors["yaw_rate"].append((drive.yaw_rate[:, None] - yaw)[fitted])
            errors["ay"].append((drive.ay[:, None] - ay)[fitted])
            gravity = GRAVITY * np.sin(theta[7 + i])
            turning = drive.wheel_speed[:, None] * speed * (drive.yaw_rate[:, None] - gyro)
            kinematic = drive.ay[:, None] - ay_bias - turning - vy_rate + gravity
            errors["kinematic"].append(kinematic[settled])
        return {name: np.concatenate(parts) for name, parts in errors.items()}

    def residuals(self, theta: np.ndarray) -> np.ndarray:
        """Weighted residuals (rows) for each parameter column, with the mean-bank prior as the last row."""
        errors = self.channel_errors(theta)
        banks = theta[len(SHARED):]
        prior = banks.mean(axis=0, keepdims=True) / MEAN_BANK_STD
        return np.concatenate([errors[name] * self.weights[name] for name in errors] + [prior])

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        steps = DIFF_STEP * self.scales
        columns = np.column_stack([x, x[:, None] + np.diag(steps)])
        values = self.residuals(columns)
        return (values[:, 1:] - values[:, :1]) / steps


def _over_step(values: np.ndarray) -> np.ndarray:
    """Each tick's input over its step to the next tick, (ticks, columns): the mean of the step's two ends (a
    sampled input moves between its samples; held at the first, the model's steering ran half a step, 10 ms,
    behind the yaw rate and ay it is compared with). The last tick keeps its own value; the step from a stretch's
    last tick is never used (the next tick starts its stretch from its own samples)."""
    following = np.concatenate([values[1:], values[-1:]])
    return 0.5 * (values + following)


def optimizer():
    """scipy.optimize, or a DependencyError naming the extra that installs it (scipy is not a core dependency)."""
    return DependencyError.require("scipy.optimize", "canest calibrate", INSTALL)


def calibrate(vehicle: VehicleParams, drives: list, progress=None) -> Fit:
    """Fit the parameters (module docstring) to ``drives``; ``progress(evaluations)`` after each evaluation."""
    optimize = optimizer()
    model = SingleTrackFit(vehicle, drives)
    x0 = np.array([p.start for p in model.parameters])
    bounds = (np.array([p.low for p in model.parameters]), np.array([p.high for p in model.parameters]))
    evaluations = 0

    def fun(x):
        nonlocal evaluations
        evaluations += 1
        if progress is not None:
            progress(evaluations)
        return model.residuals(x[:, None])[:, 0]

    solution = x0
    for _ in range(2):  # the second pass weights each channel by its own residual RMS of the first
        result = optimize.least_squares(fun, solution, jac=lambda x: model.jacobian(x), bounds=bounds,
                                        x_scale=model.scales, method="trf", xtol=1e-10, ftol=1e-10, max_nfev=200)
        solution = result.x
        errors = {name: e[:, 0] for name, e in model.channel_errors(solution[:, None]).items()}
        rms = {name: float(np.sqrt(np.mean(e**2))) for name, e in errors.items()}
        model.weights = {name: 1.0 / max(value, 1e-9) for name, value in rms.items()}
    jac = model.jacobian(solution)
    covariance = np.linalg.pinv(jac.T @ jac)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0)) * max(widening(e) for e in errors.values())
    correlation = covariance / np.outer(*(2 * [np.sqrt(np.maximum(np.diag(covariance), 1e-300))]))
    seconds = float(sum(f.sum() for f in model.fitted) * STEP)
    return second_gyro.with_second_gyro(Fit(model.names, solution, CONFIDENCE * std, correlation, rms, seconds), drives)
