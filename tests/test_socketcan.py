"""End to end on real SocketCAN virtual buses (vcan0 -> daemon -> vcan1).

Run on a machine with vcan0/vcan1, or on any Linux host through the UML guest:
``tools/vcan-guest -- python -m pytest -m socketcan``.
"""
import re
import signal
import subprocess
import sys
import time

import can
import cantools
import numpy as np
import pytest

from canest.codec import integrity
from canest.apps.evaluate import read_table, score
from canest.apps.replay import replay
from tests import live
from tests.conftest import CONFIG, ROOT
from tests.live import Daemon

pytestmark = pytest.mark.socketcan
OUTPUT_DB = cantools.database.load_file(str(ROOT / "dbc" / "canest_estimates.dbc"))
YAW_SIDESLIP = OUTPUT_DB.get_message_by_name("CE_YawSideslip")


def assert_in_order(sent, ticks, tolerance):
    """Every sent value is a tick's value, in tick order (superseded ticks are skipped, none reordered)."""
    i = 0
    for value in sent:
        while i < len(ticks) and abs(ticks[i] - value) > tolerance:
            i += 1
        assert i < len(ticks), f"sent value {value} is not a tick value in order"
        i += 1


def yaw_frames(frames):
    return [m for m in frames if m.arbitration_id == YAW_SIDESLIP.frame_id]


def check_integrity(frames):
    counters = [YAW_SIDESLIP.decode(m.data)["CE_YawSideslip_Counter"] for m in frames]
    assert all(integrity.checksum_ok(m.arbitration_id, m.data, 7) for m in frames)
    assert all((b - a) % 16 == 1 for a, b in zip(counters, counters[1:])), "a frame was lost on vcan1"


def live_accuracy(live_csv, truth_csv, first_frame_time):
    live = read_table(live_csv)
    live["t"] = live["t"] - live["t"][0] + first_frame_time  # ticks are anchored at the first frame
    return {s.state: s.rmse for s in score(live, read_table(truth_csv), skip=0.5)}, live


def compare_with_offline(live, log):
    offline = []
    replay(read_config(), log, progress=False, on_estimate=offline.append)
    n = min(len(offline), len(live["t"]))
    offline_yaw = np.array([e.values["yaw_rate"] for e in offline[:n]])
    started = np.isfinite(offline_yaw) & np.isfinite(live["yaw_rate"][:n])
    difference = live["yaw_rate"][:n][started] - offline_yaw[started]
    # Replay and live differ only where kernel timestamps move a frame across a tick boundary.
    assert np.sqrt(np.mean(difference**2)) < np.radians(0.1)
    assert np.max(np.abs(difference)) < np.radians(0.5)


def read_config():
    from canest.config import load_config

    return load_config(CONFIG)


class Capture:
    """Frames on vcan1, by python-can and by can-utils' candump at the same time."""

    def __init__(self, candump_path):
        self.python_can = live.Capture("vcan1")
        self.candump_path = candump_path
        self.candump = subprocess.Popen(["candump", "-L", "vcan1"], stdout=open(candump_path, "w"))
        time.sleep(0.2)

    def finish(self):
        time.sleep(0.3)
        frames = self.python_can.stop()
        self.candump.send_signal(signal.SIGINT)
        self.candump.wait(timeout=10)
        return frames, list(can.LogReader(str(self.candump_path)))


def run_end_to_end(tmp_path, dlc_run, play_command):
    log, truth_csv, sim = dlc_run
    capture = Capture(tmp_path / "candump.log")
    daemon = Daemon(tmp_path / "live.csv")
    try:
        subprocess.run(play_command(log), check=True, timeout=120, capture_output=True)
        time.sleep(0.3)
    finally:
        code = daemon.terminate()
    by_python_can, by_candump = capture.finish()
    stderr = daemon.stderr
    assert code == 0, stderr
    assert f"frames={len(sim.frames)}" in stderr and f"decoded={len(sim.frames)}" in stderr, stderr
    yaw_py, yaw_dump = yaw_frames(by_python_can), yaw_frames(by_candump)
    assert len(yaw_py) == len(yaw_dump) > 700
    assert [m.data for m in yaw_py] == [m.data for m in yaw_dump]
    check_integrity(yaw_py)
    rmse, live = live_accuracy(tmp_path / "live.csv", truth_csv, sim.frames[0].timestamp)
    superseded = int(re.search(r"superseded=(\d+)", stderr).group(1)) if "superseded=" in stderr else 0
    assert len(yaw_py) == len(live["t"]) - superseded and superseded < 0.05 * len(live["t"])
    sent_as = np.nan_to_num(live["yaw_rate"], nan=0.0)  # not-yet-initialized ticks go out as 0, flagged invalid
    assert_in_order([YAW_SIDESLIP.decode(m.data)["YawRate"] for m in yaw_py], sent_as, 1e-4)
    assert rmse["vx"] < 0.1 and rmse["yaw_rate"] < 0.3 and rmse["beta"] < 0.5, rmse
    compare_with_offline(live, log)
    return rmse


def test_daemon_with_canest_player_python_can_and_candump_capture(tmp_path, dlc_run):
    run_end_to_end(tmp_path, dlc_run, lambda log: [sys.executable, "-m", "canest", "replay", str(log), "--realtime",
                                                   "--config", str(CONFIG), "--channel", "vcan0", "-q"])


def test_daemon_with_canplayer(tmp_path, dlc_run):
    run_end_to_end(tmp_path, dlc_run, lambda log: ["canplayer", "-I", str(log)])


def test_sigterm_on_an_idle_bus_exits_zero(tmp_path):
    daemon = Daemon(tmp_path / "idle.csv")
    time.sleep(0.5)
    assert daemon.terminate() == 0
    assert "frames=0" in daemon.stderr
