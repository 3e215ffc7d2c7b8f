"""The canest command as a user runs it."""
import json
import subprocess
import sys

import can
import cantools
import numpy as np
import pytest

from canest.apps.evaluate import read_table
from tests.conftest import CONFIG, ROOT

CANEST = [sys.executable, "-m", "canest"]


def canest(*args, check=True):
    result = subprocess.run([*CANEST, *map(str, args)], capture_output=True, text=True, timeout=300)
    if check and result.returncode != 0:
        raise AssertionError(f"canest {' '.join(map(str, args))} failed:\n{result.stdout}\n{result.stderr}")
    return result


def test_help_lists_every_command():
    out = canest("--help").stdout
    for command in ("demo", "run", "replay", "simulate", "evaluate", "check"):
        assert command in out
    assert "--maneuver" in canest("simulate", "--help").stdout


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_simulate_replay_evaluate(tmp_path, suffix):
    log, truth = tmp_path / f"drive{suffix}", tmp_path / "truth.csv"
    out = canest("simulate", "--maneuver", "dlc", "--speed", 80, "--mu", 0.85, "--out", log, "--truth", truth)
    assert "frames" in out.stdout
    est_log, est_csv = tmp_path / "est.log", tmp_path / "est.csv"
    out = canest("replay", log, "--config", ROOT / "configs" / "dici_ev.yaml", "--out", est_log, "--csv", est_csv, "-q")
    assert out.stdout.startswith("frames=")
    frames = int(out.stdout.split()[0].split("=")[1])
    assert f"decoded={frames}" in out.stdout  # nothing lost or rejected
    table = read_table(est_csv)
    assert list(table)[:5] == ["t", "vx", "vy", "beta", "yaw_rate"]
    assert {"vx_std", "vy_std", "beta_std", "yaw_rate_std", "valid", "mode"} <= set(table)
    db = cantools.database.load_file(str(ROOT / "dbc" / "canest_estimates.dbc"))
    decoded = [db.decode_message(m.arbitration_id, m.data) for m in can.LogReader(str(est_log))
               if m.arbitration_id == 0x501]
    assert len(decoded) == len(table["t"])
    assert decoded[-1]["YawRate"] == pytest.approx(table["yaw_rate"][-1], abs=1e-4)
    report = canest("evaluate", est_csv, truth, "--plot", tmp_path / "plot.png").stdout
    assert "RMSE" in report and "beta" in report
    assert (tmp_path / "plot.png").stat().st_size > 10000


def test_check_prints_the_resolved_map():
    out = canest("check", "--config", ROOT / "configs" / "production_example.yaml").stdout
    assert "EPS_STEERING.STW_ANGLE" in out and "0x1806e5f4" in out and out.strip().endswith("OK")


def test_errors_are_one_clear_line_and_exit_2(tmp_path):
    result = canest("check", "--config", tmp_path / "missing.yaml", check=False)
    assert result.returncode == 2
    assert result.stderr.strip() == f"canest: error: {tmp_path / 'missing.yaml'}: config file not found"
    result = canest("replay", tmp_path / "nope.log", check=False)
    assert result.returncode == 66 and "nope.log: log file not found" in result.stderr  # EX_NOINPUT
    result = canest("simulate", "--mu", "abc", "--out", tmp_path / "x.log", "--truth", tmp_path / "t.csv", check=False)
    assert result.returncode == 2 and "--mu" in result.stderr


def test_simulate_gives_the_imu_a_real_car_s_vibration_on_request(tmp_path):
    """``--vibration 1``: about one 10 ms step of ay in six beyond 2 m/s^2, as measured on a real drive
    (:mod:`canest.sim.sensors`); without it the simulated ESC accelerometer steps far less."""
    from canest.codec.decode import InputDecoder
    from canest.config import DEFAULT_CONFIG, load_config

    decoder = InputDecoder(load_config(DEFAULT_CONFIG))

    def big_steps(scale):
        log = tmp_path / f"vib{scale}.log"
        canest("simulate", "-m", "step", "--duration", 3, "--vibration", scale, "-o", log, "--truth", tmp_path / "t.csv")
        ay = [value for msg in can.LogReader(str(log)) for name, value in (decoder.decode(msg) or ()) if name == "ay"]
        return np.mean(np.abs(np.diff(ay)) > 2.0), len(ay)

    (vibrating, samples), (quiet, _) = big_steps(1), big_steps(0)
    assert samples > 250 and 0.08 < vibrating < 0.35 and quiet == 0.0, (vibrating, quiet)
    result = canest("simulate", "--vibration", "nan", "-o", tmp_path / "x.log", "--truth", tmp_path / "t.csv",
                    check=False)
    assert result.returncode == 2 and "--vibration: a scale from 0 to 10" in result.stderr


def test_simulate_biases_the_airbag_units_gyro_on_request(tmp_path):
    """``--gyro-bias-2 2``: the second gyro reads 2 deg/s above the first (whose bias is the simulator's 0.05)."""
    from canest.codec.decode import InputDecoder
    from canest.config import DEFAULT_CONFIG, load_config

    decoder = InputDecoder(load_config(DEFAULT_CONFIG))
    log = tmp_path / "biased.log"
    canest("simulate", "-m", "step", "--duration", 2, "--gyro-bias-2", 2, "-o", log, "--truth", tmp_path / "t.csv")
    gyros = {"yaw_rate": [], "yaw_rate_2": []}
    for msg in can.LogReader(str(log)):
        for name, value in decoder.decode(msg) or ():
            gyros.get(name, []).append(value)
    assert min(map(len, gyros.values())) > 90
    difference = np.degrees(np.mean(gyros["yaw_rate_2"]) - np.mean(gyros["yaw_rate"]))
    assert difference == pytest.approx(2.0 - 0.05, abs=0.1)


def test_simulate_blows_a_gusty_day_s_side_wind_on_request(tmp_path):
    """``--crosswind 1``: on a straight launch the calm car's sideslip and yaw rate stay zero; gusts move both
    (:mod:`canest.sim.wind`: 180 N in RMS at 80 km/h, the driver steering back onto the lane)."""
    def straight(scale):
        truth = tmp_path / f"wind{scale}.csv"
        canest("simulate", "-m", "launch", "--duration", 4, "--crosswind", scale, "-o", tmp_path / "w.log",
               "--truth", truth)
        table = read_table(truth)
        return np.degrees(np.abs(table["beta"]).max()), np.degrees(np.abs(table["yaw_rate"]).max())

    (calm_beta, calm_yaw), (gusty_beta, gusty_yaw) = straight(0), straight(1)
    assert calm_beta < 1e-9 and calm_yaw < 1e-9
    assert 0.005 < gusty_beta < 0.5 and 0.1 < gusty_yaw < 5.0, (gusty_beta, gusty_yaw)
    result = canest("simulate", "--crosswind", "nan", "-o", tmp_path / "x.log", "--truth", tmp_path / "t.csv",
                    check=False)
    assert result.returncode == 2 and "--crosswind: a scale from 0 to 5 (1: a gusty day's)" in result.stderr


def test_run_on_a_bus_that_does_not_exist_fails_cleanly():
    result = canest("run", "--interface", "socketcan", "--channel", "nosuchcan9", check=False)
    assert result.returncode == 2
    assert "cannot open input bus socketcan:nosuchcan9" in result.stderr


def test_compare_every_filter_on_one_log(dlc_run, tmp_path):
    log, truth, _ = dlc_run
    result = canest("compare", log, truth, "--filters", "all", "--plot", tmp_path / "compare.png", "--json")
    from canest.filters import FILTERS

    runs = {run["filter"]: run for run in json.loads(result.stdout)}
    assert list(runs) == list(FILTERS) and "ckf: done" in result.stderr
    for name, run in runs.items():
        rmse = {state: run["scores"][state]["rmse"] for state in ("vx", "yaw_rate", "beta")}
        assert rmse["vx"] < 0.1 and rmse["yaw_rate"] < 0.3 and rmse["beta"] < 0.5, (name, rmse)
        assert run["cpu_us_per_step"] > 0
    assert runs["dici-gfckf"]["scores"]["fy_fl"]["rmse"] < 200  # forces scored where estimated
    assert "fy_fl" not in runs["ckf"]["scores"] and "mu_fl" in runs["dckf"]["scores"]
    assert (tmp_path / "compare.png").stat().st_size > 20000


def test_compare_plot_tells_thirteen_filters_apart_and_has_titles():
    from matplotlib.colors import to_hex

    from canest.apps.compare import FilterRun, comparison_figure
    from canest.filters import FILTERS

    t = np.linspace(0.0, 5.0, 51)
    truth = {"t": t, "vx": 20 + 0 * t, "yaw_rate": np.sin(t), "beta": 0.01 * np.sin(t)}
    runs = [FilterRun(name, {"t": t, **{s: truth[s] + 0.01 * i for s in ("vx", "yaw_rate", "beta")}}, {}, 1.0, 0)
            for i, name in enumerate(FILTERS)]
    fig = comparison_figure(runs, truth)
    for ax in fig.axes:
        assert ax.get_title() and ax.get_ylabel()
        looks = [(to_hex(line.get_color()), line.get_linestyle()) for line in ax.get_lines()
                 if line.get_label() != "truth"]
        assert len(looks) == len(set(looks)) == len(FILTERS) == 13  # no two filters share colour and dash
        assert all(a[0] != b[0] and a[1] != b[1] for a, b in zip(looks, looks[1:]))  # neighbours differ in both
    legend = [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    assert legend == ["truth", *FILTERS]


def test_compare_table_fits_a_terminal(dlc_run):
    from canest.apps.compare import format_comparison, run_filter
    from canest.apps.evaluate import read_table
    from canest.config import load_config

    log, truth, _ = dlc_run
    runs = [run_filter(load_config(CONFIG), log, read_table(truth), name) for name in ("ckf", "dckf", "dici-gfckf")]
    table = format_comparison(runs, "title")
    blocks = table.split("\n\n")
    assert len(blocks) > 1 and all(len(line) <= 120 for line in table.splitlines())
    for block in blocks:
        rows = [line.split("|")[0].strip() for line in block.splitlines() if "|" in line]
        assert rows == ["filter", "ckf", "dckf", "dici-gfckf"]
    assert "CPU us/step" in blocks[0] and "us/step" not in blocks[1]
    forces = next(block for block in blocks if "fy_fl" in block.splitlines()[0 if block.startswith("filter") else 1])
    ckf_cells = next(line for line in forces.splitlines() if line.startswith("ckf")).split("|")[1:]
    assert all(cell.strip() == "-" for cell in ckf_cells)  # states a filter does not estimate show '-'
    assert next(line for line in blocks[0].splitlines() if line.startswith("ckf")).split("|")[-1].strip() != "-"


def test_compare_rejects_unknown_filter(dlc_run):
    log, truth, _ = dlc_run
    result = canest("compare", log, truth, "--filters", "ckf,kalman9", check=False)
    assert result.returncode == 2 and "unknown filter 'kalman9'" in result.stderr


def test_compare_refuses_a_filter_whose_model_lacks_inputs_and_all_skips_it(dlc_run):
    """jckf on a config without motor torques ran on torques of 0, silently (on configs/hard_drive.yaml's honesty
    grid its vx was 0.15 m/s off, valid but wrong on 3 % of the ticks); named, it is refused before any replay;
    in 'all' it is left out, saying why."""
    from canest.apps.compare import runnable
    from canest.config import load_config
    from canest.filters import FILTERS
    log, truth, _ = dlc_run
    no_torques = ROOT / "configs" / "hard_drive.yaml"
    result = canest("compare", log, truth, "--config", no_torques, "--filters", "ckf,jckf", check=False)
    assert result.returncode != 0 and "cannot run jckf (on model two_track) needs motor_torque_fl" in result.stderr
    assert "Traceback" not in result.stderr and "done" not in result.stdout  # refused before any replay
    assert set(FILTERS) - set(runnable(load_config(no_torques), "all")) == {"jckf", "dckf"}


def test_run_with_a_broken_config_fails_before_touching_the_bus(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text((ROOT / "configs" / "dici_ev.yaml").read_text().replace("ESC_IMU.LatAccel", "ESC_IMU.LatAcc"))
    result = canest("run", "--config", bad, "--interface", "socketcan", "--channel", "nosuchcan9", check=False)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{bad}:" in lines[0] and "input.signals.ay.signal" in lines[0]
    assert "nosuchcan9" not in result.stderr


def test_replay_of_concatenated_logs_accounts_for_every_frame(dlc_run, tmp_path):
    """The second log's clock starts before the first one ends (a replay of concatenated drives)."""
    log, _, sim = dlc_run
    joined = tmp_path / "joined.log"
    with can.Logger(str(joined)) as writer:
        for frame in sim.frames:
            writer.on_message_received(frame)
        for frame in sim.frames:
            writer.on_message_received(can.Message(timestamp=frame.timestamp + 5.0, arbitration_id=frame.arbitration_id,
                                                   data=frame.data, is_extended_id=False))
    out = canest("replay", joined, "--csv", tmp_path / "est.csv", "-q").stdout
    fields = dict(part.split("=") for part in out.split())
    accounted = sum(int(v) for k, v in fields.items() if k == "decoded" or k.startswith("rejected_") or k == "ignored_id")
    assert int(fields["frames"]) == 2 * len(sim.frames) == accounted
    assert int(fields["time_backwards"]) > 0 and int(fields["time_jumps"]) == 1
    t = read_table(tmp_path / "est.csv")["t"]
    steps = np.diff(t)
    assert np.sum(steps < 0) == 1, "ticks follow the source clock: one step back, at the junction"
    assert np.allclose(steps[steps > 0], 0.01), "one row per tick, none skipped or repeated"


def test_every_command_takes_a_log_level():
    """--log-level on every command: records with their level and logger at and above it, none below."""
    toyota = ROOT / "configs" / "toyota_rav4_opendbc.yaml"
    pytest.importorskip("opendbc", reason="the tolerated-DBC warning needs the opendbc extra (in the test extra)")
    plain = canest("check", "--config", toyota).stderr
    leveled = canest("check", "--config", toyota, "--log-level", "WARNING").stderr
    quiet = canest("check", "--config", toyota, "--log-level", "ERROR").stderr
    assert "overlapping in message PCS_HUD" in plain and not plain.startswith("WARNING")
    assert leveled.startswith("WARNING canest.config: ") and "PCS_HUD" in leveled
    assert "PCS_HUD" not in quiet
    from canest.cli import COMMANDS

    for command in COMMANDS:
        assert "--log-level" in canest(command, "--help").stdout, command


def test_a_filters_run_is_scored_over_its_valid_ticks_or_all_of_them(dlc_run):
    """``canest compare`` scores a filter over its valid ticks; tools/filter_claims.py over every tick (the filters'
    valid ticks differ, and RMSEs over different ticks do not compare)."""
    from canest.apps.compare import run_filter
    from canest.config import load_config

    log, truth, _ = dlc_run
    valid = run_filter(load_config(CONFIG), log, read_table(truth), "ckf").scores["beta"]
    every = run_filter(load_config(CONFIG), log, read_table(truth), "ckf", only_valid=False).scores["beta"]
    assert valid.valid < 1.0  # the premise: some ticks of the drive are not valid
    assert every.samples > valid.samples and every.valid == valid.valid  # the invalid ticks scored too
