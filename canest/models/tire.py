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


NEWTON_STEPS = 8  # :func:`magic_formula_input`: exact to rounding for every curvature canest admits (-10 to 1)


def magic_formula_input(phi, curvature: float):
    """The ``x = B s`` (>= 0) at which the Magic Formula's inner function ``x - E (x - atan x)`` equals ``phi``
    (>= 0); vectorized. Newton's method from ``x = phi``, monotone: for ``E <= 0`` the function is convex and
    ``phi`` lies above the root, for ``0 < E < 1`` concave and below it; at ``E = 1`` it is ``atan x``, bounded by
    ``pi / 2``, and ``phi`` is held below that."""
    if curvature >= 1.0:
        phi = np.minimum(phi, 0.5 * np.pi - 1e-6)
    x = np.asarray(phi, dtype=float)
    for _ in range(NEWTON_STEPS):
        x = x - ((1.0 - curvature) * x + curvature * np.arctan(x) - phi) / (1.0 - curvature
                                                                            + curvature / (1.0 + x * x))
    return x


def slip_for_force(force, stiffness, shape: float, curvature: float, peak):
    """The slip (>= 0) at which :func:`magic_formula` carries ``|force|``, the peak's slip where the force is
    beyond the peak (a curve of ``shape <= 1`` has none: it rises towards ``sin(shape pi / 2)`` of ``peak``, and
    the slip is taken just below that); vectorized over broadcast arrays. The formula's outer part inverts in
    closed form, ``atan(x - E (x - atan x)) = asin(|F| / D) / C``, its inner one by :func:`magic_formula_input`."""
    peak = np.maximum(peak, MIN_PEAK)
    angle = min(0.5 * np.pi / shape, 0.5 * np.pi - 1e-6)  # the inner function's atan at the peak
    share = np.minimum(np.abs(force) / peak, np.sin(shape * angle))
    phi = np.tan(np.arcsin(share) / shape)
    return magic_formula_input(phi, curvature) * shape * peak / np.maximum(stiffness, MIN_PEAK)


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
