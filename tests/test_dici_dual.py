"""The DICI-GFCKF (fused local filters), the DCKF (interleaved state and parameter filters) and the joint CKF."""
import numpy as np
import pytest

from canest.config import DEFAULT_CONFIG, load_config
from canest.filters import FILTERS, Measurement, Transition
from canest.filters.dici import DICIGeneralizedFifthDegreeCKF
from canest.filters.dual import DoubleCubatureKalmanFilter
from canest.filters.fusion import fuse
from canest.filters.joint import JointCubatureKalmanFilter
from canest.filters.sigma import GeneralizedFifthDegreeCKF, predict_together
from canest.models.tire_force import TireForceModel

A = np.array([[1.0, 0.1], [0.0, 0.95]])
LINEAR = Transition(lambda X, u, dt: X @ A.T)
H = np.array([[1.0, 0.0]])
POSITION = Measurement(lambda X, u: X @ H.T)
Q = np.diag([0.01, 0.02])


def test_local_update_from_the_fused_prior_is_the_kalman_update_of_it():
    """Eqs 35-41 as implemented: each local posterior is the exact Kalman update of the fused prediction."""
    f = DICIGeneralizedFifthDegreeCKF([1.0, 0.5], np.diag([0.5, 0.3]), process_scale=(1.0, 4.0), initial_scale=(1.0, 3.0))
    f.predict(LINEAR, None, 0.01, Q)
    prior_x, prior_P = f.x.copy(), f.P.copy()
    R1, R2 = np.eye(1) * 0.1, np.eye(1) * 0.4
    f.update_sets([(np.array([1.2]), POSITION, R1), (np.array([1.1]), POSITION, R2)], None)
    for local, z, R in zip(f.locals, (1.2, 1.1), (R1, R2)):
        S = H @ prior_P @ H.T + R
        K = prior_P @ H.T @ np.linalg.inv(S)
        np.testing.assert_allclose(local.x, prior_x + K @ (np.array([z]) - H @ prior_x), atol=1e-10)
        np.testing.assert_allclose(local.P, (np.eye(2) - K @ H) @ prior_P, atol=1e-10)
    fused = fuse("ici", [lf.x for lf in f.locals], [lf.P for lf in f.locals])
    np.testing.assert_allclose(f.x, fused.x)
    np.testing.assert_allclose(f.P, fused.P)


def test_identical_local_filters_reduce_to_one_gfckf():
    x0, P0 = np.array([1.0, 0.5]), np.diag([0.5, 0.3])
    dici = DICIGeneralizedFifthDegreeCKF(x0, P0, process_scale=(1.0, 1.0), initial_scale=(1.0, 1.0))
    single = GeneralizedFifthDegreeCKF(x0, P0)
    for z in (1.1, 1.3, 1.2):
        for filt in (dici, single):
            filt.predict(LINEAR, None, 0.01, Q)
            filt.update(np.array([z]), POSITION, None, np.eye(1) * 0.2)
    np.testing.assert_allclose(dici.x, single.x, atol=1e-9)
    np.testing.assert_allclose(dici.P, single.P, atol=1e-9)


def test_batched_local_time_updates_equal_separate_ones_on_the_tire_force_model():
    """Step 1 (eqs 28-31) with both local filters' cubature points through one RK4 call of the 7-state model equals
    each local filter's own predict; the filter's fused prediction too."""
    model = TireForceModel(load_config(DEFAULT_CONFIG).vehicle)
    transition = Transition(model.transition)
    u = np.array([0.04, 0.3, 4.5, 0.0, 300.0, 300.0, -50.0, -50.0])  # a left turn at 22 m/s, ay 4.5 m/s^2
    x0 = np.array([0.2, -0.01, 22.0, 2500.0, 1800.0, 2200.0, 1600.0])
    P0 = np.diag([0.05, 0.02, 1.0, 800.0, 800.0, 800.0, 800.0]) ** 2
    Q = np.diag([0.05, 0.01, 0.3, 3e3, 3e3, 3e3, 3e3]) ** 2 * 0.01
    rng = np.random.default_rng(4)
    dici = DICIGeneralizedFifthDegreeCKF(x0, P0)
    for local in dici.locals:  # distinct, correlated posteriors
        root = np.linalg.cholesky(local.P) @ (np.eye(7) + 0.3 * rng.standard_normal((7, 7)))
        local.x, local.P = x0 + np.sqrt(np.diag(local.P)) * rng.standard_normal(7), root @ root.T
    separate = [GeneralizedFifthDegreeCKF(local.x, local.P) for local in dici.locals]
    for local, scale in zip(separate, dici.process_scale):
        local.predict(transition, u, 0.01, Q * scale)
    dici.predict(transition, u, 0.01, Q)
    for batched, alone in zip(dici.locals, separate):
        np.testing.assert_allclose(batched.x, alone.x, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(batched.P, alone.P, rtol=1e-12, atol=1e-12 * np.abs(alone.P).max())
        assert batched.repairs == alone.repairs
    fused = fuse(dici.fusion, [f.x for f in separate], [f.P for f in separate])
    np.testing.assert_allclose(dici.x, fused.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dici.P, fused.P, rtol=1e-12, atol=1e-12 * np.abs(fused.P).max())


def test_batched_time_update_refuses_a_filter_with_its_own():
    class Tempered(GeneralizedFifthDegreeCKF):
        def predict(self, transition, u, dt, Q):
            super().predict(transition, u, dt, 2.0 * Q)

    filters = [GeneralizedFifthDegreeCKF(np.zeros(2), np.eye(2)), Tempered(np.zeros(2), np.eye(2))]
    with pytest.raises(TypeError, match="Tempered"):
        predict_together(filters, LINEAR, None, 0.01, [Q, Q])


def test_ici_keeps_a_dominating_local_filter_and_uses_the_other_when_it_is_alone():
    """ICI cannot prove a worse, possibly correlated source independent: it adds nothing to a dominating one.
    Its value is redundancy: with the first sensor set silent the second still corrects the state."""
    f = DICIGeneralizedFifthDegreeCKF([1.0, 0.5], np.diag([0.5, 0.3]))
    f.predict(LINEAR, None, 0.01, Q)
    f.update_sets([(np.array([1.2]), POSITION, np.eye(1) * 0.1), (np.array([0.0]), POSITION, np.eye(1) * 0.4)], None)
    np.testing.assert_allclose(f.x, f.locals[0].x, atol=1e-6)
    f.predict(LINEAR, None, 0.01, Q)
    predicted = f.P[0, 0]
    f.update_sets([None, (np.array([1.2]), POSITION, np.eye(1) * 0.4)], None)
    assert f.P[0, 0] < predicted


def test_dici_paper_defaults_and_fusion_choice():
    f = FILTERS["dici-gfckf"](np.zeros(7), np.eye(7))
    assert f.process_scale == (1.0, 10.0) and f.sensor_sets == 2
    np.testing.assert_allclose(f.locals[1].P, 10 * np.eye(7))
    with pytest.raises(ValueError, match="fusion"):
        FILTERS["dici-gfckf"](np.zeros(3), np.eye(3), fusion="mean")


# DCKF: a scalar state s and a scalar parameter p; s' = s, measurement z = p * s (+ s to keep s observable)
STATE_AND_GAIN = Transition(lambda X, u, dt: X)
PRODUCT = Measurement(lambda X, u: np.column_stack([X[:, 0] * X[:, 1], X[:, 0]]))


def test_dckf_interleaves_parameter_update_before_state_update():
    f = DoubleCubatureKalmanFilter([2.0, 1.0], np.diag([0.1, 0.2]), parameters=1)
    f.predict(STATE_AND_GAIN, None, 0.01, np.diag([0.01, 0.001]))
    s_prior, p_prior = f.states.x.copy(), f.params.x.copy()
    Ps, Pp = f.states.P.copy(), f.params.P.copy()
    z, R = np.array([3.0, 2.1]), np.diag([0.05, 0.05])
    f.update(z, PRODUCT, None, R)
    # step 3 with the state at its prediction: z = p * s_prior is linear in p; the state's spread adds to R
    Hp = np.array([[s_prior[0]], [0.0]])
    Hs_prior = np.array([[p_prior[0]], [1.0]])
    Kp = Pp @ Hp.T @ np.linalg.inv(Hp @ Pp @ Hp.T + R + Hs_prior @ Ps @ Hs_prior.T)
    p_post = p_prior + Kp @ (z - np.array([p_prior[0] * s_prior[0], s_prior[0]]))
    np.testing.assert_allclose(f.params.x, p_post, atol=1e-9)
    # step 4 with the parameter at its new estimate: z = (p_post * s, s) is linear in s
    Hs = np.array([[p_post[0]], [1.0]])
    Ks = Ps @ Hs.T @ np.linalg.inv(Hs @ Ps @ Hs.T + R)
    np.testing.assert_allclose(f.states.x, s_prior + Ks @ (z - Hs @ s_prior), atol=1e-9)
    np.testing.assert_allclose(f.x, np.concatenate([f.states.x, f.params.x]))
    assert f.P[0, 1] == 0.0  # block diagonal: the dual filter's approximation


def test_dckf_frozen_parameters_hold_and_their_variance_stays_bounded():
    f = DoubleCubatureKalmanFilter([2.0, 0.8], np.diag([0.1, 0.09]), parameters=1)
    f.parameters.frozen = np.array([True])
    for _ in range(500):
        f.predict(STATE_AND_GAIN, None, 0.01, np.diag([0.01, 0.001]))
        f.update(np.array([3.0, 2.0]), PRODUCT, None, np.diag([0.05, 0.05]))
    assert f.params.x[0] == pytest.approx(0.8)
    assert f.params.P[0, 0] == pytest.approx(0.09)  # grew to its cap, not beyond
    f.parameters.frozen = np.array([False])
    f.predict(STATE_AND_GAIN, None, 0.01, np.diag([0.01, 0.001]))
    f.update(np.array([3.0, 2.0]), PRODUCT, None, np.diag([0.05, 0.05]))
    assert f.params.x[0] > 1.0 and f.params.P[0, 0] < 0.09  # learning again: z/s = 1.5


def kalman_update_then_predict(x, P, z, F, H, Q, R):
    """The linear Kalman filter, update first: a parameter's variance then stays below its cap (the initial 1)."""
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    x, P = x + K @ (z - H @ x), (np.eye(len(x)) - K @ H) @ P
    return F @ x, F @ P @ F.T + Q


def test_dckf_equals_the_kalman_filter_on_a_decoupled_linear_system():
    """States and parameters that do not interact: the dual filter's block-diagonal covariance is exact."""
    F = np.diag([0.98, 1.0, 1.0])  # two states (one observed), one random-walk parameter
    F[0, 1] = 0.1
    H = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    Q, R = np.diag([0.01, 0.02, 0.001]), np.diag([0.2, 0.3])
    transition = Transition(lambda X, u, dt: X @ F.T)
    measurement = Measurement(lambda X, u: X @ H.T)
    f = DoubleCubatureKalmanFilter(np.zeros(3), np.eye(3), parameters=1)
    x, P = np.zeros(3), np.eye(3)
    rng = np.random.default_rng(5)
    for _ in range(40):
        z = rng.standard_normal(2)
        x, P = kalman_update_then_predict(x, P, z, F, H, Q, R)
        f.update(z, measurement, None, R)
        f.predict(transition, None, 0.01, Q)
        np.testing.assert_allclose(f.x, x, atol=1e-9)
        np.testing.assert_allclose(f.P, P, atol=1e-9)


def test_dckf_needs_a_parameter_block():
    with pytest.raises(ValueError, match="parameters"):
        DoubleCubatureKalmanFilter(np.zeros(3), np.eye(3), parameters=3)


def test_jckf_equals_the_kalman_filter_on_a_coupled_linear_system_where_dckf_does_not():
    """The joint filter keeps the state-parameter cross-covariance the dual filter drops.

    A state observed only together with a random-walk parameter (z1 = s + p), and the parameter alone (z2 = p).
    """
    F, H = np.array([[0.95, 0.0], [0.0, 1.0]]), np.array([[1.0, 1.0], [0.0, 1.0]])
    Q, R = np.diag([0.02, 0.001]), np.diag([0.1, 0.5])
    transition, measurement = Transition(lambda X, u, dt: X @ F.T), Measurement(lambda X, u: X @ H.T)
    joint = JointCubatureKalmanFilter(np.zeros(2), np.eye(2), parameters=1)
    dual = DoubleCubatureKalmanFilter(np.zeros(2), np.eye(2), parameters=1)
    x, P = np.zeros(2), np.eye(2)
    rng = np.random.default_rng(7)
    for _ in range(30):
        z = rng.standard_normal(2)
        x, P = kalman_update_then_predict(x, P, z, F, H, Q, R)
        for f in (joint, dual):
            f.update(z, measurement, None, R)
            f.predict(transition, None, 0.01, Q)
        np.testing.assert_allclose(joint.x, x, atol=1e-9)
        np.testing.assert_allclose(joint.P, P, atol=1e-9)
    assert abs(P[0, 1]) > 0.01 and dual.P[0, 1] == 0.0
    assert not np.allclose(dual.x, x, atol=1e-3)


def test_jckf_frozen_parameters_hold_their_variance_is_capped_and_bounds_truncate():
    f = JointCubatureKalmanFilter([2.0, 0.8], np.diag([0.1, 0.09]), parameters=1, parameter_bounds=(0.1, 1.3))
    f.parameters.frozen = np.array([True])
    for _ in range(500):
        f.predict(STATE_AND_GAIN, None, 0.01, np.diag([0.01, 0.001]))
        f.update(np.array([3.0, 2.0]), PRODUCT, None, np.diag([0.05, 0.05]))
    assert f.x[1] == pytest.approx(0.8)
    assert f.P[1, 1] == pytest.approx(0.09)
    assert np.all(np.linalg.eigvalsh(f.P) > 0)
    f.parameters.frozen = np.array([False])
    for _ in range(200):
        f.predict(STATE_AND_GAIN, None, 0.01, np.diag([0.01, 0.001]))
        f.update(np.array([6.0, 2.0]), PRODUCT, None, np.diag([0.05, 0.05]))  # z/s = 3: beyond the bound
    std = np.sqrt(f.P[1, 1])
    assert 1.3 - 2 * std < f.x[1] < 1.3  # the truncated Gaussian's mean lies inside, about 0.8 std from the bound
    assert f.parameters.pressed[0]
    assert np.all(np.linalg.eigvalsh(f.P) > 0)


@pytest.mark.parametrize("kind", (JointCubatureKalmanFilter, DoubleCubatureKalmanFilter))
def test_a_refused_rise_keeps_the_parameter_and_its_variance_and_a_fall_is_taken(kind):
    """One-sided evidence (``may_rise`` clear: the data bound the parameter from below only). Clipping the risen
    mean back kept the variance the refused evidence had shrunk; noise then ratcheted the mean down (falls kept,
    rises clipped) while the variance fell as if every update had been used."""
    f = kind([2.0, 0.8], np.diag([0.1, 0.09]), parameters=1, parameter_bounds=(0.1, 1.3))
    f.parameters.may_rise = np.array([False])
    rises = falls = 0
    for k in range(200):
        f.predict(STATE_AND_GAIN, None, 0.01, np.diag([0.01, 0.0001]))
        before, variance = f.x[1], f.P[1, 1]
        f.update(np.array([1.6 + (0.3 if k % 2 else -0.3), 2.0]), PRODUCT, None, np.diag([0.05, 0.05]))
        if f.x[1] == before:  # refused: the step would have raised it
            rises += 1
            assert f.P[1, 1] == pytest.approx(variance)
        else:
            falls += 1
            assert f.x[1] < before and f.P[1, 1] < variance
        assert np.all(np.linalg.eigvalsh(f.P) > 0)
    assert rises > 10 and falls > 10  # both kinds of tick were seen


def test_jckf_needs_a_parameter_block():
    with pytest.raises(ValueError, match="parameters"):
        JointCubatureKalmanFilter(np.zeros(3), np.eye(3), parameters=0)
