"""Frames out: estimates as frames of the output DBC, and canonical inputs as frames of the input DBC.

The output DBC is canest's published contract (``dbc/canest_estimates.dbc``);
``OUTPUT_MESSAGES`` names, per message, which estimate field fills which
signal. A message is sent when the running estimator provides all its values;
the status message is sent every tick. Each frame gets its rolling counter and
CRC (:mod:`canest.codec.integrity`). A value that is not a number is sent as 0 with
its validity bit cleared; a value or standard deviation beyond its signal's
range is sent saturated. The online calibration (``CALIBRATION_MESSAGE``, one
multiplexed page per learned parameter) is sent once per its cycle time when
the learner runs and the output DBC has the message; a user's DBC without it
still works, the calibration is then not sent.
"""
from __future__ import annotations

import math

import can

from canest.codec import integrity
from canest.codec.dbc import clamp_to_signal, load_database, tolerated_problems
from canest.codec.decode import InputDecoder
from canest.errors import DbcError
from canest.estimation.estimate import CAN_VALID_BITS, MODES, Estimate
from canest.estimation.learned_parameters import NAMES
from canest.settings import Config
from canest.signals import WHEELS

_WHEEL_SIGNAL = {"fl": "FL", "fr": "FR", "rl": "RL", "rr": "RR"}


def _state_signals(pairs) -> dict:
    """{signal: field} for value, Std and Valid signals of each (signal stem, state) pair."""
    out = {}
    for stem, state in pairs:
        out[stem] = ("value", state)
        out[f"{stem}Std"] = ("value", f"{state}_std")
        out[f"{stem}Valid"] = ("valid", state)
    return out


OUTPUT_MESSAGES = {
    "CE_Velocity": _state_signals([("Vx", "vx"), ("Vy", "vy")]),
    "CE_YawSideslip": _state_signals([("YawRate", "yaw_rate"), ("Sideslip", "beta")]),
    "CE_LateralForcesFront": _state_signals([(f"Fy{_WHEEL_SIGNAL[w]}", f"fy_{w}") for w in ("fl", "fr")]),
    "CE_LateralForcesRear": _state_signals([(f"Fy{_WHEEL_SIGNAL[w]}", f"fy_{w}") for w in ("rl", "rr")]),
    "CE_Friction": {**_state_signals([(f"Mu{_WHEEL_SIGNAL[w]}", f"mu_{w}") for w in WHEELS]),
                    **{f"Mu{_WHEEL_SIGNAL[w]}Observable": ("flag", f"mu_{w}_observable") for w in WHEELS}},
}
STATUS_MESSAGE = "CE_Status"
CAUSE_MESSAGE = "CE_ValidityCause"
CAUSE_SIGNALS = {"VxCause": "vx", "YawRateCause": "yaw_rate", "SideslipCause": "beta", "ForcesCause": "forces",
                 "FrictionCause": "friction"}
STATUS_SIGNALS = ("FilterId", "Mode", "ValidFlags", "MissingInputs", "ResetCount", "InnovationNis")
CALIBRATION_MESSAGE = "CE_Calibration"
CALIBRATION_PAGE = "CalParameter"  # the multiplexer: which learned parameter (its index in NAMES)


def calibration_signal(name: str) -> str:
    """The value signal of a learned parameter in ``CE_Calibration`` (``gyro_bias`` -> ``CalGyroBias``); its std is
    the same name + ``Std``."""
    return "Cal" + "".join(part.capitalize() for part in name.split("_"))


def calibration_pages_missing(signals) -> list:
    """The learned parameters whose page a ``CE_Calibration`` with ``signals`` (names) lacks whole, value and std
    (an older canest's DBC, before a parameter was learned): not sent. A page with one of the two is a gap."""
    return [n for n in NAMES if not {calibration_signal(n), f"{calibration_signal(n)}Std"} & set(signals)]


def integrity_signals(message):
    """The rolling counter and checksum signals of an output message (``*_Counter``, ``*_CRC``)."""
    counter = next(s for s in message.signals if s.name.endswith("_Counter"))
    checksum = next(s for s in message.signals if s.name.endswith("_CRC"))
    return counter, checksum


def contract_gaps(database, broken=None) -> list:
    """What the output DBC lacks of canest's contract: messages, signals, counter and CRC, Mode values; and
    which of its messages are ``broken`` ({message name: problem})."""
    required = {**{name: list(fields) for name, fields in OUTPUT_MESSAGES.items()},
                STATUS_MESSAGE: list(STATUS_SIGNALS), CAUSE_MESSAGE: list(CAUSE_SIGNALS)}
    if CALIBRATION_MESSAGE in {m.name for m in database.messages}:  # optional; each page it has complete
        present = {s.name for s in database.get_message_by_name(CALIBRATION_MESSAGE).signals}
        missing = calibration_pages_missing(present)
        pages = [n for n in NAMES if n not in missing]
        required[CALIBRATION_MESSAGE] = [CALIBRATION_PAGE, "CalLearned", "CalConverged",
                                         *(f"{calibration_signal(n)}{std}" for n in pages for std in ("", "Std"))]
    gaps = []
    for name, signals in required.items():
        try:
            message = database.get_message_by_name(name)
        except KeyError:
            gaps.append(f"message {name}")
            continue
        if name in (broken or {}):
            gaps.append(f"a well-formed message {name} ({broken[name]})")
        present = {s.name: s for s in message.signals}
        gaps += [f"signal {name}.{signal}" for signal in signals if signal not in present]
        gaps += [f"a *_{suffix} signal in {name}" for suffix in ("Counter", "CRC")
                 if not any(s.endswith(f"_{suffix}") for s in present)]
        if name == STATUS_MESSAGE and "Mode" in present:
            named = {str(v) for v in (present["Mode"].choices or {}).values()}
            gaps += [f"value {mode!r} of {name}.Mode" for mode in MODES if mode not in named]
    return gaps


class _Sender:
    """Counter and checksum state of one output message."""

    def __init__(self, message):
        self.message = message
        self.signals = {s.name: s for s in message.signals}
        counter, checksum = integrity_signals(message)
        self.counter_name, self.counter_modulus = counter.name, 2 ** counter.length
        self.crc_name, self.crc_index = checksum.name, integrity.checksum_byte(checksum)
        self.counter = 0
        self.cycle_time = (message.cycle_time or 0) / 1000.0  # s

    def due(self, t: float, next_at: float) -> bool:
        """Whether a message sent at its cycle is due at ``t``, its next send planned at ``next_at``: also where
        ``t`` lies more than a cycle before it, a clock that stepped back (the frames' time base taking over
        from a silent bus's ticks on the service's clock, an adapter's stamps, a log's clock step): planned on
        the old base, it would have been sent on change only until that base's time came round."""
        return t >= next_at or t < next_at - self.cycle_time

    def frame(self, values: dict, timestamp: float, channel) -> can.Message:
        values[self.counter_name] = self.counter
        values[self.crc_name] = 0
        self.counter = (self.counter + 1) % self.counter_modulus
        data = integrity.seal(self.message.frame_id, bytearray(self.message.encode(values, strict=False)),
                              self.crc_index)
        return can.Message(timestamp=timestamp, arbitration_id=self.message.frame_id,
                           is_extended_id=self.message.is_extended_frame, data=data, channel=channel)


class EstimateEncoder:
    """Turn an :class:`Estimate` into the frames of the output DBC."""

    def __init__(self, dbc_path, channel=None):
        self.database = load_database(dbc_path, "output.dbc")
        gaps = contract_gaps(self.database, tolerated_problems(dbc_path, "output.dbc"))
        if gaps:
            raise DbcError(f"{dbc_path}: output DBC lacks {', '.join(gaps)}; start from dbc/canest_estimates.dbc "
                           "(README 'DBC contract')")
        self.channel = channel
        self.senders = {name: _Sender(self.database.get_message_by_name(name))
                        for name in (*OUTPUT_MESSAGES, STATUS_MESSAGE, CAUSE_MESSAGE)}
        status = self.senders[STATUS_MESSAGE].signals
        self.filter_ids = {str(v): k for k, v in (status["FilterId"].choices or {}).items()}
        self.mode_ids = {str(v): k for k, v in status["Mode"].choices.items()}
        self.last_causes, self.next_causes = None, -float("inf")  # CE_ValidityCause: on change, else at its cycle
        self.has_calibration = CALIBRATION_MESSAGE in {m.name for m in self.database.messages}
        self.calibration_missing = []  # learned parameters the DBC's CE_Calibration has no page for
        if self.has_calibration:
            self.senders[CALIBRATION_MESSAGE] = _Sender(self.database.get_message_by_name(CALIBRATION_MESSAGE))
            self.calibration_missing = calibration_pages_missing(self.senders[CALIBRATION_MESSAGE].signals)
        self.next_calibration = -float("inf")

    def encode(self, estimate: Estimate) -> list:
        frames = []
        for name, fields in OUTPUT_MESSAGES.items():
            if not all(key in estimate.values for kind, key in fields.values() if kind == "value"):
                continue
            sender = self.senders[name]
            values = {}
            for signal_name, (kind, key) in fields.items():
                if kind == "value":
                    value = estimate.values[key]
                    values[signal_name] = clamp_to_signal(sender.signals[signal_name], value) if math.isfinite(value) else 0.0
                elif kind == "flag":
                    values[signal_name] = int(bool(estimate.valid.get(key, False)))
                else:
                    finite = math.isfinite(estimate.values[key])
                    values[signal_name] = int(bool(estimate.valid.get(key, False)) and finite)
            frames.append(sender.frame(values, estimate.t, self.channel))
        status = self.senders[STATUS_MESSAGE]
        frames.append(status.frame({
            "FilterId": self.filter_ids.get(estimate.filter, 0),
            "Mode": self.mode_ids[estimate.mode],
            "ValidFlags": estimate.valid_flags & ((1 << CAN_VALID_BITS) - 1),
            "MissingInputs": estimate.missing_mask,
            "ResetCount": min(estimate.resets, 255),
            "InnovationNis": clamp_to_signal(status.signals["InnovationNis"], estimate.nis),
        }, estimate.t, self.channel))
        causes = {signal: estimate.cause_code(group) for signal, group in CAUSE_SIGNALS.items()}
        sender = self.senders[CAUSE_MESSAGE]
        if causes != self.last_causes or sender.due(estimate.t, self.next_causes):
            frames.append(sender.frame(dict(causes), estimate.t, self.channel))
            self.last_causes, self.next_causes = causes, estimate.t + sender.cycle_time
        if (self.has_calibration and estimate.calibration
                and self.senders[CALIBRATION_MESSAGE].due(estimate.t, self.next_calibration)):
            frames += self._calibration_frames(estimate)
        return frames

    def _calibration_frames(self, estimate: Estimate) -> list:
        """One ``CE_Calibration`` page per learned parameter the DBC has: value, std, learned and converged flags."""
        sender = self.senders[CALIBRATION_MESSAGE]
        self.next_calibration = estimate.t + sender.cycle_time
        frames = []
        for page, name in enumerate(NAMES):
            if name in self.calibration_missing:
                continue
            signal, report = calibration_signal(name), estimate.calibration
            frames.append(sender.frame({
                CALIBRATION_PAGE: page,
                signal: clamp_to_signal(sender.signals[signal], report[f"calib_{name}"]),
                f"{signal}Std": clamp_to_signal(sender.signals[f"{signal}Std"], report[f"calib_{name}_std"]),
                "CalLearned": int(report[f"calib_{name}_learned"]),
                "CalConverged": int(report[f"calib_{name}_converged"]),
            }, estimate.t, self.channel))
        return frames


def _encodable(signal) -> tuple:
    """(lowest, highest) physical value the signal's bits can hold (a DBC's declared range may say less or more)."""
    if signal.is_float:
        return -math.inf, math.inf
    bits = signal.length
    raw = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signal.is_signed else (0, (1 << bits) - 1)
    low, high = sorted(r * signal.scale + signal.offset for r in raw)
    return low, high


class InputEncoder:
    """Encode canonical SI values into input frames (the simulator's side of the signal map)."""

    def __init__(self, config: Config):
        self.decoder_plans = InputDecoder(config).plans
        self.counters = {fid: 0 for fid in self.decoder_plans}
        self.pages = {fid: 0 for fid in self.decoder_plans}

    @property
    def messages(self):
        return [plan.message for plan in self.decoder_plans.values()]

    @staticmethod
    def _parts(plan, spec, value: float) -> dict:
        """DBC values of the signals adding up to ``value``: each but the last takes what its resolution carries of
        the rest (coarse + fine steering), every one within what its bits hold and, unless the config replaced the
        range, within its DBC range (a sender keeps to what it can send, not to the config's range)."""
        parts, rest = {}, value
        for i, name in enumerate(spec.names):
            signal = plan.signal_by_name[name]
            part = rest if i == len(spec.names) - 1 else round(rest / signal.scale) * signal.scale
            lowest, highest = _encodable(signal)
            part = min(max(part, lowest), highest)
            parts[name] = part if spec.range_given else clamp_to_signal(signal, part)
            rest -= parts[name]
        return parts

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
                values.update(self._parts(plan, spec, (si_values[spec.canonical] - spec.offset) / spec.factor))
        checks = plan.checks
        if checks.counter:
            values[checks.counter] = self.counters[frame_id]
            self.counters[frame_id] = (self.counters[frame_id] + 1) % plan.counter_modulus
        for valid in [checks.valid, *(spec.valid for spec in plan.specs)]:
            if valid:
                values[valid.signal] = valid.values[0] if valid.values else 1
        data = bytearray(message.encode(values, strict=False))
        if plan.checksum is not None:
            data = plan.checksum.seal(frame_id, data)
        return can.Message(timestamp=timestamp, arbitration_id=frame_id, is_extended_id=message.is_extended_frame,
                           data=bytes(data), is_fd=message.is_fd if plan.is_fd is None else plan.is_fd,
                           channel=channel)
