"""Damaged logs: what cannot be read is skipped and counted by cause, the rest is replayed, nothing silently lost."""
import gzip
import logging

import can
import pytest

from canest.apps.evaluate import read_table
from canest.apps.replay import play, replay
from canest.errors import LogError
from canest.estimation.learned_parameters import NAMES
from canest.io.logfiles import open_log
from canest.sim.simulate import simulate


@pytest.fixture(scope="module")
def drive(config):
    """A one-second simulated drive: its frames, in time order."""
    return simulate(config, "dlc", 80.0, 0.85, duration=1.0, seed=5).frames


def write(frames, path):
    with can.Logger(str(path)) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    return path


def write_blf(frames, path, block=8192):
    """A BLF of several compressed blocks (python-can's default block holds 128 kB)."""
    with can.BLFWriter(str(path), max_container_size=block) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    return path


def accounted(summary) -> int:
    """Frames the pipeline accounts for: decoded, ignored by ID, rejected by cause."""
    return summary["decoded"] + summary.get("ignored_id", 0) + sum(
        v for k, v in summary.items() if k.startswith("rejected_"))


def replace_line(path, number, text):
    lines = path.read_text().splitlines(keepends=True)
    lines[number - 1] = text
    path.write_text("".join(lines))


def same_frame(a, b) -> bool:
    return (a.arbitration_id, bytes(a.data)) == (b.arbitration_id, bytes(b.data)) and a.timestamp == pytest.approx(
        b.timestamp)


def test_a_bad_candump_line_is_skipped_counted_and_the_replay_goes_on(config, drive, tmp_path, caplog):
    clean, bad = write(drive, tmp_path / "clean.log"), write(drive, tmp_path / "bad.log")
    replace_line(bad, 200, "(0.400000) vcan0 130#ZZ00000000000000 R\n")
    expected = replay(config, clean, out_csv=tmp_path / "clean.csv", progress=False)
    with caplog.at_level(logging.WARNING, logger="canest"):
        summary = replay(config, bad, out_csv=tmp_path / "bad.csv", progress=False)
    assert summary["log_bad_lines"] == 1 and summary["frames"] == len(drive) - 1 == accounted(summary)
    assert summary["frames"] + summary["log_bad_lines"] == len(bad.read_text().splitlines())
    assert read_table(tmp_path / "bad.csv")["t"][-1] == read_table(tmp_path / "clean.csv")["t"][-1], \
        "the replay went on to the end of the log"
    assert expected["frames"] == len(drive)
    assert "bad.log: skipped 1 line(s) the reader could not parse (line 200)" in caplog.text
    assert "invalid literal for int() with base 16: 'ZZ'" in caplog.text


def test_a_torn_last_line_is_reported_as_such(config, drive, tmp_path, caplog):
    log = write(drive, tmp_path / "torn.log")
    log.write_bytes(log.read_bytes()[:-25])  # the logger was killed in the middle of the last line
    with caplog.at_level(logging.WARNING, logger="canest"):
        summary = replay(config, log, progress=False)
    assert summary["log_torn_line"] == 1 and "log_bad_lines" not in summary
    assert summary["frames"] == len(drive) - 1 == accounted(summary)
    assert f"skipped the last line, cut mid-write (the logger stopped while writing it) (line {len(drive)})" \
        in caplog.text


def test_asc_junk_and_bad_frame_lines_are_counted_header_and_events_are_not(drive, tmp_path):
    log = write(drive, tmp_path / "d.asc")
    lines = log.read_text().splitlines(keepends=True)
    header = next(i for i, line in enumerate(lines) if line.split()[1:2] == ["1"])  # first frame line
    lines[header + 10] = "this is not an ASC line\n"
    lines[header + 20] = lines[header + 20].replace(" d 8 ", " d 8 ZZ ", 1)
    lines.insert(header + 30, "   0.500000 Statistic: D 0 R 0 XD 0 XR 0 E 0 O 0 B 0.00%\n")  # an event: not damage
    log.write_text("".join(lines))
    source = open_log(log)
    frames = list(source)
    assert len(frames) == len(drive) - 2
    assert source.damage.counts == {"junk_lines": 1, "bad_lines": 1}
    assert source.damage.where == {"junk_lines": [header + 11], "bad_lines": [header + 21]}
    assert len(frames) + 2 + source.damage.quiet_lines == source.damage.lines == len(lines)


def test_trc_short_and_bad_lines_are_counted_not_dropped_silently(drive, tmp_path):
    log = write(drive, tmp_path / "d.trc")
    lines = log.read_text().splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if not line.startswith(";"))
    lines[first + 5] = "      5\n"  # python-can's reader logs an IndexError and drops the line
    lines[first + 6] = lines[first + 6].rstrip("\n").rsplit(" ", 1)[0] + " QQ\n"  # a data byte that is no hex
    log.write_text("".join(lines))
    source = open_log(log)
    frames = list(source)
    assert source.damage.counts == {"bad_lines": 2} and source.damage.where["bad_lines"] == [first + 6, first + 7]
    assert [f.arbitration_id for f in frames] == [f.arbitration_id for i, f in enumerate(drive) if i not in (5, 6)]


def test_python_can_csv_bad_line(drive, tmp_path):
    log = write(drive, tmp_path / "d.csv")
    replace_line(log, 11, "0.1,0x130,0,0,0,8,not base64!\n")
    source = open_log(log)
    frames = list(source)
    assert source.damage.counts == {"bad_lines": 1} and len(frames) == len(drive) - 1
    assert all(same_frame(a, b) for a, b in zip(frames, drive[:9] + drive[10:]))


def test_a_gzip_compressed_log_with_a_bad_line(drive, tmp_path):
    plain = write(drive, tmp_path / "d.log")
    replace_line(plain, 3, "garbage\n")
    packed = tmp_path / "d.log.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    source = open_log(packed)
    assert len(list(source)) == len(drive) - 1 and source.damage.where == {"bad_lines": [3]}


def test_a_cut_gzip_log_gives_the_lines_before_the_cut_and_says_so(drive, tmp_path):
    packed = gzip.compress(write(drive, tmp_path / "d.log").read_bytes())
    (tmp_path / "cut.log.gz").write_bytes(packed[:len(packed) // 2])
    source = open_log(tmp_path / "cut.log.gz")
    frames = list(source)
    assert 0 < len(frames) < len(drive) and all(same_frame(a, b) for a, b in zip(frames, drive))
    assert source.damage.counts["corrupt"] == 1
    assert source.damage.stopped.startswith(f"decompression failed after line {source.damage.lines}, the rest is "
                                            "unreadable (EOFError")


def test_a_blf_cut_in_half_gives_its_first_frames_and_says_where_it_ends(config, drive, tmp_path, caplog):
    whole = write_blf(drive, tmp_path / "whole.blf")
    cut = tmp_path / "cut.blf"
    cut.write_bytes(whole.read_bytes()[:whole.stat().st_size // 2])
    source = open_log(cut)
    frames = list(source)
    intact = list(can.LogReader(str(whole)))
    assert 0 < len(frames) < len(intact)
    assert all(same_frame(a, b) for a, b in zip(frames, intact)), "exactly the frames before the cut"
    assert source.damage.counts == {"truncated": 1}
    assert f"truncated: the file ends inside a block at byte {cut.stat().st_size} (its header says " \
           f"{whole.stat().st_size} bytes)" in source.damage.stopped
    with caplog.at_level(logging.WARNING, logger="canest"):
        summary = replay(config, cut, progress=False)
    assert summary["log_truncated"] == 1 and summary["frames"] == len(frames)
    assert "cut.blf: truncated" in caplog.text


def test_a_corrupt_blf_block_ends_the_reading_with_where_and_how_much(drive, tmp_path):
    log = write_blf(drive, tmp_path / "d.blf")
    data = bytearray(log.read_bytes())
    middle = len(data) // 2
    data[middle:middle + 64] = bytes(64)  # zeros in the middle of compressed data
    log.write_bytes(bytes(data))
    source = open_log(log)
    frames = list(source)
    assert source.damage.counts == {"corrupt": 1}
    assert 0 < source.damage.unread_bytes < len(data) and "could not be decoded" in source.damage.stopped
    intact = list(can.LogReader(str(write_blf(drive, tmp_path / "intact.blf"))))
    assert 0 < len(frames) < len(intact) and all(same_frame(a, b) for a, b in zip(frames, intact))


def test_a_blf_of_100_bytes_is_an_error_saying_it_is_truncated(drive, tmp_path):
    log = write(drive, tmp_path / "d.blf")
    log.write_bytes(log.read_bytes()[:100])
    with pytest.raises(LogError, match=r"d\.blf: no frame could be read: truncated: the file ends inside a block "
                                       r"at byte 100 \(its header says \d+ bytes\)"):
        list(open_log(log))


def test_a_log_of_which_nothing_is_readable_is_an_error(tmp_path):
    log = tmp_path / "junk.log"
    log.write_text("this is\nnot a candump log\n")
    with pytest.raises(LogError, match=r"junk\.log: no frame could be read: skipped 2 line\(s\) the reader could "
                                       r"not parse \(line 1, 2\)"):
        list(open_log(log))


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf", ".trc", ".csv"])
def test_an_empty_log_gives_a_csv_with_its_header_and_a_warning(config, tmp_path, suffix, caplog):
    log = tmp_path / f"empty{suffix}"
    log.write_bytes(b"")
    with caplog.at_level(logging.WARNING, logger="canest"):
        summary = replay(config, log, out_csv=tmp_path / "est.csv", progress=False)
    assert summary["frames"] == 0
    learned = [f"calib_{name}{part}" for name in NAMES for part in ("", "_std")]  # the online learner is on
    assert (tmp_path / "est.csv").read_text().splitlines() == [
        "t,vx,vy,beta,yaw_rate,vx_std,vy_std,beta_std,yaw_rate_std,valid,mode,"
        "why_vx,why_yaw_rate,why_beta,why_forces,why_friction," + ",".join(learned)]
    assert "the log holds no CAN frames" in caplog.text


def test_one_infinite_timestamp_is_one_rejected_frame_not_a_backwards_clock(config, drive, tmp_path):
    clean, glitch = write(drive, tmp_path / "clean.log"), write(drive, tmp_path / "glitch.log")
    line = glitch.read_text().splitlines()[99]
    replace_line(glitch, 100, "(inf)" + line[line.index(")") + 1:] + "\n")
    expected = replay(config, clean, out_csv=tmp_path / "clean.csv", progress=False)
    summary = replay(config, glitch, out_csv=tmp_path / "glitch.csv", progress=False)
    assert summary["rejected_timestamp"] == 1 and "time_backwards" not in summary and "time_jumps" not in summary
    assert summary["frames"] == len(drive) == accounted(summary)
    assert len(read_table(tmp_path / "glitch.csv")["t"]) == len(read_table(tmp_path / "clean.csv")["t"])
    assert expected["decoded"] - summary["decoded"] <= 1


def test_realtime_playback_skips_bad_lines_and_frames_without_a_time_and_says_so(drive, tmp_path, caplog):
    log = write(drive, tmp_path / "play.log")
    replace_line(log, 10, "(0.02) vcan0 130#ZZ\n")
    line = log.read_text().splitlines()[19]
    replace_line(log, 20, "(nan)" + line[line.index(")") + 1:] + "\n")
    bus, listener = can.Bus(interface="virtual", channel="play"), can.Bus(interface="virtual", channel="play")
    try:
        with caplog.at_level(logging.WARNING, logger="canest"):
            sent = play(log, bus, speed=100.0, progress=False)
        received = iter(lambda: listener.recv(timeout=0.2), None)
        assert sent == len(drive) - 2 == sum(1 for _ in received)
    finally:
        bus.shutdown()
        listener.shutdown()
    assert "skipped 1 line(s) the reader could not parse (line 10)" in caplog.text
    assert "1 frame(s) without a finite timestamp were not sent" in caplog.text
