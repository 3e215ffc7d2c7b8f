"""A python-can bus that survives its interface going away.

:class:`BusLink` wraps one ``can.Bus``. Errors while receiving or sending
close the bus and schedule a reopen with exponential backoff
(``BACKOFF_START`` doubling to ``BACKOFF_MAX``); while the bus is away
``recv`` waits out its timeout and returns None and ``send`` returns False,
so the daemon's loop never blocks and never dies of a missing interface.
A full transmit queue (ENOBUFS) or a downed interface (ENETDOWN) only drops
the frame, and a downed input only waits: the socket stays bound and traffic
resumes the moment the interface is up again. A vanished interface (ENODEV)
needs a new socket: that is what the backoff reopens.

On SocketCAN the frames go through the bus's socket with python-can's own
frame codec (:class:`SocketcanFrames`) instead of ``recv``/``send``, which
read the wall clock around every frame for their timeouts. Where the clock
is a system call (a virtual machine without vDSO: a User-Mode-Linux guest
costs ~0.1 ms per read) those reads were a third of the daemon's load.

Frames the kernel dropped because the receive queue was full (the daemon
fell behind for longer than the queue holds, ``net.core.rmem_default``) are
counted by the kernel per socket; :meth:`BusLink.kernel_dropped` reads that
count (``SO_MEMINFO``, on SocketCAN) so no frame is lost silently.
"""
from __future__ import annotations

import errno
import logging
import select
import socket
import struct
import sys
import time

import can

from canest.errors import BusOpenError

log = logging.getLogger("canest.bus")

BACKOFF_START = 0.1  # s
BACKOFF_MAX = 5.0  # s
DROP_ONLY = {errno.ENOBUFS, errno.ENETDOWN, errno.EAGAIN}
SO_MEMINFO = 55  # Linux >= 4.6: the socket's memory counters, u32[9], the last one the frames dropped
MEMINFO = struct.Struct("9I")
GONE = {errno.ENODEV, errno.ENXIO, errno.EBADF, errno.ENOTCONN}  # the socket is useless: reopen


def _error_code(exc: Exception):
    return getattr(exc, "error_code", None) or getattr(exc, "errno", None)


NO_SOCKETCAN = ("this machine has no SocketCAN; use vcan in a Linux guest (tools/vcan-guest), -i udp_multicast for "
                "separate processes on this machine (e.g. -c 239.74.163.2), or -i virtual within one process "
                "(canest demo)")


def python_can_config() -> dict:
    """python-can's own bus configuration, in python-can's order (``can.util.load_config``: the config files
    ``~/.canrc`` and others, overridden by ``CAN_INTERFACE``, ``CAN_CHANNEL``, ``CAN_BITRATE``, ``CAN_CONFIG``);
    only the keys they set."""
    try:
        found = can.util.load_config()
    except can.exceptions.CanInterfaceNotImplementedError as exc:
        if '"None"' not in str(exc):
            raise BusOpenError(f"python-can's configuration (~/.canrc or CAN_INTERFACE): {exc}; "
                               f"choose one of {', '.join(sorted(can.VALID_INTERFACES))}") from None
        found = {k: v for k, v in can.util.load_config(config={"interface": "virtual"}).items() if k != "interface"}
    return {k: v for k, v in found.items() if v is not None}


def open_bus(kwargs: dict, role: str, **extra) -> can.BusABC:
    where = f"{kwargs.get('interface')}:{kwargs.get('channel')}"
    try:
        return can.Bus(**kwargs, **extra)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        if _error_code(exc) == errno.EAFNOSUPPORT and kwargs.get("interface") == "socketcan":
            raise BusOpenError(f"cannot open {role} bus {where}: {exc}: {NO_SOCKETCAN}") from None
        raise BusOpenError(f"cannot open {role} bus {where}: {exc}") from None


class PythonCanFrames:
    """Frames in and out through python-can's own ``recv`` and ``send`` (every interface)."""

    def __init__(self, bus: can.BusABC):
        self.bus = bus

    def recv(self, timeout: float):
        return self.bus.recv(timeout=timeout)

    def send(self, msg: can.Message) -> None:
        self.bus.send(msg, timeout=0)

    def kernel_dropped(self) -> int:
        return 0  # python-can does not report an interface's receive-queue overflows


class SocketcanFrames:
    """Frames in and out of a python-can SocketCAN bus's socket: one ``select`` and one ``recvmsg`` per
    frame received, one non-blocking ``send`` per frame sent, no clock read (python-can's codec)."""

    def __init__(self, bus: can.BusABC):
        from can.interfaces.socketcan.socketcan import build_can_frame, capture_message
        self.socket, self.channel = bus.socket, bus.channel
        self.build, self.capture = build_can_frame, capture_message

    def recv(self, timeout: float):
        if not select.select([self.socket], [], [], timeout)[0]:
            return None
        msg = self.capture(self.socket)
        if msg is not None and not msg.channel:
            msg.channel = self.channel
        return msg

    def send(self, msg: can.Message) -> None:
        self.socket.send(self.build(msg), socket.MSG_DONTWAIT)  # a full queue raises EAGAIN/ENOBUFS: dropped

    def kernel_dropped(self) -> int:
        """Frames the kernel dropped on this socket because its receive queue was full (``sk_drops``)."""
        try:
            return MEMINFO.unpack(self.socket.getsockopt(socket.SOL_SOCKET, SO_MEMINFO, MEMINFO.size))[-1]
        except OSError:  # a closed socket, or a kernel older than 4.6
            return 0


def frames_of(bus: can.BusABC):
    """The fastest way in and out of ``bus``: its socket on SocketCAN, python-can's calls elsewhere."""
    if type(bus).__name__ == "SocketcanBus" and isinstance(getattr(bus, "socket", None), socket.socket):
        return SocketcanFrames(bus)
    return PythonCanFrames(bus)


class BusLink:
    def __init__(self, kwargs: dict, role: str, counts, **open_extra):
        self.kwargs = kwargs
        self.role = role
        self.open_extra = open_extra
        self.counts = counts
        self.bus = open_bus(kwargs, role, **open_extra)  # the first open must succeed: fail fast at start
        self.frames = frames_of(self.bus)
        self.backoff = BACKOFF_START
        self.next_attempt = 0.0
        self.dropped_by_closed = 0  # kernel drops of the sockets closed before this one
        self.refusing = False  # its sends fail on an interface that is down (:meth:`send` warned)
        # when it reported its interface down, until a frame received after that came (the frames queued before
        # it are read after the report: :meth:`recv`)
        self.down_at = None

    def kernel_dropped(self) -> int:
        """Frames the kernel dropped on this link's sockets since it was created (receive queue full)."""
        return self.dropped_by_closed + (self.frames.kernel_dropped() if self.bus is not None else 0)

    @property
    def up(self) -> bool:
        return self.bus is not None

    @property
    def stamps_at_receive(self) -> bool:
        """Its frames' timestamps tell when they reached this link's queue, on ``time.time``'s base: SocketCAN's
        kernel stamps, python-can's virtual bus (stamped when sent) and udp_multicast on Linux (SO_TIMESTAMPNS).
        Elsewhere (udp_multicast on macOS and Windows, slcan, ...) python-can stamps a frame when it is read."""
        interface = self.kwargs.get("interface")
        return interface in ("socketcan", "virtual") or (interface == "udp_multicast" and sys.platform == "linux")

    def _lost(self, exc: Exception) -> None:
        log.warning("%s bus %s lost: %s; reconnecting", self.role, self.kwargs.get("channel"), exc)
        self.counts[f"{self.role}_bus_lost"] += 1
        self.close()
        self.next_attempt = time.monotonic() + self.backoff

    def _reopen(self) -> None:
        if time.monotonic() < self.next_attempt:
            return
        try:
            self.bus = open_bus(self.kwargs, self.role, **self.open_extra)
            self.frames = frames_of(self.bus)
        except BusOpenError as exc:
            self.backoff = min(self.backoff * 2.0, BACKOFF_MAX)
            self.next_attempt = time.monotonic() + self.backoff
            log.warning("%s; next attempt in %.1f s", exc, self.backoff)
            return
        log.warning("%s bus %s reopened", self.role, self.kwargs.get("channel"))
        self.counts[f"{self.role}_bus_reconnects"] += 1

    def recv(self, timeout: float):
        if self.bus is None:
            self._reopen()
            if self.bus is None:
                time.sleep(timeout)
                return None
        for attempt in range(2):
            try:
                msg = self.frames.recv(timeout)
            except (can.CanError, OSError) as exc:
                if _error_code(exc) not in DROP_ONLY:
                    self._lost(exc)
                    return None
                log.warning("%s bus %s is down: %s", self.role, self.kwargs.get("channel"), exc)
                self.counts[f"{self.role}_bus_down"] += 1
                self.down_at = time.time()
                # SocketCAN reports a downed interface once, ahead of the frames still queued: read on. An
                # interface that reports it at every call would spin: the second error waits out the timeout.
                if attempt:
                    time.sleep(timeout)
                continue
            if msg is not None:
                self.backoff = BACKOFF_START  # a frame arrived: the link is really back
                if self.down_at is not None and (msg.timestamp > self.down_at or not self.stamps_at_receive):
                    log.warning("%s bus %s delivers frames again", self.role, self.kwargs.get("channel"))
                    self.down_at = None
            return msg
        return None

    def set_filters(self, can_filters) -> None:
        """Receive only what ``can_filters`` (python-can's) pass from now on, also after a reopen."""
        self.open_extra["can_filters"] = can_filters
        if self.bus is not None:
            self.bus.set_filters(can_filters)

    def send(self, msg: can.Message) -> bool:
        if self.bus is None:
            self._reopen()
            if self.bus is None:
                return False
        try:
            self.frames.send(msg)
            self.backoff = BACKOFF_START
        except (can.CanError, OSError) as exc:
            if _error_code(exc) in GONE:
                self._lost(exc)
            elif _error_code(exc) == errno.ENETDOWN and not self.refusing:  # once, not a line a frame
                log.warning("%s bus %s is down: %s; its frames are dropped (counted) until it is up", self.role,
                            self.kwargs.get("channel"), exc)
                self.refusing = True
            return False  # anything else (queue full, interface down): this frame is dropped
        if self.refusing:
            log.warning("%s bus %s takes frames again", self.role, self.kwargs.get("channel"))
            self.refusing = False
        return True

    def close(self) -> None:
        if self.bus is not None:
            self.dropped_by_closed = self.kernel_dropped()
            try:
                self.bus.shutdown()
            except (can.CanError, OSError):
                pass
            self.bus = None
