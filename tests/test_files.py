"""Files as a user (or a full disk, or a signal) meets them: `python -m canest` in a subprocess, exit status per the
README's table, one line naming the file and the remedy, inputs intact, no partial or temporary file left.

The tests run as root, whom permissions do not stop: a log that may not be read is a link to a write-only
/proc/sys entry, a folder that may not be written is /sys, a full disk is /dev/full or a file size limit
(RLIMIT_FSIZE, as `ulimit -f`), a read that fails midway is /proc/self/mem.
"""
import os
import resource
import signal
import subprocess
import sys
import time

import can
import pytest

from canest.apps.evaluate import read_table
from canest.sim.simulate import simulate
from tests.conftest import ROOT

CANEST = [sys.executable, "-m", "canest"]
WRITE_ONLY = ["/proc/sys/vm/compact_memory", "/proc/sys/net/ipv4/route/flush", "/proc/sysrq-trigger"]


def canest(*args, **kwargs):
    return subprocess.run([*CANEST, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=ROOT,
                          **kwargs)


def canest_blocking(module, *args):
    """canest in a subprocess in which ``module`` cannot be imported (as if it were not installed)."""
    code = f"import sys; sys.modules[{module!r}] = None; from canest.cli import main; main({list(map(str, args))!r})"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)


def one_line_error(result, status, *parts):
    """The run failed with ``status`` and exactly one stderr line ``canest: error: ...`` holding ``parts``."""
    errors = [line for line in result.stderr.splitlines() if not line.startswith("note:")]
    assert result.returncode == status, result.stderr
    assert len(errors) == 1 and errors[0].startswith("canest: error: "), result.stderr
    for part in parts:
        assert part in errors[0], errors[0]
    return errors[0]


def leftovers(folder) -> list:
    return sorted(p.name for p in folder.iterdir() if ".partial" in p.name)


@pytest.fixture(scope="module")
def drive(config, tmp_path_factory):
    """A one-second simulated drive as a candump log, in a folder of its own."""
    folder = tmp_path_factory.mktemp("drive")
    sim = simulate(config, "dlc", 80.0, 0.85, duration=1.0, seed=5)
    sim.write_log(folder / "drive.log")
    return folder / "drive.log", len(sim.frames)


@pytest.mark.parametrize("make_output", ["same", "hard link", "symbolic link"])
@pytest.mark.parametrize("option", ["--out", "--csv"])
def test_an_output_that_is_the_input_log_is_refused_and_the_log_kept(drive, tmp_path, option, make_output):
    log = tmp_path / "same.log"
    log.write_bytes(drive[0].read_bytes())
    output = {"same": lambda: log, "hard link": lambda: os.link(log, tmp_path / "hard.log") or tmp_path / "hard.log",
              "symbolic link": lambda: os.symlink(log, tmp_path / "sym.log") or tmp_path / "sym.log"}[make_output]()
    result = canest("replay", log, option, output, "-q")
    how = {"same": "the same file", "hard link": "a hard link to it", "symbolic link": "a symbolic link to it"}
    one_line_error(result, 2, f"{option} {output}: that is the input log {log} ({how[make_output]})",
                   "choose another output name")
    assert log.read_bytes() == drive[0].read_bytes() and leftovers(tmp_path) == []


def test_outputs_may_not_be_the_config_or_each_other(drive, tmp_path):
    config = tmp_path / "car.yaml"
    config.write_text((ROOT / "configs" / "dici_ev.yaml").read_text().replace("../dbc/", f"{ROOT / 'dbc'}/"))
    before = config.read_text()
    one_line_error(canest("replay", drive[0], "--config", config, "--csv", config, "-q"), 2,
                   f"--csv {config}: that is the config {config}")
    assert config.read_text() == before
    one_line_error(canest("replay", drive[0], "--out", tmp_path / "e.log", "--csv", tmp_path / "e.log", "-q"), 2,
                   f"--csv {tmp_path / 'e.log'}: that is --out {tmp_path / 'e.log'} (the same file)")
    one_line_error(canest("simulate", "--out", tmp_path / "s.log", "--truth", tmp_path / "s.log"), 2,
                   "--truth", "that is --out")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["car.yaml"]


def test_a_failed_replay_leaves_the_old_output_and_no_temporary_file(tmp_path, drive):
    junk, est = tmp_path / "junk.log", tmp_path / "est.csv"
    junk.write_text("not a candump line\n")
    est.write_text("old\n")
    one_line_error(canest("replay", junk, "--csv", est, "-q"), 65,
                   f"{junk}: no frame could be read: skipped 1 line(s) the reader could not parse (line 1)")
    assert est.read_text() == "old\n" and leftovers(tmp_path) == []
    result = canest("replay", drive[0], "--csv", est, "-q")  # an existing output is replaced when the run succeeds
    assert result.returncode == 0 and len(read_table(est)["t"]) > 50 and leftovers(tmp_path) == []


def test_writing_to_dev_full_is_one_line_and_exit_74_and_dev_full_stays(drive, tmp_path):
    before = sorted(os.listdir("/dev"))
    one_line_error(canest("replay", drive[0], "--csv", "/dev/full", "-q"), 74,
                   "/dev/full: cannot write: No space left on device; the disk is full")
    os.symlink("/dev/full", tmp_path / "full.log")
    one_line_error(canest("replay", drive[0], "--out", tmp_path / "full.log", "-q"), 74,
                   f"{tmp_path / 'full.log'}: cannot write: No space left on device")
    assert sorted(os.listdir("/dev")) == before, "nothing created or renamed in /dev"
    assert os.path.exists("/dev/full") and not os.path.isfile("/dev/full")


def limit_file_size(limit):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing the process
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.parametrize("option, name", [("--csv", "est.csv"), ("--out", "est.blf"), ("--out", "est.log")])
def test_a_disk_that_fills_up_midway_is_one_line_and_no_partial_file(drive, tmp_path, option, name):
    result = canest("replay", drive[0], option, tmp_path / name, "-q", preexec_fn=limit_file_size(512))
    one_line_error(result, 74, f"{tmp_path / name}: cannot write: File too large", "write elsewhere")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", ["replay", "simulate"])
def test_a_log_format_no_reader_reads_back_is_refused_and_nothing_written(drive, tmp_path, command):
    """python-can writes .txt as a printout; canest's reader (and python-can's) refused the file it had written."""
    arguments = [drive[0], "--out"] if command == "replay" else ["--truth", tmp_path / "t.csv", "-o"]
    one_line_error(canest(command, *arguments, tmp_path / "frames.txt"), 2, "frames.txt: python-can writes '.txt' as "
                   "a printout no reader (canest's either) reads back; name a log: .log (candump)")
    assert list(tmp_path.iterdir()) == []


def test_outputs_that_cannot_be_created_exit_73(drive, tmp_path):
    one_line_error(canest("replay", drive[0], "--csv", "/sys/canest-est.csv", "-q"), 73,
                   "/sys/canest-est.csv: cannot create:")
    one_line_error(canest("replay", drive[0], "--csv", tmp_path, "-q"), 73,
                   f"{tmp_path}: cannot create: that is a folder; name a file in it")
    one_line_error(canest("replay", drive[0], "--out", tmp_path / "no" / "est.log", "-q"), 73,
                   "cannot create: No such file or directory; the folder does not exist; create it first")
    one_line_error(canest("simulate", "--out", "/sys/canest-d.log", "--truth", tmp_path / "t.csv"), 73,
                   "/sys/canest-d.log: cannot create:")
    assert not os.path.exists("/sys/canest-est.csv") and list(tmp_path.iterdir()) == []


def test_a_log_that_may_not_be_read_exits_66_one_that_fails_midway_74(tmp_path):
    write_only = next((path for path in WRITE_ONLY if os.path.exists(path)), None)
    assert write_only is not None, f"none of {WRITE_ONLY} on this kernel: find another file root may not read"
    os.symlink(write_only, tmp_path / "forbidden.log")
    one_line_error(canest("replay", tmp_path / "forbidden.log", "-q"), 66,
                   f"{tmp_path / 'forbidden.log'}: cannot read: Permission denied")
    one_line_error(canest("replay", tmp_path / "nope.log", "-q"), 66, f"{tmp_path / 'nope.log'}: log file not found")
    os.symlink("/proc/self/mem", tmp_path / "failing.log")  # reading at offset 0 fails with EIO
    one_line_error(canest("replay", tmp_path / "failing.log", "-q"), 74,
                   f"{tmp_path / 'failing.log'}: cannot read: Input/output error")


def test_a_corrupt_or_cut_blf_is_read_up_to_the_damage_a_100_byte_one_is_exit_65(drive, tmp_path):
    frames = list(can.LogReader(str(drive[0])))
    with can.BLFWriter(str(tmp_path / "d.blf"), max_container_size=4096) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    data = (tmp_path / "d.blf").read_bytes()
    (tmp_path / "cut.blf").write_bytes(data[:len(data) // 2])
    result = canest("replay", tmp_path / "cut.blf", "-q")
    assert result.returncode == 0 and "log_truncated=1" in result.stdout
    assert "canest: warning: " in result.stderr and "truncated: the file ends inside a block" in result.stderr
    fields = dict(part.split("=") for part in result.stdout.split())
    assert 0 < int(fields["frames"]) < len(frames)
    (tmp_path / "short.blf").write_bytes(data[:100])
    one_line_error(canest("replay", tmp_path / "short.blf", "-q"), 65, "short.blf: no frame could be read: truncated")
    (tmp_path / "other.blf").write_bytes(b"this is no BLF file at all" * 10)
    one_line_error(canest("replay", tmp_path / "other.blf", "-q"), 65, "other.blf: not a readable BLF file")


def test_bad_lines_warn_on_stderr_and_the_summary_counts_them(drive, tmp_path):
    lines = drive[0].read_text().splitlines(keepends=True)
    lines[99] = "(0.2) vcan0 130#ZZ00000000000000 R\n"
    (tmp_path / "bad.log").write_text("".join(lines)[:-10])
    result = canest("replay", tmp_path / "bad.log", "--csv", tmp_path / "est.csv", "-q")
    assert result.returncode == 0
    fields = dict(part.split("=") for part in result.stdout.split())
    assert int(fields["frames"]) == drive[1] - 2 and fields["log_bad_lines"] == "1" and fields["log_torn_line"] == "1"
    warnings = result.stderr.strip().splitlines()
    assert warnings == [
        f"canest: warning: {tmp_path / 'bad.log'}: skipped 1 line(s) the reader could not parse (line 100); first: "
        "ValueError: invalid literal for int() with base 16: 'ZZ'",
        f"canest: warning: {tmp_path / 'bad.log'}: skipped the last line, cut mid-write (the logger stopped while "
        f"writing it) (line {drive[1]}); first: {lines[-1].strip()[:-9]!r}"]


def test_a_log_without_a_mapped_message_warns_naming_it_and_its_inputs(drive, tmp_path):
    """The IMU's frames left out of the log: every other frame decodes and the summary's counts look healthy, yet no
    tick estimates a yaw rate; one warning says which message and inputs never arrived (before, nothing did)."""
    imu = [line for line in drive[0].read_text().splitlines(keepends=True) if " vcan0 130#" in line]
    assert imu, "the simulated log holds ESC_IMU (0x130) frames"
    (tmp_path / "no_imu.log").write_text("".join(line for line in drive[0].read_text().splitlines(keepends=True)
                                                 if line not in imu))
    result = canest("replay", tmp_path / "no_imu.log", "--csv", tmp_path / "est.csv", "-q")
    assert result.returncode == 0
    assert result.stderr.strip() == (
        f"canest: warning: {tmp_path / 'no_imu.log'}: no value of 3 mapped input(s) in the whole log (ESC_IMU: ax, "
        "ay, yaw_rate); the states that need them are not estimated: compare the log's IDs with the config's input "
        "DBC (canest check --config ...) or leave the inputs the car does not send unmapped")
    assert canest("replay", drive[0], "--csv", tmp_path / "whole.csv", "-q").stderr == ""


def test_an_empty_log_gives_a_csv_header_a_warning_and_exit_0(tmp_path):
    (tmp_path / "empty.log").write_text("")
    result = canest("replay", tmp_path / "empty.log", "--csv", tmp_path / "est.csv", "-q")
    assert result.returncode == 0 and result.stdout.strip() == "frames=0"
    assert result.stderr.strip() == f"canest: warning: {tmp_path / 'empty.log'}: the log holds no CAN frames; the " \
                                    "outputs have no ticks"
    assert (tmp_path / "est.csv").read_text().startswith("t,vx,vy,beta,yaw_rate,")


def test_a_log_none_of_whose_frames_decode_exits_65_naming_the_causes_with_its_outputs_written(tmp_path):
    """A car's log read through the wrong DBC: every frame read, none an input. The outputs and the summary are
    written (every tick no_input), and the exit status says the run estimated nothing."""
    lines = [f"({i * 0.01:.6f}) can0 7F0#0102030405060708" for i in range(300)]
    (tmp_path / "other_car.log").write_text("\n".join(lines) + "\n")
    result = canest("replay", tmp_path / "other_car.log", "--csv", tmp_path / "est.csv", "-q")
    one_line_error(result, 65, "other_car.log", "none of its 300 frames decoded", "ignored_id=300")
    assert result.stdout.strip() == "frames=300 ignored_id=300"
    modes = read_table(tmp_path / "est.csv")["mode"]
    assert len(modes) > 250 and set(modes) == {"no_input"}


def test_a_log_without_a_finite_timestamp_says_so_not_to_compare_ids(drive, tmp_path):
    timeless = "".join(f"(nan) {line.split(') ', 1)[1]}" for line in drive[0].read_text().splitlines(keepends=True))
    (tmp_path / "timeless.log").write_text(timeless)
    one_line_error(canest("replay", tmp_path / "timeless.log", "-q"), 65, f"rejected_timestamp={drive[1]}",
                   "its frames have no finite timestamp")  # it said to compare the IDs and CAN FD flags


def test_missing_optional_packages_exit_69_naming_the_remedy(drive, tmp_path):
    one_line_error(canest_blocking("asammdf", "replay", drive[0], "--out", tmp_path / "est.mf4", "-q"), 69,
                   f"{tmp_path / 'est.mf4'}: The asammdf package was not found", "[mf4]")
    result = canest("replay", drive[0], "--csv", tmp_path / "est.csv", "-q")
    assert result.returncode == 0
    (tmp_path / "truth.csv").write_text((tmp_path / "est.csv").read_text())
    one_line_error(canest_blocking("matplotlib", "evaluate", tmp_path / "est.csv", tmp_path / "truth.csv", "--plot",
                                   tmp_path / "p.png"), 69, "--plot needs the Python package 'matplotlib'",
                   "pip install 'canest[plot]'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["est.csv", "truth.csv"]


def test_evaluate_inputs_missing_exit_66(tmp_path):
    one_line_error(canest("evaluate", tmp_path / "est.csv", tmp_path / "truth.csv"), 66,
                   f"{tmp_path / 'est.csv'}: cannot read: No such file or directory")


def test_a_damaged_csv_is_one_line_naming_file_and_line_a_torn_row_a_warning(drive, tmp_path):
    """evaluate (and compare, batch: one reader) on CSVs a user may give: before, each of these but the missing
    file ended in a traceback (IndexError, TypeError, UnicodeDecodeError)."""
    estimate, truth = tmp_path / "est.csv", tmp_path / "truth.csv"
    assert canest("simulate", "-m", "dlc", "--duration", "2", "-o", tmp_path / "d.log", "--truth", truth).returncode == 0
    assert canest("replay", tmp_path / "d.log", "--csv", estimate, "-q").returncode == 0
    lines = estimate.read_text().splitlines(keepends=True)
    torn = tmp_path / "torn.csv"
    torn.write_text("".join(lines[:150]) + "1.5,22.2\n" + "".join(lines[150:]) + "\n")  # and a blank line
    result = canest("evaluate", torn, truth)
    assert result.returncode == 0 and "yaw_rate" in result.stdout
    assert result.stderr.startswith(f"canest: warning: {torn}: left out 1 line(s)") and "line 151, 2 fields" in \
        result.stderr and result.stderr.count("\n") == 1
    text = tmp_path / "text.csv"
    text.write_text("".join(lines[:150]) + lines[150].replace(lines[150].split(",")[1], "abc", 1) + "".join(lines[151:]))
    one_line_error(canest("evaluate", text, truth), 65, f"{text}:151: column 'vx' holds 'abc' where its other rows")
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"t,vx\n\xff\xfe\x00\x01\n")
    one_line_error(canest("evaluate", estimate, binary), 65, f"{binary}: not a text CSV")
    header_only = tmp_path / "header.csv"
    header_only.write_text(lines[0])
    one_line_error(canest("evaluate", estimate, header_only), 65, f"{header_only}: no rows under the header")
    one_line_error(canest("evaluate", truth, estimate), 2, "the arguments look swapped")
    one_line_error(canest("compare", tmp_path / "d.log", estimate), 2, "has the 'valid' column of an estimate CSV")
    one_line_error(canest("compare", tmp_path / "d.log", text), 65, f"{text}:151: column 'vx'")
    one_line_error(canest("compare", tmp_path / "d.log", tmp_path / "none.csv"), 66, "none.csv: cannot read")
    elsewhere = tmp_path / "elsewhere.csv"  # another drive's truth: its clock 100 s on (a table of NaN, exit 0)
    truth_lines = truth.read_text().splitlines(keepends=True)
    elsewhere.write_text(truth_lines[0] + "".join(f"{float(line.split(',')[0]) + 100.0},{line.split(',', 1)[1]}"
                                                  for line in truth_lines[1:]))
    result = canest("compare", tmp_path / "d.log", elsewhere, "--filters", "ckf")
    assert result.returncode == 65 and "no tick of any filter could be scored" in result.stderr, result.stderr
    for command in (("evaluate", estimate, truth), ("compare", tmp_path / "d.log", truth)):
        one_line_error(canest(*command, "--plot", tmp_path / "p.txt"), 2, "--plot", "cannot write '.txt' files")
    assert not (tmp_path / "p.txt").exists()


@pytest.mark.parametrize("arguments, says", [
    (("simulate", "--duration", "1e-9"), "--duration: seconds from 0.1, got 1e-09"),  # was ZeroDivisionError
    (("simulate", "--mu-jump", "nan:0.3"), "--mu-jump: expected T:MU with T >= 0 s"),  # ValueError
    (("simulate", "--mu-jump", "20:0.3", "--duration", "5"), "--mu-jump: the friction jump at 20 s is not within "
                                                             "the drive's 5 s"),  # never jumped
    (("simulate", "--mu-jump", "1:9"), "--mu-jump: expected one or four values"),  # said --mu
    (("simulate", "--noise-scale", "nan"), "--noise-scale: a scale from 0 to 10"),  # ValueError in cantools
    (("simulate", "-m", "sine", "--amplitude", "nan"), "--amplitude: sine takes steering wheel deg"),
    (("simulate", "--amplitude", "30"), "--amplitude: dlc follows its own path"),  # silently unused
    (("simulate", "--seed", "-1"), "--seed: an integer from 0"),  # numpy ValueError
    (("simulate", "--start-time", "nan"), "--start-time: seconds from 0"),  # wrote nan timestamps
    (("demo", "--playback-speed", "0"), "--playback-speed: a factor above 0"),  # KeyError after the run
    (("demo", "--speed", "nan"), "--speed: a target speed from 2 to 300 km/h"),
    (("monitor", "-i", "virtual", "-c", "m", "--refresh", "0"), "--refresh: seconds from 0.05"),  # busy loop
    (("monitor", "-i", "virtual", "-c", "m", "--duration", "nan"), "--duration: seconds above 0"),  # no output
    (("batch", "x.log", "--out", "results", "--workers", "-1"), "--workers: worker processes"),  # hung
    (("batch", "x.log", "--out", "results", "--connect-timeout", "nan"), "--connect-timeout: seconds above 0"),
    (("replay", "x.log", "-i", "virtual", "-c", "can7", "--csv", "e.csv"),  # both silently ignored offline
     "offline replay reads the log and opens no bus; -i/--interface and -c/--channel choose the bus --realtime"),
    (("replay", "x.log", "--realtime", "-i", "virtual", "--json"),  # text was printed
     "--realtime plays the log onto a bus (a running daemon estimates); --json belongs to offline replay"),
    (("replay", "x.log", "--realtime", "-i", "virtual", "--state-file", "s.json", "--output-channel", "o"),
     "--state-file and --output-channel belong to offline replay"),
    (("evaluate", "x.csv", "y.csv", "--skip", "nan"), "--skip: seconds from 0"),  # blamed the clocks
    (("batch", "x.log", "--out", "README.md"), "--out README.md: that is a file; name the results folder"),
    (("evaluate", "x.csv", "y.csv", "--align", "offset", "nan"), "--align offset nan: expected first, none"),
    (("compare", "x.log", "y.csv", "--filters", ","), "--filters ',': name at least one filter"),  # ran none, exit 0
    (("compare", "x.log", "y.csv", "--skip", "-1"), "--skip: seconds from 0"),
])
def test_numbers_a_command_cannot_take_are_one_line_before_any_work(tmp_path, arguments, says):
    outputs = ("-o", tmp_path / "d.log", "--truth", tmp_path / "t.csv") if arguments[0] == "simulate" else ()
    arguments = [tmp_path / word if word in ("x.log", "results") else word for word in arguments]
    one_line_error(canest(*arguments, *outputs), 73 if "README.md" in arguments else 2, says)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("speed", ["0", "-20", "nan"])
def test_simulate_at_a_speed_the_plant_cannot_drive_is_a_usage_error(tmp_path, speed):
    result = canest("simulate", "--speed", speed, "--out", tmp_path / "d.log", "--truth", tmp_path / "t.csv")
    one_line_error(result, 2, f"--speed: a target speed from 2 to 300 km/h, got {float(speed)}")
    assert list(tmp_path.iterdir()) == []


def test_realtime_playback_at_speed_0_is_a_usage_error(drive):
    one_line_error(canest("replay", drive[0], "--realtime", "--speed", "0", "--interface", "virtual"), 2,
                   "--speed: a playback speed factor above 0, e.g. 1 or 10, got 0.0")


def test_the_exit_status_table_is_in_the_help():
    out = canest("--help").stdout
    for line in ("  65  input data", "  66  no input", "  69  unavailable", "  73  cannot create", "  74  I/O error"):
        assert line in out


@pytest.fixture(scope="module")
def long_log(config, tmp_path_factory):
    """Two minutes of traffic (the one-second drive, repeated back to back): a replay of several seconds."""
    sim = simulate(config, "dlc", 80.0, 0.85, duration=1.0, seed=5)
    path = tmp_path_factory.mktemp("long") / "long.log"
    with can.Logger(str(path)) as writer:
        for k in range(120):
            for frame in sim.frames:
                writer.on_message_received(can.Message(timestamp=frame.timestamp + k * 1.1, data=frame.data,
                                                       arbitration_id=frame.arbitration_id, is_extended_id=False))
    return path, 120 * len(sim.frames)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_the_replay_in_order_with_its_summary_and_complete_files(long_log, tmp_path, signum):
    log, total = long_log
    est_csv, est_log = tmp_path / "est.csv", tmp_path / "est.log"
    process = subprocess.Popen([*CANEST, "replay", str(log), "--csv", str(est_csv), "--out", str(est_log), "-q"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    deadline = time.monotonic() + 120
    while not any(p.stat().st_size > 60000 for p in tmp_path.iterdir() if ".partial" in p.name):  # > 100 rows
        assert process.poll() is None and time.monotonic() < deadline, "the replay ended before it was signalled"
        time.sleep(0.05)
    process.send_signal(signum)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 0, stderr
    fields = dict(part.split("=") for part in stdout.split())
    assert fields["stopped"] == "1" and 0 < int(fields["frames"]) < total
    assert int(fields["frames"]) == int(fields["decoded"]) + int(fields.get("ignored_id", 0)) + sum(
        int(v) for k, v in fields.items() if k.startswith("rejected_"))
    assert f"canest: replay stopped by {signal.Signals(signum).name} after {fields['frames']} frames" in stderr
    assert leftovers(tmp_path) == []
    rows = est_csv.read_text().splitlines()
    assert len({row.count(",") for row in rows}) == 1, "every row complete"
    ticks = [m.timestamp for m in can.LogReader(str(est_log)) if m.arbitration_id == 0x501]
    assert len(ticks) == len(rows) - 1 > 100, "both files hold the same ticks, up to the last one processed"


def test_a_second_signal_aborts_at_once_without_outputs(long_log, tmp_path):
    log, _ = long_log
    est_csv = tmp_path / "est.csv"
    process = subprocess.Popen([*CANEST, "replay", str(log), "--csv", str(est_csv), "-q"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    deadline = time.monotonic() + 120
    while not any(p.stat().st_size > 60000 for p in tmp_path.iterdir() if ".partial" in p.name):  # > 100 rows
        assert process.poll() is None and time.monotonic() < deadline, "the replay ended before it was signalled"
        time.sleep(0.05)
    process.send_signal(signal.SIGSTOP)  # both pending when it goes on: its handlers run back to back
    process.send_signal(signal.SIGINT)
    process.send_signal(signal.SIGTERM)
    process.send_signal(signal.SIGCONT)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 130 and stdout == "", stderr
    assert list(tmp_path.iterdir()) == [], "no output and no temporary file"
