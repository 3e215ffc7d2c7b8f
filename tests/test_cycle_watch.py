"""Each used message's cycle measured on the bus: a warning once per message when the assumed cycle is more
than 2x off, and the timeouts of a message whose DBC gives no GenMsgCycleTime follow the measured cycle."""
import logging

import pytest

from canest.apps.init import starting_config, write_new
from canest.codec.cycle_watch import SAMPLES, CycleWatch
from canest.codec.encode import InputEncoder
from canest.config import load_config
from canest.pipeline import Pipeline
from tests.test_codec import VALUES
from tests.test_init import WITH_ACCELEROMETER

CYCLE = 0.012  # s: Toyota's WHEEL_SPEEDS, KINEMATICS and STEER_ANGLE_SENSOR


@pytest.fixture
def config(tmp_path):
    """A config through a DBC without GenMsgCycleTime (canest assumes 100 ms for each of its messages)."""
    dbc = tmp_path / "car.dbc"
    dbc.write_text(WITH_ACCELEROMETER)
    assert "GenMsgCycleTime" not in WITH_ACCELEROMETER
    out = tmp_path / "car.yaml"
    write_new(out, starting_config(str(dbc), out=out)[0])
    return load_config(out)


def drive(pipeline, config, frames_each: int, start: float = 100.0):
    """Every mapped message every 12 ms (each 1 ms after the other); the time of the last frame."""
    encoder = InputEncoder(config)
    t = start
    for k in range(frames_each):
        for i, frame_id in enumerate(pipeline.decoder.frame_ids):
            t = start + k * CYCLE + i * 0.001
            pipeline.feed(encoder.encode(frame_id, VALUES, t))
    return t


def test_a_12_ms_message_without_a_dbc_cycle_is_warned_once_and_its_timeouts_follow_it(config, caplog):
    pipeline = Pipeline(config)
    assert {plan.cycle_time() for plan in pipeline.decoder.plans.values()} == {(0.1, "default")}
    assert set(pipeline.resampler.timeouts) == {0.5}  # 5 cycles of 100 ms
    with caplog.at_level(logging.WARNING, logger="canest.codec.cycle_watch"):
        last = drive(pipeline, config, 5 * SAMPLES)
    warnings = [r.getMessage() for r in caplog.records if r.name == "canest.codec.cycle_watch"]
    assert sorted(w.split()[1] for w in warnings) == ["KINEMATICS", "STEERING", "WHEELS"]  # once per message
    assert all("comes every 12.0 ms, the assumed cycle is 100 ms (default): the timeouts follow" in w
               for w in warnings)
    assert pipeline.resampler.timeouts == pytest.approx([5 * CYCLE] * len(pipeline.resampler.names))
    # the senders stop: the inputs go stale after 5 measured cycles, not after 0.5 s
    assert not pipeline.resampler.sample(last + 0.05).stale.any()
    assert pipeline.resampler.sample(last + 0.07).stale.all()
    assert pipeline.summary()["decoded"] == 5 * SAMPLES * 3  # every frame still accounted for


def test_a_cycle_from_the_config_or_the_dbc_is_kept_and_only_warned_about_when_more_than_2x_off(caplog):
    watch = CycleWatch({0x10: (0.01, "DBC"), 0x20: (0.012, "config"), 0x30: (0.1, "default")},
                       {0x10: "FAST", 0x20: "RIGHT", 0x30: "DEFAULT"})
    follows = []
    with caplog.at_level(logging.WARNING, logger="canest.codec.cycle_watch"):
        for k in range(3 * SAMPLES):
            t = k * 0.025  # 25 ms: 2.5x the DBC's 10 ms, 2.1x the config's 12 ms, 0.25x the default
            follows += [watch.observe(fid, t) for fid in (0x10, 0x20, 0x30)]
            follows.append(watch.observe(0x99, t))  # not a used message: never measured
    assert [f for f in follows if f is not None] == [pytest.approx(0.025)]  # only the default's is followed
    warnings = sorted(r.getMessage() for r in caplog.records)
    assert len(warnings) == 3
    assert "message DEFAULT (0x30) comes every 25.0 ms" in warnings[0]
    assert "message FAST (0x10) comes every 25.0 ms, the assumed cycle is 10 ms (DBC): timeouts stay DBC's: " \
           "set input.messages.FAST.cycle_time" in warnings[1]
    assert "RIGHT" in warnings[2] and "(config)" in warnings[2]


def test_a_lost_frame_does_not_move_the_measured_cycle():
    watch = CycleWatch({0x30: (0.1, "default")}, {0x30: "M"})
    times = [k * CYCLE for k in range(SAMPLES + 4) if k not in (5, 6, 11)]  # three of them lost
    measured = [watch.observe(0x30, t) for t in times]
    assert [m for m in measured if m is not None] == [pytest.approx(CYCLE)]


def test_check_says_a_default_cycle_is_measured_at_run_time(config, capsys):
    from canest.cli import main
    with pytest.raises(SystemExit) as done:
        main(["check", "--config", str(config.path)])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert "100ms (default)" in out
    assert "cycle (default): the DBC gives no GenMsgCycleTime; replay and run measure the cycle" in out
