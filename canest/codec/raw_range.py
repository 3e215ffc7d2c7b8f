"""DBC ranges written in raw counts instead of physical values (``init`` writes ``range: none``, ``check`` warns).

Toyota's KINEMATICS declares ``[0|65535]`` for YAW_RATE, 10 bits of
0.244 deg/s from -125 deg/s: the bits carry -125 to 124.6 deg/s, the range
admits none of the negative ones, and every frame of a right turn is
rejected out of range (a real RAV4 drive: 4 913 of 4 914 KINEMATICS frames).
Such a range is *raw-style*: its bounds are the integer limits of a bit
field (0 or -2^(k-1) to 2^k - 1), it cuts off values the signal's bits
carry, and it reaches beyond what they carry. A config replaces it with
``range: none`` or ``range: [low, high]`` (physical).
"""
from __future__ import annotations

import math


def carried(signal) -> tuple:
    """(lowest, highest) physical value the signal's bits carry: scale * raw + offset over its integer range."""
    half = 2 ** (signal.length - 1)
    raws = (-half, half - 1) if signal.is_signed else (0, 2 * half - 1)
    ends = [signal.scale * raw + signal.offset for raw in raws]
    return min(ends), max(ends)


def _integer_limits(low: float, high: float) -> bool:
    """``[low, high]`` is the integer range of some bit field: ``[0, 2^k - 1]`` or ``[-2^(k-1), 2^(k-1) - 1]``."""
    if not math.isfinite(high) or high != int(high) or high < 1:
        return False
    bits = (int(high) + 1).bit_length() - 1
    return (low == 0 and high == 2 ** bits - 1) or (low == -(high + 1) and high == 2 ** bits - 1)


def raw_style(signal) -> bool:
    """The DBC range of ``signal`` is in raw counts: integer limits that cut off values its bits carry and reach
    beyond them on the other side."""
    low, high = signal.minimum, signal.maximum
    if low is None or high is None or signal.is_float:
        return False
    lowest, highest = carried(signal)
    slack = abs(signal.scale) / 2.0
    cuts = low > lowest + slack or high < highest - slack
    beyond = low < lowest - slack or high > highest + slack
    return cuts and beyond and _integer_limits(low, high)


def raw_range_warnings(signals, database) -> list:
    """One line per mapped input whose DBC range is raw-style and not overridden in the config (``signals``:
    canonical -> SignalSpec, ``database``: the input DBC)."""
    out = []
    for canonical, spec in signals.items():
        if spec.range_given:
            continue
        message = database.get_message_by_name(spec.message)
        for name in spec.names:
            signal = message.get_signal_by_name(name)
            if raw_style(signal):
                lowest, highest = carried(signal)
                out.append(f"input {canonical}: {spec.message}.{name} declares the raw-style range "
                           f"[{signal.minimum:g}|{signal.maximum:g}] (bit counts) while its bits carry "
                           f"{lowest:g} to {highest:g} {signal.unit or ''}: the values outside are rejected out of "
                           f"range; give input.signals.{canonical}.range: none (or [low, high])")
    return out
