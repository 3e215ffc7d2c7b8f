"""The live daemon: frames from a python-can bus, estimate frames to a bus.

Ticks follow the receive timestamps of the frames (the kernel's on SocketCAN),
exactly as replay follows log timestamps, so a log played onto a bus gives the
estimates an offline replay of it gives. The loop waits for frames only until
the next tick is due (plus ``TICK_MARGIN``): when the socket has been empty
that long, every frame stamped before the tick has been read, so the tick runs
at once instead of waiting for a later frame. This bounds the input-to-output
latency to about ``TICK_MARGIN`` plus the processing time, keeps ticking on an
idle bus (stale inputs lose their validity bits), and leaves the estimates
identical to replay's. Before the first frame (the vehicle off, a cable not yet
connected) it ticks on ``clock`` and publishes every tick as ``no_input``, so
the output bus shows a running daemon waiting for its car; the first frame
anchors the grid of the frames' own time base (:meth:`Pipeline.advance`).

What the loop guarantees:

- it never blocks on output: a frame the output bus refuses is dropped and
  counted (:mod:`canest.io.bus`), and a lost bus is reopened with backoff;
- it transmits at most one set of estimate frames per loop pass, the newest:
  when several ticks complete at once (after a stall) the older ones are
  logged to the CSV but not sent (``superseded``), so the output never bursts
  above the DBC cycle rate whatever arrives;
- systemd: READY=1 once the buses are open and the first valid estimate is
  out, WATCHDOG=1 from the loop itself (a hung loop is restarted, an idle bus
  is not), STATUS= with input rate, tick rate and mode;
- SIGTERM/SIGINT stop it cleanly: the frames queued on the input bus at the stop are still decoded and
  estimated, for at most ``DRAIN_SECONDS`` (:meth:`Service._drain`; the systemd units allow 10 s to stop);
  SIGHUP reloads the config (buses are
  reopened only if their settings changed; a broken config, or one whose
  buses do not open, is logged and the running one kept: :meth:`Service._new_links`);
  SIGUSR1 logs the status now.
"""
from __future__ import annotations

import logging
import math
import signal
import threading
import time
from collections import Counter, deque

import numpy as np

from canest.codec.decode import InputDecoder
from canest.io.bus import BusLink
from canest.io.sinks import BusSink
from canest.errors import BusOpenError, CanestError, ConfigError
from canest.settings import Config
from canest.apps.notify import Notifier
from canest.pipeline import Pipeline, format_summary

log = logging.getLogger("canest.apps.service")

TICK_MARGIN = 0.001  # s after a tick's time before it runs without a later frame
STATUS_EVERY = 10.0  # s between status log lines
NOTIFY_STATUS_EVERY = 1.0  # s between STATUS= updates to systemd
DRAIN_SECONDS = 2.0  # s a stop reads on the frames queued before it, at most
DRAIN_QUIET = 0.01  # s without a mapped frame that ends the drain (a shorter wait ends it at an unmapped one)
LATENCY_WINDOW = 10_000  # send latencies kept for percentiles, cleared at every status line
# interfaces whose handles on one channel open and close independently: a reload opens its buses beside them
SHARED_CHANNEL_INTERFACES = ("socketcan", "virtual", "udp_multicast")


class StartupSignals:
    """The signals that reach ``canest run`` while it starts (config, DBCs, filter: 1-2 s), before :class:`Service`
    takes them over: their default action ends the process, so a ``systemctl reload`` or ``kill -USR1`` sent then
    killed the daemon (exit 129, 138) and a SIGTERM ended it without its summary. A stop is remembered for the
    service (:meth:`hand_over`); a reload or a status request is moot (the config being read is the newest)."""

    def __init__(self):
        self.stop_requested = False
        signal.signal(signal.SIGTERM, self._stop)
        signal.signal(signal.SIGINT, self._stop)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
        signal.signal(signal.SIGUSR1, signal.SIG_IGN)

    def _stop(self, *_args) -> None:
        self.stop_requested = True

    def hand_over(self, service: Service) -> None:
        """``service`` takes the signals; one asked to stop already stops at once."""
        service.install_signal_handlers()
        if self.stop_requested:
            service.stop()


class Service:
    """Run the pipeline on live buses until :meth:`stop` (or SIGINT/SIGTERM) is called.

    Every tick's estimates go to ``sinks`` (:mod:`canest.io.sinks`, e.g. a CSV
    or a callback) and the newest of each pass to the output bus.
    ``reload_config`` (no arguments, returns a Config) is called on SIGHUP.
    ``clock`` is the time base of the input frames' timestamps, read when the bus is idle: ``time.time`` for
    SocketCAN's and python-can's receive stamps; before the first frame it alone times the ``no_input`` ticks.
    :meth:`wait_until_listening` tells a thread that plays frames in when to start: a bus gives a frame only to
    the receivers open when it is sent.
    """

    def __init__(self, config: Config, sinks=(), reload_config=None, notifier=None, clock=time.time):
        self.config = config
        self.clock = clock
        self.pipeline = Pipeline(config, output_channel=config.output_bus.channel)
        self.sinks = list(sinks)
        self.reload_config = reload_config
        self.notifier = notifier or Notifier()
        self.stopping = threading.Event()
        self.listening = threading.Event()  # set once, when run() has opened the buses (not cleared after)
        self.reload_requested = threading.Event()
        self.status_requested = threading.Event()
        self.counts = Counter(ticks=0, sent=0, send_dropped=0, superseded=0)
        self.earlier = Counter()  # summaries of pipelines replaced by a reload
        self.latency = deque(maxlen=LATENCY_WINDOW)
        self.ready = False
        self.inputs = self.outputs = self.bus_sink = None

    def stop(self, *_args) -> None:
        self.stopping.set()

    def wait_until_listening(self, timeout: float) -> bool:
        """Wait until :meth:`run` has opened the buses (True), or it stopped or failed to open them, or ``timeout``
        s passed (False)."""
        deadline = time.monotonic() + timeout
        while not self.listening.wait(0.05):
            if self.stopping.is_set() or time.monotonic() > deadline:
                return False
        return True

    def install_signal_handlers(self) -> None:
        signal.signal(signal.SIGTERM, self.stop)
        signal.signal(signal.SIGINT, self.stop)
        signal.signal(signal.SIGHUP, lambda *_: self.reload_requested.set())
        signal.signal(signal.SIGUSR1, lambda *_: self.status_requested.set())

    def _open(self) -> None:
        self._use(self._links(self.config, self.pipeline.decoder.can_filters()))

    def _links(self, config: Config, can_filters) -> tuple:
        """(input, output) links opened for ``config``'s buses (one if they are the same); the input one closed
        again if the output one does not open."""
        input_kwargs, output_kwargs = config.input_bus.kwargs(), config.output_bus.kwargs()
        inputs = BusLink(input_kwargs, "input", self.counts, can_filters=can_filters)
        if output_kwargs == input_kwargs:
            return inputs, inputs
        try:
            return inputs, BusLink(output_kwargs, "output", self.counts)
        except BaseException:
            inputs.close()
            raise

    def _use(self, links: tuple) -> None:
        self.inputs, self.outputs = links
        self.bus_sink = BusSink(self.outputs, self.pipeline.encoder, self.counts)

    def _close(self) -> None:
        if self.inputs is not None:
            self.earlier["input_kernel_dropped"] += self.inputs.kernel_dropped()
        for link in {id(self.inputs): self.inputs, id(self.outputs): self.outputs}.values():
            if link is not None:
                link.close()
        self.inputs = self.outputs = None

    def _publish(self, estimates) -> None:
        self.counts["ticks"] += len(estimates)
        for sink in (*self.sinks, self.bus_sink):
            sink.publish(estimates)
        newest = estimates[-1]
        self.latency.append(self.clock() - newest.t)
        if not self.ready and any(newest.valid.values()):
            self.ready = True
            self.notifier.notify(READY=1, STATUS="estimating")
            log.info("first valid estimate sent: ready")

    def run(self) -> dict:
        """Open the buses and loop; returns the frame summary when stopped."""
        try:
            self._open()
        except BaseException:
            self.stopping.set()  # a thread waiting for the buses returns
            raise
        self.listening.set()
        log.info("estimating: %s -> %s, filter %s at %.0f Hz", self.config.input_bus.channel,
                 self.config.output_bus.channel, self.config.estimator.filter, self.config.estimator.rate_hz)
        schedule = _Schedule(self.notifier.watchdog_interval)
        try:
            now = self.clock()
            while not self.stopping.is_set():
                msg = self.inputs.recv(self._wait(now))
                if msg is not None:
                    estimates = self.pipeline.feed(msg)
                    # the kernel's receive time: no clock read per frame (a non-finite one was rejected)
                    now = msg.timestamp if math.isfinite(msg.timestamp) else self.clock()
                else:
                    now = self.clock()
                    estimates = self.pipeline.advance(now - TICK_MARGIN)
                if estimates:
                    self._publish(estimates)
                if estimates or msg is None:  # at most once a tick or an idle wait, not once a frame
                    self._housekeeping(schedule)
            self._drain()
        finally:
            self.pipeline.close()  # the online calibration saved
            self._close()
            self.notifier.notify(STOPPING=1)
        return self.summary()

    def _drain(self) -> None:
        """Decode and estimate the frames queued on the input bus at a stop, until a quiet :data:`DRAIN_QUIET` s,
        for at most :data:`DRAIN_SECONDS` (then it says so); where the bus stamps frames when they arrive
        (:attr:`BusLink.stamps_at_receive`, on :attr:`clock`'s time base), up to the first that arrived after
        the stop (counted ``after_stop``), so a live bus, which never falls silent, does not hold the stop. Not
        on a lost bus (reopened at a stop it would only delay it). The wait is not zero: python-can returns no
        frame from a zero wait that met a frame its software filters drop (virtual buses, udp_multicast), with
        mapped frames still queued behind it."""
        if not self.inputs.up:
            return
        stopped_at = self.clock() if self.inputs.stamps_at_receive else math.inf
        deadline, read = time.monotonic() + DRAIN_SECONDS, 0
        while (msg := self.inputs.recv(DRAIN_QUIET)) is not None:
            if math.isfinite(msg.timestamp) and msg.timestamp > stopped_at:
                self.counts["after_stop"] += 1  # the bus goes on, the daemon does not
                break
            read += 1
            estimates = self.pipeline.feed(msg)
            if estimates:
                self._publish(estimates)
            if time.monotonic() > deadline:
                log.warning("stopping: %d frames read in %.0f s after the stop, the rest left unread", read,
                            DRAIN_SECONDS)
                return
        if read:
            log.info("stopping: %d frames read after the stop", read)

    def _wait(self, now: float) -> float:
        """Seconds to wait for a frame after ``now``: until the next tick is due, at most one tick period.

        ``now`` is the receive time of the last frame while frames flow: the clock is read only after an
        idle wait (a clock read is a system call in some virtual machines, costlier than decoding a frame).
        While frames queue up a stale ``now`` costs nothing (the socket is not empty); when the bus falls
        silent the first wait is at most one period."""
        period = 1.0 / self.config.estimator.rate_hz
        due = self.pipeline.next_tick + TICK_MARGIN - now
        return min(max(due, 0.0), period)

    def _housekeeping(self, schedule: "_Schedule") -> None:
        now = time.monotonic()
        if schedule.due("watchdog", now):
            self.notifier.notify(WATCHDOG=1)
        if schedule.due("notify_status", now):
            self.notifier.notify(STATUS=self._status_line(schedule.rates(self.summary(), now)))
        if schedule.due("log_status", now) or self.status_requested.is_set():
            self.status_requested.clear()
            log.info("status: %s | latency %s", format_summary(self.summary()), self.latency_text())
            self.latency.clear()  # each status line reports the latency since the previous one
        if self.reload_requested.is_set():
            self.reload_requested.clear()
            self._reload()

    def _status_line(self, rates) -> str:
        mode = self.pipeline.estimator.last_mode
        return f"mode {mode}, input {rates['frames']:.0f} frames/s, {rates['ticks']:.0f} ticks/s"

    def latency_text(self) -> str:
        if not self.latency:
            return "-"
        ms = np.array(self.latency) * 1e3
        return f"p50 {np.median(ms):.2f} ms, p99 {np.percentile(ms, 99):.2f} ms, max {ms.max():.2f} ms"

    def _reload(self) -> None:
        if self.reload_config is None:
            log.warning("SIGHUP: no config to reload from")
            return
        try:
            config = self.reload_config()
        except (CanestError, OSError, ValueError) as exc:
            return self._reload_failed(exc)
        buses_changed = (config.input_bus, config.output_bus) != (self.config.input_bus, self.config.output_bus)
        links = None
        if buses_changed:
            try:
                links = self._new_links(config)
            except (BusOpenError, ConfigError) as exc:
                return self._reload_failed(exc)
        self.earlier.update({k: v for k, v in self.pipeline.summary().items() if isinstance(v, int)})
        self.config = config
        self.pipeline.close()  # saved, so the new pipeline's calibration starts from what this one learned
        self.pipeline = Pipeline(config, output_channel=config.output_bus.channel)
        if links is not None:
            self._close()
            self._use(links)
        else:  # the same buses: the input takes the messages the new config maps
            self.inputs.set_filters(self.pipeline.decoder.can_filters())
            self.bus_sink.encoder = self.pipeline.encoder
        self.counts["reloads"] += 1
        log.info("config reloaded from %s%s", config.path, "; buses reopened" if buses_changed else "")

    def _reload_failed(self, exc: Exception) -> None:
        self.counts["reload_failed"] += 1
        log.error("reload failed, keeping the running config: %s", exc)

    def _new_links(self, config: Config) -> tuple:
        """The reloaded ``config``'s links. Opened beside the running ones, so that buses which do not open change
        nothing, where every channel they share with them is on an interface that takes several handles per
        channel (:data:`SHARED_CHANNEL_INTERFACES`). An adapter that takes one (PCAN, Vector: a second open is
        refused; slcan on Linux: it opens, and closing the first then closes the adapter's CAN channel) has the
        running links closed first, and if the new ones do not open the running config's are opened again (if
        those do not either, the daemon ends)."""
        filters = InputDecoder(config).can_filters()
        running = {_device(link.kwargs) for link in (self.inputs, self.outputs)}
        wanted = {_device(bus.kwargs()) for bus in (config.input_bus, config.output_bus)}
        if all(interface in SHARED_CHANNEL_INTERFACES for interface, _ in running & wanted):
            return self._links(config, filters)
        self._close()
        try:
            return self._links(config, filters)
        except BusOpenError:
            self._open()
            raise

    def summary(self) -> dict:
        merged = Counter(self.earlier)
        merged.update({k: v for k, v in self.pipeline.summary().items() if isinstance(v, int)})
        merged.update(self.counts)
        merged["input_kernel_dropped"] += self.inputs.kernel_dropped() if self.inputs is not None else 0
        return dict(merged)


class _Schedule:
    """Fixed-interval events of the loop, and input/tick rates between status updates."""

    def __init__(self, watchdog_interval):
        intervals = {"notify_status": NOTIFY_STATUS_EVERY, "log_status": STATUS_EVERY}
        if watchdog_interval:
            intervals["watchdog"] = watchdog_interval
        now = time.monotonic()
        self.intervals = intervals
        self.next = {name: now + interval for name, interval in intervals.items()}
        self.previous = ({}, now)

    def due(self, name: str, now: float) -> bool:
        if name not in self.next or now < self.next[name]:
            return False
        self.next[name] = now + self.intervals[name]
        return True

    def rates(self, summary: dict, now: float) -> dict:
        before, then = self.previous
        self.previous = (summary, now)
        span = max(now - then, 1e-9)
        return {key: (summary.get(key, 0) - before.get(key, 0)) / span for key in ("frames", "ticks")}


def _device(kwargs: dict) -> tuple:
    """(interface, channel) of a bus's python-can arguments."""
    return kwargs.get("interface"), str(kwargs.get("channel"))
