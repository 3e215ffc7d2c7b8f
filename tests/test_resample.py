"""Zero-order hold, staleness, freshness and the tick grid."""
import math

import pytest

from canest.resample import Resampler, TickClock


def test_hold_stale_and_fresh():
    r = Resampler(["a", "b"], {"a": 0.05, "b": 0.1})
    never = r.sample(0.0)
    assert list(never.stale) == [True, True] and not never.fresh.any()
    r.hold("a", 1.5, 0.00)
    s = r.sample(0.01)
    assert s.values[0] == 1.5 and s.fresh[0] and not s.stale[0]
    assert s.ages[0] == pytest.approx(0.01)
    again = r.sample(0.02)
    assert again.values[0] == 1.5 and not again.fresh[0], "a held value is not fresh twice"
    assert r.sample(0.051).stale[0], "older than its timeout"


def test_ticks_lie_on_a_grid_anchored_at_the_first_frame():
    clock = TickClock(0.01)
    assert list(clock.due(5.0003)) == []
    ticks = list(clock.due(5.0351))
    assert ticks == pytest.approx([5.0003, 5.0103, 5.0203, 5.0303])
    assert list(clock.due(5.0352)) == []


def test_a_frame_at_exactly_a_tick_time_belongs_to_that_tick():
    clock = TickClock(0.01)
    list(clock.due(1.0))
    assert list(clock.due(1.01)) == [1.0]  # the tick at 1.01 waits: a frame stamped 1.01 still counts for it


def test_a_long_gap_reanchors_instead_of_catching_up():
    clock = TickClock(0.01, max_gap=1.0)
    list(clock.due(0.0))
    assert list(clock.due(100.0)) == []
    assert clock.jumps == 1
    assert clock.next_tick == 100.0
    assert not math.isinf(clock.next_tick)


def test_a_clock_step_back_reanchors_instead_of_waiting():
    clock = TickClock(0.01, max_gap=1.0)
    list(clock.due(100.0))
    list(clock.due(100.5))
    assert list(clock.due(90.0)) == [] and clock.jumps == 1
    assert list(clock.due(90.025)) == pytest.approx([90.0, 90.01, 90.02])


def test_small_reordering_does_not_reanchor():
    clock = TickClock(0.01, max_gap=1.0)
    list(clock.due(5.0))
    list(clock.due(5.1))
    assert list(clock.due(5.05)) == [] and clock.jumps == 0
