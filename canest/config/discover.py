"""Finding the usual inputs in a DBC: wheel speeds, steering angle, yaw rate, ax, ay, motor torques.

For ``canest init``. Each signal of the DBC is judged by its name, split into
words (``WhlFl_W_Meas`` -> WHL FL W MEAS, ``ESP_VL_Radgeschw_02`` -> ESP VL
RADGESCHW 02), and by its unit (any spelling :func:`canest.signals.normal_unit`
knows): a canonical input takes the best-named signal whose unit measures its
quantity. Commands, requests, limits and status words count against a
signal. What is found is a guess for the user to confirm: each
:class:`Candidate` says why it was taken.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from canest.signals import CANONICAL, LINEAR_SPEED_UNITS, UNITS, WHEELS, normal_unit

# words that make a signal a command, a setpoint, a limit or a status rather than a measurement
AGAINST = {"REQ", "RQ", "REQUEST", "CMD", "COMMAND", "TARGET", "DES", "DESIRED", "SET", "LIMIT", "LIM", "MAX", "MIN",
           "OFFSET", "OFFST", "ERR", "ERROR", "QF", "CNT", "COUNTER", "CS", "CHECKSUM", "CRC", "STAT", "STATUS", "VALID",
           "LKA", "LKAS", "APA", "ACC", "AEB", "PCS", "FILT", "RAW", "INIT", "TOLERANCE", "DIFF", "DELTA",
           "ADJUST", "MOTOR", "EPS", "OVERRIDE", "CALIBRATION", "CAL", "TORQUE", "TQ", "RATE", "SPEED", "DIR"}
POSITIONS = {"fl": {"FL", "LF", "VL"}, "fr": {"FR", "RF", "VR"}, "rl": {"RL", "LR", "HL"}, "rr": {"RR", "HR"}}
AXLE_WORDS = {"F": "f", "FR": "f", "FRT": "f", "FRONT": "f", "VORNE": "f", "RE": "r", "REAR": "r", "BACK": "r",
              "HINTEN": "r"}
SIDE_WORDS = {"L": "l", "LH": "l", "LEFT": "l", "LINKS": "l", "R": "r", "RH": "r", "RIGHT": "r", "RECHTS": "r"}
WHEEL_WORDS = {"WHL", "WHEEL", "SPD", "SPEED", "RADGESCHW", "MOT", "MOTOR", "TQ", "TORQUE"}


@dataclass(frozen=True)
class Hints:
    """Name words that point to a canonical input (``strong`` count twice) and words that rule a signal out."""

    strong: frozenset
    weak: frozenset = frozenset()
    never: frozenset = frozenset()


HINTS = {
    "steering_wheel_angle": Hints(frozenset({"STEERING_ANGLE", "STEER_ANGLE", "STRWHLANG", "STEERINGWHEELANGLE",
                                             "LENKRADWINKEL", "SAS_ANGLE", "STEWHL", "STEPIN", "STR_ANG"}),
                                  frozenset({"STEER", "STEERING", "STR", "STE", "SAS", "LWI", "WHL", "WHEEL", "ANGLE",
                                             "ANG", "AN", "SWA"}),
                                  frozenset({"LKA", "APA", "CMD", "REQ", "TORQUE", "TQ", "FRACTION", "TARGET",
                                             "DESIRED", "ROAD", "WHEELS", "TIRE", "ROLL", "PITCH", "OFFSET",
                                             "OFFST", "RQ", "BRK"})),
    "yaw_rate": Hints(frozenset({"YAW_RATE", "YAWRATE", "GIERRATE", "YAW"}), frozenset({"RATE", "W", "VEH"}),
                      frozenset({"ACC", "ACCEL", "CMD", "REQ", "OFFSET", "TARGET", "DESIRED", "ROLL", "PITCH"})),
    "ax": Hints(frozenset({"ACCEL_X", "ACC_X", "LONG_ACC", "LONGACC", "LAENGSBESCHL", "LONG", "LONGITUDINAL",
                           "AX", "LONG2", "LONGACCEL"}),
                frozenset({"ACCEL", "ACC", "A", "VEH", "X"}),
                frozenset({"CMD", "REQ", "TARGET", "DESIRED", "SET", "LIMIT", "MAX", "MIN", "LAT", "Y", "VERT",
                           "Z", "ENG", "OFFSET", "BRAKE", "JERK"})),
    "ay": Hints(frozenset({"ACCEL_Y", "ACC_Y", "LAT_ACC", "LATACC", "QUERBESCHLEUNIGUNG", "LAT", "LATERAL", "AY",
                           "LAT2", "LATACCEL"}),
                frozenset({"ACCEL", "ACC", "A", "VEH", "Y"}),
                frozenset({"CMD", "REQ", "TARGET", "DESIRED", "SET", "LIMIT", "MAX", "MIN", "LONG", "X", "VERT",
                           "Z", "OFFSET", "JERK", "COMP"})),
    **{f"wheel_speed_{w}": Hints(frozenset({"WHEEL_SPEED", "WHEELSPEED", "WHL_SPD", "WHLSPD", "RADGESCHW",
                                            "WHEEL", "WHL"}),
                                 frozenset({"SPEED", "SPD", "MEAS", "W", "V"}),
                                 frozenset({"DIR", "DIRECTION", "PULSE", "CNT", "COUNTER", "QF", "STAT", "VALID",
                                            "TORQUE", "TQ", "SLIP", "PRESSURE", "TIRE", "ANGLE"}))
       for w in WHEELS},
    **{f"motor_torque_{w}": Hints(frozenset({"MOTOR", "MOT", "EM", "INVERTER", "DRIVE"}),
                                  frozenset({"TORQUE", "TQ", "TRQ", "ACTUAL", "ACT", "EST"}),
                                  frozenset({"REQ", "CMD", "LIMIT", "LIM", "MAX", "MIN", "TARGET", "DESIRED", "SET",
                                             "BRAKE", "STEER", "EPS", "CAPACITY"}))
       for w in WHEELS},
}


# the unit taken for a well-named signal whose DBC gives none (it costs a point; init marks it ASSUMED)
ASSUMED_UNITS = {"angle": "deg", "angular_velocity": "deg/s", "acceleration": "m/s^2", "torque": "N m"}
WHEEL_SPEED_ASSUMED = "km/h"


@dataclass(frozen=True)
class Candidate:
    """A DBC signal taken for a canonical input, and why."""

    canonical: str
    message: str
    signal: str
    frame_id: int
    unit: str  # the DBC's, or ASSUMED_UNITS' for a signal without one (:attr:`assumed`)
    score: int
    words: tuple  # the name words that pointed to it
    assumed: bool = False

    @property
    def reference(self) -> str:
        return f"{self.message}.{self.signal}"


def words_of(name: str) -> list:
    """``WhlFl_W_Meas`` -> [WHL, FL, W, MEAS]; ``STEER_ANGLE`` -> [STEER, ANGLE]; digits kept with their word."""
    spaced = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name)
    return [word.upper() for word in re.split(r"[_\W]+", spaced) if word]


def joined_words(words: list) -> set:
    """Every word and every pair of neighbouring words, joined with and without ``_`` (STEER_ANGLE, STEERANGLE)."""
    pairs = {f"{a}{sep}{b}" for a, b in zip(words, words[1:]) for sep in ("_", "")}
    return set(words) | pairs | {"".join(words)}


def wheel_of(words: list) -> str | None:
    """The wheel a signal name points to (``fl``, ...), if exactly one: an axle word next to a side word
    (FRONT LEFT, Tesla's FR L, LEFT FRONT), else a code word (FL, VL, ...) or a code joined to a wheel word (WHLFL)."""
    pairs = {AXLE_WORDS[a] + SIDE_WORDS[b] for a, b in zip(words, words[1:]) if a in AXLE_WORDS and b in SIDE_WORDS}
    pairs |= {AXLE_WORDS[b] + SIDE_WORDS[a] for a, b in zip(words, words[1:]) if a in SIDE_WORDS and b in AXLE_WORDS}
    if len(pairs) == 1:
        return pairs.pop()
    found = {wheel for wheel, codes in POSITIONS.items()
             if set(words) & codes or any(word.endswith(code) and word[:-len(code)] in WHEEL_WORDS
                                          for word in words for code in codes)}
    return found.pop() if len(found) == 1 else None


def fits_quantity(canonical: str, unit: str | None) -> bool:
    """Whether a DBC unit measures the canonical input's quantity (wheel speeds: also a linear speed)."""
    accepted = UNITS[CANONICAL[canonical]][1]
    return unit in accepted or (canonical.startswith("wheel_speed_") and unit in LINEAR_SPEED_UNITS)


def score(canonical: str, words: list) -> tuple:
    """(score, the hint words matched) of a signal's name for ``canonical``; score 0: not a candidate."""
    hints = HINTS[canonical]
    names = joined_words(words)
    if names & hints.never:
        return 0, ()
    strong, weak = sorted(names & hints.strong), sorted(set(words) & hints.weak)
    if not strong:
        return 0, ()
    return 2 * len(strong) + len(weak) - len(set(words) & AGAINST - hints.strong - hints.weak), tuple(strong + weak)


def assumed_unit(canonical: str) -> str:
    return WHEEL_SPEED_ASSUMED if canonical.startswith("wheel_speed_") else ASSUMED_UNITS[CANONICAL[canonical]]


def candidates(database, keep: int = 3) -> dict:
    """canonical -> its best :class:`Candidate` s in the cantools ``database``, best first, at most ``keep``
    (inputs without one are left out). Ties go to the shorter name, then the lower frame ID. A signal named
    only by its wheel (Subaru's ``Wheel_Speeds.FL``) is judged with its message's name in front."""
    found = {}
    for message in sorted(database.messages, key=lambda m: m.frame_id):
        for signal in message.signals:
            if signal.multiplexer_ids or signal.is_multiplexer or signal.length < 4:
                continue
            words = words_of(signal.name)
            wheel = wheel_of(words)
            if wheel is not None and len(words) <= 2:
                words = words_of(message.name) + words
            unit = normal_unit(signal.unit) if signal.unit else None
            for canonical in HINTS:
                if canonical[-3:-2] == "_" and canonical[-2:] in WHEELS and canonical[-2:] != wheel:
                    continue  # a per-wheel input takes only a signal naming that wheel
                assumed = not signal.unit
                if not (assumed or fits_quantity(canonical, unit)):
                    continue
                points, matched = score(canonical, words)
                points -= assumed
                if points > 0:
                    found.setdefault(canonical, []).append((-points, len(words), message.frame_id, Candidate(
                        canonical, message.name, signal.name, message.frame_id,
                        assumed_unit(canonical) if assumed else signal.unit, points, matched, assumed)))
    return {canonical: [ranked[-1] for ranked in sorted(ranks, key=lambda r: r[:3])[:keep]]
            for canonical, ranks in found.items()}
