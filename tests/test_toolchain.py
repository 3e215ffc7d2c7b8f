"""canest among python-can's tools: bus options spelled as theirs, python-can's configuration honoured in its
order, and daemon, monitor and player as separate processes on udp_multicast where there is no SocketCAN."""
import queue
import random
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

from canest.cli import build_parser
from canest.commands.common import config_from_args
from tests.conftest import CONFIG, ROOT

CANEST = [sys.executable, "-m", "canest"]


def resolved(argv, monkeypatch, tmp_path, canrc=None, **env):
    """The config `canest ARGV` would run with, HOME in ``tmp_path`` (its ~/.canrc ``canrc``) and ``env`` set."""
    monkeypatch.setenv("HOME", str(tmp_path))
    for name in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    if canrc is not None:
        (tmp_path / ".canrc").write_text(canrc)
    return config_from_args(build_parser().parse_args(argv))


CANRC = "[default]\ninterface = udp_multicast\nchannel = 239.74.163.9\nbitrate = 250000\n"


def test_python_cans_canrc_applies_below_the_command_line(monkeypatch, tmp_path):
    config = resolved(["run"], monkeypatch, tmp_path, CANRC)
    assert (config.input_bus.interface, config.input_bus.channel) == ("udp_multicast", "239.74.163.9")
    assert config.input_bus.options == {"fd": True, "bitrate": 250000}  # built-in fd, python-can bitrate
    assert config.output_bus.interface == "udp_multicast"  # the output bus takes python-can's interface only
    config = resolved(["run", "-c", "239.74.163.7", "-b", "500000", "--fd", "--bus-kwargs", "port=43999",
                       "--bus-option", "receive_own_messages=true"], monkeypatch, tmp_path, CANRC)
    assert config.input_bus.channel == "239.74.163.7"
    assert config.input_bus.options == {"bitrate": 500000, "fd": True, "port": 43999, "receive_own_messages": True}


def test_environment_overrides_canrc_as_in_python_can(monkeypatch, tmp_path):
    config = resolved(["replay", "x.log"], monkeypatch, tmp_path, CANRC, CAN_INTERFACE="virtual",
                      CAN_CHANNEL="bench")
    assert (config.input_bus.interface, config.input_bus.channel) == ("virtual", "bench")
    assert config.input_bus.options["bitrate"] == 250000  # what the environment does not set, ~/.canrc does


def test_the_config_files_bus_overrides_python_cans_and_the_command_line_overrides_both(monkeypatch, tmp_path):
    config = resolved(["run", "--config", str(CONFIG)], monkeypatch, tmp_path, CANRC, CAN_CHANNEL="can7")
    assert (config.input_bus.interface, config.input_bus.channel) == ("socketcan", "vcan0")
    assert config.input_bus.options == {"bitrate": 250000, "fd": True}  # the config's options on python-can's
    config = resolved(["run", "--config", str(CONFIG), "-i", "virtual", "-c", "in"], monkeypatch, tmp_path, CANRC)
    assert (config.input_bus.interface, config.input_bus.channel) == ("virtual", "in")
    assert (config.output_bus.interface, config.output_bus.channel) == ("virtual", "vcan1")


def test_monitor_bus_options_name_the_watched_output_bus(monkeypatch, tmp_path):
    config = resolved(["monitor", "-i", "virtual", "-c", "out"], monkeypatch, tmp_path)
    assert (config.output_bus.interface, config.output_bus.channel) == ("virtual", "out")


def test_old_c_for_the_config_still_works_and_says_what_to_type(monkeypatch, tmp_path, capsys):
    config = resolved(["run", "-c", str(CONFIG)], monkeypatch, tmp_path)
    assert config.input_bus.options == {"fd": True}  # dici_ev.yaml's bus
    assert config.input_bus.channel == "vcan0"
    config = resolved(["simulate", "-c", str(CONFIG), "--out", "d.log", "--truth", "t.csv"], monkeypatch, tmp_path)
    assert config.input_bus.options == {"fd": True}
    warnings = capsys.readouterr().err.splitlines()
    assert warnings == [f"canest: warning: -c for the config is deprecated (python-can's tools use -c for the "
                        f"channel); type --config {CONFIG} now"] * 2


def test_a_bad_bus_keyword_is_a_usage_error():
    result = subprocess.run([*CANEST, "run", "--bus-kwargs", "port"], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 2
    assert "--bus-kwargs port: expected KEY=VALUE" in result.stderr


def socketcan_available() -> bool:
    try:
        socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW).close()
        return True
    except (AttributeError, OSError):
        return False


@pytest.mark.skipif(socketcan_available(), reason="this kernel has SocketCAN: the message for its absence cannot show")
def test_without_socketcan_the_error_names_the_alternatives():
    result = subprocess.run([*CANEST, "run"], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        "canest: error: cannot open input bus socketcan:vcan0: [Errno 97] Address family not supported by protocol: "
        "this machine has no SocketCAN; use vcan in a Linux guest (tools/vcan-guest), -i udp_multicast for separate "
        "processes on this machine (e.g. -c 239.74.163.2), or -i virtual within one process (canest demo)"]


class Lines:
    """A process's output lines, read in a thread; :meth:`wait_for` a line holding a text."""

    def __init__(self, stream):
        self.seen = []
        self.queue = queue.Queue()
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream):
        for line in stream:
            self.queue.put(line)

    def wait_for(self, text, timeout=60.0) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = self.queue.get(timeout=max(end - time.monotonic(), 0.01))
            except queue.Empty:
                break
            self.seen.append(line)
            if text in line:
                return line
        raise AssertionError(f"no line with {text!r} within {timeout} s; seen: {self.seen[-5:]}")


def multicast(port, group):
    return ["-i", "udp_multicast", "-c", group, "--bus-kwargs", f"port={port}"]


def test_daemon_monitor_and_player_as_three_processes_on_udp_multicast(tmp_path):
    log = tmp_path / "drive.log"
    assert subprocess.run([*CANEST, "simulate", "--duration", "4", "--out", log, "--truth", tmp_path / "t.csv"],
                          cwd=ROOT, capture_output=True).returncode == 0
    port = random.randrange(20000, 60000)  # a port of its own: other runs on this machine do not cross
    inputs, outputs = "239.74.163.2", "239.74.163.3"

    def start(*args):
        return subprocess.Popen([*CANEST, *map(str, args)], cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)

    daemon = start("run", *multicast(port, inputs), "--output-channel", outputs)
    monitor = start("monitor", *multicast(port, outputs), "--refresh", "0.2", "--duration", "60")
    once = start("monitor", *multicast(port, outputs), "--once", "--duration", "60")
    try:
        Lines(daemon.stderr).wait_for("estimating:")
        player = subprocess.run([*CANEST, "replay", log, "--realtime", *multicast(port, inputs)], cwd=ROOT,
                                capture_output=True, text=True, timeout=120)
        assert player.returncode == 0, player.stderr
        assert player.stdout.startswith("sent ")
        line = Lines(monitor.stdout).wait_for(" mode=normal ")
        words = dict(word.split("=", 1) for word in line.split())
        assert 21.0 < float(words["vx"].rstrip("?")) < 23.5  # the simulated 80 km/h
        assert words["crc_errors"] == "0" and "yaw_rate" in words and int(words["frames"]) > 0
        snapshot, _ = once.communicate(timeout=60)
        assert once.returncode == 0 and len(snapshot.splitlines()) == 1 and " vx=" in snapshot
    finally:
        for process in (monitor, once, daemon):
            process.send_signal(signal.SIGTERM)
        for process in (monitor, once, daemon):
            process.wait(30)
    assert daemon.returncode == 0


def test_monitor_once_without_a_daemon_exits_69():
    result = subprocess.run([*CANEST, "monitor", *multicast(random.randrange(20000, 60000), "239.74.163.4"),
                             "--once", "--duration", "1"], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert result.returncode == 69
    assert result.stderr.splitlines() == ["canest: error: udp_multicast:239.74.163.4: no estimate frames within 1 s; "
                                          "is the daemon running and sending on this bus?"]


def test_a_drive_round_trips_through_mf4_with_identical_estimates(config, tmp_path):
    """canest simulate --out x.mf4 keeps every frame's timestamp exactly: the replay of the MF4 gives the estimates
    of the simulation's own frames, bit for bit; replay --out est.mf4 writes the estimate frames of --out est.log."""
    pytest.importorskip("asammdf", reason="MF4 needs the mf4 extra: pip install 'canest[mf4]'")
    from canest.apps.replay import replay
    from canest.pipeline import Pipeline
    from canest.sim.simulate import simulate

    drive, truth = tmp_path / "drive.mf4", tmp_path / "truth.csv"
    result = subprocess.run([*CANEST, "simulate", "--config", CONFIG, "--maneuver", "sine", "--duration", "3",
                             "--out", drive, "--truth", truth], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    pipeline = Pipeline(config, output_channel=config.output_bus.channel)
    expected = [e for msg in simulate(config, "sine", 80.0, 0.85, duration=3.0).frames for e in pipeline.feed(msg)]
    read_back = []
    replay(config, drive, progress=False, on_estimate=read_back.append)
    assert [(e.t, e.values, e.valid_flags) for e in read_back] == [(e.t, e.values, e.valid_flags) for e in expected]

    for suffix in (".mf4", ".log"):
        out = subprocess.run([*CANEST, "replay", drive, "--config", CONFIG, "--out", tmp_path / f"est{suffix}", "-q"],
                             capture_output=True, text=True, cwd=ROOT)
        assert out.returncode == 0, out.stderr
    import can

    mf4, log = list(can.LogReader(str(tmp_path / "est.mf4"))), list(can.LogReader(str(tmp_path / "est.log")))
    assert len(mf4) == len(log) > 0
    assert [(m.arbitration_id, bytes(m.data)) for m in mf4] == [(m.arbitration_id, bytes(m.data)) for m in log]
    assert max(abs(a.timestamp - b.timestamp) for a, b in zip(mf4, log)) < 1e-6  # candump keeps 6 decimals


def test_mf4_without_asammdf_is_one_line_exit_69(tmp_path):
    code = ("import sys; sys.modules['asammdf'] = None; from canest.cli import main; "
            f"main(['simulate', '--out', {str(tmp_path / 'x.mf4')!r}, '--truth', {str(tmp_path / 't.csv')!r}])")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert result.returncode == 69
    assert len(result.stderr.splitlines()) == 1 and result.stderr.startswith(f"canest: error: {tmp_path / 'x.mf4'}: ")
    assert "pip install 'canest[mf4]'" in result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []
