"""The online calibration reaches the outputs: CSV columns, the CE_Calibration message, ``check`` and ``monitor``.

The drive: test_online_calibration's 45 s of simulated country road by a wrong car (the learner moves every
parameter off its start within it).
"""
import csv
import dataclasses
import io
import json

import can
import cantools
import pytest

from canest.apps.monitor import CALIBRATION_UNITS, CALIBRATION_WAIT, Monitor, run_monitor
from canest.apps.replay import replay
from canest.cli import main
from canest.codec.encode import CALIBRATION_MESSAGE, EstimateEncoder, calibration_signal
from canest.errors import DbcError
from canest.estimation.estimate import Estimate
from canest.estimation.learned_parameters import NAMES, parameters
from canest.pipeline import Pipeline
from tests.conftest import CONFIG
from tests.test_online_calibration import config, drive  # noqa: F401  (fixtures: the wrong car's 45 s drive)
from tests.test_output_dbc_contract import REFERENCE, edited_dbc, without_message, without_signal

CALIBRATION_ID = 1297


@pytest.fixture(scope="module")
def estimates(config, drive):
    pipeline = Pipeline(config)
    out = [e for frame in drive.frames for e in pipeline.feed(frame)]
    return out, pipeline.calibration.report()


def without_learner(config):
    return dataclasses.replace(config, estimator=dataclasses.replace(config.estimator, online_calibration=False))


def calibration_columns():
    return [f"calib_{name}{suffix}" for name in NAMES for suffix in ("", "_std")]


def read_csv(path):
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


# -- CSV ---------------------------------------------------------------------------------------------------------------

def test_each_tick_carries_the_learners_report_of_that_tick(estimates):
    ticks, report = estimates
    assert ticks[-1].calibration == report
    assert ticks[0].calibration != report, "a report of the tick, not a shared one"


def test_replay_csv_carries_the_learned_values_equal_to_the_learners_report(config, drive, tmp_path):
    log, out = tmp_path / "drive.log", tmp_path / "est.csv"
    drive.write_log(log)
    ticks = []
    replay(config, log, out_csv=out, progress=False, on_estimate=ticks.append)
    rows = read_csv(out)
    assert list(rows[0])[-len(NAMES) * 2:] == calibration_columns()
    assert len(rows) == len(ticks) > 3000
    for row, estimate in zip(rows, ticks):
        assert {c: float(row[c]) for c in calibration_columns()} == pytest.approx(
            {c: estimate.calibration[c] for c in calibration_columns()}, rel=1e-8, abs=1e-15)
    starts = {p.name: p.start for p in parameters(config.vehicle)}
    assert all(float(rows[-1][f"calib_{name}"]) != starts[name] for name in NAMES), "the drive taught nothing"


def test_without_the_learner_the_csv_has_no_calibration_columns(config, drive, tmp_path):
    log, out = tmp_path / "drive.log", tmp_path / "est.csv"
    drive.write_log(log)
    replay(without_learner(config), log, out_csv=out, progress=False)
    header = read_csv(out)[0]
    assert "vx" in header and not any(column.startswith("calib_") for column in header)


def test_a_live_csv_takes_the_calibration_columns_from_the_first_estimate(estimates, tmp_path):
    """``canest run --csv`` gives no states: the first estimate makes the header, calibration included."""
    from canest.io.sinks import CsvSink
    ticks, _ = estimates
    with CsvSink(tmp_path / "live.csv") as sink:
        sink.publish(ticks[-2:])
    rows = read_csv(tmp_path / "live.csv")
    assert list(rows[0])[-len(NAMES) * 2:] == calibration_columns()
    assert float(rows[1]["calib_ratio_std"]) == pytest.approx(ticks[-1].calibration["calib_ratio_std"], rel=1e-8)


# -- CE_Calibration ----------------------------------------------------------------------------------------------------

def tick(t, calibration):
    return Estimate(t, {}, {}, "normal", "ckf", calibration=calibration)


def report_at(config, where):
    """A report with every parameter at its lower or upper bound, learned, converged on every other one."""
    out = {}
    for i, p in enumerate(parameters(config.vehicle)):
        out.update({f"calib_{p.name}": getattr(p, where), f"calib_{p.name}_std": p.std,
                    f"calib_{p.name}_learned": True, f"calib_{p.name}_converged": i % 2 == 0})
    return out


def decoded_pages(frames):
    db = cantools.database.load_file(str(REFERENCE))
    return [db.decode_message(f.arbitration_id, f.data, decode_choices=False)
            for f in frames if f.arbitration_id == CALIBRATION_ID]


@pytest.mark.parametrize("where", ["low", "high", "drive"])
def test_calibration_message_round_trips_within_the_dbc_resolution(config, estimates, where):
    report = estimates[1] if where == "drive" else report_at(config, where)
    pages = decoded_pages(EstimateEncoder(REFERENCE).encode(tick(0.0, report)))
    message = cantools.database.load_file(str(REFERENCE)).get_message_by_name(CALIBRATION_MESSAGE)
    assert [page["CalParameter"] for page in pages] == list(range(len(NAMES)))
    for name, page in zip(NAMES, pages):
        signal = calibration_signal(name)
        for key, suffix in ((signal, ""), (f"{signal}Std", "_std")):
            resolution = message.get_signal_by_name(key).scale
            assert page[key] == pytest.approx(report[f"calib_{name}{suffix}"], abs=resolution / 2 + 1e-12), key
        assert page["CalLearned"] == int(report[f"calib_{name}_learned"])
        assert page["CalConverged"] == int(report[f"calib_{name}_converged"])


def test_calibration_signal_ranges_hold_each_parameters_bounds(config):
    message = cantools.database.load_file(str(REFERENCE)).get_message_by_name(CALIBRATION_MESSAGE)
    for p in parameters(config.vehicle):
        signal = message.get_signal_by_name(calibration_signal(p.name))
        assert signal.minimum <= p.low and p.high <= signal.maximum, p.name
        assert message.get_signal_by_name(f"{calibration_signal(p.name)}Std").maximum >= p.std, p.name


def test_calibration_is_sent_once_a_second_one_page_per_parameter(config, estimates):
    encoder = EstimateEncoder(REFERENCE)
    report = estimates[1]
    frames = [f for k in range(300) for f in encoder.encode(tick(k * 0.01, report))]
    pages = decoded_pages(frames)
    assert [page["CalParameter"] for page in pages] == list(range(len(NAMES))) * 3
    assert message_cycle_ms() == 1000


def test_calibration_and_causes_keep_their_cycle_when_the_clock_steps_back(estimates):
    """A silent bus's ticks run on the service's clock (epoch seconds); the first frame's time base may be an
    adapter's own. The next sends were planned on the old base: CE_Calibration and CE_ValidityCause stayed silent
    (causes unchanged) until that base's time came round."""
    encoder = EstimateEncoder(REFERENCE)
    report = estimates[1]
    encoder.encode(tick(1.7e9, report))  # on the service's clock
    frames = [f for k in range(300) for f in encoder.encode(tick(100.0 + k * 0.01, report))]  # the adapter's
    assert [page["CalParameter"] for page in decoded_pages(frames)] == list(range(len(NAMES))) * 3
    causes = cantools.database.load_file(str(REFERENCE)).get_message_by_name("CE_ValidityCause")
    assert sum(f.arbitration_id == causes.frame_id for f in frames) == 3000 // causes.cycle_time  # unchanged causes


def message_cycle_ms():
    return cantools.database.load_file(str(REFERENCE)).get_message_by_name(CALIBRATION_MESSAGE).cycle_time


def test_an_output_dbc_without_the_calibration_message_works_and_sends_none(config, estimates, tmp_path):
    dbc = edited_dbc(tmp_path / "mine.dbc", lambda db: without_message(db, CALIBRATION_MESSAGE))
    encoder = EstimateEncoder(dbc)
    frames = encoder.encode(tick(0.0, estimates[1]))
    assert frames and not any(f.arbitration_id == CALIBRATION_ID for f in frames)


def test_an_incomplete_calibration_message_is_named(tmp_path):
    dbc = edited_dbc(tmp_path / "mine.dbc", without_signal(CALIBRATION_MESSAGE, "CalRatioStd"))
    with pytest.raises(DbcError, match=r"signal CE_Calibration\.CalRatioStd"):
        EstimateEncoder(dbc)


def older_dbc(path):
    """The reference output DBC as an older canest wrote it: no pages for the cornering stiffnesses."""
    def edit(db):
        for signal in ("CalFront", "CalFrontStd", "CalRear", "CalRearStd"):
            without_signal(CALIBRATION_MESSAGE, signal)(db)
    return edited_dbc(path, edit)


def test_an_older_dbc_without_the_stiffness_pages_works_and_sends_the_pages_it_has(estimates, tmp_path):
    encoder = EstimateEncoder(older_dbc(tmp_path / "older.dbc"))
    pages = decoded_pages(encoder.encode(tick(0.0, estimates[1])))
    assert [page["CalParameter"] for page in pages] == [NAMES.index(n) for n in NAMES if n not in ("front", "rear")]
    assert encoder.calibration_missing == ["front", "rear"]


def check_output(capsys, config_path, *options):
    with pytest.raises(SystemExit) as exit_status:
        main(["check", "--config", str(config_path), *options])
    assert exit_status.value.code in (0, None)
    return capsys.readouterr().out


def test_check_notes_once_that_a_dbc_without_the_message_sends_no_calibration(capsys, tmp_path):
    import yaml
    dbc = edited_dbc(tmp_path / "mine.dbc", lambda db: without_message(db, CALIBRATION_MESSAGE))
    doc = yaml.safe_load(CONFIG.read_text())
    if ":" not in doc["input"]["dbc"]:
        doc["input"]["dbc"] = str((CONFIG.parent / doc["input"]["dbc"]).resolve())
    doc["output"]["dbc"] = str(dbc)
    mine = tmp_path / "car.yaml"
    mine.write_text(yaml.safe_dump(doc))
    assert check_output(capsys, mine).count(f"has no {CALIBRATION_MESSAGE} message") == 1
    assert json.loads(check_output(capsys, mine, "--json"))["calibration_sent"] is False
    assert "CE_Calibration" not in check_output(capsys, CONFIG)
    assert json.loads(check_output(capsys, CONFIG, "--json"))["calibration_sent"] is True
    doc["output"]["dbc"] = str(older_dbc(tmp_path / "older.dbc"))
    mine.write_text(yaml.safe_dump(doc))
    assert check_output(capsys, mine).count("has no page for front, rear (a DBC of an older canest)") == 1
    assert json.loads(check_output(capsys, mine, "--json"))["calibration_not_sent"] == ["front", "rear"]


# -- monitor -----------------------------------------------------------------------------------------------------------

def last_second_frames(estimates):
    """The frames of the drive's last second, from a fresh encoder: estimates, status and one calibration burst."""
    ticks, _ = estimates
    encoder = EstimateEncoder(REFERENCE)
    return [f for e in ticks[-100:] for f in encoder.encode(e)], ticks[-100].calibration


def expected_display(report, name):
    unit, factor = CALIBRATION_UNITS[name]
    message = cantools.database.load_file(str(REFERENCE)).get_message_by_name(CALIBRATION_MESSAGE)
    resolution = message.get_signal_by_name(calibration_signal(name)).scale * factor
    state = "converged" if report[f"calib_{name}_converged"] else \
        "learning" if report[f"calib_{name}_learned"] else "prior"
    return report[f"calib_{name}"] * factor, resolution, state


def watch(frames, **options):
    """Send the frames on a virtual bus and run the monitor on it once; its output."""
    channel = f"calib-monitor-{options.get('lines')}"
    watcher = can.Bus(interface="virtual", channel=channel)
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        for frame in frames:
            sender.send(frame)
        out = io.StringIO()
        db = cantools.database.load_file(str(REFERENCE))
        monitor = run_monitor(watcher, db, "virtual", out, refresh=0.1, duration=3.0, once=True, **options)
    finally:
        sender.shutdown()
        watcher.shutdown()
    assert monitor.complete() and monitor.counts["crc_errors"] == 0
    return out.getvalue()


def test_monitor_line_mode_prints_each_learned_parameter(estimates):
    frames, report = last_second_frames(estimates)
    words = dict(word.split("=", 1) for word in watch(frames, lines=True).split())
    for name in NAMES:
        value, resolution, state = expected_display(report, name)
        assert float(words[f"calib_{name}"]) == pytest.approx(value, rel=1e-5, abs=resolution)
        assert words[f"calib_{name}_state"] == state
        assert float(words[f"calib_{name}_std"]) > 0.0


def test_monitor_view_has_one_line_per_learned_parameter(estimates):
    frames, report = last_second_frames(estimates)
    lines = watch(frames, lines=False).splitlines()
    for name in NAMES:
        row = [line.split() for line in lines if line.split()[:1] == [name]]
        assert len(row) == 1, name
        value, resolution, state = expected_display(report, name)
        assert float(row[0][1]) == pytest.approx(value, abs=max(resolution, 1e-5)) and row[0][-1] == state


def test_monitor_without_calibration_frames_shows_the_estimates_and_waits_one_cycle_for_it(estimates):
    frames, _ = last_second_frames(estimates)
    monitor = Monitor(cantools.database.load_file(str(REFERENCE)))
    for frame in frames:
        if frame.arbitration_id != CALIBRATION_ID:
            monitor.receive(frame)
    assert monitor.complete() and not monitor.settled(), "--once waits for a calibration cycle"
    assert "calib_" not in monitor.line() and "learned" not in monitor.render("t")
    monitor.completed_at -= CALIBRATION_WAIT
    assert monitor.settled()


def test_the_monitor_says_when_the_estimates_stopped_and_shows_no_stale_value_as_valid(estimates, monkeypatch):
    """A stopped daemon's last values stayed on screen flagged valid, and the frame rate was the mean since start."""
    from canest.apps import monitor as monitor_module

    clock = [100.0]
    monkeypatch.setattr(monitor_module.time, "monotonic", lambda: clock[0])
    frames, _ = last_second_frames(estimates)
    monitor = Monitor(cantools.database.load_file(str(REFERENCE)))
    for frame in frames:
        monitor.receive(frame)
    clock[0] += 0.5
    fresh_line, fresh_view = monitor.line(), monitor.render("t")
    assert " age=0.5 " in fresh_line and " vx=" in fresh_line and "no estimate frames" not in fresh_view
    vx_valid = next(line for line in fresh_view.splitlines() if line.startswith("vx ")).split()[-1]
    clock[0] += monitor_module.STALE_AFTER
    line, view = monitor.line(), monitor.render("t")
    assert all(word.endswith("?") for word in line.split() if word.startswith(("vx=", "yaw_rate=", "sideslip=")))
    assert f"no estimate frames for {0.5 + monitor_module.STALE_AFTER:.1f} s" in view and "(0/s)" in view
    assert vx_valid == "yes" and next(row for row in view.splitlines() if row.startswith("vx ")).endswith("stale")
