"""Fleet replay on Dask: a local cluster, and a cluster of separate processes losing a worker."""
import json
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from canest.apps.batch import ESTIMATES, SUMMARY, run_batch
from canest.apps.evaluate import read_table
from canest.apps.replay import replay
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
    (root / "drives" / "south" / "broken.log").write_text("(1.0) vcan0 130#00\nthis is not a candump line\n")
    return root / "drives"


def test_local_cluster_matches_sequential_replay_and_resumes(config, fleet, tmp_path):
    out = tmp_path / "results"
    messages = []
    rows = run_batch(config, [str(fleet / "**" / "*.log")], out, ["ckf"], workers=2, progress=False,
                     report=messages.append)
    assert len(rows) == LOGS + 1
    failed = [r for r in rows if r["status"] != "ok"]
    assert len(failed) == 1 and failed[0]["log"].endswith("broken.log")
    assert "broken.log: frame 2 is unreadable" in failed[0]["error"]
    assert any("dashboard http" in m for m in messages)
    for row in rows:
        if row["status"] != "ok":
            continue
        log = Path(row["log"])
        result = read_table(out / log.parent.name / log.name / "ckf" / ESTIMATES)
        sequential = tmp_path / "sequential.csv"
        replay(config, log, out_csv=sequential, progress=False)
        expected = read_table(sequential)
        np.testing.assert_array_equal(result["t"], expected["t"])
        np.testing.assert_array_equal(result["yaw_rate"], expected["yaw_rate"])
        assert row["rmse_beta"] < 1.5 and 0.9 < row["valid_share"] <= 1.0
    assert (out / "fleet_summary.csv").read_text().count("\n") == LOGS + 2

    victim = out / "north" / "drive01.log" / "ckf" / SUMMARY
    summary = json.loads(victim.read_text())
    summary["csv_bytes"] += 1  # as if the CSV had been cut short
    victim.write_text(json.dumps(summary))
    messages.clear()
    run_batch(config, [str(fleet / "**" / "*.log")], out, ["ckf"], workers=2, progress=False, report=messages.append)
    assert messages[0].startswith(f"{LOGS + 1} tasks (25 logs x 1 filters): {LOGS - 1} already complete, 2 to run")


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
