"""The kinematic and steady-state identities that make the calibration parameters observable while driving.

Signs are ISO 8855 (x forward, y left, z up; yaw rate, lateral acceleration
and steering angles positive to the left). Two slopes are not ISO angles but
the conventions of :mod:`canest.sim.mismatch` and the offline fit
(:mod:`canest.models.output_error`): ``bank`` positive when the road falls to the
left (that is *minus* the ISO roll of the road, which is positive left side
up) and ``grade`` positive when the road rises ahead (*minus* the ISO pitch,
which is positive nose down). What the sensors measure: an accelerometer the
specific force (the tires' and air's force per mass, not gravity's pull
along the road), a gyro the body's rate, a wheel-speed sensor ``w`` whose
speed is ``R w`` with the effective radius ``R``; every sensor adds its bias.
:mod:`canest.estimation.online_calibration` learns from these.
"""
from __future__ import annotations

import numpy as np

from canest.models.wheels import GRAVITY


def lateral_specific_force(vx, yaw_rate, vy_rate=0.0, bank=0.0):
    """What a bias-free lateral accelerometer reads: ``ay = dvy/dt + vx r - g sin(bank)``.

    Newton along the body's y axis: ``m (dvy/dt + vx r) = F_tires + m g sin(bank)``
    (gravity's component along y pulls to the left on a road falling to the left);
    the accelerometer measures ``F_tires / m``. In steady driving (dvy/dt ~ 0) it is
    ``vx r - g sin(bank)``: with the measured speed ``s v_wheel`` and yaw rate
    ``r_m - b_r`` (:func:`measured_ay`) it makes the speed scale ``s``, the gyro bias
    and the constant offset ``b_ay - g sin(bank)`` observable in any bend."""
    return vy_rate + vx * yaw_rate - GRAVITY * np.sin(bank)


def measured_ay(wheel_speed, measured_yaw_rate, speed_scale, gyro_bias, ay_offset):
    """The lateral accelerometer's reading in steady driving, in the parameters' terms:
    ``ay_m = s v_w (r_m - b_r) + c`` with ``c = b_ay - g sin(bank)``.

    From :func:`lateral_specific_force` with ``vx = s v_w`` (``v_w`` the wheel speeds
    times the configured radius, ``s`` the effective radius over it), ``r = r_m - b_r``
    and the accelerometer's bias ``b_ay``. A constant bank and the bias enter only as
    their sum ``c``: no drive with these sensors tells them apart (the offline fit's
    identifiability note), so the learner learns ``c``, the lateral offset."""
    return speed_scale * wheel_speed * (measured_yaw_rate - gyro_bias) + ay_offset


def road_wheel_angle(steering_wheel_angle, steering_offset, steering_ratio):
    """``delta = (delta_sw - offset) / ratio``: the road wheels' angle from the steering wheel's measured one."""
    return (steering_wheel_angle - steering_offset) / steering_ratio


def steady_yaw_rate(vx, delta, wheelbase, understeer_gradient, bank=0.0):
    """The linear single-track model's steady yaw rate ``r = vx (delta + K_us g sin(bank)) / (L + K_us vx^2)``.

    In a steady bend the road wheel angle is the Ackermann angle plus the axles'
    slip-angle difference, ``delta = L r / vx + K_us ay`` (:func:`understeer_gradient`),
    where ``ay`` is the force the tires carry per mass: ``vx r - g sin(bank)``
    (:func:`lateral_specific_force`). Solved for r; on a flat road the textbook
    ``r = vx delta / (L + K_us vx^2)``."""
    return vx * (delta + understeer_gradient * GRAVITY * np.sin(bank)) / (wheelbase + understeer_gradient * vx * vx)


def steady_steering_wheel_angle(vx, yaw_rate, ay, steering_offset, steering_ratio, wheelbase, understeer_gradient):
    """The steering-wheel angle a steady bend needs: ``delta_sw = offset + ratio (L r / vx + K_us ay)``.

    :func:`steady_yaw_rate` with :func:`road_wheel_angle`, ``ay`` the lateral
    accelerometer's (bias-free) reading, which includes a bank's effect. The term
    ``L r / vx`` against ``K_us ay`` separates the steering ratio from the understeer
    gradient (they scale differently with speed); straight driving (r = 0, ay = 0)
    gives the offset."""
    return steering_offset + steering_ratio * (wheelbase * yaw_rate / vx + understeer_gradient * ay)


def understeer_gradient(mass, cg_to_front, cg_to_rear, cornering_stiffness_front, cornering_stiffness_rear):
    """``K_us = m (b C_r - a C_f) / (L C_f C_r)`` (rad per m/s^2): the axles' slip-angle difference per unit ay.

    Steady state: each axle carries its share of ``m ay`` (front ``b / L``, rear
    ``a / L``), so ``alpha_f - alpha_r = m ay (b / (L C_f) - a / (L C_r))``. It fixes the
    *balance* of the two stiffnesses, not their scale (:func:`steady_sideslip` does)."""
    wheelbase = cg_to_front + cg_to_rear
    return mass * (cg_to_rear * cornering_stiffness_rear - cg_to_front * cornering_stiffness_front) / (
        wheelbase * cornering_stiffness_front * cornering_stiffness_rear)


def steady_sideslip(vx, yaw_rate, ay, mass, cg_to_front, cg_to_rear, cornering_stiffness_rear):
    """The steady sideslip ``beta = b r / vx - m a ay / (L C_r)``, ``ay`` the tires' force per mass.

    The rear axle's slip angle is ``alpha_r = b r / vx - beta`` (ISO: the wheel's
    velocity points ``beta - b r / vx`` left of its heading) and its force
    ``C_r alpha_r`` carries ``m ay a / L`` (the yaw moment balance). Sideslip over ay
    thus measures the rear stiffness alone: the stiffness *scale* that the
    understeer gradient leaves open."""
    wheelbase = cg_to_front + cg_to_rear
    return cg_to_rear * yaw_rate / vx - mass * cg_to_front * ay / (wheelbase * cornering_stiffness_rear)


def longitudinal_specific_force(vx_rate, vy, yaw_rate, grade=0.0):
    """What a bias-free longitudinal accelerometer reads: ``ax = dvx/dt - vy r + g sin(grade)``.

    Newton along x: ``m (dvx/dt - vy r) = F_x - m g sin(grade)`` (gravity pulls back
    uphill); the accelerometer measures ``F_x / m``. With the measured speed's rate
    ``s dv_w/dt`` the constant ``b_ax + g sin(grade)`` is observable (again one sum: a
    bias and a mean grade cannot be told apart)."""
    return vx_rate - vy * yaw_rate + GRAVITY * np.sin(grade)

