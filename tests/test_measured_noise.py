"""A sensor's noise read from its samples: the noise, not the motion, at a gyro's sampling rates, and its colour."""
import numpy as np
import pytest

from canest.estimation.measured_noise import WARMUP, MeasuredNoise
from canest.sim.sensors import Vibration

SLALOM = (0.2, 0.5)  # rad/s, Hz: a yaw rate swinging 11 deg/s


def measured(times, values) -> float | None:
    noise = MeasuredNoise()
    for t, value in zip(times, values):
        noise.add(t, value)
    return noise.std


def sampled(rate: float, jitter: float, seconds: float, rng) -> np.ndarray:
    return np.sort(np.arange(0.0, seconds, 1.0 / rate) + rng.uniform(0.0, jitter, int(seconds * rate)))


@pytest.mark.parametrize("rate, jitter", [(100.0, 0.0), (100.0, 0.004), (50.0, 0.0)])
def test_a_white_noise_is_read_at_its_std_and_a_slalom_s_motion_below_a_datasheet_gyro_s_noise(rate, jitter):
    rng = np.random.default_rng(1)
    t = sampled(rate, jitter, 20.0, rng)
    stds = [measured(t[t < end], 0.002 * rng.standard_normal((t < end).sum())) for end in (5.0, 10.0, 15.0, 20.0)]
    assert all(0.0017 < std < 0.0023 for std in stds), stds
    amplitude, frequency = SLALOM
    motion = amplitude * np.sin(2.0 * np.pi * frequency * t) + 0.5 * t
    assert measured(t, motion) < 0.0012  # never above a datasheet gyro's 0.002 rad/s by the car's own motion


def test_a_noise_correlated_over_15_ms_reads_above_its_std_as_a_filter_averaging_its_samples_sees_it():
    """The simulator's body vibration (0.3 deg/s, correlated over 15 ms) beside a white 0.1 deg/s: the means of a
    few samples scatter 1.9 times as much as a white noise's of the same variance (module docstring)."""
    for seed in range(3):
        rng = np.random.default_rng(seed)
        vibration = Vibration(rng, np.radians(0.3), 0.0)
        t = np.arange(0.0, 30.0, 0.01)
        values = [vibration.at(ti) + np.radians(0.1) * rng.standard_normal() for ti in t]
        assert 1.0 < measured(t, values) / np.radians(np.hypot(0.3, 0.1)) < 1.3


def test_nothing_is_said_before_a_warmup_of_samples_and_time_running_backwards_starts_over():
    t = np.arange(0.0, WARMUP + 0.2, 0.01)
    assert measured(t[t < WARMUP], np.zeros((t < WARMUP).sum())) is None
    noise = MeasuredNoise()
    for ti in t:
        noise.add(ti, 0.01 * (-1) ** round(ti / 0.01))
    assert noise.std is not None
    noise.add(0.1, 0.0)  # a replay looped back: what was measured belongs to another stretch
    assert noise.std is None and list(noise.samples) == [(0.1, 0.0)]
    noise.add(0.1, 1.0)  # a sample already seen adds nothing
    assert list(noise.samples) == [(0.1, 0.0)]
    for ti in t:
        noise.add(0.1 + ti, 0.01 * (-1) ** round(ti / 0.01))
    period = noise.period
    noise.add(60.0, 0.0)  # a gap of a minute: the sampling period is not a minute
    assert noise.std is None and noise.period is None and list(noise.samples) == [(60.0, 0.0)]
    noise.add(60.01, 0.0)
    assert noise.period == pytest.approx(period)


def test_a_sparse_channel_is_measured_too_and_a_non_finite_sample_is_left_out():
    """A 20 Hz channel's 30 ms spans would hold no sample at times: its spans are 1.5 sampling periods."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 20.0, 0.05)
    values = 0.002 * rng.standard_normal(len(t))
    values[100] = np.nan
    assert 0.0016 < measured(t, values) < 0.0024


@pytest.mark.parametrize("model", ["single_track", "tire_force"])
def test_vx_integrating_a_vibrating_ax_takes_its_measured_density_as_process_noise(config, model):
    """A car without motor torques: both models integrate the measured ax into vx (the tire-force model's forces
    come from ax), so its measured density is vx's process noise when it exceeds the configured one; and while
    the reference speed integrates that ax, enough to hold vx's variance at the walk every tick shares, which
    the reference channel's std then leaves out (it is in the prior)."""
    from dataclasses import replace

    from canest.estimation.reference_speed import TORQUES
    from canest.pipeline import Pipeline
    from canest.sim.simulate import simulate

    torqueless = replace(config, signals={k: v for k, v in config.signals.items() if k not in TORQUES},
                         estimator=replace(config.estimator, model=model, filter="ckf"))
    sim = simulate(config, "sine", 80.0, 0.85, duration=4.0, seed=1, vibration=1.0)
    pipeline = Pipeline(torqueless)
    estimator, noise, density_floor, walk_floor = pipeline.estimator, [], [], []
    vx, dt = estimator.vx, estimator.dt
    for frame in sim.frames:
        if pipeline.feed(frame) and estimator.ax_noise.density is not None:
            t = estimator.reference_speed.last_t + dt
            noise.append(estimator._process_noise(t)[vx, vx])
            density_floor.append(max(estimator.Q[vx, vx], estimator.ax_noise.density * dt))
            walk_floor.append(estimator._shared_walk(t) ** 2 - estimator.filter.P[vx, vx])
    density = estimator.ax_noise.density
    assert estimator.integrates_ax and density > estimator.Q[vx, vx] / dt
    np.testing.assert_allclose(noise, np.maximum(density_floor, walk_floor), rtol=1e-12)
    binding = np.array(walk_floor) > np.array(density_floor)
    assert 0 < binding.sum() < binding.size  # the walk binds between the wheels' anchors, not at them
    later = estimator.reference_speed.last_t + 1.0  # nothing taken for a second: no walk shared
    assert estimator._process_noise(later)[estimator.vx, estimator.vx] == pytest.approx(density * estimator.dt)
