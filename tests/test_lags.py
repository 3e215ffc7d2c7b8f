"""The two signal memories of :mod:`canest.estimation.lags`."""
import math

import pytest

from canest.estimation.lags import FadingMaximum, FirstOrderLag


def test_first_order_lag_starts_at_its_first_sample_and_follows_a_step_with_its_time_constant():
    dt, tau = 0.01, 0.05
    lag = FirstOrderLag(dt, tau)
    assert lag.update(2.0) == 2.0  # no transient from an assumed zero
    values = [lag.update(3.0) for _ in range(200)]
    # backward Euler: the gap to the step shrinks by tau / (tau + dt) per sample
    assert values[0] == pytest.approx(2.0 + dt / (tau + dt))
    gap_after = {n: 3.0 - values[n - 1] for n in (5, 10)}
    assert gap_after[5] == pytest.approx((tau / (tau + dt)) ** 5)
    # about one time constant (5 samples) leaves about e^-1 of the step
    assert gap_after[5] == pytest.approx(math.exp(-1.0), abs=0.05)
    assert values[-1] == pytest.approx(3.0, abs=1e-9)


def test_first_order_lag_reset_restarts_at_the_next_sample():
    lag = FirstOrderLag(0.01, 0.05)
    lag.update(0.0)
    lag.update(10.0)
    lag.reset()
    assert lag.value is None
    assert lag.update(-4.0) == -4.0


def test_fading_maximum_holds_a_peak_fading_with_its_memory_and_a_larger_value_takes_over():
    dt, memory = 0.01, 1.0
    peak = FadingMaximum(dt, memory)
    assert peak.update(2.0) == 2.0
    for _ in range(100):
        value = peak.update(0.5)
    assert value == pytest.approx(2.0 * math.exp(-1.0))  # one memory later: e^-1 of the peak
    assert peak.update(1.5) == 1.5  # above the faded peak
    assert peak.update(0.0) == pytest.approx(1.5 * math.exp(-dt / memory))
    peak.reset()
    assert peak.update(0.1) == 0.1
