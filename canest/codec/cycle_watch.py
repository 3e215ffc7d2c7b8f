"""Each used message's cycle time as measured on the bus, against the one assumed.

Timeouts are a number of cycles (``estimator.timeout_cycles``). The cycle
comes from the config, the DBC's ``GenMsgCycleTime`` or, lacking both, a
100 ms default; Toyota's DBCs give none for messages sent every 12 ms, so
their inputs counted as fresh for 0.5 s after a sender stopped. The watch
takes the median of a message's first ``SAMPLES`` frame intervals (a lost
frame or a burst does not move it), warns once per message when the assumed
cycle is more than ``TOLERANCE`` times off, and hands back the measured cycle
of a message whose cycle was only the default, for its timeouts to follow.
"""
from __future__ import annotations

import logging
import statistics

LOG = logging.getLogger(__name__)
SAMPLES = 20  # frame intervals measured per message
TOLERANCE = 2.0  # a factor: the assumed cycle more than this far off is warned about


class CycleWatch:
    """Per frame ID: the assumed (seconds, source) and the message name; :meth:`observe` every used frame."""

    def __init__(self, assumed: dict, names: dict):
        self.assumed = assumed  # frame ID -> (s, "config" | "DBC" | "default")
        self.names = names  # frame ID -> message name
        self.last = {}  # frame ID -> time of its latest frame
        self.intervals = {fid: [] for fid in assumed}
        self.measured = {}  # frame ID -> s, once SAMPLES intervals were seen

    def observe(self, frame_id: int, t: float) -> float | None:
        """Note a frame of ``frame_id`` at ``t``; the measured cycle when it has just been measured and the
        assumed one was the default (the caller's timeouts should follow it), else None."""
        if frame_id in self.measured or frame_id not in self.assumed:
            return None
        last, self.last[frame_id] = self.last.get(frame_id), t
        if last is None or t <= last:
            return None
        intervals = self.intervals[frame_id]
        intervals.append(t - last)
        if len(intervals) < SAMPLES:
            return None
        measured = self.measured[frame_id] = statistics.median(intervals)
        assumed, source = self.assumed[frame_id]
        if not assumed / TOLERANCE <= measured <= assumed * TOLERANCE:
            follow = "the timeouts follow the measured one" if source == "default" else \
                f"timeouts stay {source}'s: set input.messages.{self.names[frame_id]}.cycle_time"
            LOG.warning("message %s (%#x) comes every %.1f ms, the assumed cycle is %g ms (%s): %s",
                        self.names[frame_id], frame_id, measured * 1000, assumed * 1000, source, follow)
        return measured if source == "default" else None
