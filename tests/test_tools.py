"""Smoke runs of the benchmark and evaluation tools, so they do not rot."""
import subprocess
import sys

from canest.filters import FILTERS
from tests.conftest import ROOT


def run_tool(*args):
    result = subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_filter_benchmark_prints_every_filter():
    out = run_tool(ROOT / "tools" / "bench" / "filters.py", "--steps", "30")
    rows = {line.split()[0]: line.split() for line in out.splitlines()[1:] if line and line.split()[0] in FILTERS}
    assert set(rows) == set(FILTERS)
    assert all(float(row[1]) > 0 for row in rows.values())


def test_fleet_benchmark_smoke_run():
    out = run_tool(ROOT / "tools" / "bench" / "fleet.py", "--logs", "2", "--seconds", "2", "--workers", "1")
    assert "drive-h/min" in out and out.strip().splitlines()[-1].split()[0] == "1"


def test_replay_benchmark_smoke_run():
    out = run_tool(ROOT / "tools" / "bench" / "replay.py", "--minutes", "0.1", "--hours", "0.005", "--filters", "ckf")
    lines = out.strip().splitlines()
    assert lines[2].startswith("ckf") and float(lines[2].split()[4]) > 1.0  # faster than real time
    assert lines[-1].startswith("memory over")


def test_live_benchmark_smoke_run_on_virtual_buses():
    out = run_tool(ROOT / "tools" / "bench" / "live.py", "--bus", "virtual", "--seconds", "1", "--multipliers", "1")
    last = out.strip().splitlines()[-1].split()
    assert last[0] == "1x" and int(last[3]) == 0  # nothing dropped at nominal rate


def test_online_calibration_tool_prints_finite_rmse(tmp_path):
    """``tools/calibration.py --online`` scores the replays after 60 s: every row a number."""
    out = run_tool(ROOT / "tools" / "calibration.py", "--online", "--bank", "0", "--duration", "61",
                   "--workdir", tmp_path)
    rows = {" ".join(line.split()[:-3]): line.split()[-3:] for line in out.splitlines()
            if " ".join(line.split()[:-3]) in ("online calibration", "without", "true parameters")}
    assert len(rows) == 3, out
    assert all(0.0 < float(value) < 5.0 for values in rows.values() for value in values), rows


def test_the_calibration_tools_cached_drives_keep_their_own_truth(tmp_path):
    """Its cache once named the truth without the drive's duration: a 120 s log was scored against the truth of
    a later 60 s run, and every RMSE read nan."""
    sys.path.insert(0, str(ROOT / "tools"))
    import calibration
    (log60, truth60), (log120, truth120) = (calibration.drive_files(tmp_path, "online-s3-bank0", d) for d in (60, 120))
    assert len({log60, truth60, log120, truth120}) == 4
    assert truth60.stem == log60.stem and truth120.stem == log120.stem
