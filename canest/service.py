"""The live daemon: frames from a python-can bus, estimate frames to a bus.

Ticks follow the receive timestamps of the frames (the kernel's on SocketCAN),
exactly as replay follows log timestamps, so a log played onto a bus gives the
estimates an offline replay of it gives. When the bus is idle, ticks still
happen ``IDLE_MARGIN`` behind the wall clock so stale inputs are noticed.
Sending never blocks the loop: a frame the output bus refuses (``ENOBUFS``,
interface down) is dropped and counted.
"""
from __future__ import annotations

import logging
import signal
import threading
import time

import can

from canest.config import Config
from canest.pipeline import Pipeline

log = logging.getLogger("canest.service")

IDLE_MARGIN = 0.05  # s behind the wall clock before an idle tick is run
STATUS_EVERY = 10.0  # s between status log lines


class BusOpenError(RuntimeError):
    pass


def open_bus(kwargs: dict, role: str, **extra) -> can.BusABC:
    try:
        return can.Bus(**kwargs, **extra)
    except (can.CanError, OSError, ValueError, ImportError) as exc:
        raise BusOpenError(f"cannot open {role} bus {kwargs.get('interface')}:{kwargs.get('channel')}: {exc}") from None


class Service:
    """Run the pipeline on live buses until :meth:`stop` (or SIGINT/SIGTERM) is called."""

    def __init__(self, config: Config, on_estimate=None, csv_writer=None):
        self.config = config
        self.pipeline = Pipeline(config, output_channel=config.output_bus.channel)
        self.on_estimate = on_estimate
        self.csv_writer = csv_writer
        self.stopping = threading.Event()
        self.sent = 0
        self.dropped = 0
        self.ticks = 0

    def stop(self, *_args) -> None:
        self.stopping.set()

    def install_signal_handlers(self) -> None:
        signal.signal(signal.SIGTERM, self.stop)
        signal.signal(signal.SIGINT, self.stop)

    def _send(self, bus: can.BusABC, estimates) -> None:
        for estimate in estimates:
            self.ticks += 1
            if self.csv_writer:
                self.csv_writer.write(estimate)
            if self.on_estimate:
                self.on_estimate(estimate)
            for frame in self.pipeline.encoder.encode(estimate):
                try:
                    bus.send(frame, timeout=0)
                    self.sent += 1
                except can.CanError:
                    self.dropped += 1

    def run(self) -> dict:
        """Open the buses and loop; returns the frame summary when stopped."""
        input_kwargs = self.config.input_bus.kwargs()
        output_kwargs = self.config.output_bus.kwargs()
        bus_in = open_bus(input_kwargs, "input", can_filters=self.pipeline.decoder.can_filters())
        bus_out = bus_in if output_kwargs == input_kwargs else open_bus(output_kwargs, "output")
        log.info("estimating: %s -> %s, filter %s at %.0f Hz", self.config.input_bus.channel,
                 self.config.output_bus.channel, self.config.estimator.filter, self.config.estimator.rate_hz)
        dt = 1.0 / self.config.estimator.rate_hz
        next_status = time.monotonic() + STATUS_EVERY
        try:
            while not self.stopping.is_set():
                msg = bus_in.recv(timeout=dt)
                if msg is not None:
                    self._send(bus_out, self.pipeline.feed(msg))
                else:
                    self._send(bus_out, self.pipeline.advance(time.time() - IDLE_MARGIN))
                if time.monotonic() >= next_status:
                    next_status += STATUS_EVERY
                    log.info("status: %s", self.summary())
        finally:
            bus_in.shutdown()
            if bus_out is not bus_in:
                bus_out.shutdown()
        return self.summary()

    def summary(self) -> dict:
        return {**self.pipeline.summary(), "ticks": self.ticks, "sent": self.sent, "send_dropped": self.dropped}
