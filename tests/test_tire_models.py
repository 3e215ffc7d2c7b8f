"""Signs, units and physics of the tire, wheel, tire-force (7-state) and two-track (7-DOF) models."""
import numpy as np
import pytest

from canest.models import tire_force, two_track
from canest.models.tire import (TireModelParams, cornering_stiffness, left_shares, magic_formula, magic_formula_input,
                                magic_formula_slope, slip_for_force)
from canest.models.tire_force import AxDrivenTireForceModel, TireForceModel
from canest.models.two_track import TwoTrackModel
from canest.models.wheel_force import WheelAcceleration, longitudinal_forces
from canest.models.wheels import GRAVITY, WheelGeometry


def test_magic_formula_slope_is_its_derivative_and_the_stiffness_at_zero():
    slip = np.linspace(-0.3, 0.3, 61)
    stiffness, peak = 50000.0, 4000.0
    numeric = np.gradient(magic_formula(slip, stiffness, 1.3, -0.3, peak), slip)
    analytic = magic_formula_slope(slip, stiffness, 1.3, -0.3, peak)
    np.testing.assert_allclose(analytic[1:-1], numeric[1:-1], rtol=0.02, atol=200.0)
    assert magic_formula_slope(0.0, stiffness, 1.3, -0.3, peak) == pytest.approx(stiffness)


def test_friction_lowers_the_peak_not_the_stiffness():
    small = 0.001
    high, low = (magic_formula(np.array([small, 0.3]), 50000.0, 1.3, -0.3, mu * 4000.0) for mu in (0.9, 0.3))
    assert high[0] == pytest.approx(low[0], rel=0.01)  # linear range: friction invisible
    assert low[1] < 0.35 * high[1]  # near the limit: the force follows mu


def test_degressive_cornering_stiffness_equals_the_configured_one_at_static_load():
    assert cornering_stiffness(50000.0, 4000.0, 4000.0, 2.0) == pytest.approx(50000.0)
    assert cornering_stiffness(50000.0, 8000.0, 4000.0, 2.0) < 2 * 50000.0  # less than proportional


@pytest.mark.parametrize("curvature", (-10.0, -2.0, -0.3, 0.0, 0.5, 0.9, 0.99, 1.0))
def test_the_magic_formula_s_inner_function_is_inverted_to_rounding(curvature):
    x = np.linspace(0.0, 20.0, 401)  # a tire's peak lies at 2-4
    phi = x - curvature * (x - np.arctan(x))
    np.testing.assert_allclose(magic_formula_input(phi, curvature), x, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("shape, curvature", ((1.3, -0.3), (1.3, -0.6), (1.6, 0.2), (1.0, 0.0), (0.8, -1.0)))
def test_the_slip_for_a_force_inverts_the_magic_formula_up_to_its_peak(shape, curvature):
    stiffness, peak = 50000.0, 4000.0
    slips = np.linspace(0.0, 1.0, 20001)
    forces = magic_formula(slips, stiffness, shape, curvature, peak)
    rising = slips[: np.argmax(forces)]  # up to the peak (a curve of shape <= 1 rises throughout)
    np.testing.assert_allclose(slip_for_force(-forces[: rising.size], stiffness, shape, curvature, peak), rising,
                               rtol=1e-6, atol=1e-9)  # either side's force
    if shape > 1.0:  # beyond the peak: the peak's slip
        assert slip_for_force(1.5 * peak, stiffness, shape, curvature, peak) == pytest.approx(rising[-1], abs=1e-4)


def test_an_axle_s_split_leans_on_the_loaded_wheel_the_more_the_stiffer_its_load_makes_it():
    static = np.full(4, 4000.0)
    assert left_shares(static, static, 2.0) == pytest.approx([0.5, 0.5])  # straight: equal loads
    turning = np.array([2000.0, 6000.0, 2500.0, 5500.0])  # a right turn unloads the left wheels
    shares = left_shares(turning, static, np.array([[1.0], [2.0], [1e3]]))
    assert np.all(np.diff(shares, axis=0) < 0) and np.all(shares < 0.5)  # more proportional, less on the left
    np.testing.assert_allclose(shares[-1], [0.25, 2500.0 / 8000.0], rtol=1e-3)  # q large: its load's share


def test_loads_sum_to_weight_and_a_left_turn_unloads_the_left_wheels(config):
    wheels = WheelGeometry(config.vehicle)
    loads = wheels.loads(2.0, 5.0)
    assert loads.sum() == pytest.approx(config.vehicle.mass * GRAVITY)
    assert loads[0] < loads[1] and loads[2] < loads[3]  # left lighter in a left turn (ay > 0)
    braking = wheels.loads(-5.0, 0.0)
    assert braking[:2].sum() > wheels.static_load[:2].sum()  # braking loads the front


def test_slip_angles_of_a_left_turn_are_positive(config):
    wheels = WheelGeometry(config.vehicle)
    r, vx, vy = np.array([0.0]), np.array([20.0]), np.array([0.0])
    straight = wheels.slip_angles(*wheels.wheel_velocities(r, vx, vy, 0.0))
    np.testing.assert_allclose(straight, 0.0, atol=1e-12)
    steered = wheels.slip_angles(*wheels.wheel_velocities(r, vx, vy, 0.05))
    np.testing.assert_allclose(steered[0, :2], 0.05, rtol=1e-3)  # front: alpha = delta (eq 8) at r = vy = 0
    np.testing.assert_allclose(steered[0, 2:], 0.0, atol=1e-12)


def test_body_accelerations_of_left_forces(config):
    wheels = WheelGeometry(config.vehicle)
    fy = np.array([[1000.0, 1000.0, 1000.0, 1000.0]])
    ax, ay, yaw_acc = wheels.body_accelerations(np.zeros((1, 4)), fy, 0.0)
    assert ay[0] == pytest.approx(4000.0 / config.vehicle.mass) and ax[0] == pytest.approx(0.0)
    p = config.vehicle
    assert yaw_acc[0] == pytest.approx(2000.0 * (p.cg_to_front - p.cg_to_rear) / p.yaw_inertia)
    _, _, yaw_from_drive = wheels.body_accelerations(np.array([[0.0, 500.0, 0.0, 500.0]]), np.zeros((1, 4)), 0.0)
    assert yaw_from_drive[0] > 0  # right wheels pushing forward turn the car left


def test_longitudinal_force_uses_the_wheel_acceleration_not_its_speed():
    fx = longitudinal_forces([300.0] * 4, [10.0, 0.0, -10.0, 0.0], 1.5, 0.36, [40.0, 40.0, 0.0, 0.0])
    np.testing.assert_allclose(fx, [(300 - 15) / 0.36 - 40, 300 / 0.36 - 40, (300 + 15) / 0.36, 300 / 0.36])


def test_wheel_acceleration_recovers_a_ramp_and_ignores_one_outlier():
    estimator = WheelAcceleration()
    for k in range(5):
        slope = estimator.update(0.01 * k, [50.0 + 3.0 * 0.01 * k] * 4)
    np.testing.assert_allclose(slope, 3.0)
    estimator.reset()
    for k in range(5):
        speeds = np.full(4, 50.0 + 3.0 * 0.01 * k)
        if k == 2:
            speeds[1] += 5.0  # a corrupted sample on one wheel
        slope = estimator.update(0.01 * k, speeds)
    assert abs(slope[1] - 3.0) < 0.35 * 5.0 / 0.01 / 10


@pytest.mark.parametrize("window", (5, 7))
def test_the_wheel_acceleration_s_noise_gain_is_the_scatter_of_its_slopes_of_white_noise(window):
    """What the yaw acceleration's std takes from a gyro's noise (:mod:`canest.estimation.two_track`)."""
    rng = np.random.default_rng(1)
    estimator = WheelAcceleration(window)
    slopes = [estimator.update(0.01 * k, [0.02 * rng.standard_normal()])[0] for k in range(20000)][window:]
    assert np.std(slopes) == pytest.approx(0.02 * estimator.noise_gain(), rel=0.03)


def test_eq4_reproduces_the_plants_longitudinal_force(dlc_run, config):
    """Fx = (T - J dw/dt) / R - f_r Fz against the simulator's tire force (its rolling resistance is the config's
    default, 0.012)."""
    _, _, sim = dlc_run
    p = config.vehicle
    truth = sim.truth
    t = truth["t"]
    for w in ("fl", "fr", "rl", "rr"):
        omega, torque = truth[f"w_{w}"], truth[f"torque_{w}"]
        fx = longitudinal_forces(torque[1:-1], np.gradient(omega, t)[1:-1], p.wheel_inertia, p.wheel_radius,
                                 p.tire.rolling_resistance * truth[f"fz_{w}"][1:-1])
        assert np.median(np.abs(fx - truth[f"fx_{w}"][1:-1])) < 30.0


def left_turn(model, X, u, seconds=3.0):
    for _ in range(int(seconds / 0.01)):
        X = model.transition(X, u, 0.01)
    return X


def test_tire_force_model_left_turn_signs_and_relaxation(config):
    model = TireForceModel(config.vehicle)
    u = np.array([0.03, 0.0, 3.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    X = left_turn(model, np.array([[0.0, 0.0, 20.0, 0.0, 0.0, 0.0, 0.0]]), u)
    z = model.measure(X, u)
    assert X[0, tire_force.YAW] > 0 and z[0, 1] > 0  # positive yaw rate and lateral acceleration
    assert np.all(X[0, tire_force.FY] > 0)  # every tire pushes left
    assert X[0, 4] > X[0, 3]  # the loaded outer (right) front tire carries more
    steady = model.steady_state_forces(X[:, 0], X[:, 2], X[:, 2] * np.tan(X[:, 1]), u, model.longitudinal_forces(X, u))
    np.testing.assert_allclose(X[0, tire_force.FY], steady[0], rtol=0.02)  # relaxed onto the steady state
    ay = z[0, 1]
    assert ay == pytest.approx(X[0, 0] * X[0, 2], rel=0.02)  # steady turn: ay = r vx


def test_two_track_model_left_turn_drive_and_stiff_wheels(config):
    model = TwoTrackModel(config.vehicle)
    R = config.vehicle.wheel_radius
    x0 = np.array([[0.0, 0.0, 20.0, *[20.0 / R] * 4, *[0.9] * 4]])
    u = np.array([0.03, 0.0, 3.0, 0.0, 200.0, 200.0, 200.0, 200.0])
    X = left_turn(model, x0, u)
    z = model.measure(X, u)
    assert np.all(np.isfinite(X))
    assert X[0, two_track.YAW] > 0 and z[0, 1] > 0
    assert np.all(X[0, two_track.W] * R > X[0, two_track.VX])  # driving torque: positive slip
    np.testing.assert_allclose(X[0, two_track.MU], 0.9)  # friction is a parameter: unchanged by the transition
    sensitivity = model.friction_sensitivity(X[0], u)
    straight = model.friction_sensitivity(x0[0], np.zeros(8))
    assert np.all(sensitivity > straight)
    np.testing.assert_allclose(model.friction_sensitivity(np.stack([X[0], x0[0]]), u)[0], sensitivity)  # batched


@pytest.mark.parametrize("model_class", [TireForceModel, AxDrivenTireForceModel, TwoTrackModel])
def test_a_grades_gravity_slows_a_force_driven_models_vx_beside_its_forces(config, model_class):
    """The offset of ax the wheels show (g sin(grade) uphill) is not a tire force: the accelerometer reads the
    forces, gravity slows the car beside them. Yaw and sideslip are left as on the flat road."""
    model = model_class(config.vehicle)
    R = config.vehicle.wheel_radius
    # the two-track's wheel speeds and frictions, the tire-force model's lateral forces
    per_wheel = [*[20.0 / R] * 4, *[0.9] * 4] if model_class is TwoTrackModel else [0.0] * 4
    X = np.array([[0.05, 0.01, 20.0, *per_wheel]])
    torques = [] if model_class is AxDrivenTireForceModel else [150.0] * 4
    flat, uphill = (np.array([0.02, 0.4, 1.0, offset, *torques]) for offset in (0.0, GRAVITY * np.sin(0.06)))
    dt = 0.01
    slowed = model.transition(X, flat, dt)[0] - model.transition(X, uphill, dt)[0]
    feedback = 0.05 if model_class is TwoTrackModel else 1e-3  # a slower vx slips its driven wheels more
    assert (two_track.YAW, two_track.BETA, two_track.VX) == (tire_force.YAW, tire_force.BETA, tire_force.VX)
    assert slowed[two_track.VX] == pytest.approx(GRAVITY * np.sin(0.06) * dt, rel=feedback)
    assert abs(slowed[two_track.YAW]) < 1e-4 and abs(slowed[two_track.BETA]) < 1e-4  # rad/s, rad: nothing else
    low_speed = TireForceModel.transition_low_speed
    if model_class is not TwoTrackModel:  # below min_speed vx integrates ax less the offset
        assert (low_speed(model, X, flat, dt) - low_speed(model, X, uphill, dt))[0, two_track.VX] == pytest.approx(
            GRAVITY * np.sin(0.06) * dt)


def test_tire_defaults_differ_from_the_plant():
    from canest.sim.tire import LOAD_SENSITIVITY, TireParams

    ours, plant = TireModelParams(), TireParams()
    assert ours.lateral_curvature != plant.lateral_curvature
    assert ours.load_sensitivity != LOAD_SENSITIVITY
    assert ours.relaxation_length != plant.relaxation_length
