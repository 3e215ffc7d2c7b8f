"""decode -> resample -> estimate -> encode, the same for live and replay.

Feed frames in time order with :meth:`Pipeline.feed`; it returns the
estimates of every tick that completed before the frame (a tick at time T
uses every frame stamped <= T). A live source with an idle bus calls
:meth:`Pipeline.advance` so ticks still happen and stale inputs are noticed;
a frame stamped at or before a tick that already ran that way is used in the
next tick and counted ``late_frames`` (replay never has one). Before the
first frame, ``advance`` ticks on the source's clock, every tick ``no_input``
(a silent bus), and the first frame anchors the frames' grid as in replay.
Where frames come from and where estimates go is the caller's business.
"""
from __future__ import annotations

import math
from collections import Counter

import can

from canest.codec.decode import InputDecoder
from canest.codec.encode import EstimateEncoder
from canest.estimation.catalog import make_estimator
from canest.estimation.leveling import AccelerometerLeveling
from canest.estimation.online_calibration import make_calibration
from canest.resample import Resampler, TickClock
from canest.settings import Config


class Pipeline:
    def __init__(self, config: Config, output_channel=None):
        self.config = config
        self.decoder = InputDecoder(config)
        self.resampler = Resampler(config.signals, self.decoder.timeouts(config.estimator.timeout_cycles))
        self.estimator = make_estimator(config)
        self.leveling = AccelerometerLeveling(config.vehicle, self.resampler.names)  # the body's tilt out of ax, ay
        self.calibration = make_calibration(config, self.resampler.names)  # corrects each sample before a step
        self.encoder = EstimateEncoder(config.output_dbc, output_channel)
        self.clock = TickClock(1.0 / config.estimator.rate_hz)
        self.idle_clock = TickClock(self.clock.dt)  # the ticks before the first frame: :meth:`advance`
        self.counts = Counter()
        self.last_time = None
        self.last_tick = None  # the latest tick estimated
        self.ticked = 0  # ticks run: the drive's length for the reset rate

    def _ticks(self, t: float) -> list:
        jumps = self.clock.jumps
        ticks = list(self.clock.due(t))
        estimates = [self._step(tick) for tick in ticks]
        self.ticked += len(estimates)
        if self.clock.jumps != jumps:
            self.counts["time_jumps"] += 1
            self.estimator.reset()
            self.last_tick = None  # a new grid: no frame is late for the old one
        elif ticks:
            self.last_tick = ticks[-1]  # the tick's own float: t0 + k dt, not next_tick - dt
        return estimates

    def _step(self, tick: float):
        """One tick's estimate on the inputs held at ``tick``, levelled and corrected (the learner takes them)."""
        return self._estimate(self.calibration.correct(self.leveling.level(self.resampler.sample(tick))))

    def _estimate(self, sample):
        """The estimator's step on ``sample``, carrying the online calibration's report when the learner runs."""
        if self.calibration.enabled:
            self.estimator.use_stiffness(*self.calibration.stiffness, self.calibration.stiffness_error)
            self.estimator.use_kinematic_offsets(*self.calibration.kinematic_offsets)
            self.estimator.use_correction_std(*self.calibration.correction_std)
        estimate = self.estimator.step(sample)
        if self.calibration.enabled:
            estimate.calibration = self.calibration.report()
        return estimate

    def feed(self, msg: can.Message) -> list:
        t = msg.timestamp
        if not math.isfinite(t):  # no place in time: one rejected frame, not a clock that later frames fall behind
            self.decoder.counts.update(("frames", "rejected_timestamp"))
            return []
        if self.last_time is not None and t < self.last_time:
            self.counts["time_backwards"] += 1
        elif self.last_tick is not None and t <= self.last_tick:
            # its tick already ran without it: a live source advanced the clock on an idle bus (advance) before
            # this frame was read; replay would have used it in that tick, so here live and replay part
            self.counts["late_frames"] += 1
        self.last_time = t if self.last_time is None else max(self.last_time, t)
        values = self.decoder.decode(msg)
        if values is not None:
            self._watch_cycle(msg.arbitration_id, t)
        estimates = self._ticks(t)
        if values:
            for name, value in values:
                self.resampler.hold(name, value, t, name in self.decoder.last_saturated)
        return estimates

    def _watch_cycle(self, frame_id: int, t: float) -> None:
        """Where only the default cycle was assumed, the inputs' timeouts follow the measured one."""
        for name, seconds in self.decoder.measured_timeouts(frame_id, t, self.config.estimator.timeout_cycles).items():
            self.resampler.set_timeout(name, seconds)

    def advance(self, t: float) -> list:
        """Ticks strictly before ``t`` with no new frame (idle bus).

        Before the first frame (a silent bus: the vehicle off, a cable not yet connected) they lie on a grid of
        their own, anchored at the first ``t`` (the live source's clock), and each says ``no_input``, so a daemon
        waiting for its car is seen running. They touch neither the frames' grid nor the learner: the first frame
        anchors that grid at its own timestamp, as in replay, whatever the base of the source's clock (an
        adapter's stamps need not be on it), so the idle phase is no time jump, no step back and makes no frame
        late, and the ticks from there are replay's."""
        if self.clock.t0 is None:
            return [self._estimate(self.resampler.sample(tick)) for tick in self.idle_clock.due(t)]
        return self._ticks(t)

    @property
    def next_tick(self) -> float:
        """When the next tick falls due: on the frames' grid, before the first frame on the idle one (inf until
        :meth:`advance` anchored it)."""
        return (self.idle_clock if self.clock.t0 is None else self.clock).next_tick

    def close(self) -> None:
        """At shutdown: the online calibration saves its state."""
        self.calibration.close()

    def summary(self) -> dict:
        """Every frame accounted for: decoded, ignored by ID, rejected by cause; and timing events."""
        repairs = self.estimator.filter.repairs if self.estimator.filter is not None else 0
        summary = {**self.decoder.counts, **self.counts, "resets": self.estimator.resets, "repairs": repairs}
        store = self.calibration.store
        if store is not None and store.failed_saves:
            summary["state_save_failures"] = store.failed_saves  # warned as they happened; the estimation went on
        hours = self.ticked * self.clock.dt / 3600.0
        if self.estimator.resets and hours:
            summary["resets_per_hour"] = round(self.estimator.resets / hours, 1)  # divergence resets, per hour driven
        return summary


def format_summary(summary: dict) -> str:
    """One line: every input frame accounted for (decoded, ignored by ID, rejected by cause) and events."""
    parts = [f"{k}={v}" for k, v in sorted(summary.items()) if k != "frames" and v]
    return " ".join([f"frames={summary.get('frames', 0)}", *parts])
