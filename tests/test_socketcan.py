"""End to end on real SocketCAN virtual buses (vcan0 -> daemon -> vcan1).

Run on a machine with vcan0/vcan1, or on any Linux host through the UML guest:
``tools/vcan-guest -- python -m pytest -m socketcan``.
"""
import signal
import subprocess
import sys
import threading
import time

import can
import cantools
import numpy as np
import pytest

from canest import integrity
from canest.evaluate import read_table, score
from canest.replay import replay
from tests.conftest import CONFIG, ROOT

pytestmark = pytest.mark.socketcan
OUTPUT_DB = cantools.database.load_file(str(ROOT / "dbc" / "canest_estimates.dbc"))
YAW_SIDESLIP = OUTPUT_DB.get_message_by_name("CE_YawSideslip")


class Daemon:
    """``canest run`` as a subprocess on vcan0 -> vcan1, started and stopped as systemd would."""

    def __init__(self, csv_path):
        self.process = subprocess.Popen([sys.executable, "-m", "canest", "run", "--config", str(CONFIG),
                                         "--csv", str(csv_path)],
                                        stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.stderr = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            line = self.process.stderr.readline()
            self.stderr.append(line)
            if "estimating:" in line or not line:
                break
        assert "estimating:" in self.stderr[-1], "".join(self.stderr)
        self.reader = threading.Thread(target=lambda: self.stderr.extend(self.process.stderr), daemon=True)
        self.reader.start()

    def terminate(self) -> int:
        self.process.send_signal(signal.SIGTERM)
        code = self.process.wait(timeout=20)
        self.reader.join(timeout=5)
        return code


class Capture:
    """Frames on vcan1, by python-can and by can-utils' candump at the same time."""

    def __init__(self, candump_path):
        self.bus = can.Bus(interface="socketcan", channel="vcan1")
        self.frames = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        self.candump_path = candump_path
        self.candump = subprocess.Popen(["candump", "-L", "vcan1"], stdout=open(candump_path, "w"))
        time.sleep(0.2)

    def _run(self):
        while not self.stop.is_set():
            msg = self.bus.recv(timeout=0.1)
            if msg is not None:
                self.frames.append(msg)

    def finish(self):
        time.sleep(0.3)
        self.stop.set()
        self.thread.join()
        self.bus.shutdown()
        self.candump.send_signal(signal.SIGINT)
        self.candump.wait(timeout=10)
        return self.frames, list(can.LogReader(str(self.candump_path)))


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
    assert code == 0, "".join(daemon.stderr)
    stderr = "".join(daemon.stderr)
    assert f"frames={len(sim.frames)}" in stderr and f"decoded={len(sim.frames)}" in stderr, stderr
    yaw_py, yaw_dump = yaw_frames(by_python_can), yaw_frames(by_candump)
    assert len(yaw_py) == len(yaw_dump) > 700
    assert [m.data for m in yaw_py] == [m.data for m in yaw_dump]
    check_integrity(yaw_py)
    rmse, live = live_accuracy(tmp_path / "live.csv", truth_csv, sim.frames[0].timestamp)
    assert len(yaw_py) == len(live["t"])
    decoded = [YAW_SIDESLIP.decode(m.data) for m in yaw_py]
    sent_as = np.nan_to_num(live["yaw_rate"], nan=0.0)  # not-yet-initialized ticks go out as 0, flagged invalid
    np.testing.assert_allclose([d["YawRate"] for d in decoded], sent_as, atol=1e-4)
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
    assert "frames=0" in "".join(daemon.stderr)
