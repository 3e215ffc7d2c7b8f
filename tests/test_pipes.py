"""canest in pipes, as can-utils and cantools are used: `-` is standard input as a log and standard output as an
output, and machine-readable output (--json) for what a script reads. Real `python -m canest` processes throughout.
"""
import json
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from tests.conftest import CONFIG, ROOT

CANEST = [sys.executable, "-m", "canest"]


def canest(*args, stdin=None, text=True):
    return subprocess.run([*CANEST, *map(str, args)], capture_output=True, text=text, timeout=300, cwd=ROOT,
                          stdin=stdin)


def spawn(*args, stdin=None):
    return subprocess.Popen([*CANEST, *map(str, args)], stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            cwd=ROOT)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The file-based run: simulate to a log, replay it to a CSV, evaluate it as JSON."""
    folder = tmp_path_factory.mktemp("files")
    log, truth, est = folder / "drive.log", folder / "truth.csv", folder / "est.csv"
    assert canest("simulate", "--maneuver", "sine", "--duration", "6", "--out", log, "--truth", truth).returncode == 0
    replayed = canest("replay", log, "--config", CONFIG, "--csv", est, "-q", "--json")
    assert replayed.returncode == 0, replayed.stderr
    result = canest("evaluate", est, truth, "--json")
    assert result.returncode == 0, result.stderr
    return {"log": log, "truth": truth, "est": est, "scores": json.loads(result.stdout),
            "summary": json.loads(replayed.stdout)}


def test_simulate_replay_evaluate_through_pipes_gives_the_file_based_numbers(files, tmp_path):
    truth = tmp_path / "truth.csv"
    simulate = spawn("simulate", "--maneuver", "sine", "--duration", "6", "--out", "-", "--truth", truth)
    replay = spawn("replay", "-", "--config", CONFIG, "--csv", "-", stdin=simulate.stdout)
    evaluate = spawn("evaluate", "-", truth, "--json", stdin=replay.stdout)
    simulate.stdout.close()
    replay.stdout.close()
    out, err = evaluate.communicate(timeout=300)
    assert [simulate.wait(60), replay.wait(60), evaluate.returncode] == [0, 0, 0], err
    assert json.loads(out) == files["scores"]
    assert json.loads(out)["yaw_rate"]["samples"] > 400
    # the messages stay on stderr, and a pipe gets no progress bar
    assert simulate.stderr.read().decode().startswith("wrote ")
    frames = files["summary"]["frames"]
    assert replay.stderr.read().decode().splitlines() == [f"frames={frames} decoded={frames}"]
    assert truth.read_bytes() == files["truth"].read_bytes()


def test_replay_outputs_on_stdout_equal_the_files(files, tmp_path):
    est_log = tmp_path / "est.log"
    assert canest("replay", files["log"], "--config", CONFIG, "--out", est_log, "-q").returncode == 0
    to_stdout = canest("replay", files["log"], "--config", CONFIG, "--out", "-")
    assert to_stdout.returncode == 0
    assert to_stdout.stdout == est_log.read_text()  # candump text, the summary on stderr
    assert to_stdout.stderr.startswith("frames=")
    with open(files["log"]) as log:
        csv_out = canest("replay", "-", "--config", CONFIG, "--csv", "-", stdin=log, text=False)
    assert csv_out.stdout == files["est"].read_bytes()


def test_replay_of_a_live_pipe_writes_ticks_before_the_input_ends(files):
    """Standard input is read as it arrives: rows come out while the writer still holds the pipe open."""
    lines = files["log"].read_bytes().splitlines(keepends=True)
    replay = spawn("replay", "-", "--config", CONFIG, "--csv", "-", stdin=subprocess.PIPE)
    replay.stdin.write(b"".join(lines[:1500]))
    replay.stdin.flush()
    header = replay.stdout.readline()
    first_row = replay.stdout.readline()
    assert header.startswith(b"t,vx,") and first_row[:1].isdigit()
    assert replay.poll() is None  # still waiting for more input

    def write_the_rest():  # while this thread reads: a full stdout pipe would block the writer and the replay
        replay.stdin.write(b"".join(lines[1500:]))
        replay.stdin.close()
    writer = threading.Thread(target=write_the_rest)
    writer.start()
    rest = replay.stdout.read()
    writer.join()
    assert replay.wait(60) == 0
    assert header + first_row + rest == files["est"].read_bytes()


def test_replay_to_redirected_stderr_has_no_progress_bar(files, tmp_path):
    result = canest("replay", files["log"], "--config", CONFIG, "--csv", tmp_path / "est.csv")
    assert result.returncode == 0
    assert result.stderr == ""  # no bar text, not even a carriage return
    assert result.stdout.startswith("frames=")


def on_terminal(*args) -> str:
    """What a canest command writes to a terminal of 120 columns as its stderr (stdout is a pipe)."""
    import fcntl
    import os
    import pty
    import struct
    import termios

    main_fd, terminal = pty.openpty()
    fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 120, 0, 0))
    process = subprocess.Popen([*CANEST, *map(str, args)], stdout=subprocess.PIPE, stderr=terminal, cwd=ROOT)
    os.close(terminal)
    shown = b""
    while True:
        try:
            chunk = os.read(main_fd, 4096)
        except OSError:  # the terminal's last writer has closed it
            break
        if not chunk:
            break
        shown += chunk
    os.close(main_fd)
    process.stdout.read()
    assert process.wait(60) == 0
    return shown.decode()


def test_replay_progress_bar_on_a_terminal_counts_log_seconds_and_frames_and_stays(files, tmp_path):
    shown = on_terminal("replay", files["log"], "--config", CONFIG, "--csv", tmp_path / "est.csv")
    last = [part.strip() for part in re.split(r"[\r\n]", shown) if part.strip()][-1]  # what stays on screen
    frames = files["summary"]["frames"]
    seconds, total = map(float, re.search(r"\| ([\d.]+)/([\d.]+) \[", last).groups())
    assert last.startswith("replay drive.log, log seconds: 100%|") and seconds == total == pytest.approx(6, abs=0.02)
    assert last.endswith(f"{frames} frames]"), last


def test_replay_reads_other_formats_from_stdin_with_format(files, tmp_path):
    asc = tmp_path / "drive.asc"
    assert canest("simulate", "--maneuver", "sine", "--duration", "6", "--out", asc, "--truth",
                  tmp_path / "t.csv").returncode == 0
    with open(asc) as log:
        result = canest("replay", "-", "--format", "asc", "--config", CONFIG, "--json", stdin=log)
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["decoded"] == files["summary"]["decoded"]


def test_two_outputs_on_stdout_are_refused(files):
    result = canest("replay", files["log"], "--out", "-", "--csv", "-")
    assert result.returncode == 2
    assert result.stderr.splitlines() == ["canest: error: --out and --csv all name - (standard output); only one "
                                          "output can go there: name files for the others"]


def test_replay_summary_as_json_says_what_the_text_says(files):
    text = canest("replay", files["log"], "--config", CONFIG).stdout.strip()
    summary = files["summary"]
    assert summary["frames"] == summary["decoded"] == files["log"].read_text().count("\n")
    assert text == " ".join([f"frames={summary['frames']}", *(f"{k}={v}" for k, v in sorted(summary.items())
                                                               if k != "frames" and v)])


def shifted(source, target, seconds):
    """The estimate CSV with ``seconds`` added to every time (a live CSV's epoch clock)."""
    rows = source.read_text().splitlines()
    out = [rows[0]] + [f"{float(r.split(',', 1)[0]) + seconds:.6f},{r.split(',', 1)[1]}" for r in rows[1:]]
    target.write_text("\n".join(out) + "\n")


def test_evaluate_of_a_csv_on_another_clock_fails_and_align_puts_it_right(files, tmp_path):
    epoch = 1_712_345_678.0
    live = tmp_path / "live.csv"
    shifted(files["est"], live, epoch)
    unaligned = canest("evaluate", live, files["truth"], "--json")
    assert unaligned.returncode == 65
    assert unaligned.stderr.startswith(f"canest: error: {live}: no tick could be scored against")
    assert "--align first" in unaligned.stderr and len(unaligned.stderr.splitlines()) == 1
    by_offset = json.loads(canest("evaluate", live, files["truth"], "--json", "--align", "offset", epoch).stdout)
    # The epoch clock's times are written to the microsecond: the truth is interpolated up to 1 us off, which moves
    # a score by a few parts per million (a tick's misalignment would move it by percent)
    for state, score in files["scores"].items():
        numbers = {key: value for key, value in score.items() if key != "unit"}
        assert {key: by_offset[state][key] for key in numbers} == pytest.approx(numbers, rel=1e-4, abs=1e-9), state
    first = canest("evaluate", live, files["truth"], "--json", "--align", "first")
    assert first.returncode == 0
    assert json.loads(first.stdout)["vx"]["samples"] > 400


def test_evaluate_align_needs_a_mode(files):
    result = canest("evaluate", files["est"], files["truth"], "--align", "offset", "soon")
    assert result.returncode == 2
    assert "--align offset soon: expected first, none or offset SECONDS" in result.stderr


def test_evaluate_json_has_the_documented_keys(files):
    keys = {"unit", "rmse", "mae", "max_error", "samples", "valid", "cov1", "cov2", "cov3", "nees", "vbw",
            "wrong_sign"}
    assert set(files["scores"]) == {"vx", "vy", "beta", "yaw_rate"}
    assert all(set(score) == keys for score in files["scores"].values())
    assert np.isfinite(files["scores"]["beta"]["rmse"])


def test_replay_speed_is_renamed_rate(files):
    old = canest("replay", files["log"], "--speed", "2")
    assert old.returncode == 2
    assert "--speed is the playback speed of --realtime" in old.stderr
    new = canest("replay", files["log"], "--rate", "0", "--realtime", "-i", "virtual")
    assert new.returncode == 2 and "--rate: a playback speed factor above 0" in new.stderr
    start = time.monotonic()
    played = canest("replay", files["log"], "--realtime", "--speed", "50", "-i", "virtual")
    assert played.returncode == 0 and time.monotonic() - start < 30
    assert "canest: warning: replay --speed is deprecated (simulate's --speed is km/h); type --rate 50 now" \
        in played.stderr


def repeated(log, times: int, first_copy: int = 0) -> bytes:
    """A candump -L log played ``times`` over, each copy's timestamps after the last one's: a long drive, fast.
    ``first_copy``: the copies numbered from there (their timestamps after as many copies before)."""
    lines = log.read_bytes().splitlines()
    length = float(lines[-1].split(b")")[0].lstrip(b"(")) + 0.001
    out = []
    for copy in range(first_copy, first_copy + times):
        for line in lines:
            stamp, rest = line.split(b")", 1)
            out.append(b"(%.6f)%s\n" % (float(stamp.lstrip(b"(")) + copy * length, rest))
    return b"".join(out)


def peak_memory(pid: int):
    """The process's peak resident memory since its exec (VmHWM, KiB), or None once it is gone.

    Not getrusage's ru_maxrss: that keeps the peak from before the exec too, the forking parent's own memory."""
    try:
        with open(f"/proc/{pid}/status") as status:
            return next(int(line.split()[1]) for line in status if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return None


def stream(log, times: int, chunk: int = 1 << 16) -> tuple:
    """``canest replay - --csv -`` fed ``log`` ``times`` over (see :func:`repeated`) in chunks by a writer thread:
    (CSV rows, whether the first row came out while the input was still open, the process's peak resident memory
    in KiB, as last seen while it wrote rows)."""

    process = subprocess.Popen([*CANEST, "replay", "-", "--config", CONFIG, "--csv", "-"], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, cwd=ROOT)
    first_row, input_open_at_first_row = threading.Event(), []

    def write():
        for copy in range(times):  # one copy at a time: the parent's memory stays the same for any length
            text = repeated(log, 1, first_copy=copy)
            for start in range(0, len(text), chunk):
                process.stdin.write(text[start:start + chunk])
                process.stdin.flush()
                if copy == start == 0:  # the rest only once a row of the first chunk is out
                    first_row.wait(120)
                    input_open_at_first_row.append(first_row.is_set())
        process.stdin.close()

    writer = threading.Thread(target=write)
    writer.start()
    rows, peak = 0, None
    for line in process.stdout:
        rows += 1
        if rows == 2:  # the header, then a row
            first_row.set()
        if rows % 100 == 0:
            peak = peak_memory(process.pid) or peak
    writer.join(300)
    assert process.wait(60) == 0 and peak is not None
    return rows - 1, input_open_at_first_row == [True], peak


def test_replay_of_stdin_streams_in_bounded_memory(files):
    """18 s and 198 s of drive (the 6 s drive 3 and 33 times) through `canest replay - --csv -`: rows come out while
    the input is still being written, and the peak memory does not grow with the log."""
    ticks_short, streamed_short, peak_short = stream(files["log"], 3)
    ticks_long, streamed_long, peak_long = stream(files["log"], 33)
    assert streamed_short and streamed_long
    assert 10 < ticks_long / ticks_short < 12
    print(f"peak RSS: {peak_short} KiB for {ticks_short} ticks, {peak_long} KiB for {ticks_long} ticks")
    assert peak_long / peak_short < 1.5
    assert peak_long - peak_short < 16 * 1024  # 18 000 more ticks: under 1 KiB each (a kept row is about that)
