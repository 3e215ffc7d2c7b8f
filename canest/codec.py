"""DBC decoding of input frames to SI signals, and encoding the other way.

:class:`InputDecoder` turns a ``can.Message`` into canonical SI values through
the config's signal map, checking integrity and counting every frame it does
not use by cause. :class:`InputEncoder` is its inverse (the simulator writes
logs through it, so a simulated log follows any config's DBC). The encoder of
estimates lives in :mod:`canest.outputs`.
"""
from __future__ import annotations

import math
from collections import Counter

import can

from canest import integrity
from canest.config import Config, ConfigError, MessageChecks, load_database
from canest.plausibility import SlewLimit


def clamp_to_signal(signal, value: float) -> float:
    """Limit a physical value to the signal's DBC range."""
    low = signal.minimum if signal.minimum is not None else -math.inf
    high = signal.maximum if signal.maximum is not None else math.inf
    return min(max(value, low), high)


class _MessagePlan:
    """What to do with one mapped message: its signals, integrity checks and counter state."""

    def __init__(self, message, specs, checks: MessageChecks | None, config_path):
        self.message = message
        self.specs = specs
        self.checks = checks or MessageChecks()
        self.signal_by_name = {s.name: s for s in message.signals}
        self.crc_index = None
        if self.checks.checksum:
            try:
                self.crc_index = integrity.checksum_byte(self.signal_by_name[self.checks.checksum])
            except ValueError as exc:
                raise ConfigError(f"{config_path}: input.messages.{message.name}.checksum: {exc}") from None
        self.last_counter = None
        self.counter_modulus = 2 ** self.signal_by_name[self.checks.counter].length if self.checks.counter else 0


MAX_COUNTER_DELTA = 3  # accept up to two lost frames between consecutive counters (AUTOSAR E2E MaxDeltaCounter)


class InputDecoder:
    """Decode mapped frames into ``[(canonical, si_value), ...]``; count what is not used.

    Counter rule (as AUTOSAR E2E profile 1): the same counter again is rejected
    (a frozen sender); an increment of 2 or 3 is accepted and counted as lost
    frames; a larger jump is rejected (``counter_sequence``) and the new
    value becomes the reference, so a sender that restarted is followed from
    its next frame on. Last, values that change faster than physics allows
    are rejected (``implausible``, :mod:`canest.plausibility`).
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
        self.plausible = SlewLimit(config.signals)
        self.counts = Counter()

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
        if msg.is_fd != plan.message.is_fd:
            return self._reject("fd_mismatch")
        if len(msg.data) != plan.message.length:
            return self._reject("dlc")
        if plan.crc_index is not None and not integrity.checksum_ok(msg.arbitration_id, msg.data, plan.crc_index):
            return self._reject("checksum")
        try:
            values = plan.message.decode(msg.data, decode_choices=False)
        except Exception:  # cantools raises DecodeError and others for malformed payloads
            return self._reject("decode")
        checks = plan.checks
        if checks.valid and not values.get(checks.valid, 1):
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
        for spec in plan.specs:
            if spec.signal not in values:
                continue  # another multiplexer page of this message
            raw = float(values[spec.signal])
            signal = plan.signal_by_name[spec.signal]
            if not math.isfinite(raw):
                return self._reject("non_finite")
            if (signal.minimum is not None and raw < signal.minimum - 1e-9) or \
                    (signal.maximum is not None and raw > signal.maximum + 1e-9):
                return self._reject("out_of_range")
            out.append((spec.canonical, spec.factor * raw + spec.offset))
        if not self.plausible.accept(out, msg.timestamp):
            return self._reject("implausible")
        self.counts["decoded"] += 1
        return out


class InputEncoder:
    """Encode canonical SI values into input frames (the simulator's side of the signal map)."""

    def __init__(self, config: Config):
        self.decoder_plans = InputDecoder(config).plans
        self.counters = {fid: 0 for fid in self.decoder_plans}
        self.pages = {fid: 0 for fid in self.decoder_plans}

    @property
    def messages(self):
        return [plan.message for plan in self.decoder_plans.values()]

    def encode(self, frame_id: int, si_values: dict, timestamp: float, channel: str = "vcan0") -> can.Message:
        plan = self.decoder_plans[frame_id]
        message = plan.message
        pages = sorted({s.multiplexer_value for s in plan.specs if s.multiplexer_value is not None})
        page = pages[self.pages[frame_id] % len(pages)] if pages else None
        self.pages[frame_id] += 1
        values = {}
        for signal in message.signals:
            if signal.multiplexer_ids and page not in signal.multiplexer_ids:
                continue
            values[signal.name] = page if signal.is_multiplexer else clamp_to_signal(signal, 0.0)
        for spec in plan.specs:
            if spec.signal in values and spec.canonical in si_values:
                raw = (si_values[spec.canonical] - spec.offset) / spec.factor
                values[spec.signal] = clamp_to_signal(plan.signal_by_name[spec.signal], raw)
        checks = plan.checks
        if checks.counter:
            values[checks.counter] = self.counters[frame_id]
            self.counters[frame_id] = (self.counters[frame_id] + 1) % plan.counter_modulus
        if checks.valid:
            values[checks.valid] = 1
        data = bytearray(message.encode(values, strict=False))
        if plan.crc_index is not None:
            data = integrity.seal(frame_id, data, plan.crc_index)
        return can.Message(timestamp=timestamp, arbitration_id=frame_id, is_extended_id=message.is_extended_frame,
                           data=bytes(data), is_fd=message.is_fd, channel=channel)
