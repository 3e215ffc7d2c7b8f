"""Progress bars for a person at a terminal: on stderr, left on screen when done, and only when stderr is a
terminal, so redirected or piped output never holds bar text."""
from __future__ import annotations

import math
import sys

from tqdm import tqdm


def terminal_bar(progress: bool, **options) -> tqdm:
    """A tqdm bar (``options`` as tqdm's) shown when ``progress`` is on and stderr is a terminal."""
    return tqdm(file=sys.stderr, leave=True, disable=not (progress and sys.stderr.isatty()), **options)


class LogTimeBar:
    """Seconds of log time replayed, and frames read, of a log ``source`` (:class:`canest.io.logfiles.LogSource`).

    Where the file's size is known, the total is the log's length in seconds extrapolated from the bytes read
    (exact at the end); standard input has no total.
    """

    def __init__(self, source, desc: str, progress: bool):
        self.source = source
        self.size = source.size()
        self.start = None
        self.frames = 0
        self.bar = terminal_bar(progress, desc=f"{desc} {source.path.name}, log seconds", unit="s", unit_scale=True)

    def __enter__(self):
        return self

    def at(self, frames: int, timestamp: float) -> None:
        """``frames`` read so far, the last at ``timestamp`` (log seconds); the first call starts the log's clock."""
        self.frames = frames
        if self.bar.disable or not math.isfinite(timestamp):
            return
        if self.start is None:
            self.start = timestamp
        seconds = timestamp - self.start
        read = self.source.position() if self.size else 0  # 0 too once the reader has closed the file
        if read:
            self.bar.total = max(seconds * self.size / read, seconds)
        self.bar.set_postfix_str(f"{self.frames} frames", refresh=False)
        self.bar.update(seconds - self.bar.n)

    def finish(self) -> None:
        """The whole log is read: the total is what was replayed."""
        if self.size and not self.bar.disable:
            self.bar.total = self.bar.n
            self.bar.set_postfix_str(f"{self.frames} frames", refresh=False)
            self.bar.refresh()

    def __exit__(self, *exc):
        self.bar.close()
