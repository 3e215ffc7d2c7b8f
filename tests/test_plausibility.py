"""Slew-rate plausibility of input samples."""
import math

from canest.codec.plausibility import RESYNC_AFTER, SlewLimit


def test_rejects_an_impossible_jump_for_its_own_input_only_and_keeps_the_reference():
    limit = SlewLimit(["yaw_rate", "ay"])
    assert limit.accept([("yaw_rate", 0.10), ("ay", 1.0)], 0.00) == [("yaw_rate", 0.10), ("ay", 1.0)]
    # ay from 1 to 80 m/s^2 in 10 ms is dropped; the yaw rate of the same frame is used
    assert limit.accept([("yaw_rate", 0.11), ("ay", 80.0)], 0.01) == [("yaw_rate", 0.11)]
    assert limit.accept([("yaw_rate", 0.12), ("ay", 1.2)], 0.02) == [("yaw_rate", 0.12), ("ay", 1.2)]
    assert limit.last["ay"] == (1.2, 0.02)  # judged against the last accepted sample


def test_a_real_step_is_accepted_after_a_few_rejections():
    limit = SlewLimit(["yaw_rate"])
    assert limit.accept([("yaw_rate", 0.0)], 0.0)
    verdicts = [bool(limit.accept([("yaw_rate", 1.5)], 0.01 * (k + 1))) for k in range(RESYNC_AFTER + 2)]
    assert verdicts == [False] * RESYNC_AFTER + [True, True]


def test_fast_but_physical_changes_pass():
    limit = SlewLimit(["steering_wheel_angle"])
    # 250 deg at 1 Hz peaks at 1570 deg/s, as fast as a steering robot turns.
    angle = [math.radians(250.0) * math.sin(2 * math.pi * 1.0 * k * 0.01) for k in range(200)]
    assert all(limit.accept([("steering_wheel_angle", a)], k * 0.01) for k, a in enumerate(angle))
