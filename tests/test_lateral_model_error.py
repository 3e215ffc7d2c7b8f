"""ay's R carries the model's lateral error, which grows with ay (``estimator.lateral_model_error``)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from canest.estimation import channels as ch


def test_only_the_lateral_accelerometer_rows_take_the_model_error_in_quadrature():
    channels = ch.Channels(mask=np.ones(3, dtype=bool), z=np.array([-4.0, 0.2, 3.0]), std=np.array([0.06, 0.002, 0.3]),
                           ages=np.zeros(3))
    widened = ch.with_lateral_model_error(channels, [0, 2], 0.05)
    np.testing.assert_allclose(widened.std, [math.hypot(0.06, 0.2), 0.002, math.hypot(0.3, 0.15)])
    np.testing.assert_array_equal(channels.std, [0.06, 0.002, 0.3])  # the assembled channels are not changed
    assert ch.with_lateral_model_error(channels, [0, 2], 0.0).std.tolist() == channels.std.tolist()


@pytest.mark.parametrize("share", [0.0, 0.05])
def test_the_filter_and_the_consistency_test_take_ay_at_its_noise_and_the_model_s_error_at_that_ay(config, share):
    """On a quiet IMU through a sine steer (|ay| to 6 m/s^2) the ay row the filter updates with and the consistency
    test judges by is the configured sensor noise and ``share |ay|`` in quadrature, never below ay's measured
    noise; on the straight before the steer it is the sensor's alone."""
    from canest.pipeline import Pipeline
    from canest.sim.simulate import simulate

    config = replace(config, estimator=replace(config.estimator, lateral_model_error=share))
    sim = simulate(config, "sine", 80.0, 0.85, duration=4.0, seed=1)
    pipeline = Pipeline(config)
    estimator = pipeline.estimator
    row = estimator.model.measurement_names.index("ay")
    taken = []
    update = estimator._update

    def spy(channels, inputs, u, lateral_ok, t):
        if channels.mask[row]:
            measured = estimator.input_noise["ay"].std or 0.0
            taken.append((channels.z[row], channels.std[row], measured))
        return update(channels, inputs, u, lateral_ok, t)

    recorded = []  # the channels the consistency tests take (friction's at the configured noise)
    record = estimator.judge.record

    def record_spy(channels, measured_std, *args):
        if channels.mask[row]:
            recorded.append((channels.z[row], channels.std[row]))
        return record(channels, measured_std, *args)

    estimator._update = spy
    estimator.judge.record = record_spy
    for frame in sim.frames:
        pipeline.feed(frame)
    z, std, measured = np.array(taken).T
    sensor = config.estimator.measurement_noise["ay"]
    np.testing.assert_allclose(std, np.maximum(np.hypot(sensor, share * z), measured), rtol=1e-12)
    configured_z, configured = np.array(recorded).T
    np.testing.assert_allclose(configured, np.hypot(sensor, share * configured_z), rtol=1e-12)
    assert np.abs(z).max() > 4.0
    bend, straight = np.abs(z) > 4.0, np.abs(z) < 0.2
    if share:
        assert std[bend].min() > 1.8 * sensor and std[straight].max() < 1.05 * sensor
    else:
        np.testing.assert_allclose(std, sensor)  # a quiet ay's measured noise stays below the configured


def test_a_second_imu_s_ay_takes_the_model_error_too(config):
    """dici-gfckf's tire-force model measures both IMUs' ay: both rows are widened, no other."""
    from canest.pipeline import Pipeline

    dici = replace(config.estimator, filter="dici-gfckf", model="tire_force")
    estimator = Pipeline(replace(config, estimator=dici)).estimator
    names = estimator.model.measurement_names
    assert [names[row] for row in estimator.lateral_rows] == ["ay", "ay_2"]


@pytest.mark.parametrize("ay, loud", [(0.0, True), (6.0, False)])
def test_ay_is_loud_for_the_kinematic_check_only_above_its_std_at_that_ay(config, ay, loud):
    """A measured ay noise of 0.2 m/s^2: above the sensor's configured 0.11 on a straight (the kinematic check takes
    its density), below the channel's std in a 6 m/s^2 bend (0.32: what the spans read there is the bend's ay)."""
    from types import SimpleNamespace

    from canest.pipeline import Pipeline

    estimator = Pipeline(config).estimator
    for noise in (estimator.input_noise["ay"], estimator.ay_noise):
        noise.variance, noise.seen, noise.period = 0.2 ** 2, 10.0, 0.01
    density = estimator._ay_density(SimpleNamespace(values={"ay": ay}))
    assert density == (pytest.approx(0.2 ** 2 * 0.01) if loud else 0.0)
