"""Where estimates go: one small protocol, one class per destination (python-can's ``Listener`` for estimates).

Every sink gets each tick's estimates in order through :meth:`Sink.publish`
(a list: after a stall several ticks complete at once) and is closed at the
end. The live service and replay both just iterate over their sinks:

- :class:`CsvSink`: one row per tick (every tick);
- :class:`LogSink`: the estimate frames of every tick into a CAN log, its
  format chosen by python-can from the suffix (``can.Logger``);
- :class:`BusSink`: the newest tick's frames onto a bus link, never a burst
  (older ticks of the same pass are counted ``superseded``);
- :class:`CallbackSink`: a function called with every estimate.

Frame sinks take an encoder (anything with ``encode(estimate) -> [can.Message]``).
"""
from __future__ import annotations

import csv

import can

from canest.estimation.estimate import CAUSE_GROUPS


class Sink:
    def publish(self, estimates: list) -> None:
        for estimate in estimates:
            self.write(estimate)

    def write(self, estimate) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Flush and release what the sink holds (nothing by default)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class CsvSink(Sink):
    """One row per tick: ``t``, the states, their ``_std`` columns, ``valid`` (bit mask), ``mode`` and
    ``why_vx``, ``why_yaw_rate``, ``why_beta``, ``why_forces``, ``why_friction`` (why a bit is clear).

    ``valid`` bits: 0 vx, 1 vy, 2 beta, 3 yaw rate, 4 lateral forces, 5 friction, 6 friction observable now,
    7-10 lateral force fl, fr, rl, rr, 11-14 friction fl, fr, rl, rr (``canest.estimation.estimate.VALID_BITS``).
    """

    def __init__(self, path):
        self.handle = open(path, "w", newline="")
        self.writer = csv.writer(self.handle)
        self.columns = None

    def write(self, estimate) -> None:
        if self.columns is None:
            states = [k for k in estimate.values if not k.endswith("_std")]
            self.columns = states + [f"{k}_std" for k in states]
            self.writer.writerow(["t", *self.columns, "valid", "mode", *(f"why_{g}" for g in CAUSE_GROUPS)])
        self.writer.writerow([f"{estimate.t:.6f}", *(f"{estimate.values[c]:.9g}" for c in self.columns),
                              estimate.valid_flags, estimate.mode, *(estimate.causes.get(g, "") for g in CAUSE_GROUPS)])

    def close(self) -> None:
        self.handle.close()


class LogSink(Sink):
    """Every tick's estimate frames into a CAN log (``.log`` candump, ``.asc``, ``.blf``, ... by suffix)."""

    def __init__(self, path, encoder):
        self.logger = can.Logger(str(path))
        self.encoder = encoder

    def write(self, estimate) -> None:
        for frame in self.encoder.encode(estimate):
            self.logger.on_message_received(frame)

    def close(self) -> None:
        self.logger.stop()


class BusSink(Sink):
    """The newest estimate of each pass onto a bus link; ``counts`` gets sent, send_dropped and superseded."""

    def __init__(self, link, encoder, counts):
        self.link = link
        self.encoder = encoder
        self.counts = counts

    def publish(self, estimates: list) -> None:
        self.counts["superseded"] += len(estimates) - 1
        for frame in self.encoder.encode(estimates[-1]):
            self.counts["sent" if self.link.send(frame) else "send_dropped"] += 1


class CallbackSink(Sink):
    """Calls ``function(estimate)`` for every tick."""

    def __init__(self, function):
        self.function = function

    def write(self, estimate) -> None:
        self.function(estimate)
