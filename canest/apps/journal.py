"""Logging for the daemon: levels to stderr (the journal), repeated warnings rate limited."""
from __future__ import annotations

import logging
import sys
import time

REPEAT_INTERVAL = 10.0  # s between two records with the same message template


class RateLimit(logging.Filter):
    """Let one record per message template through every ``interval`` seconds; count the rest.

    The next record that passes says how many were suppressed, so nothing is
    silently lost from the count.
    """

    def __init__(self, interval: float = REPEAT_INTERVAL, clock=time.monotonic):
        super().__init__()
        self.interval = interval
        self.clock = clock
        self.last = {}
        self.suppressed = {}

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno < logging.WARNING:
            return True
        key = (record.name, record.msg)
        now = self.clock()
        if key in self.last and now - self.last[key] < self.interval:
            self.suppressed[key] = self.suppressed.get(key, 0) + 1
            return False
        self.last[key] = now
        count = self.suppressed.pop(key, 0)
        if count:
            record.msg = f"{record.msg} ({count} similar suppressed)"
        return True


def setup(level: str = "INFO") -> None:
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    handler.addFilter(RateLimit())
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    logging.getLogger("can").setLevel(max(logging.WARNING, root.level))  # python-can's per-socket chatter
