"""systemd's service notification protocol (sd_notify(3)), for Type=notify units.

The protocol is one datagram of newline-separated ``KEY=VALUE`` lines to the
AF_UNIX socket named in ``$NOTIFY_SOCKET`` (a leading ``@`` means the abstract
namespace). sd_notify(3) documents it as a stable interface and recommends
reimplementing it rather than linking libsystemd, which is what this does.
Outside systemd (no ``$NOTIFY_SOCKET``) every call is a no-op.
"""
from __future__ import annotations

import logging
import os
import socket

log = logging.getLogger("canest.apps.notify")


class Notifier:
    def __init__(self, environ=os.environ):
        address = environ.get("NOTIFY_SOCKET", "")
        self.address = "\0" + address[1:] if address.startswith("@") else address
        self.socket = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) if self.address else None
        usec = environ.get("WATCHDOG_USEC")
        pid = environ.get("WATCHDOG_PID")
        mine = pid is None or pid == str(os.getpid())
        self.watchdog_interval = int(usec) / 2e6 if usec and mine else None

    @property
    def enabled(self) -> bool:
        return self.socket is not None

    def notify(self, **fields) -> None:
        """Send e.g. ``notify(READY=1, STATUS="...")``; failures are logged, never raised."""
        if self.socket is None:
            return
        message = "\n".join(f"{key}={value}" for key, value in fields.items()).encode()
        try:
            self.socket.sendto(message, self.address)
        except OSError as exc:
            log.warning("sd_notify to %s failed: %s", self.address.lstrip("\0"), exc)

    def close(self) -> None:
        if self.socket is not None:
            self.socket.close()
            self.socket = None
