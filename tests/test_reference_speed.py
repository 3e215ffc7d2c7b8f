"""The reference speed: the wheels while they roll freely, the integrated acceleration while they slip."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from canest.config import load_config
from canest.estimation.inputs import TickInputs
from canest.estimation.longitudinal_offset import PRIOR_STD
from canest.estimation.reference_speed import DRIFT, MAX_GAP, PAIR_SETTLE, ReferenceSpeed, tick_usage
from canest.models.wheel_force import DriveLayout
from canest.models.wheels import WheelGeometry
from tests.conftest import CONFIG

RADIUS, STIFFNESS, ANCHORED_STD = 0.3, 15.0, 0.05
ROLLING = np.zeros(4)


def reference():
    return ReferenceSpeed(RADIUS, STIFFNESS, ANCHORED_STD)


def test_free_rolling_wheels_give_the_speed_less_their_linear_slip():
    ref = reference()
    usage = np.full(4, 0.06)  # a gentle drive: each tire needs slip usage / stiffness
    speed, std = ref.update(0.0, 0.5, np.full(4, 50.0), np.full(4, 0.5 / RADIUS), usage)
    assert speed == pytest.approx(RADIUS * 50.0 / (1 + 0.06 / STIFFNESS))
    assert std == pytest.approx(ANCHORED_STD)


SIX_PERCENT = 9.81 * np.sin(np.arctan(0.06))  # m/s^2 the accelerometer reads of gravity uphill at 6 %


def launch(ref, t0, ax, offset=0.0, seconds=1.0, dt=0.01):
    """``seconds`` of a launch from 50 rad/s at ``t0``: the car accelerates at ``ax``, its wheels spin up three times
    faster, the accelerometer reads ``ax + offset`` (a grade's gravity); the last (speed, std)."""
    for k in range(1, int(round(seconds / dt)) + 1):
        wheels = np.full(4, 50.0 + 3 * ax * k * dt / RADIUS)
        speed, std = ref.update(t0 + k * dt, ax + offset, wheels, np.full(4, 3 * ax / RADIUS), np.full(4, 0.4))
    return speed, std


def test_spinning_wheels_are_not_followed_and_the_uncertainty_grows():
    ref, t0 = rolled(2.0)  # long enough for the wheels to have measured ax's offset (none here)
    assert ref.offset.value == pytest.approx(0.0, abs=1e-9) and ref.offset.measured_std < DRIFT
    speed, std = launch(ref, t0, 3.0)
    assert speed == pytest.approx(RADIUS * 50.0 + 3.0 * 1.0)
    assert std == pytest.approx(np.hypot(ANCHORED_STD, DRIFT * 1.0))


def test_a_road_grade_free_rolling_wheels_measured_is_taken_out_of_the_integrated_ax():
    """Uphill at 6 % the accelerometer reads 0.59 m/s^2 of gravity at a steady speed; integrated, it ran the
    reference away from the car (and no wheel was ever in step with it: their R dw/dt is 0)."""
    ref = reference()
    for k in range(301):  # 3 s at a steady speed on the hill
        ref.update(k * 0.01, SIX_PERCENT, np.full(4, 50.0), ROLLING, ROLLING)
    assert ref.anchored_at == ref.last_t  # the wheels in step with ax less its offset
    assert ref.offset.value == pytest.approx(SIX_PERCENT, abs=0.05)
    speed, std = launch(ref, ref.last_t, 3.0, offset=SIX_PERCENT)
    assert speed == pytest.approx(RADIUS * 50.0 + 3.0, abs=0.05)
    assert std == pytest.approx(np.hypot(ANCHORED_STD, max(DRIFT, ref.offset.measured_std) * 1.0))


def test_an_offset_no_wheel_has_measured_yet_is_in_the_integrated_speed_s_std():
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    _, std = launch(ref, 0.0, 3.0)
    assert std == pytest.approx(np.hypot(ANCHORED_STD, PRIOR_STD * 1.0))  # a 5 % grade as one std


def test_wheels_whose_force_grows_do_not_measure_the_offset():
    """Their slip grows with their force: at a launch's start on 0.35 (usage still below the free-rolling 0.1) the
    wheels ran ahead of the car and read as an offset of -0.044 m/s^2, integrated over the launch."""
    ref, t0 = rolled(2.0)
    before = ref.offset.value
    for k in range(1, 51):  # half a second: usage 0 -> 0.09, the wheels' slip growing with it (three times a
        usage = np.full(4, 0.09 * k / 50)  # linear tire's, as on low friction)
        ref.update(t0 + k * 0.01, 0.0, np.full(4, 50.0 * (1.0 + usage[0] / STIFFNESS * 3)), ROLLING, usage)
    assert abs(ref.offset.value - before) < 0.01  # the slip's growth reads as -0.54 m/s^2


def test_a_grade_that_begins_on_the_way_is_learned_anew():
    """A climb begun in a bend, where nothing is learned, shows on the next straight as a step the offset's
    settled variance gates out: its random walk would take 10 s to admit 6 %, the reference integrating gravity."""
    ref, t0 = rolled(3.0)
    for k in range(1, 301):  # 3 s at a steady speed on the hill
        ref.update(t0 + k * 0.01, SIX_PERCENT, np.full(4, 50.0), ROLLING, ROLLING)
    assert ref.offset.value == pytest.approx(SIX_PERCENT, abs=0.05)


def test_an_estimate_off_the_reference_is_off_by_what_the_reference_s_std_does_not_explain():
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    for k in range(1, 101):  # a second of spinning wheels: the reference integrates ax
        speed, std = ref.update(k * 0.01, 3.0, np.full(4, 50.0 + 0.3 * k), np.full(4, 30.0), np.full(4, 0.4))
    assert std > 2 * ANCHORED_STD
    t = ref.last_t
    assert ref.disagreement(t, speed + 0.5 * std) == 0.0  # within its std: the estimate's own says enough
    assert ref.disagreement(t, speed - 3.0 * std) == pytest.approx(2.0 * std)
    assert ref.disagreement(t, speed - 3.0 * std, beside=std) == pytest.approx((3.0 - np.sqrt(2.0)) * std)
    assert ref.disagreement(t + 0.01, speed + 9.0) == 0.0  # no update at that tick: nothing to compare with


def rolled(seconds=PAIR_SETTLE, drive_front_share=1.0):
    """A reference after ``seconds`` of 10 ms ticks of free rolling at 50 rad/s: its pairs have settled."""
    ref = ReferenceSpeed(RADIUS, STIFFNESS, ANCHORED_STD, drive_front_share)
    for k in range(int(round(seconds / 0.01)) + 1):
        ref.update(k * 0.01, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    return ref, ref.last_t


def test_an_integrated_ax_that_vibrates_grows_the_uncertainty_as_its_random_walk():
    """An IMU vibrating as the simulator's (ax density 0.06 m^2/s^3: 0.24 m/s per sqrt(s)) integrated for a second."""
    ref, t0 = rolled(2.0)
    for k in range(1, 101):
        speed, std = ref.update(t0 + k * 0.01, 3.0, np.full(4, 60.0), np.full(4, 9.0 / RADIUS), np.full(4, 0.4),
                                ax_density=0.06)
    t = ref.last_t
    assert std == pytest.approx(np.sqrt(ANCHORED_STD**2 + max(DRIFT, ref.offset.measured_std)**2 + 0.06 * 1.0))
    shared = max(DRIFT, ref.offset.measured_std) * 1.0  # ax's offset's error: every tick's too
    assert ref.integration_std(t) == pytest.approx(np.hypot(np.sqrt(0.06 * 1.0), shared))  # the walk every tick shared
    assert ref.integration_std(t, 0.24) == pytest.approx(np.hypot(np.sqrt(0.24 * 1.0), shared))  # density measured since
    assert ref.integration_std(t + 0.01) == 0.0  # not updated at that tick: nothing taken there
    ref.update(t + 0.01, 3.0, np.full(4, 60.0), np.full(4, 3.0 / RADIUS), ROLLING, ax_density=0.06)  # free: anchored
    assert ref.anchored_at == t + 0.01 and ref.integration_std(t + 0.01) == 0.0


def test_free_rolling_wheels_anchor_the_speed_on_a_vibrating_imu_and_a_runaway_wheel_still_does_not():
    """ax vibrating by 1.4 m/s^2 correlated over 15 ms (the simulator's vibration 1; density 0.06 m^2/s^3) beside
    wheels rolling freely at the car's 1 m/s^2: against ax's mean over the wheels' window the wheels anchor the
    speed on most ticks with that mean's noise in the tolerance, on fewer than half without it (density not yet
    measured; against the raw ax sample, on the simulator's vibrating sine, 30 ticks of 1300). A wheel spinning up
    4 m/s^2 faster than the car is out of step but on the ticks the vibration hides it (the tolerance's price:
    ~3 %; a tire spinning on its own torque also transmits more than ``FREE_ROLLING_USAGE``)."""
    dt, std, density = 0.01, 1.4, 0.06
    keep = np.exp(-dt / 0.015)
    vibration = np.zeros(500)
    for k, w in enumerate(np.random.default_rng(2).standard_normal(vibration.size)):
        vibration[k] = keep * vibration[k - 1] + np.sqrt(1.0 - keep * keep) * std * w
    rolling = np.full(4, 1.0 / RADIUS)
    runaway = np.array([5.0 / RADIUS, 1.0 / RADIUS, 1.0 / RADIUS, 1.0 / RADIUS])
    for wheels, told, expected in ((rolling, 0.0, lambda share: share < 0.5), (rolling, density, lambda share: share > 0.8),
                                   (runaway, density, lambda share: share < 0.08)):
        ref, anchored = reference(), []
        for k, noise in enumerate(vibration):
            ref.update(k * dt, 1.0 + noise, np.full(4, (20.0 + k * dt) / RADIUS), wheels, ROLLING, ax_density=told,
                       usage_measured=True)
            anchored.append(ref.anchored_at == k * dt)
        assert expected(np.mean(anchored[1:])), (told, np.mean(anchored[1:]))


def test_without_torques_the_wheels_are_held_to_the_ax_sample_their_usage_came_from():
    """A car without torques launching at 3 m/s^2, its wheels spinning up at 3.5, its IMU vibrating: the usage is the
    drive layout's share of the vibrating ax (all four driven: ``ax / g``), which dips below the free-rolling usage.
    Against the window's mean and tolerance the spinning wheels would anchor the speed on those ticks; held to the
    sample, never."""
    dt, std, density = 0.01, 1.4, 0.06
    keep = np.exp(-dt / 0.015)
    ax = np.zeros(500)
    for k, w in enumerate(np.random.default_rng(3).standard_normal(ax.size)):
        ax[k] = keep * (ax[k - 1] - 3.0) + 3.0 + np.sqrt(1.0 - keep * keep) * std * w if k else 3.0
    spinning = np.full(4, 3.5 / RADIUS)
    shares = {}
    for usage_measured in (True, False):
        ref, anchored = reference(), []
        for k, sample in enumerate(ax):
            ref.update(k * dt, sample, np.full(4, (20.0 + 3.5 * k * dt) / RADIUS), spinning, np.full(4, sample / 9.81),
                       ax_density=density, usage_measured=usage_measured)
            anchored.append(ref.anchored_at == k * dt)
        shares[usage_measured] = np.mean(anchored[1:])
    assert shares[False] == 0.0 and shares[True] > 0.01, shares


def test_a_wheel_out_of_step_with_the_imu_stops_the_anchoring_on_its_axle_even_without_torque():
    ref, t = rolled()
    locking = np.array([-20.0, 0.0, 0.0, 0.0])  # rad/s^2: one front wheel decelerating on its own
    speed, std = ref.update(t + 0.01, 0.0, np.array([49.0, 50.0, 50.2, 50.2]), locking, ROLLING)
    assert speed == pytest.approx(RADIUS * 50.2)  # the rear pair's speed, not the mean with the locking wheel
    assert std == pytest.approx(np.sqrt(2.0) * ANCHORED_STD)  # two wheels' noise, not four
    locking = np.array([-20.0, 0.0, 0.0, -20.0])  # a wheel of each axle: no pair rolls freely, ax is integrated
    speed, std = ref.update(t + 0.02, 0.0, np.array([48.0, 50.0, 50.2, 49.0]), locking, ROLLING)
    assert speed == pytest.approx(RADIUS * 50.2) and std > np.sqrt(2.0) * ANCHORED_STD


def test_no_pair_measures_the_speed_before_it_has_been_seen_undriven_for_the_settling_time():
    """After a start or a gap nothing is known of what the pairs transmitted: one locking wheel then stops the
    anchoring, as it did before pairs were used."""
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    ref.update(0.01, 0.0, np.array([49.0, 50.0, 50.2, 50.2]), np.array([-20.0, 0.0, 0.0, 0.0]), ROLLING)
    assert ref.anchored_at == 0.0


def test_braking_leaves_no_pair_undriven_whatever_the_torques_say():
    """Motor torques do not show the friction brakes, which act on both axles: braking at 8 m/s^2 with a rear wheel
    locking and the others 4 % slow, the front pair (torque 0) anchored the speed 0.75 m/s low, std 0.07."""
    ref, t = rolled()
    wheels = np.array([48.0, 48.0, 20.0, 48.0])
    locking = np.array([-8.0 / RADIUS, -8.0 / RADIUS, -200.0, -8.0 / RADIUS])
    speed, std = ref.update(t + 0.01, -8.0, wheels, locking, ROLLING)
    assert speed == pytest.approx(RADIUS * 50.0 - 0.08) and std > ANCHORED_STD


@pytest.mark.parametrize("drive_front_share", [1.0, 0.0, 0.5])
def test_only_an_undriven_axles_pair_measures_the_speed_alone(drive_front_share):
    """At a steady speed ax shows no drive force, but drag and rolling resistance need some from the driven pair:
    with a wheel of the other pair out of step, a front-driven car's rear pair gives the speed, a rear-driven car's
    rear pair (driven, 0.6 % ahead) does not, nor either pair of a car driven at all four."""
    ref, t = rolled(drive_front_share=drive_front_share)
    ahead = np.array([50.3, 50.3, 50.0, 50.0]) if drive_front_share else np.array([50.0, 50.0, 50.3, 50.3])
    front_out_of_step = np.array([0.0, -20.0, 0.0, 0.0])
    speed, _ = ref.update(t + 0.01, 0.0, ahead, front_out_of_step, ROLLING)
    if drive_front_share == 1.0:
        assert ref.anchored_at == t + 0.01 and speed == pytest.approx(RADIUS * 50.0)
    else:
        assert ref.anchored_at == t and speed == pytest.approx(RADIUS * 50.0, abs=1e-3)  # integrated


def test_a_pair_brought_to_the_four_wheels_mean_by_the_steered_front_wheels():
    """The measurement is the four wheel centres' mean speed; a rear pair rolls at vx, a steered front pair at
    ``vx + front_excess``, so the four wheels' mean is the rear pair's plus half the excess (a front-driven car),
    and the front pair's less half of it (a rear-driven one). A driven pair is no reference alone, even below the
    free-rolling usage."""
    excess = -0.04  # m/s
    for drive_front_share, usage, expected in ((1.0, [0.3, 0.3, 0.0, 0.0], RADIUS * 50.0 + excess / 2),
                                                (0.0, [0.0, 0.0, 0.3, 0.3], RADIUS * 50.0 - excess / 2)):
        ref, t = rolled(drive_front_share=drive_front_share)
        speed, _ = ref.update(t + 0.01, 0.0, np.full(4, 50.0), ROLLING, np.array(usage), excess)
        assert ref.anchored_at == t + 0.01 and speed == pytest.approx(expected)
        ref.update(t + 0.02, 0.0, np.full(4, 50.0), ROLLING, np.array(usage)[::-1], excess)
        assert ref.anchored_at == t + 0.01


def test_a_pair_its_motors_just_released_does_not_anchor_the_speed():
    """A launch on four motors ends: the torques are cut while the wheels still spin 3.5 m/s ahead, and a pair
    whose deceleration matches ax for a sample is no measurement of the car's speed until it has settled."""
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    ref.update(0.01, 3.0, np.full(4, 50.0), np.full(4, 3.0 / RADIUS), np.full(4, 0.3))  # launching
    spinning = np.full(4, 50.0 + 3.5 / RADIUS)
    out_of_step = np.array([-30.0, -30.0, 0.0, 0.0])  # torques cut: the front pair settling, the rear in step
    for k in range(2, 51):  # 10 ms ticks until the rear pair has been released for PAIR_SETTLE
        speed, _ = ref.update(k * 0.01, 0.0, spinning, out_of_step, ROLLING)
    assert speed == pytest.approx(RADIUS * 50.0 + 0.03) and ref.anchored_at == 0.0
    speed, std = ref.update(0.01 + PAIR_SETTLE, 0.0, spinning, out_of_step, ROLLING)
    assert speed == pytest.approx(RADIUS * spinning[2]) and std == pytest.approx(np.sqrt(2.0) * ANCHORED_STD)


@pytest.mark.parametrize("drive, followed", [("front", "rear"), ("rear", "front"), ("all", None)])
def test_a_car_without_torques_accelerating_is_not_measured_by_its_driven_wheels(drive, followed):
    """No motor torques on the bus (most cars): the share of ``m ax`` the drive layout gives each wheel says which
    ones slip. A front-driven car speeding up at 3 m/s^2 with its front wheels 2 % ahead: the reference is the rear
    pair's speed (it was the front wheels' in the mean, 1 % high, flagged valid); driven at all four, ax is
    integrated."""
    config = load_config(CONFIG)
    vehicle = replace(config.vehicle, drive_front_share={"front": 1.0, "rear": 0.0, "all": 0.5}[drive])
    geometry, layout = WheelGeometry(vehicle), DriveLayout(vehicle)
    ax, v, dt = 3.0, 20.0, 0.01
    slip = {"front": np.array([1.02, 1.02, 1.0, 1.0]), "rear": np.array([1.0, 1.0, 1.02, 1.02]),
            "all": np.full(4, 1.02)}[drive]
    ref = ReferenceSpeed(vehicle.wheel_radius, vehicle.tire.longitudinal_stiffness, ANCHORED_STD,
                         vehicle.drive_front_share)
    ref.update(0.0, 0.0, np.full(4, v / vehicle.wheel_radius), ROLLING, ROLLING)
    for k in range(1, 101):
        v += ax * dt
        inputs = tick_inputs(k * dt, {"ax": ax, "ay": 0.0})
        usage = tick_usage(inputs, geometry, vehicle, layout)
        wheels = slip * v / vehicle.wheel_radius
        speed, std = ref.update(k * dt, ax, wheels, np.full(4, ax / vehicle.wheel_radius), usage)
    assert speed == pytest.approx(v, abs=0.01)
    if followed is None:
        assert ref.offset.measured_std == PRIOR_STD  # ax's offset not measured yet (accelerating: never)
        assert max(usage) > 0.1 and ref.anchored_at == 0.0 and std == pytest.approx(np.hypot(ANCHORED_STD, PRIOR_STD))
    else:
        assert ref.anchored_at == pytest.approx(1.0) and std == pytest.approx(np.sqrt(2.0) * ANCHORED_STD)


def tick_inputs(t, values):
    n = len(values)
    return TickInputs(SimpleNamespace(t=t, names=list(values), values=list(values.values()), stale=[False] * n,
                                      fresh=[True] * n, ages=[0.0] * n, saturated=[False] * n))


def test_a_gap_in_the_inputs_takes_the_wheels_again():
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    ref.update(0.01, 2.0, np.full(4, 60.0), np.full(4, 30.0), np.full(4, 0.4))
    speed, std = ref.update(0.01 + 2 * MAX_GAP, 2.0, np.full(4, 60.0), np.full(4, 30.0), np.full(4, 0.4))
    assert speed == pytest.approx(RADIUS * 60.0 / (1 + 0.4 / STIFFNESS)) and std == pytest.approx(ANCHORED_STD)


def test_while_the_wheels_are_missing_ax_carries_the_speed_and_spinning_wheels_are_not_taken_back():
    """Wheel frames lost for 0.2 s in a spin: restarted on the wheels, the reference took their spin with the
    anchored std. Coasting on ax, it keeps its anchor: the wheels, back and still spinning, are not taken."""
    ref = reference()
    ref.update(0.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    for k in range(1, 21):  # the wheels missing for 0.2 s while the car accelerates at 2 m/s^2
        ref.coast(k * 0.01, 2.0)
    speed, std = ref.update(0.21, 2.0, np.full(4, 60.0), np.full(4, 30.0), np.full(4, 0.4))
    assert speed == pytest.approx(RADIUS * 50.0 + 2.0 * 0.21)
    assert std == pytest.approx(np.hypot(ANCHORED_STD, PRIOR_STD * 0.21))  # ax's offset not measured yet
    fresh = reference()
    fresh.coast(0.01, 2.0)  # nothing before a first anchor
    assert fresh.speed is None


def test_a_gated_span_after_a_bend_does_not_count_with_one_before_it():
    """Relearning needs RELEARN s of gated spans on end: two outliers either side of a bend are not a new grade."""
    ref, t0 = rolled(3.0)
    learned = ref.offset.measured_std
    for k in range(1, 61):  # 0.6 s: ax jumps by 1 m/s^2 (a pothole's outlier spans once the span is full)
        ref.update(t0 + k * 0.01, 1.0, np.full(4, 50.0), ROLLING, ROLLING)
    for k in range(61, 261):  # a 2 s bend: nothing learned, nothing gated
        ref.update(t0 + k * 0.01, 0.0, np.full(4, 50.0), ROLLING, ROLLING, turning=3.0)
    for k in range(261, 321):  # straight again, the same outlier for 0.6 s
        ref.update(t0 + k * 0.01, 1.0, np.full(4, 50.0), ROLLING, ROLLING)
    assert ref.offset.measured_std == pytest.approx(learned, rel=0.5)  # not back at the prior
    assert ref.offset.value == pytest.approx(0.0, abs=0.05)


def test_wheels_back_after_a_gap_anchor_only_once_their_slopes_span_samples_since_it():
    """A wheel slope over samples from before the gap says nothing of the wheels now: wheels back 10 rad/s faster,
    their slopes still those of free rolling, anchored the speed 3.5 m/s high with the anchored std."""
    ref = reference()
    for k in range(10):
        ref.update(k * 0.01, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    for k in range(10, 30):
        ref.coast(k * 0.01, 0.0)
    speeds = [ref.update(k * 0.01, 0.0, np.full(4, 60.0), ROLLING, ROLLING)[0] for k in range(30, 34)]
    assert speeds == pytest.approx([RADIUS * 50.0] * 4)
    assert ref.update(0.34, 0.0, np.full(4, 60.0), ROLLING, ROLLING)[0] == pytest.approx(RADIUS * 60.0)


def test_time_running_backwards_takes_the_wheels_again():
    """A log whose clock jumps back (two drives concatenated) must not integrate ax over a negative interval."""
    ref = reference()
    ref.update(10.0, 0.0, np.full(4, 50.0), ROLLING, ROLLING)
    ref.update(10.01, 2.0, np.full(4, 60.0), np.full(4, 30.0), np.full(4, 0.4))
    speed, std = ref.update(3.0, 2.0, np.full(4, 60.0), np.full(4, 30.0), np.full(4, 0.4))
    assert speed == pytest.approx(RADIUS * 60.0 / (1 + 0.4 / STIFFNESS)) and std == pytest.approx(ANCHORED_STD)
