"""The estimators' tire: Magic Formula with friction scaling, and relaxation.

Magic Formula (DICI-GFCKF paper eq 5, DCKF paper eqs 7-9; Pacejka, "Tire and
Vehicle Dynamics", ch. 4) for a slip ``s`` (slip angle in rad or slip ratio):

    F = D sin(C atan(B s - E (B s - atan(B s)))),   D = mu Fz,   B = K / (C D)

The cornering stiffness grows degressively with load (Pacejka's
``K = p_Ky1 Fz0 sin(2 atan(Fz / (p_Ky2 Fz0)))``), normalized here to equal the
configured axle stiffness at static load: ``K(Fz) = k Fz0 g(Fz / Fz0) / g(1)``,
``g(x) = sin(2 atan(x / q))`` with ``q = load_sensitivity`` (larger q: closer to
proportional). The longitudinal slip stiffness is ``K = k_x Fz``. Neither
depends on friction: a lower ``mu`` lowers the peak, not the slope at zero
slip (Pacejka's friction scaling). This is how a per-wheel
friction coefficient "scales" the forces in the DCKF model (its eqs 2-5 write
``mu F0``; literally that would scale the cornering stiffness too and make mu
look observable from a stiffness error while the tire is far from its limit).
Consequently friction is observable only where the tire works near its peak.

Combined slip: when the two pure-slip forces together exceed the friction
circle ``mu Fz`` they are scaled back onto it (the simulator's plant uses a
friction ellipse on the lateral force instead: the estimator's model is
deliberately not the plant's).

Relaxation (DICI-GFCKF eqs 6 and 13): a lateral force lags its steady state
``Fy_ss`` over the relaxation length ``sigma`` travelled,

    dFy/dt = V / sigma (Fy_ss - Fy),   V = sqrt(vx^2 + vy^2) = vx sqrt(1 + tan^2 beta).

Eqs 6 and 13 print ``(Fy - Fy_ss)``, an unstable growth; the first-order lag
needs the sign above (tests/test_tire_models.py integrates it).
"""
from __future__ import annotations

import math

import numpy as np

from canest.params import TireModelParams  # noqa: F401  (re-exported: the tire model's parameters)

MIN_PEAK = 1e-6  # N, guards B = K / (C D) for an unloaded tire


def cornering_stiffness(static_stiffness, fz, static_load, load_sensitivity: float):
    """Degressive load dependency ``K(Fz) = K0 sin(2 atan(Fz / (q Fz0))) / sin(2 atan(1 / q))``."""
    shape = np.sin(2.0 * np.arctan(np.maximum(fz, 0.0) / (load_sensitivity * static_load)))
    return static_stiffness * shape / np.sin(2.0 * np.arctan(1.0 / load_sensitivity))


def left_shares(loads, static_load, load_sensitivity):
    """Each axle's share of its lateral force on its left wheel in the linear range, ``K_l / (K_l + K_r)`` of
    :func:`cornering_stiffness` (both wheels of an axle turn at one slip angle there); shape ``(..., 2)``
    (front, rear) for ``loads`` ``(4,)`` and ``load_sensitivity`` a scalar or an array ``(..., 1)``."""
    stiffness = cornering_stiffness(1.0, loads, static_load, load_sensitivity)
    left, right = stiffness[..., 0::2], stiffness[..., 1::2]
    return left / np.maximum(left + right, MIN_PEAK)


def magic_formula(slip, stiffness, shape: float, curvature: float, peak):
    """Pacejka's Magic Formula with ``B = stiffness / (shape * peak)``; vectorized."""
    peak = np.maximum(peak, MIN_PEAK)
    bs = stiffness / (shape * peak) * slip
    return peak * np.sin(shape * np.arctan(bs - curvature * (bs - np.arctan(bs))))


def peak_input(shape: float, curvature: float) -> float:
    """``B s`` at :func:`magic_formula`'s peak, where ``shape atan(x - E (x - atan x)) = pi / 2``; by bisection."""
    target, low, high = math.tan(0.5 * math.pi / shape), 0.0, 100.0
    for _ in range(60):
        x = 0.5 * (low + high)
        low, high = (x, high) if x - curvature * (x - math.atan(x)) < target else (low, x)
    return 0.5 * (low + high)


def slip_for_force(force, stiffness, shape: float, curvature: float, peak, peak_x: float):
    """The slip (>= 0) at which :func:`magic_formula` carries ``|force|``, the peak's slip where the force is
    beyond the peak; ``peak_x``: :func:`peak_input` of the curve; vectorized over broadcast arrays, by bisection on
    ``B s`` (the curve rises monotonically up to its peak)."""
    peak = np.maximum(peak, MIN_PEAK)
    share = np.minimum(np.abs(force) / peak, 1.0)
    low, high = np.zeros_like(share), np.full_like(share, peak_x)
    for _ in range(30):
        x = 0.5 * (low + high)
        below = np.sin(shape * np.arctan(x - curvature * (x - np.arctan(x)))) < share
        low, high = np.where(below, x, low), np.where(below, high, x)
    return 0.5 * (low + high) * shape * peak / np.maximum(stiffness, MIN_PEAK)


def magic_formula_slope(slip, stiffness, shape: float, curvature: float, peak):
    """dF/d(slip) of :func:`magic_formula` (equals ``stiffness`` at zero slip)."""
    peak = np.maximum(peak, MIN_PEAK)
    b = stiffness / (shape * peak)
    bs = b * slip
    phi = bs - curvature * (bs - np.arctan(bs))
    dphi = b * (1.0 - curvature + curvature / (1.0 + bs * bs))
    return peak * np.cos(shape * np.arctan(phi)) * shape * dphi / (1.0 + phi * phi)


def friction_circle(fx, fy, peak):
    """Scale (fx, fy) back onto the circle of radius ``peak`` where they exceed it."""
    norm = np.sqrt(fx * fx + fy * fy)
    scale = np.minimum(1.0, np.maximum(peak, MIN_PEAK) / np.maximum(norm, MIN_PEAK))
    return fx * scale, fy * scale


def relaxation_rate(speed, relaxation_length: float):
    """``V / sigma`` of the relaxation equation (1/s)."""
    return speed / relaxation_length
