"""What real cars reach, and whether the mapped DBC signals can carry it (``canest check`` warns).

A signal whose DBC range stops short of what a car reaches sends its limit
instead of the value: canest's own input DBC once capped wheel speed at
1600 rpm (50 m/s at a 0.30 m radius) and, above it, vx was 6 m/s off. The
decoder treats a value at a limit as saturated (not a measurement), so a
short range costs validity rather than truth; ``check`` says so before a
drive does. Reaches, SI: wheel speed to 300 km/h at a 0.35 m radius, yaw
rate +-180 deg/s, accelerations +-16 m/s^2 (a real hard drive reached
16.6 m/s^2 of lateral acceleration with vibration); published vx to
90 m/s (and -10 reversing), sideslip +-30 deg.
"""
from __future__ import annotations

import math

from canest.codec.encode import OUTPUT_MESSAGES
from canest.signals import WHEELS

WHEEL_SPEED_REACH = 300 / 3.6 / 0.35  # rad/s
INPUT_REACH = {  # canonical input -> (low, high), SI; None: not required on that side
    **{f"wheel_speed_{w}": (None, WHEEL_SPEED_REACH) for w in WHEELS},
    "yaw_rate": (-math.pi, math.pi), "yaw_rate_2": (-math.pi, math.pi),
    "ax": (-16.0, 16.0), "ay": (-16.0, 16.0), "ax_2": (-16.0, 16.0), "ay_2": (-16.0, 16.0),
}
WHY = {"wheel_speed": " (300 km/h at a 0.35 m radius)"}
OUTPUT_REACH = {"vx": (-10.0, 90.0), "beta": (-math.radians(30), math.radians(30)),
                "yaw_rate": (-math.pi, math.pi)}


def _short(carried: tuple, reach: tuple) -> bool:
    """The interval ``carried`` (None: open) does not contain ``reach`` (None: not required)."""
    (low, high), (need_low, need_high) = carried, reach
    return ((need_low is not None and low is not None and low > need_low)
            or (need_high is not None and high is not None and high < need_high))


def _si_interval(spec, bounds: tuple) -> tuple:
    """The SI interval of a mapped signal whose DBC value lies in ``bounds`` (None: open)."""
    low, high = bounds
    ends = [None if v is None else spec.factor * v + spec.offset for v in (low, high)]
    return tuple(ends) if spec.factor >= 0 else (ends[1], ends[0])


def _text(interval: tuple, scale: float, unit: str) -> str:
    return "[" + ", ".join("open" if v is None else f"{v * scale:g}" for v in interval) + f"] {unit}"


def _shown(canonical: str) -> tuple:
    """(scale, unit) to print an SI value of ``canonical`` the way people read it."""
    if canonical.startswith("wheel_speed"):
        return 1.0, "rad/s"
    if canonical.startswith("yaw_rate") or canonical == "beta":
        return math.degrees(1.0), "deg/s" if canonical.startswith("yaw_rate") else "deg"
    return 1.0, "m/s^2" if canonical.startswith("a") else "m/s"


def input_shortfalls(signals) -> list:
    """One line per mapped input whose range cannot carry what a car reaches (``signals``: canonical -> spec)."""
    out = []
    for canonical, spec in signals.items():
        reach = INPUT_REACH.get(canonical)
        carried = _si_interval(spec, spec.range)
        if reach and _short(carried, reach):
            scale, unit = _shown(canonical)
            out.append(f"input {canonical} ({spec.message}.{spec.signal}) carries {_text(carried, scale, unit)}; "
                       f"cars reach {_text(reach, scale, unit)}{WHY.get(canonical[:11], '')}: beyond it the value is "
                       "saturated, not measured")
    return out


def output_shortfalls(database) -> list:
    """One line per published state whose signal in the output DBC ``database`` (SI values) cannot carry
    its reach."""
    out = []
    for message, fields in OUTPUT_MESSAGES.items():
        for name, (kind, state) in fields.items():
            if kind != "value" or state not in OUTPUT_REACH:
                continue
            signal = database.get_message_by_name(message).get_signal_by_name(name)
            carried = (signal.minimum, signal.maximum)
            if _short(carried, OUTPUT_REACH[state]):
                scale, unit = _shown(state)
                out.append(f"output {state} ({message}.{name}) carries {_text(carried, scale, unit)}; cars reach "
                           f"{_text(OUTPUT_REACH[state], scale, unit)}: beyond it the value is sent saturated")
    return out
