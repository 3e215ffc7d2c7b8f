"""Fleet replay on Dask: a local cluster, and a cluster of separate processes losing a worker.

Also: logs of one stem, truth files by either name, inputs changed between runs, a failing task,
and SIGINT / SIGTERM during a batch.
"""
import copy
import csv
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
import pytest

from canest.apps.batch import run_batch
from canest.apps.batch_plan import (ESTIMATES, FLEET_SUMMARY, SUMMARY, Task, complete, find_logs, fingerprint,
                                    input_root, plan)
from canest.apps.evaluate import read_table, score
from canest.apps.fleet_report import COLUMNS, rmse_key
from canest.apps.replay import replay
from canest.errors import CanestError
from canest.sim.simulate import simulate
from tests.conftest import write_log_and_truth

LOGS = 24


@pytest.fixture(scope="module")
def fleet(config, tmp_path_factory):
    """24 small drives in two folders (4 distinct simulations, copied), truth beside each, one corrupt log."""
    root = tmp_path_factory.mktemp("fleet")
    sources = []
    for seed, maneuver in enumerate(("dlc", "sine", "step", "slalom")):
        sim = simulate(config, maneuver, 60.0, 0.85, seed=seed, duration=3.0)
        log, truth = root / f"src{seed}.log", root / f"src{seed}.truth.csv"
        write_log_and_truth(sim, log, truth)
        sources.append((log, truth))
    for i in range(LOGS):
        folder = root / "drives" / ("north" if i % 2 else "south")
        folder.mkdir(parents=True, exist_ok=True)
        log, truth = sources[i % 4]
        shutil.copy(log, folder / f"drive{i:02d}.log")
        shutil.copy(truth, folder / f"drive{i:02d}.truth.csv")
    (root / "drives" / "south" / "broken.log").write_text("this is not a candump line\nnor is this\n")  # no frame
    return root / "drives"


def test_local_cluster_matches_sequential_replay_and_resumes(config, fleet, tmp_path):
    out = tmp_path / "results"
    messages = []
    rows = run_batch(config, [str(fleet / "**" / "*.log")], out, ["ckf"], workers=2, progress=False,
                     report=messages.append)
    assert len(rows) == LOGS + 1
    failed = [r for r in rows if r["status"] != "ok"]
    assert len(failed) == 1 and failed[0]["log"].endswith("broken.log")
    assert "broken.log: no frame could be read: skipped 2 line(s) the reader could not parse (line 1, 2)" \
        in failed[0]["error"]
    assert any("dashboard http" in m for m in messages)
    for row in rows:
        if row["status"] != "ok":
            continue
        log = Path(row["log"])
        result = read_table(out / log.parent.name / log.name / "ckf" / ESTIMATES)
        expected = replayed(config, log, tmp_path)
        np.testing.assert_array_equal(result["t"], expected["t"])
        np.testing.assert_array_equal(result["yaw_rate"], expected["yaw_rate"])
        assert row["beta_rmse_deg"] < 1.5 and 0.75 < row["valid_share"] <= 1.0  # 3 s: vx initializing ~0.5 s
    assert (out / "fleet_summary.csv").read_text().count("\n") == LOGS + 2
    assert not list(out.rglob("*.tmp")), "the broken log's task left its partial CSV behind"
    assert not list((out / "south" / "broken.log").rglob("*.*")), "a failed task leaves nothing in its folder"

    victim = out / "north" / "drive01.log" / "ckf" / SUMMARY
    summary = json.loads(victim.read_text())
    summary["csv_bytes"] += 1  # as if the CSV had been cut short
    victim.write_text(json.dumps(summary))
    messages.clear()
    run_batch(config, [str(fleet / "**" / "*.log")], out, ["ckf"], workers=2, progress=False, report=messages.append)
    assert messages[0].startswith(f"{LOGS + 1} tasks (25 logs x 1 filters): {LOGS - 1} already complete, 2 to run")


def test_batch_json_is_the_summary_and_redirected_output_has_no_progress_bar(fleet, tmp_path):
    """Two logs with truth, one without, a broken one: --json on stdout, every message on stderr, no bar text."""
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("drive00.log", "drive00.truth.csv", "drive01.log", "drive01.truth.csv", "drive02.log"):
        shutil.copy(fleet / "south" / name if name[6] in "02" else fleet / "north" / name, logs / name)
    (logs / "broken.log").write_text("not a candump line\n")
    out = tmp_path / "results"
    result = subprocess.run([sys.executable, "-m", "canest", "batch", str(logs / "*.log"), "--out", str(out),
                             "--workers", "2", "--json"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 1, result.stderr  # the broken log's task failed
    found = json.loads(result.stdout)
    assert set(found) == {"tasks", "totals", "summary_csv", "plot", "stopped_by"}
    assert found["summary_csv"] == str(out / FLEET_SUMMARY) and found["plot"] is found["stopped_by"] is None
    tasks = {Path(task["log"]).name: task for task in found["tasks"]}
    assert list(tasks) == ["broken.log", "drive00.log", "drive01.log", "drive02.log"]
    assert all(tuple(task) == COLUMNS for task in tasks.values())
    for name in ("drive00.log", "drive01.log", "drive02.log"):
        task = tasks[name]
        assert task["status"] == "ok" and task["error"] is None and task["result"] == str(out / name / "ckf")
        stored = json.loads((out / name / "ckf" / SUMMARY).read_text())
        assert {k: task[k] for k in ("frames", "decoded", "ticks", "duration_s", "valid_share")} == \
            {k: stored[k] for k in ("frames", "decoded", "ticks", "duration_s", "valid_share")}
        has_truth = name != "drive02.log"
        for state in ("vx", "yaw_rate", "beta"):
            assert (task[rmse_key(state)] == stored[rmse_key(state)]) if has_truth else task[rmse_key(state)] is None
    assert tasks["broken.log"]["status"] == "failed" and "no frame could be read" in tasks["broken.log"]["error"]
    totals = found["totals"]
    assert {k: totals[k] for k in ("tasks", "ok", "failed", "stopped")} == {"tasks": 4, "ok": 3, "failed": 1,
                                                                           "stopped": 0}
    assert totals["frames"] == sum(tasks[n]["frames"] for n in ("drive00.log", "drive01.log", "drive02.log"))
    assert totals["drive_hours"] == pytest.approx(sum(t["duration_s"] or 0 for t in tasks.values()) / 3600)
    assert totals["tasks_per_min"] == pytest.approx(60 * 4 / totals["seconds"])
    # the messages and the fleet table went to stderr, and no progress bar to either stream
    assert "beta RMSE [deg] median / p95" in result.stderr and "4 tasks in" in result.stderr
    for text in (result.stdout, result.stderr):
        assert "\r" not in text and "task/s" not in text and "%|" not in text
    with open(out / FLEET_SUMMARY) as handle:
        assert tuple(csv.DictReader(handle).fieldnames) == COLUMNS
    assert {"vx_rmse_m_s", "yaw_rate_rmse_deg_s", "beta_rmse_deg"} <= set(COLUMNS)


def test_fleet_plot_and_table_name_the_units_of_the_errors():
    from canest.apps.fleet_report import errors_figure, fleet_table
    rows = [{"log": f"{i}.log", "filter": name, "status": "ok", "duration_s": 60.0, "valid_share": 0.9,
             "vx_rmse_m_s": 0.1 * i, "yaw_rate_rmse_deg_s": 0.2 * i, "beta_rmse_deg": 0.3 * i}
            for i in range(1, 4) for name in ("ckf", "ekf")]
    axes = errors_figure(rows).axes
    assert [ax.get_ylabel() for ax in axes] == ["vx RMSE [m/s]", "yaw_rate RMSE [deg/s]", "beta RMSE [deg]"]
    assert all(ax.get_title() for ax in axes)
    header, ckf, _ = fleet_table(rows).splitlines()
    assert "vx RMSE [m/s]" in header and "yaw_rate RMSE [deg/s]" in header and "beta RMSE [deg]" in header
    assert ckf.endswith("0.6000 / 0.8700") and len(ckf) == len(header)  # beta median / p95 under its header


def replayed(config, log, folder) -> dict:
    """The estimates of a sequential replay of ``log`` (the batch must give exactly these)."""
    csv_path = folder / "sequential.csv"
    replay(config, log, out_csv=csv_path, progress=False)
    return read_table(csv_path)


def as_blf(source: Path, target: Path) -> Path:
    with can.LogReader(str(source)) as reader, can.Logger(str(target)) as writer:
        for msg in reader:
            writer.on_message_received(msg)
    return target


def test_logs_of_one_stem_each_get_their_results_and_truth(config, fleet, tmp_path):
    """day1/a.log and day1/a.blf: two results; a truth named after the whole log name beats the stem's."""
    src = fleet.parent
    root = tmp_path / "logs"
    (root / "day1").mkdir(parents=True)
    (root / "day2").mkdir()
    shutil.copy(src / "src0.log", root / "day1" / "a.log")
    as_blf(src / "src0.log", root / "day1" / "a.blf")
    shutil.copy(src / "src0.truth.csv", root / "day1" / "a.truth.csv")
    shutil.copy(src / "src1.log", root / "day2" / "b.log")
    as_blf(src / "src1.log", root / "day2" / "b.blf")
    shutil.copy(src / "src1.truth.csv", root / "day2" / "b.log.truth.csv")
    shutil.copy(src / "src0.truth.csv", root / "day2" / "b.truth.csv")  # another drive's: b.blf is scored on it
    truth_of = {"a.log": "a.truth.csv", "a.blf": "a.truth.csv", "b.log": "b.log.truth.csv", "b.blf": "b.truth.csv"}
    out = tmp_path / "results"
    messages = []
    rows = run_batch(config, [str(root / "**" / "*")], out, ["ckf"], workers=2, progress=False,
                     report=messages.append)
    assert [(Path(r["log"]).relative_to(root).as_posix(), r["status"]) for r in rows] == [
        ("day1/a.blf", "ok"), ("day1/a.log", "ok"), ("day2/b.blf", "ok"), ("day2/b.log", "ok")]
    for row in rows:
        log = Path(row["log"])
        folder = out / log.relative_to(root) / "ckf"
        expected = replayed(config, log, tmp_path)
        np.testing.assert_array_equal(read_table(folder / ESTIMATES)["yaw_rate"], expected["yaw_rate"])
        truth = log.parent / truth_of[log.name]
        assert json.loads((folder / SUMMARY).read_text())["inputs"]["truth"]["path"] == str(truth)
        scores = {s.state: s.rmse for s in score(expected, read_table(truth), ["vx", "yaw_rate", "beta"], skip=0.5)}
        assert {state: row[rmse_key(state)] for state in scores} == scores
    assert rows[2]["yaw_rate_rmse_deg_s"] > 3 * rows[3]["yaw_rate_rmse_deg_s"], "b.blf is scored on the wrong drive's truth"
    with open(out / FLEET_SUMMARY) as handle:
        assert sorted(r["log"] for r in csv.DictReader(handle)) == sorted(r["log"] for r in rows)

    messages.clear()
    run_batch(config, [str(root / "**" / "*")], out, ["ckf"], workers=2, progress=False, report=messages.append)
    assert messages == ["4 tasks (4 logs x 1 filters): 4 already complete, 0 to run"]


def flip_last_data_digit(log: Path) -> None:
    """Change one hex digit of the last frame's data; size and modification time stay the same."""
    stat = os.stat(log)
    data = bytearray(log.read_bytes())
    where = data.rindex(b"#") + 2
    data[where] = ord("0") if data[where] != ord("0") else ord("1")
    log.write_bytes(bytes(data))
    os.utime(log, ns=(stat.st_atime_ns, stat.st_mtime_ns))


def test_changed_inputs_are_redone_and_failed_tasks_leave_nothing(config, fleet, tmp_path):
    src = fleet.parent
    root = tmp_path / "logs"
    root.mkdir()
    x, y, torn = root / "x.log", root / "y.log", root / "torn.log"
    shutil.copy(src / "src0.log", x)
    shutil.copy(src / "src1.log", y)
    shutil.copy(src / "src1.truth.csv", root / "y.truth.csv")
    torn.write_bytes((src / "src2.log").read_bytes()[:-12])  # a logger killed mid-line
    try:  # the batch reports a torn log exactly as a replay of it does
        torn_frames, torn_error = replay(config, torn, out_csv=tmp_path / "torn.csv", progress=False), None
    except CanestError as exc:
        torn_frames, torn_error = None, str(exc)
    out = tmp_path / "results"

    def batch():
        messages = []
        rows = run_batch(config, [str(root / "*.log")], out, ["ckf"], workers=2, progress=False,
                         report=messages.append)
        assert not list(out.rglob("*.tmp"))
        return {Path(r["log"]).name: r for r in rows}, messages

    rows, _ = batch()
    assert rows["x.log"]["status"] == rows["y.log"]["status"] == "ok" and "beta_rmse_deg" in rows["y.log"]
    if torn_error is None:
        assert rows["torn.log"]["status"] == "ok" and rows["torn.log"]["frames"] == torn_frames["frames"]
    else:
        assert rows["torn.log"]["status"] == "failed" and torn_error in rows["torn.log"]["error"]
        assert not list((out / "torn.log").rglob("*.*"))

    flip_last_data_digit(x)  # same size, same mtime: only the content hash tells
    (root / "y.truth.csv").write_text("garbage\n")
    rows, messages = batch()
    redo = 2 if torn_error is None else 3
    assert messages[0] == f"3 tasks (3 logs x 1 filters): {3 - redo} already complete, {redo} to run"
    expected = replayed(config, x, tmp_path)
    np.testing.assert_array_equal(read_table(out / "x.log" / "ckf" / ESTIMATES)["yaw_rate"], expected["yaw_rate"])
    frames = replay(config, x, progress=False)
    assert rows["x.log"]["rejected"] == {k: v for k, v in frames.items() if k.startswith("rejected_") and v} != {}
    assert rows["y.log"]["status"] == "failed"
    assert rows["y.log"]["error"].startswith(f"TableError: {root / 'y.truth.csv'}: no 't' column")
    assert not list((out / "y.log").rglob("*.*")), "the stale result of y.log is gone, no new one is there"

    task = Task(x, "ckf", out / "x.log" / "ckf")
    assert complete(task, fingerprint(config)) is not None
    stat = os.stat(x)
    os.utime(x, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))  # touched: redone too
    assert complete(task, fingerprint(config)) is None


def test_filter_sweep_writes_one_result_per_filter(config, fleet, tmp_path):
    rows = run_batch(config, [str(fleet / "north" / "drive0[13].log")], tmp_path, ["ckf", "ekf"], workers=1,
                     progress=False, report=lambda m: None)
    assert sorted((Path(r["log"]).name, r["filter"]) for r in rows) == [
        ("drive01.log", "ckf"), ("drive01.log", "ekf"), ("drive03.log", "ckf"), ("drive03.log", "ekf")]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_separate_process_cluster_survives_a_killed_worker(fleet, tmp_path):
    dask = str(Path(sys.executable).with_name("dask"))
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers = [subprocess.Popen([dask, "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard",
                                 "--name", f"w{i}"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
               for i in range(2)]
    out = tmp_path / "results"
    try:
        time.sleep(3.0)
        batch = subprocess.Popen([sys.executable, "-m", "canest", "batch", str(fleet / "**" / "*.log"), "--out",
                                  str(out), "--scheduler", address, "-q", "--filters", "ckf,ekf"],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while len(list(out.glob(f"**/{SUMMARY}"))) < 6 and time.monotonic() < deadline:
            time.sleep(0.05)
        workers[0].send_signal(signal.SIGKILL)  # mid-run: about a tenth of the tasks done
        stdout, stderr = batch.communicate(timeout=300)
    finally:
        for process in (*workers, scheduler):
            process.kill()
            process.wait()
    assert batch.returncode == 1, stderr  # 1: the broken log failed, as it should
    assert len(list(out.glob(f"**/{SUMMARY}"))) == 2 * LOGS, "every readable log finished despite the lost worker"
    table = {line.split()[0]: line.split() for line in stdout.splitlines() if line.startswith(("ckf ", "ekf "))}
    assert {name: (int(row[1]), int(row[2])) for name, row in table.items()} == {"ckf": (LOGS, 1), "ekf": (LOGS, 1)}


@pytest.fixture(scope="module")
def long_drives(fleet, tmp_path_factory):
    """8 logs of a 21 s drive (a 3 s one seven times over, timestamps shifted): tasks that take a while."""
    root = tmp_path_factory.mktemp("long")
    messages = list(can.LogReader(str(fleet.parent / "src3.log")))
    span = messages[-1].timestamp - messages[0].timestamp + 0.01
    with can.Logger(str(root / "drive0.log")) as writer:
        for lap in range(7):
            for msg in messages:
                shifted = copy.copy(msg)
                shifted.timestamp = msg.timestamp + lap * span
                writer.on_message_received(shifted)
    for i in range(1, 8):
        shutil.copy(root / "drive0.log", root / f"drive{i}.log")
    return root


def start_batch(pattern, out, stdout):
    """``canest batch`` in its own session (as a shell job: a Ctrl-C reaches it and its workers)."""
    return subprocess.Popen([sys.executable, "-m", "canest", "batch", pattern, "--out", str(out), "-q",
                             "--workers", "2"], stdout=stdout, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})


def wait_for(condition, what, seconds=120.0):
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, f"no {what} after {seconds} s"
        time.sleep(0.02)


def stopped_batch_is_consistent(config, root, out) -> list:
    """Rows of the fleet summary; each ok one complete on disk, no other result, no temporary file."""
    with open(out / FLEET_SUMMARY) as handle:
        rows = list(csv.DictReader(handle))
    tasks = plan(find_logs([str(root / "*.log")], out), ["ckf"], input_root([str(root / "*.log")]), out)
    assert sorted(r["log"] for r in rows) == sorted(str(t.log) for t in tasks), "every task has its row"
    assert not list(out.rglob("*.tmp"))
    done = {str(t.log) for t in tasks if complete(t, fingerprint(config))}  # what a rerun skips
    assert done == {r["log"] for r in rows if r["status"] == "ok"}
    for task in tasks:
        if str(task.log) not in done:
            assert not (task.out / SUMMARY).exists() and not (task.out / ESTIMATES).exists()
    return rows


def test_ctrl_c_stops_in_order_and_running_tasks_finish(config, long_drives, tmp_path):
    out = tmp_path / "results"
    with open(tmp_path / "stdout.txt", "w") as stdout:
        batch = start_batch(str(long_drives / "*.log"), out, stdout)
        wait_for(lambda: list(out.glob(f"*/ckf/{SUMMARY}")), "first result")
        os.killpg(batch.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole process group
        _, stderr = batch.communicate(timeout=120)
    printed = (tmp_path / "stdout.txt").read_text()
    assert batch.returncode == 0, printed + stderr
    assert "SIGINT: " in printed and "stopped by SIGINT: " in printed
    rows = stopped_batch_is_consistent(config, long_drives, out)
    statuses = [r["status"] for r in rows]
    assert statuses.count("ok") >= 2, "the tasks running at the Ctrl-C finished: the workers ignored it"
    assert statuses.count("stopped") >= 1 and statuses.count("ok") + statuses.count("stopped") == len(rows)
    assert {r["error"] for r in rows if r["status"] == "stopped"} == {"not started (SIGINT)"}
    assert f"{statuses.count('stopped')} of {len(rows)} tasks not done" in printed


def test_second_sigterm_cancels_running_tasks(config, long_drives, tmp_path):
    out = tmp_path / "results"
    stdout_path = tmp_path / "stdout.txt"
    with open(stdout_path, "w") as stdout:
        batch = start_batch(str(long_drives / "*.log"), out, stdout)
        wait_for(lambda: list(out.glob(f"*/ckf/{SUMMARY}")), "first result")
        batch.send_signal(signal.SIGTERM)
        wait_for(lambda: "tasks withdrawn" in stdout_path.read_text(), "withdrawal")
        batch.send_signal(signal.SIGTERM)
        _, stderr = batch.communicate(timeout=120)
    printed = stdout_path.read_text()
    assert batch.returncode == 0, printed + stderr
    rows = stopped_batch_is_consistent(config, long_drives, out)
    assert "cancelled (SIGTERM)" in {r["error"] for r in rows}
