"""DBC decoding of input frames to SI signals.

:class:`InputDecoder` turns a ``can.Message`` into canonical SI values through
the config's signal map, checking integrity and counting every frame it does
not use by cause, and answers the timeouts of its inputs. Its inverse,
:class:`canest.codec.encode.InputEncoder`, lets the simulator write logs
through any config's DBC.
"""
from __future__ import annotations

import math
from collections import Counter

import can

from canest.codec.checksums import make_checksum
from canest.codec.cycle_watch import CycleWatch
from canest.codec.dbc import load_database
from canest.codec.plausibility import SlewLimit
from canest.codec.sample_checks import MOVING_WHEEL_SPEED, SignalBounds, StuckDetector
from canest.errors import ConfigError
from canest.settings import Config, MessageChecks
from canest.signals import INPUT_GROUPS


class _MessagePlan:
    """What to do with one mapped message: its signals, integrity checks and counter state."""

    def __init__(self, message, specs, checks: MessageChecks | None, config_path):
        self.message = message
        self.specs = specs
        self.checks = checks or MessageChecks()
        self.signal_by_name = {s.name: s for s in message.signals}
        # per mapped signal, fixed at start-up: (spec, the DBC signals adding up to its value, its bounds)
        self.signals = [(spec, spec.names, SignalBounds(spec.range, self.signal_by_name[spec.signal].scale))
                        for spec in specs]
        self.checksum = None  # resolved once: per frame only its ok() runs
        if self.checks.checksum:
            where = f"{config_path}: input.messages.{message.name}.checksum"
            try:
                self.checksum = make_checksum(self.checks.checksum_algorithm, self.checks.crc,
                                              self.signal_by_name[self.checks.checksum], message.length, where)
            except ValueError as exc:
                raise ConfigError(f"{where}: {exc}") from None
        self.last_counter = None
        self.counter_modulus = 2 ** self.signal_by_name[self.checks.counter].length if self.checks.counter else 0
        self.is_fd = {"dbc": message.is_fd, "fd": True, "classic": False}.get(self.checks.fd)  # None: any

    def cycle_time(self) -> tuple:
        """(seconds between frames, where that comes from: ``config``, ``DBC`` or ``default``)."""
        if self.checks.cycle_time is not None:
            return self.checks.cycle_time, "config"
        if self.message.cycle_time:
            return self.message.cycle_time / 1000.0, "DBC"
        return DEFAULT_CYCLE_TIME, "default"


DEFAULT_CYCLE_TIME = 0.1  # s, for messages whose DBC gives no GenMsgCycleTime
MIN_TIMEOUT = 0.05  # s
MAX_COUNTER_DELTA = 3  # accept up to two lost frames between consecutive counters (AUTOSAR E2E MaxDeltaCounter)


def timeout(cycle_time: float, timeout_cycles: float) -> float:
    """How long an input counts as fresh: ``timeout_cycles`` of its message's cycle, at least ``MIN_TIMEOUT``."""
    return max(timeout_cycles * cycle_time, MIN_TIMEOUT)


class InputDecoder:
    """Decode mapped frames into ``[(canonical, si_value), ...]``; count what is not used.

    Counter rule (as AUTOSAR E2E profile 1): the same counter again is rejected
    (a frozen sender); an increment of 2 or 3 is accepted and counted as lost
    frames; a larger jump is rejected (``counter_sequence``) and the new
    value becomes the reference, so a sender that restarted is followed from
    its next frame on. Last, values that change faster than physics allows
    are rejected (``implausible``, :mod:`canest.codec.plausibility`). A value
    at a limit of its DBC range is passed on but named in ``last_saturated``
    (counted ``saturated_samples``): the estimator does not take it as a measurement.
    """

    def __init__(self, config: Config):
        self.database = load_database(config.input_dbc, f"{config.path}: input.dbc")
        by_message = {}
        for spec in config.signals.values():
            by_message.setdefault(spec.message, []).append(spec)
        self.plans = {}
        for name, specs in by_message.items():
            message = self.database.get_message_by_name(name)
            self.plans[message.frame_id] = _MessagePlan(message, specs, config.messages.get(name), config.path)
        self.frame_of = {spec.canonical: fid for fid, plan in self.plans.items() for spec in plan.specs}
        self.plausible = SlewLimit(config.signals)
        self.stuck = StuckDetector({s.canonical: s.stuck_after for s in config.signals.values() if s.stuck_after})
        self.wheel_speeds = {}  # canonical -> latest decoded value: whether the car moves
        self.counts = Counter()
        self.last_saturated = frozenset()  # canonical inputs of the last decoded frame that sat at a limit of its range
        self.cycles = CycleWatch({fid: plan.cycle_time() for fid, plan in self.plans.items()},
                                 {fid: plan.message.name for fid, plan in self.plans.items()})

    @property
    def moving(self) -> bool:
        speeds = self.wheel_speeds.values()
        return bool(speeds) and sum(abs(w) for w in speeds) / len(speeds) > MOVING_WHEEL_SPEED

    def cycle_time(self, canonical: str) -> float:
        """Seconds between frames of the message carrying ``canonical`` (the config's, the DBC's, else
        ``DEFAULT_CYCLE_TIME``)."""
        return self.plans[self.frame_of[canonical]].cycle_time()[0]

    def timeouts(self, timeout_cycles: float) -> dict:
        """Per canonical input: ``timeout_cycles`` times its message's cycle time (at least ``MIN_TIMEOUT``)."""
        return {name: timeout(self.cycle_time(name), timeout_cycles) for name in self.frame_of}

    def measured_timeouts(self, frame_id: int, t: float, timeout_cycles: float) -> dict:
        """Note the time of a decoded frame of ``frame_id``; once a message whose cycle was only the default has
        been measured (:class:`~canest.codec.cycle_watch.CycleWatch`), its inputs' new timeouts, else ``{}``."""
        measured = self.cycles.observe(frame_id, t)
        if measured is None:
            return {}
        return {spec.canonical: timeout(measured, timeout_cycles) for spec in self.plans[frame_id].specs}

    @property
    def frame_ids(self):
        return sorted(self.plans)

    def can_filters(self) -> list:
        """python-can filters that pass only the mapped IDs (kernel filters on SocketCAN)."""
        return [{"can_id": fid, "can_mask": 0x1FFFFFFF if fid > 0x7FF else 0x7FF, "extended": fid > 0x7FF}
                for fid in self.frame_ids]

    def _reject(self, cause: str):
        self.counts[f"rejected_{cause}"] += 1
        return None

    def decode(self, msg: can.Message):
        """SI values of the mapped signals in ``msg``, or None if the frame is not used."""
        self.counts["frames"] += 1
        if msg.is_error_frame:
            return self._reject("error_frame")
        plan = self.plans.get(msg.arbitration_id)
        if plan is None or msg.is_extended_id != plan.message.is_extended_frame:
            self.counts["ignored_id"] += 1
            return None
        if msg.is_remote_frame:
            return self._reject("remote_frame")
        if plan.is_fd is not None and msg.is_fd != plan.is_fd:
            return self._reject("fd_mismatch")
        if len(msg.data) != plan.message.length:
            return self._reject("dlc")
        if plan.checksum is not None and not plan.checksum.ok(msg.arbitration_id, msg.data):
            return self._reject("checksum")
        try:
            values = plan.message.decode(msg.data, decode_choices=False)
        except Exception:  # cantools raises DecodeError and others for malformed payloads
            return self._reject("decode")
        checks = plan.checks
        if checks.valid and not checks.valid.accepts(values):
            return self._reject("invalid_flag")
        if checks.counter:
            counter = int(values[checks.counter])
            last, plan.last_counter = plan.last_counter, counter
            if last is not None:
                delta = (counter - last) % plan.counter_modulus
                if delta == 0:
                    return self._reject("counter_repeated")
                if delta > MAX_COUNTER_DELTA:
                    return self._reject("counter_sequence")
                if delta > 1:
                    self.counts["counter_jumps"] += 1
        out = []
        saturated = []
        dropped = Counter()
        for spec, names, bounds in plan.signals:
            try:
                raw = float(sum(map(values.__getitem__, names)))
            except KeyError:
                continue  # another multiplexer page of this message
            if not math.isfinite(raw):
                return self._reject("non_finite")
            if bounds.outside(raw):
                return self._reject("out_of_range")
            if spec.valid and not spec.valid.accepts(values):
                dropped["invalid_signal"] += 1
                continue
            if spec.stuck_after and self.stuck.stuck(spec.canonical, raw, msg.timestamp, self.moving):
                dropped["stuck"] += 1
                continue
            if bounds.at_limit(raw):
                saturated.append(spec.canonical)
            out.append((spec.canonical, spec.factor * raw + spec.offset))
        self.last_saturated = frozenset(saturated)
        if saturated:
            self.counts["saturated_samples"] += len(saturated)
        for cause, count in dropped.items():
            self.counts[f"{cause}_samples"] += count
        if dropped and not out:
            return self._reject(next(iter(dropped)))
        plausible = self.plausible.accept(out, msg.timestamp)
        if out and not plausible:
            return self._reject("implausible")
        self.counts["implausible_samples"] += len(out) - len(plausible)
        self.counts["decoded"] += 1
        self.wheel_speeds.update((name, value) for name, value in plausible if name in INPUT_GROUPS["wheel_speeds"])
        return plausible
