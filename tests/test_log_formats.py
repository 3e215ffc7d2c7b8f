"""Logs by content: a log named .candump, .txt or nothing is read in the format its first lines show,
--format overrides, and --log-channel reads one bus of several with the others' frames counted.

Every log here is written by python-can's own writers and then renamed.
"""
import gzip
import json
import shutil
import subprocess
import sys

import can
import pytest

from canest.apps.batch_plan import plan
from canest.apps.replay import replay
from canest.errors import InputFileError
from canest.io.logfiles import expand_logs
from canest.io.sniff import sniff_format
from canest.sim.simulate import simulate
from tests.conftest import FORD, ROOT, ford_config, realdata

CANEST = [sys.executable, "-m", "canest"]
WRITERS = {".log": can.CanutilsLogWriter, ".asc": can.ASCWriter, ".trc": can.TRCWriter, ".csv": can.CSVWriter,
           ".blf": can.BLFWriter}


def canest(*args):
    return subprocess.run([*CANEST, *map(str, args)], capture_output=True, text=True, timeout=300, cwd=ROOT)


def write(frames, path, writer):
    log = writer(str(path))
    for frame in frames:
        log.on_message_received(frame)
    log.stop()
    return path


def run(config, path, **reading):
    """The replay's summary, with the number of estimates it gave (``estimates``)."""
    estimates = []
    summary = replay(config, path, progress=False, on_estimate=estimates.append, **reading)
    return {**summary, "estimates": len(estimates)}


@pytest.fixture(scope="module")
def sim(config):
    return simulate(config, "dlc", 80.0, 0.85, duration=1.0, seed=5)


@pytest.fixture(scope="module")
def reference(config, sim, tmp_path_factory):
    """The replay summary of the drive as a ``.log``, which python-can reads by its suffix."""
    path = write(sim.frames, tmp_path_factory.mktemp("ref") / "drive.log", can.CanutilsLogWriter)
    return run(config, path)


@pytest.mark.parametrize("suffix", list(WRITERS))
@pytest.mark.parametrize("name", ["drive.candump", "drive.txt", "drive"])
def test_a_log_of_any_name_is_read_in_the_format_its_first_lines_show(config, sim, reference, tmp_path, suffix,
                                                                      name):
    written = write(sim.frames, tmp_path / f"written{suffix}", WRITERS[suffix])
    renamed = written.rename(tmp_path / name)
    summary = run(config, renamed)
    assert summary["frames"] == len(sim.frames)
    assert summary["decoded"] == reference["decoded"] > 0
    assert summary["estimates"] == reference["estimates"] > 0


def test_a_gzip_compressed_log_of_an_unknown_suffix_is_sniffed_inside(config, sim, reference, tmp_path):
    written = write(sim.frames, tmp_path / "w.asc", can.ASCWriter)
    packed = tmp_path / "drive.candump.gz"
    with open(written, "rb") as source, gzip.open(packed, "wb") as target:
        shutil.copyfileobj(source, target)
    assert run(config, packed)["decoded"] == reference["decoded"]


@pytest.mark.parametrize("head, kind", [
    (b"# recorded on the test bench\n(1487342025.615950) can0 187#E21408C800100300\n", ".log"),
    (b"(1.5) vcan0 18FEF100##1112233\n", ".log"),
    (b";##########################################################################\n;   C:\\drive.trc\n", ".trc"),
    (b"date Mon Nov 23 05:11:11.283 2026\nbase hex  timestamps absolute\n", ".asc"),
    (b"timestamp,arbitration_id,extended,remote,error,dlc,data\n", ".csv"),
    (b"LOGG\x90\x00\x00\x00", ".blf"),
    (b"  can0  187   [8]  E2 14 08 C8 00 10 03 00\n", None),  # candump without -L: no timestamps
    (b"", None),
    (b"\x00\x01\x02 binary junk", None),
])
def test_the_format_is_told_by_the_first_lines(head, kind):
    assert sniff_format(head) == kind


def test_unknown_content_is_one_line_exit_65_naming_the_file_and_the_formats_tried(tmp_path):
    path = tmp_path / "notes.txt"
    path.write_text("  can0  187   [8]  E2 14 08 C8 00 10 03 00\n")
    result = canest("replay", path, "--csv", tmp_path / "e.csv")
    errors = [line for line in result.stderr.splitlines() if line.startswith("canest:")]
    assert result.returncode == 65, result.stderr
    assert len(errors) == 1 and errors[0].startswith(f"canest: error: {path}: "), result.stderr
    for tried in ("candump -L", "Vector ASC", "PEAK TRC", "python-can CSV", "BLF", "--format"):
        assert tried in errors[0]
    assert not (tmp_path / "e.csv").exists()


def test_format_overrides_the_suffix_and_the_content(config, sim, reference, tmp_path):
    misnamed = write(sim.frames, tmp_path / "w.log", can.CanutilsLogWriter).rename(tmp_path / "drive.asc")
    summary = run(config, misnamed, log_format="log")
    assert summary["decoded"] == reference["decoded"]
    result = canest("replay", misnamed, "--format", "log", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["decoded"] == reference["decoded"]


@pytest.fixture(scope="module")
def two_buses(sim, tmp_path_factory):
    """The drive on can0 and a body bus on can1 (other IDs) interleaved, as candump -L writes one file for two
    interfaces; named without a suffix."""
    body = [can.Message(timestamp=f.timestamp + 1e-4, arbitration_id=0x7A0 + i % 3, data=bytes(8), channel="can1")
            for i, f in enumerate(sim.frames) if i % 2 == 0]
    drive = [can.Message(timestamp=f.timestamp, arbitration_id=f.arbitration_id, is_extended_id=f.is_extended_id, data=f.data,
        dlc=f.dlc, is_fd=f.is_fd, channel="can0") for f in sim.frames]
    frames = sorted(drive + body, key=lambda m: m.timestamp)
    path = write(frames, tmp_path_factory.mktemp("buses") / "w.log", can.CanutilsLogWriter)
    return path.rename(path.with_name("two_buses")), len(drive), len(body)


def test_log_channel_reads_one_bus_and_counts_the_others_frames(config, reference, two_buses):
    path, drive, body = two_buses
    result = canest("replay", path, "--log-channel", "can0", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["frames"] == drive and summary["log_other_channel"] == body
    assert summary["decoded"] == reference["decoded"] and summary.get("ignored_id", 0) == 0
    assert "channel" not in result.stderr  # nothing to warn about: one bus chosen


def test_a_log_of_several_channels_read_as_one_is_warned_about_listing_them(config, reference, two_buses):
    path, drive, body = two_buses
    result = canest("replay", path, "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["frames"] == drive + body and summary["ignored_id"] == body
    assert f"can0 ({drive} frames), can1 ({body} frames)" in result.stderr and "--log-channel" in result.stderr


def test_an_error_frame_stays_on_its_bus(sim, tmp_path):
    """candump writes an error frame's interface like any frame's; python-can's reader drops it (channel None)."""
    frames = [can.Message(timestamp=f.timestamp, arbitration_id=f.arbitration_id, is_extended_id=f.is_extended_id,
                          data=f.data, channel="can0") for f in sim.frames]
    error = can.Message(timestamp=frames[10].timestamp + 1e-4, is_error_frame=True, channel="can0")
    path = write(frames[:11] + [error] + frames[11:], tmp_path / "drive.log", can.CanutilsLogWriter)
    assert " can0 2000" in path.read_text()  # written with its interface
    result = canest("replay", path, "--log-channel", "can0", "--json")
    assert result.returncode == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["frames"] == len(frames) + 1 and "log_other_channel" not in summary
    assert summary["rejected_error_frame"] == 1
    result = canest("replay", path, "--json")
    assert "several channels" not in result.stderr and "None" not in result.stderr


def test_a_channel_the_log_does_not_hold_is_warned_about_with_the_channels_it_does(two_buses):
    path, drive, body = two_buses
    result = canest("replay", path, "--log-channel", "vcan0", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["log_other_channel"] == drive + body
    assert "no frame on channel 'vcan0'" in result.stderr and "can0 (" in result.stderr


def test_compare_reads_one_channel_of_a_log_named_without_suffix(two_buses, sim, tmp_path):
    path, drive, body = two_buses
    sim.write_truth(tmp_path / "truth.csv")
    result = canest("compare", path, tmp_path / "truth.csv", "--filters", "ckf", "--log-channel", "can0")
    assert result.returncode == 0, result.stderr
    assert "ckf" in result.stdout and "channel" not in result.stderr


def test_batch_tasks_remember_how_their_log_is_read(two_buses, tmp_path):
    path, _, _ = two_buses
    plain, = plan([path], ["ckf"], path.parent, tmp_path / "out")
    chosen, = plan([path], ["ckf"], path.parent, tmp_path / "out", log_format="log", log_channel="can0")
    assert "reading" not in plain.inputs()  # results of earlier batches stay complete
    assert chosen.inputs()["reading"] == {"log_format": "log", "log_channel": "can0"}
    assert chosen.inputs() != plain.inputs()  # another channel is estimated again, not taken from the old result


def test_the_ford_log_is_read_under_its_own_name_as_under_a_log_suffix(tmp_path):
    """The real drive as recorded (``.candump``) and as ``.log``: the same frames, decoded the same."""
    from canest.config import load_config

    log = realdata(FORD, "acc_on_speed_changing_from_30km_to_80km_per_hour.candump")
    config = load_config(ford_config(tmp_path))
    renamed = tmp_path / "drive.log"
    shutil.copy(log, renamed)
    as_recorded, as_log = run(config, log), run(config, renamed)
    assert as_recorded == as_log
    assert as_recorded["frames"] == 41250 == as_recorded["decoded"] + as_recorded["ignored_id"]


def test_log_patterns_expand_sorted_each_log_once_and_a_pattern_matching_nothing_is_named(tmp_path):
    for name in ("b.log", "a.log", "c.blf"):
        (tmp_path / name).write_text("")
    (tmp_path / "folder.log").mkdir()
    found = expand_logs([tmp_path / "*.log", tmp_path / "a.log", "not-a-pattern.log"])
    assert found == [str(tmp_path / "a.log"), str(tmp_path / "b.log"), "not-a-pattern.log"]
    with pytest.raises(InputFileError, match=r"\*\.mf4: no log matches"):
        expand_logs([tmp_path / "*.mf4"])
