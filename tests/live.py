"""Helpers for tests against a running daemon on real vcan buses."""
import os
import signal
import subprocess
import sys
import threading
import time

import can

from tests.conftest import CONFIG


def summary_value(stderr, key):
    """``key`` in the frame summary the daemon printed when it stopped (0 if absent)."""
    last = [line for line in stderr.splitlines() if line.startswith("frames=")][-1]
    fields = dict(part.split("=") for part in last.split())
    return int(fields.get(key, 0))


class Daemon:
    """``canest run`` as a subprocess (vcan0 -> vcan1 unless the config says otherwise)."""

    def __init__(self, csv_path=None, config=CONFIG, env=None, args=()):
        command = [sys.executable, "-m", "canest", "run", "--config", str(config), *args]
        if csv_path:
            command += ["--csv", str(csv_path)]
        self.process = subprocess.Popen(command, stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                        env={**os.environ, **(env or {})})
        self.lines = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            line = self.process.stderr.readline()
            self.lines.append(line)
            if "estimating:" in line or not line:
                break
        assert "estimating:" in self.lines[-1], "".join(self.lines)
        self.reader = threading.Thread(target=lambda: self.lines.extend(self.process.stderr), daemon=True)
        self.reader.start()

    @property
    def stderr(self) -> str:
        return "".join(self.lines)

    def signal(self, number) -> None:
        self.process.send_signal(number)

    def alive(self) -> bool:
        return self.process.poll() is None

    def rss_kib(self) -> int:
        with open(f"/proc/{self.process.pid}/status") as handle:
            return next(int(line.split()[1]) for line in handle if line.startswith("VmRSS:"))

    def terminate(self) -> int:
        if self.alive():
            self.process.send_signal(signal.SIGTERM)
        code = self.process.wait(timeout=30)
        self.reader.join(timeout=5)
        return code

    def counts(self) -> dict:
        """The daemon's frame summary now: asks for a status line (SIGUSR1) and reads it."""
        before = self.stderr.count("status: frames=")
        self.signal(signal.SIGUSR1)
        assert self.wait_for("status: frames=", count=before + 1, timeout=30.0), self.stderr
        line = [line for line in self.lines if "status: frames=" in line][-1]
        fields = line.split("status: ", 1)[1].split(" | ")[0].split()
        return {key: int(value) for key, value in (field.split("=") for field in fields)}

    def wait_until_counted(self, key, at_least, timeout=120.0) -> dict:
        """Wait until the daemon has read what was sent: ``key`` in its summary reaches ``at_least``.

        The guest's CPU may be shared with a busy host: frames wait in the socket's receive buffer
        until the daemon gets to them, which takes as long as it takes. Returns the last summary,
        whether or not it got there (the caller asserts on it)."""
        deadline = time.monotonic() + timeout
        while True:
            counts = self.counts()
            if counts.get(key, 0) >= at_least or time.monotonic() > deadline:
                return counts
            time.sleep(0.2)

    def wait_for(self, text, timeout=10.0, count=1) -> bool:
        """Wait until ``text`` has appeared ``count`` times in the daemon's log."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.stderr.count(text) >= count:
                return True
            time.sleep(0.05)
        return False


class Player(threading.Thread):
    """Send simulated frames onto vcan0 at their pace, looping, surviving the interface going away.

    ``drop(frame, elapsed)`` may return True to leave a frame out; ``mutate(frame, elapsed)`` returns
    the frame to send instead.
    """

    def __init__(self, frames, channel="vcan0", speed=1.0, drop=None, loops=1000, mutate=None):
        super().__init__(daemon=True)
        self.frames, self.channel, self.speed, self.drop, self.loops = frames, channel, speed, drop, loops
        self.mutate = mutate
        self.done = threading.Event()
        self.sent = 0
        self.failed = 0
        self.start_time = None
        self.duration = frames[-1].timestamp - frames[0].timestamp + 0.01  # one pass, s of log time

    def _bus(self):
        try:
            return can.Bus(interface="socketcan", channel=self.channel, fd=True)
        except (OSError, can.CanError):
            return None

    def run(self):
        bus = self._bus()
        self.start_time = time.perf_counter()
        t_first = self.frames[0].timestamp
        duration = self.duration
        for loop in range(self.loops):
            for frame in self.frames:
                if self.done.is_set():
                    break
                log_time = loop * duration + frame.timestamp - t_first
                delay = log_time / self.speed - (time.perf_counter() - self.start_time)
                if delay > 0:
                    time.sleep(delay)
                elapsed = time.perf_counter() - self.start_time
                if self.drop and self.drop(frame, elapsed):
                    continue
                if self.mutate:
                    frame = self.mutate(frame, elapsed)
                if bus is None:
                    bus = self._bus()
                    if bus is None:
                        self.failed += 1
                        continue
                try:
                    bus.send(frame)
                    self.sent += 1
                except (OSError, can.CanError):
                    self.failed += 1
                    bus.shutdown()
                    bus = None
        if bus is not None:
            bus.shutdown()
        self.done.set()

    def stop(self):
        self.done.set()
        self.join(timeout=10)


END_MARK_ID = 0x7FF  # in neither DBC: the daemon's kernel filter keeps it out of its input


def mark_end(channel):
    """Send one END_MARK_ID frame on ``channel``: a capture that has read it has read everything before it."""
    with can.Bus(interface="socketcan", channel=channel) as bus:
        bus.send(can.Message(arbitration_id=END_MARK_ID, data=b"", is_extended_id=False))


class Candump:
    """can-utils' candump logging ``channel`` to ``path``, line-buffered, until :meth:`finish`."""

    def __init__(self, channel, path):
        self.channel, self.path = channel, path
        self.process = subprocess.Popen(["stdbuf", "-oL", "candump", "-L", channel], stdout=open(path, "w"))

    def finish(self, timeout=120.0):
        """Read up to an end mark (however long a busy guest takes), stop, return the frames before it."""
        mark_end(self.channel)
        deadline = time.monotonic() + timeout
        marked = f" {END_MARK_ID:03X}#"
        while marked not in self.path.read_text() and time.monotonic() < deadline:
            time.sleep(0.1)
        self.process.send_signal(signal.SIGINT)
        self.process.wait(timeout=10)
        assert marked in self.path.read_text(), f"candump on {self.channel} did not read up to the end mark"
        lines = self.path.read_text().splitlines(keepends=True)
        self.path.write_text("".join(lines[:next(i for i, line in enumerate(lines) if marked in line)]))
        return list(can.LogReader(str(self.path)))


class Capture(threading.Thread):
    """Every frame on vcan1, with its receive time."""

    def __init__(self, channel="vcan1"):
        super().__init__(daemon=True)
        self.channel = channel
        self.bus = can.Bus(interface="socketcan", channel=channel)
        self.frames = []
        self.done = threading.Event()
        self.start()

    def run(self):
        while not self.done.is_set():
            try:
                msg = self.bus.recv(timeout=0.1)
            except (OSError, can.CanError):
                time.sleep(0.05)
                continue
            if msg is not None:
                self.frames.append(msg)

    def stop(self):
        self.done.set()
        self.join(timeout=5)
        self.bus.shutdown()
        return self.frames

    def drain(self, timeout=120.0):
        """Read up to an end mark (however long a busy guest takes), stop, return the frames before it."""
        mark_end(self.channel)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not any(m.arbitration_id == END_MARK_ID for m in self.frames):
            time.sleep(0.1)
        frames = self.stop()
        marks = [i for i, m in enumerate(frames) if m.arbitration_id == END_MARK_ID]
        assert marks, f"the capture on {self.channel} did not read up to the end mark"
        return frames[:marks[0]]


def ip(*args):
    subprocess.run(["ip", "link", *args], check=True)


def restore_vcan(name):
    """Make sure ``name`` exists, is up, and carries CAN FD (the guest's set-up)."""
    if subprocess.run(["ip", "link", "show", name], capture_output=True).returncode != 0:
        ip("add", "dev", name, "type", "vcan")
    ip("set", name, "down")
    ip("set", name, "mtu", "72")
    ip("set", name, "up")
