"""Magic Formula tire of the simulation plant (Pacejka, "Tire and Vehicle Dynamics").

``F = D sin(C atan(B s - E (B s - atan(B s))))`` with peak ``D = mu Fz`` and
stiffness ``B C D`` equal to the tire's slip stiffness, which grows
degressively with load: ``C_s(Fz) = c Fz0 sin(2 atan(Fz / (1.5 Fz0))) / sin(2 atan(1/1.5))``.
Combined slip: the lateral force shrinks with the used longitudinal friction,
``Fy = Fy0 sqrt(1 - (Fx / (mu Fz))^2)`` (friction ellipse).
All functions are vectorized over the four wheels.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from canest.models.tire import cornering_stiffness, magic_formula

LOAD_SENSITIVITY = 1.5


@dataclass(frozen=True)
class TireParams:
    """Per-tire coefficients of the plant; stiffness coefficients are per unit nominal load."""

    lateral_stiffness_front: float = 11.0  # cornering stiffness / Fz0, 1/rad
    lateral_stiffness_rear: float = 14.0
    lateral_shape: float = 1.3  # C
    lateral_curvature: float = -0.6  # E
    longitudinal_stiffness: float = 16.0  # slip stiffness / Fz0, per unit slip
    longitudinal_shape: float = 1.6
    longitudinal_curvature: float = 0.2
    relaxation_length: float = 0.6  # m
    rolling_resistance: float = 0.012


def slip_stiffness(coefficient: np.ndarray, fz: np.ndarray, fz_nominal: np.ndarray) -> np.ndarray:
    """Load-sensitive slip stiffness, equal to ``coefficient * fz_nominal`` at nominal load."""
    return cornering_stiffness(coefficient * fz_nominal, fz, fz_nominal, LOAD_SENSITIVITY)


@dataclass(frozen=True)
class SlipCurves:
    """Magic Formula coefficients of each wheel's longitudinal (row 0) and lateral (row 1) force, stacked so
    that one evaluation gives both."""

    stiffness: np.ndarray  # (2, 4), slip stiffness per unit nominal load
    shape: np.ndarray  # (2, 1), C
    curvature: np.ndarray  # (2, 1), E

    @classmethod
    def of(cls, tire: TireParams, front_mask: np.ndarray) -> "SlipCurves":
        lateral = np.where(front_mask, tire.lateral_stiffness_front, tire.lateral_stiffness_rear)
        return cls(np.stack((np.full(lateral.shape, tire.longitudinal_stiffness), lateral)),
                   np.array([[tire.longitudinal_shape], [tire.lateral_shape]]),
                   np.array([[tire.longitudinal_curvature], [tire.lateral_curvature]]))


def combined_forces(alpha, kappa, fz, mu, fz_nominal, curves: SlipCurves):
    """Steady-state (Fx, Fy) of each tire from slip angle, slip ratio, load and friction."""
    peak = mu * np.maximum(fz, 0.0)
    fx, fy0 = magic_formula(np.array((kappa, alpha)), slip_stiffness(curves.stiffness, fz, fz_nominal),
                            curves.shape, curves.curvature, peak)
    usage = np.minimum(np.maximum(fx / np.maximum(peak, 1e-6), -1.0), 1.0)
    return fx, fy0 * np.sqrt(1.0 - usage**2)
