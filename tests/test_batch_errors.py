"""One line, no traceback, before any work: a missing dask or matplotlib, an unreachable scheduler.

A missing package is made missing for one real ``canest`` process only: ``sys.modules[name] = None``
makes every import of it fail exactly as an uninstalled one does (ModuleNotFoundError).
"""
import socket
import subprocess
import sys
import time

import pytest

from canest.errors import ClusterError, DependencyError
from canest.sim.simulate import simulate
from tests.conftest import write_log_and_truth

LAUNCH = "import sys; sys.modules.update(dict.fromkeys({missing!r})); from canest.cli import main; main()"


def canest(*args, missing=()):
    command = [sys.executable, "-c", LAUNCH.format(missing=list(missing)), *map(str, args)]
    return subprocess.run(command, capture_output=True, text=True, timeout=120)


def one_line_error(result, kind) -> str:
    """The one line of a ``kind`` of error, checked to be alone and to end the process with its status."""
    assert result.returncode == getattr(kind, "exit_status", 2), result.stdout + result.stderr
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("canest: error: "), result.stderr
    return lines[0]


@pytest.fixture(scope="module")
def drive(config, tmp_path_factory):
    folder = tmp_path_factory.mktemp("drive")
    write_log_and_truth(simulate(config, "sine", 60.0, 0.85, seed=2, duration=1.0), folder / "a.log",
                        folder / "a.truth.csv")
    return folder


def test_batch_without_dask(drive, tmp_path):
    result = canest("batch", drive / "*.log", "--out", tmp_path / "out", missing=["dask", "distributed"])
    line = one_line_error(result, DependencyError)
    assert "canest batch needs the Python package 'dask.distributed'" in line and "pip install 'canest[fleet]'" in line
    assert not (tmp_path / "out").exists()


def test_batch_plot_without_matplotlib_fails_before_the_batch(drive, tmp_path):
    result = canest("batch", drive / "*.log", "--out", tmp_path / "out", "--plot", tmp_path / "err.png",
                    missing=["matplotlib"])
    line = one_line_error(result, DependencyError)
    assert "--plot needs the Python package 'matplotlib'" in line and "pip install 'canest[plot]'" in line
    assert not (tmp_path / "out").exists()


def test_compare_plot_without_matplotlib_fails_before_the_replays(drive, tmp_path):
    result = canest("compare", drive / "a.log", drive / "a.truth.csv", "--filters", "ckf", "--plot",
                    tmp_path / "cmp.png", missing=["matplotlib"])
    line = one_line_error(result, DependencyError)
    assert "--plot needs the Python package 'matplotlib'" in line and "pip install 'canest[plot]'" in line
    assert result.stdout == ""  # no filter ran


def test_compare_without_plot_needs_no_matplotlib(drive):
    result = canest("compare", drive / "a.log", drive / "a.truth.csv", "--filters", "ckf", missing=["matplotlib"])
    assert result.returncode == 0, result.stderr
    assert "ckf: done" in result.stdout


def test_unreachable_scheduler_fails_fast_in_one_line(drive, tmp_path):
    with socket.socket() as sock:  # a port nobody listens on: bound, never listening
        sock.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{sock.getsockname()[1]}"
        started = time.monotonic()
        result = canest("batch", drive / "*.log", "--out", tmp_path / "out", "--scheduler", address,
                        "--connect-timeout", 2)
        elapsed = time.monotonic() - started
    line = one_line_error(result, ClusterError)
    assert line.startswith(f"canest: error: --scheduler {address}: cannot connect to a Dask scheduler (")
    assert line.endswith("--connect-timeout (now 2 s)")
    assert not (tmp_path / "out").exists()
    assert elapsed < 30  # 2 s of trying plus starting Python and importing dask, on a busy machine


def test_malformed_scheduler_address_is_one_line(drive, tmp_path):
    line = one_line_error(canest("batch", drive / "*.log", "--out", tmp_path / "out", "--scheduler", "nowhere"),
                          ClusterError)
    assert "--scheduler nowhere" in line and "missing port number" in line
