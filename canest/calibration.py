"""The parameters canest calibrates: their names, starting values, scales and physical bounds, a fit's result, and
how correlated errors widen its intervals.

Shared by the offline fit (:mod:`canest.models.output_error`), the config writer and
the simulator's mismatched car (:mod:`canest.sim.mismatch`), so it sits below
all of them. What each parameter means: :mod:`canest.models.output_error`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class Parameter:
    name: str
    start: float
    scale: float  # typical size of a change (least_squares x_scale, difference steps)
    low: float
    high: float


SHARED = (
    Parameter("front", 1.0, 0.1, 0.2, 5.0),
    Parameter("rear", 1.0, 0.1, 0.2, 5.0),
    Parameter("ratio", 1.0, 0.02, 0.5, 2.0),
    Parameter("steering_offset", 0.0, math.radians(0.5), -math.radians(30.0), math.radians(30.0)),
    Parameter("gyro_bias", 0.0, math.radians(0.1), -math.radians(5.0), math.radians(5.0)),
    Parameter("ay_bias", 0.0, 0.05, -2.0, 2.0),
    Parameter("speed", 1.0, 0.01, 0.8, 1.25),
)
BOUNDS = {p.name: (p.low, p.high) for p in SHARED}  # name -> (low, high): what a calibration may find
BANK = Parameter("bank", 0.0, math.radians(0.5), -math.radians(15.0), math.radians(15.0))
STIFFNESSES = ("front", "rear")
# rad/s^2: a yaw rate changing slower is steady (the online calibration's steady blocks, the offline fit's ticks for the
# second gyro's bias): two gyros sampled apart in time then read one yaw rate
MAX_YAW_ACCELERATION = 0.05
BOUND_TOLERANCE = 1e-3  # of a parameter's scale: a fitted value this close to a bound is at it
CONFIDENCE = 1.96  # a 95 % two-sided interval in standard deviations
# relative, 1 std: how far the linear tires' cornering stiffness read from driving is from the tires' small-slip
# stiffness, the same in every window and every log, so no amount of driving averages it away (the curve, load
# transfer on load-sensitive tires, the tires' lag). Measured on the simulator (README "Online calibration"): three
# 60 s roads fitted together read the front 3.0 %, the rear 4.9 % soft; ten roads online after 60 s the rear 1-8 %
# soft (RMS 4.4 %), the front within 4 %; without it the rear's error was 1.7 (60 s) to 2.5 (120 s) of its std
STIFFNESS_MODEL_ERROR = 0.05
# relative, 1 std: the steering ratio's share of the same error (the front stiffness's error goes partly into the
# ratio, with which it correlates): 30 country roads online (seeds 3-17, flat and banked 3 deg) scattered 1.9-2.5 %
# in RMS about the truth after 120 s, where the posterior said 1 %; checked on ten more (README "Online calibration").
# Taken for the offline fit too, where it is on the wide side: three roads fitted together read +0.6 % (60 s roads)
# and +0.9 % (30 s)
RATIO_MODEL_ERROR = 0.02
MODEL_ERROR = {"front": STIFFNESS_MODEL_ERROR, "rear": STIFFNESS_MODEL_ERROR, "ratio": RATIO_MODEL_ERROR}
# relative, 1 std: how far a tire's rolling radius moves between drives (pressure, temperature, speed: a few tenths
# of a percent): beside a fit's own error in ``canest calibrate``'s vehicle.wheel_radius_uncertainty, and added to the
# online calibration's saved speed scale when it is reloaded
RADIUS_DRIFT = 0.003


@dataclass
class Fit:
    names: list  # parameter names, the banks as bank[i]
    values: np.ndarray
    half_widths: np.ndarray  # 95 % confidence half-widths
    correlation: np.ndarray
    rms: dict  # channel -> residual RMS at the solution (yaw_rate rad/s, ay m/s^2)
    seconds: float  # driving fitted

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def half_width(self, name: str) -> float:
        return float(self.half_widths[self.names.index(name)])

    def undetermined(self, prior_std: dict) -> dict:
        """name -> why the drives do not pin it down, for each parameter but the banks that is: "at its bound"
        where the fit pressed a shared parameter (:data:`BOUNDS`) against a physical bound (the drives' best value
        lies beyond it, and the interval, from the Jacobian at the bound, does not hold what it is), "no better known
        than before driving" where its std is no narrower than ``prior_std[name]`` (the online calibration's prior,
        in the fit's units: what canest assumes of it without a drive). A straight drive leaves the stiffnesses and
        the steering so."""
        scales = {p.name: p.scale for p in SHARED}
        reasons = {}
        for name, value, half_width in zip(self.names, self.values, self.half_widths):
            if name in BOUNDS and min(abs(value - bound) for bound in BOUNDS[name]) < BOUND_TOLERANCE * scales[name]:
                reasons[name] = "at its bound"
            elif half_width / CONFIDENCE >= prior_std.get(name, math.inf):
                reasons[name] = "no better known than before driving"
        return reasons

    def with_model_error(self) -> Fit:
        """A copy whose stiffnesses' and steering ratio's intervals also hold their :data:`MODEL_ERROR`, in
        quadrature: what the drives' residuals cannot show (a fit's intervals shrink with driving; the linear tires'
        error does not)."""
        half_widths = self.half_widths.copy()
        for name, error in MODEL_ERROR.items():
            i = self.names.index(name)
            half_widths[i] = math.hypot(half_widths[i], CONFIDENCE * error * self.values[i])
        return replace(self, half_widths=half_widths)


def widening(errors: np.ndarray) -> float:
    """sqrt((1 + rho) / (1 - rho)) of the lag-1 autocorrelation rho: how much correlated errors widen an interval."""
    centred = errors - errors.mean()
    rho = float(np.dot(centred[1:], centred[:-1]) / max(np.dot(centred, centred), 1e-300))
    rho = min(max(rho, 0.0), 0.999)
    return math.sqrt((1.0 + rho) / (1.0 - rho))
