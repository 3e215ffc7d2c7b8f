"""Estimates out: frames of the output DBC, and the per-tick CSV.

The output DBC is canest's published contract (``dbc/canest_estimates.dbc``);
``OUTPUT_MESSAGES`` names, per message, which estimate field fills which
signal. A message is sent when the running estimator provides all its values;
the status message is sent every tick. Each frame gets its rolling counter and
CRC (:mod:`canest.integrity`). A value that is not a number is sent as 0 with
its validity bit cleared; a value or standard deviation beyond its signal's
range is sent saturated.
"""
from __future__ import annotations

import csv
import math

import can

from canest import integrity
from canest.codec import clamp_to_signal
from canest.config import load_database
from canest.estimator import Estimate
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


def integrity_signals(message):
    """The rolling counter and checksum signals of an output message (``*_Counter``, ``*_CRC``)."""
    counter = next(s for s in message.signals if s.name.endswith("_Counter"))
    checksum = next(s for s in message.signals if s.name.endswith("_CRC"))
    return counter, checksum


class _Sender:
    """Counter and checksum state of one output message."""

    def __init__(self, message):
        self.message = message
        self.signals = {s.name: s for s in message.signals}
        counter, checksum = integrity_signals(message)
        self.counter_name, self.counter_modulus = counter.name, 2 ** counter.length
        self.crc_name, self.crc_index = checksum.name, integrity.checksum_byte(checksum)
        self.counter = 0

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
        self.channel = channel
        self.senders = {name: _Sender(self.database.get_message_by_name(name))
                        for name in (*OUTPUT_MESSAGES, STATUS_MESSAGE)}
        status = self.senders[STATUS_MESSAGE].signals
        self.filter_ids = {str(v): k for k, v in status["FilterId"].choices.items()}
        self.mode_ids = {str(v): k for k, v in status["Mode"].choices.items()}

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
            "ValidFlags": estimate.valid_flags,
            "MissingInputs": estimate.missing_mask,
            "ResetCount": min(estimate.resets, 255),
            "InnovationNis": clamp_to_signal(status.signals["InnovationNis"], estimate.nis),
        }, estimate.t, self.channel))
        return frames


class EstimateCsvWriter:
    """One row per tick: ``t``, the states, their ``_std`` columns, ``valid`` (bit mask) and ``mode``.

    ``valid`` bits: 0 vx, 1 vy, 2 beta, 3 yaw rate, 4 lateral forces, 5 friction, 6 friction observable now.
    """

    def __init__(self, path):
        self.handle = open(path, "w", newline="")
        self.writer = csv.writer(self.handle)
        self.columns = None

    def write(self, estimate: Estimate) -> None:
        if self.columns is None:
            states = [k for k in estimate.values if not k.endswith("_std")]
            self.columns = states + [f"{k}_std" for k in states]
            self.writer.writerow(["t", *self.columns, "valid", "mode"])
        self.writer.writerow([f"{estimate.t:.6f}", *(f"{estimate.values[c]:.9g}" for c in self.columns),
                              estimate.valid_flags, estimate.mode])

    def close(self) -> None:
        self.handle.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
