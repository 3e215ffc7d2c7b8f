"""3-DOF single-track model: ISO 8855 signs, agreement with the papers, discretization."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from canest.models.single_track import BETA, VX, YAW, SingleTrackModel


@pytest.fixture
def model(config):
    return SingleTrackModel(config.vehicle)


def simulate(model, x0, u, seconds, dt=0.01):
    X = np.array([x0], dtype=float)
    for _ in range(int(round(seconds / dt))):
        X = model.transition(X, u, dt)
    return X[0]


def test_left_turn_gives_positive_yaw_rate_and_lateral_acceleration(model):
    u = np.array([np.radians(2.0), 0.0, 1.0])  # positive road wheel angle = left
    x = simulate(model, [0.0, 0.0, 20.0], u, 3.0)
    ay = model.measure(x[None, :], u)[0, 0]
    assert x[YAW] > 0.05
    assert ay > 1.0
    assert x[BETA] < 0.0  # at 20 m/s the rear slides out less than the path turns: nose-in, beta < 0


def test_steady_state_yaw_gain_matches_understeer_gradient(model, config):
    p = config.vehicle
    vx, delta = 20.0, np.radians(1.0)
    x = simulate(model, [0.0, 0.0, vx], np.array([delta, 0.0, 1.0]), 6.0)
    K = p.mass / p.wheelbase * (p.cg_to_rear / p.cornering_stiffness_front - p.cg_to_front / p.cornering_stiffness_rear)
    v = x[VX]  # with ax = 0, dvx/dt = r vy has slowed the car slightly
    expected = v * delta / (p.wheelbase + K * v**2)
    assert K > 0  # the configured vehicle understeers
    assert x[YAW] == pytest.approx(expected, rel=1e-4)


def paper_lmrwekf(x, u, p):
    """LMRWEKF paper eqs (1)-(4) as printed, with its negative cornering stiffnesses k = -C."""
    r, beta, v = x
    delta = u[0]
    k1, k2 = -p.cornering_stiffness_front, -p.cornering_stiffness_rear
    a, b, m, Iz = p.cg_to_front, p.cg_to_rear, p.mass, p.yaw_inertia
    r_dot = (a**2 * k1 + b**2 * k2) / (Iz * v) * r + (a * k1 - b * k2) / Iz * beta - a * k1 / Iz * delta
    beta_dot = (a * k1 - b * k2 - m * v**2) / (m * v**2) * r + (k1 + k2) / (m * v) * beta - k1 / (m * v) * delta
    ay = (a * k1 - b * k2) / (m * v) * r + (k1 + k2) / m * beta - k1 / m * delta
    return np.array([r_dot, beta_dot]), ay


def paper_svd_fckf_r_dot(x, u, p):
    """SVD-FCKF paper eq (1) exactly as printed (a typo: signs of the stiffness sums, missing a)."""
    r, beta, v = x
    k1, k2 = -p.cornering_stiffness_front, -p.cornering_stiffness_rear
    a, b, Iz = p.cg_to_front, p.cg_to_rear, p.yaw_inertia
    return (a**2 * k1 - b**2 * k2) / Iz * r / v + (a * k1 + b * k2) / Iz * beta - k1 / Iz * u[0]


def test_agrees_with_lmrwekf_paper_for_small_sideslip_and_not_with_svd_fckf_typo(model, config):
    rng = np.random.default_rng(0)
    for _ in range(20):
        x = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-1e-3, 1e-3), rng.uniform(5, 40)])
        u = np.array([rng.uniform(-0.05, 0.05), 0.0, 1.0])
        ours = model.derivatives(x[None, :], u)[0]
        expected, ay = paper_lmrwekf(x, u, config.vehicle)
        np.testing.assert_allclose(ours[:2], expected, rtol=1e-5, atol=1e-9)
        assert model.measure(x[None, :], u)[0, 0] == pytest.approx(ay, rel=1e-9, abs=1e-9)
        assert abs(paper_svd_fckf_r_dot(x, u, config.vehicle) - ours[YAW]) > 1e-3


def test_rk4_step_is_accurate_where_euler_is_not(model):
    x0 = np.array([0.1, 0.02, 3.0])  # low speed: fast lateral dynamics
    u = np.array([np.radians(5.0), 0.5, 1.0])
    dt = 0.01
    exact = solve_ivp(lambda t, x: model.derivatives(x[None, :], u)[0], (0, dt), x0, rtol=1e-12, atol=1e-14).y[:, -1]
    rk4 = model.transition(x0[None, :], u, dt)[0]
    euler = x0 + dt * model.derivatives(x0[None, :], u)[0]
    scale = np.abs(exact - x0).max()
    assert np.abs(rk4 - exact).max() < 5e-3 * scale  # measured 0.2 %
    assert np.abs(euler - exact).max() > 0.2 * scale  # measured 38 %


def test_vectorized_over_points(model):
    X = np.array([[0.1, 0.01, 20.0], [0.0, 0.0, 10.0], [-0.2, -0.02, 30.0]])
    u = np.array([0.02, 0.3, 1.0])
    batch = model.transition(X, u, 0.01)
    single = np.vstack([model.transition(X[i:i + 1], u, 0.01) for i in range(3)])
    np.testing.assert_array_equal(batch, single)


def test_low_speed_model_is_finite_at_standstill_and_reversing(model):
    X = np.array([[0.0, 0.05, 0.0], [0.1, 0.0, -2.0]])
    out = model.transition_low_speed(X, np.array([0.3, -0.5, 1.0]), 0.01)
    assert np.all(np.isfinite(out))
    assert abs(out[0, BETA]) < 0.05
    assert out[1, VX] == pytest.approx(-2.005)


def complex_step_jacobian(function, x):
    """Derivative to machine precision without truncation error (Squire & Trapp 1998): an independent check."""
    columns = []
    for j in range(x.size):
        xc = x.astype(complex)
        xc[j] += 1e-30j
        columns.append(function(xc).imag / 1e-30)
    return np.column_stack(columns)


@pytest.mark.parametrize("x", [[0.2, 0.03, 15.0], [-0.4, -0.08, 30.0], [0.1, 0.01, 4.0]])
def test_analytic_jacobians_are_exact(model, x):
    x = np.array(x)
    u = np.array([0.05, 0.7, 1.1])
    np.testing.assert_allclose(model.transition_jacobian(x, u, 0.01),
                               complex_step_jacobian(lambda xc: model.transition(xc[None, :], u, 0.01)[0], x),
                               rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(model.measure_jacobian(x, u),
                               complex_step_jacobian(lambda xc: model.measure(xc[None, :], u)[0], x),
                               rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(model.transition_low_speed_jacobian(x, u, 0.01),
                               complex_step_jacobian(lambda xc: model.transition_low_speed(xc[None, :], u, 0.01)[0],
                                                     x), atol=1e-14)
    theta_step = model.measure(x.astype(complex)[None, :], u + np.array([0, 0, 1e-30j]))[0].imag / 1e-30
    np.testing.assert_allclose(model.measure_parameter_jacobian(x, u), theta_step, rtol=1e-12, atol=1e-14)
