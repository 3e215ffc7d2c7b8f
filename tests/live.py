"""Helpers for tests against a running daemon on real vcan buses."""
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import can

from canest.io.bus import frames_of
from tests.conftest import CONFIG


def counters(line: str) -> dict:
    """The ``key=value`` counters of a frame summary or status line, as integers."""
    return {key: int(value) for key, value in (part.split("=", 1) for part in line.split() if "=" in part)
            if value.isdigit()}


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

    def frames_read(self, timeout=10.0) -> int:
        """The frames the daemon has read so far, from the status line it logs on SIGUSR1."""
        before = self.stderr.count("status: frames=")
        self.signal(signal.SIGUSR1)
        assert self.wait_for("status: frames=", timeout=timeout, count=before + 1), "no status line on SIGUSR1"
        last = [line for line in self.stderr.splitlines() if "status: frames=" in line][-1]
        return counters(last)["frames"]

    def wait_until_read(self, frames=None, timeout=60.0) -> int:
        """Wait until the daemon has read ``frames`` (or, if None, until its count stops growing once the bus is
        quiet): a daemon in the loaded guest may be seconds behind the bus, its socket holding the rest, and
        SIGTERM would cut that backlog. Returns the count."""
        deadline = time.monotonic() + timeout
        count = self.frames_read()
        while time.monotonic() < deadline:
            time.sleep(0.5)
            previous, count = count, self.frames_read()
            if count == frames or (frames is None and count == previous):
                break
        return count

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
    the frame to send instead (``elapsed``: the frame's scheduled time since the start, s).
    The clock is read once per wake-up, not per frame, and frames due within ``EARLY`` are sent at
    once: a clock read is a system call in the UML guest, costlier than sending the frame.
    """

    EARLY = 0.002  # s
    RETRY = 0.1  # s of the drive between attempts to reopen a bus that went away

    def __init__(self, frames, channel="vcan0", speed=1.0, drop=None, loops=1000, mutate=None):
        super().__init__(daemon=True)
        self.frames, self.channel, self.speed, self.drop, self.loops = frames, channel, speed, drop, loops
        self.mutate = mutate
        self.done = threading.Event()
        self.sent = 0
        self.failed = 0
        self.dropped = []
        self.progress = 0.0  # the drive's time (s, from the start) of the last frame sent
        self.start_time = None
        self.duration = frames[-1].timestamp - frames[0].timestamp + 0.01  # one pass, s of log time

    def _bus(self):
        try:
            return can.Bus(interface="socketcan", channel=self.channel, fd=True)
        except (OSError, can.CanError):
            return None

    def run(self):
        bus = self._bus()
        link = bus and frames_of(bus)  # the daemon's own frame path: no clock read per frame
        self.start_time = time.perf_counter()
        t_first = self.frames[0].timestamp
        duration = self.duration
        now = retry_at = 0.0
        for loop in range(self.loops):
            for frame in self.frames:
                if self.done.is_set():
                    break
                elapsed = (loop * duration + frame.timestamp - t_first) / self.speed
                if elapsed > now + self.EARLY:
                    now = time.perf_counter() - self.start_time
                    if elapsed > now + self.EARLY:
                        time.sleep(elapsed - now)
                        now = elapsed
                if self.drop and self.drop(frame, elapsed):
                    self.dropped.append(time.time())  # wall time of each withheld frame (few: a clock read each)
                    continue
                if self.mutate:
                    frame = self.mutate(frame, elapsed)
                if bus is None and elapsed >= retry_at:  # not a new socket per frame: the guest's CPU is shared
                    retry_at = elapsed + self.RETRY
                    bus = self._bus()
                    link = bus and frames_of(bus)
                if bus is None:
                    self.failed += 1
                    continue
                try:
                    link.send(frame)
                    self.sent += 1
                    self.progress = elapsed
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


class Capture(threading.Thread):
    """Every frame on vcan1 (or those with an ID in ``ids``: a kernel filter), with its receive time."""

    def __init__(self, channel="vcan1", ids=None):
        super().__init__(daemon=True)
        filters = None if ids is None else [{"can_id": i, "can_mask": 0x7FF, "extended": False} for i in ids]
        self.bus = can.Bus(interface="socketcan", channel=channel, can_filters=filters)
        self.link = frames_of(self.bus)  # the daemon's own frame path: no clock read per frame
        self.frames = []
        self.done = threading.Event()
        self.start()

    def run(self):
        while not self.done.is_set():
            try:
                msg = self.link.recv(0.1)
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


def ip(*args):
    subprocess.run(["ip", "link", *args], check=True)


def restore_vcan(name):
    """Make sure ``name`` exists, is up, and carries CAN FD (the guest's set-up)."""
    if subprocess.run(["ip", "link", "show", name], capture_output=True).returncode != 0:
        ip("add", "dev", name, "type", "vcan")
    ip("set", name, "down")
    ip("set", name, "mtu", "72")
    ip("set", name, "up")


@contextlib.contextmanager
def receive_queues(size_bytes: int):
    """Sockets opened inside get ``size_bytes`` of receive queue (``net.core.rmem_default``, as a deployment's
    sysctl would; restored after).

    The UML guest has one CPU, shared by the daemon, the player and the capture, and the host may leave it
    unscheduled for half a second on a busy machine; the kernel's default queue (208 KiB, ~250 frames, 0.45 s of
    the drive) then overflows. A test of the data path's completeness gives the queue the room a deployment that
    values completeness over latency would (README "Operating canest as a service")."""
    paths = [Path("/proc/sys/net/core/rmem_max"), Path("/proc/sys/net/core/rmem_default")]
    before = [path.read_text() for path in paths]
    for path in paths:
        path.write_text(str(size_bytes))
    try:
        yield
    finally:
        for path, text in zip(paths, before):
            path.write_text(text)
