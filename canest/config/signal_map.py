"""``input.signals`` and ``input.messages``: the signal map through the input DBC, overrides and integrity checks."""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from canest import limits
from canest import signals as sig
from canest.codec.dbc import clamp_to_signal, tolerated_problems
from canest.config.checksum import read_checksum
from canest.errors import DbcError
from canest.params import VehicleParams
from canest.settings import MessageChecks, SignalSpec, ValidWhen
from canest.yamldoc import Document, suggestion

SIGNAL_KEYS = ("signal", "unit", "sign", "scale", "offset", "range", "valid", "stuck_after", "zero")
MESSAGE_KEYS = tuple(f.name for f in dataclasses.fields(MessageChecks) if f.name not in ("checksum_algorithm", "crc"))
SIGNAL_ROLES = ("counter", "checksum")  # message keys that name a signal of the message (checksum: or a mapping)
VALID_KEYS = ("signal", "values")
FD_CHOICES = {True: "fd", False: "classic", "any": "any"}  # input.messages.*.fd; absent: as the DBC declares
MAX_PARTS = 8  # signals one composite input may add up


def _never_decodes(message, signal) -> str | None:
    """Why no frame of ``message`` yields ``signal`` (None if one does): a frame selecting its multiplexer page(s)."""
    by_name = {s.name: s for s in message.signals}
    pages = {}
    current = signal
    while current.multiplexer_signal and current.multiplexer_ids and current.multiplexer_signal not in pages:
        pages[current.multiplexer_signal] = current.multiplexer_ids[0]
        current = by_name[current.multiplexer_signal]
    values = {s.name: pages.get(s.name, 0) if s.is_multiplexer else clamp_to_signal(s, 0.0) for s in message.signals}
    selection = ", ".join(f"{mux} = {page}" for mux, page in pages.items())
    try:
        decoded = message.decode(message.encode(values, strict=False), decode_choices=False)
    except Exception as exc:  # cantools raises several error types for a page its multiplexer cannot carry
        return f"a frame with {selection or 'its values'} cannot be built ({exc})"
    return None if signal.name in decoded else f"a frame with {selection or 'its values'} does not carry it"


def _mapped_signal(doc: Document, where: tuple, database, dbc_path: Path, given) -> tuple:
    """The DBC message and signal ``MESSAGE.SIGNAL`` names; it must decode from a frame ID of its own."""
    if not isinstance(given, str):
        raise doc.error(where, f"must be MESSAGE.SIGNAL, got {given!r}")
    message_name, _, signal_name = given.partition(".")
    try:
        message = database.get_message_by_name(message_name)
    except KeyError:
        choices = [m.name for m in database.messages]
        raise doc.error(where, f"no message '{message_name}' in {dbc_path}; {suggestion(message_name, choices)}") from None
    signal = next((s for s in message.signals if s.name == signal_name), None)
    if signal is None:
        choices = [s.name for s in message.signals]
        raise doc.error(where, f"no signal '{signal_name}' in message '{message_name}' of {dbc_path}; "
                               f"{suggestion(signal_name, choices)}")
    broken = tolerated_problems(dbc_path, f"{doc.path}: input.dbc").get(message_name)
    if broken:
        raise DbcError(str(doc.error(where, f"message '{message_name}' of {dbc_path} is malformed: {broken} "
                                            "Fix the message in the DBC, or map a signal of another message")))
    sharing = [m.name for m in database.messages if m is not message and m.frame_id == message.frame_id
               and m.is_extended_frame == message.is_extended_frame]
    if sharing:
        raise doc.error(where, f"message '{message_name}' shares frame ID {message.frame_id:#x} with "
                               f"'{', '.join(sharing)}' in {dbc_path}: its frames cannot be told apart; "
                               "give each message its own ID")
    problem = _never_decodes(message, signal)
    if problem:
        raise doc.error(where, f"{message_name}.{signal_name} never decodes from {dbc_path}: {problem}")
    return message, signal


def _mapped_signals(doc: Document, where: tuple, database, dbc_path: Path, given) -> tuple:
    """The message and the signals ``MESSAGE.SIGNAL`` (or a list of them, one message, added up) names."""
    names = given if isinstance(given, list) else [given]
    if not names or len(names) > MAX_PARTS:
        raise doc.error(where, f"must be MESSAGE.SIGNAL or a list of 1 to {MAX_PARTS} of them (added up)")
    mapped = [_mapped_signal(doc, where, database, dbc_path, name) for name in names]
    message = mapped[0][0]
    other = next((m for m, _ in mapped if m is not message), None)
    if other is not None:
        raise doc.error(where, f"the signals of a sum must come from one message, got '{message.name}' and "
                               f"'{other.name}'")
    units = {sig.normal_unit(s.unit or "") for _, s in mapped}
    if len(units) > 1:
        raise doc.error(where, f"the signals of a sum must share one unit, got {', '.join(repr(s.unit) for _, s in mapped)}")
    return message, [s for _, s in mapped]


def _unit_factor(doc: Document, where: tuple, entry: dict, canonical: str, signal, name: str, vehicle) -> float:
    """The factor to SI of the unit the entry gives (else the DBC's); a given unit must mean the DBC's."""
    unit = doc.text(where, entry, "unit", signal.unit)
    if not unit:
        raise doc.error(where, f"signal {name} has no unit in the DBC; give 'unit'")
    try:
        factor = sig.si_factor(canonical, unit, vehicle.wheel_radius)
    except ValueError as exc:
        raise doc.error(where + ("unit",), str(exc)) from None
    dbc_unit = sig.normal_unit(signal.unit or "")
    if "unit" in entry and dbc_unit is not None and dbc_unit != sig.normal_unit(unit):
        raise doc.error(where + ("unit",), f"'{unit}' contradicts the DBC unit '{signal.unit}' of {name}")
    return factor


def _range(doc: Document, where: tuple, entry: dict, signals: list) -> tuple:
    """(low, high) a value must lie in: the DBC's (summed over a composite's signals), ``[low, high]`` or ``none``."""
    if "range" not in entry:
        lows, highs = [s.minimum for s in signals], [s.maximum for s in signals]
        return (None if None in lows else sum(lows), None if None in highs else sum(highs))
    given = entry["range"]
    if given is None or given == "none":
        return (None, None)
    where = where + ("range",)
    if not isinstance(given, list) or len(given) != 2 or \
            any(isinstance(b, bool) or not isinstance(b, (int, float)) for b in given):
        raise doc.error(where, f"must be [low, high] in the DBC's physical unit, or none; got {given!r}")
    bounds = [_finite(bound) for bound in given]
    for bound, number in zip(given, bounds):
        problem = limits.SIGNAL["range"].violation(number)
        if problem:
            raise doc.error(where, f"{problem}, got {bound}")
    if not bounds[0] < bounds[1]:
        raise doc.error(where, f"low must be below high, got {given!r}")
    return tuple(bounds)


def _finite(number) -> float:
    """A YAML number as a float; an integer too large for one becomes infinity (then refused as not finite)."""
    try:
        return float(number)
    except OverflowError:
        return math.inf if number > 0 else -math.inf


def _valid_when(doc: Document, where: tuple, message, dbc_path: Path, given) -> ValidWhen:
    """``valid: SIGNAL`` (valid when not 0) or ``valid: {signal: SIGNAL, values: [...]}`` (numbers or VAL_ names)."""
    if isinstance(given, dict):
        doc.reject_unknown(where, given, VALID_KEYS)
        name, values = doc.text(where, given, "signal"), given.get("values", [])
        values = values if isinstance(values, list) else [values]
        if not values:
            raise doc.error(where + ("values",), "give at least one valid value")
    elif isinstance(given, str):
        name, values = given, []
    else:
        raise doc.error(where, f"must be a signal name or {{signal: NAME, values: [...]}}, got {given!r}")
    signal = next((s for s in message.signals if s.name == name), None)
    if signal is None:
        names = [s.name for s in message.signals]
        raise doc.error(where, f"no signal '{name}' in message '{message.name}' of {dbc_path}; {suggestion(name, names)}")
    choices = {str(label): raw * signal.scale + signal.offset for raw, label in (signal.choices or {}).items()}
    physical = []
    for value in values:
        if isinstance(value, str) and value in choices:
            physical.append(choices[value])
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(_finite(value)):
            physical.append(float(value))
        else:
            raise doc.error(where + ("values",), f"{value!r} is neither a number nor a value name of {name} "
                                                 f"({', '.join(choices) or 'it names none'})")
    return ValidWhen(name, tuple(physical))


def read_signal_specs(doc: Document, database, dbc_path: Path, vehicle: VehicleParams) -> dict:
    key_path = ("input", "signals")
    section = doc.section(key_path)
    specs, taken = {}, {}  # (message, signal, multiplexer value) -> the input first mapped to it
    for canonical, entry in section.items():
        where = key_path + (canonical,)
        if canonical not in sig.CANONICAL:
            raise doc.error(where, f"unknown canonical signal; {suggestion(canonical, sig.CANONICAL)}")
        if isinstance(entry, str):
            entry = {"signal": entry}
        if not isinstance(entry, dict) or "signal" not in entry:
            raise doc.error(where, "needs 'signal: MESSAGE.SIGNAL'")
        doc.reject_unknown(where, entry, SIGNAL_KEYS)
        message, signals = _mapped_signals(doc, where + ("signal",), database, dbc_path, entry["signal"])
        signal = signals[0]
        name = f"{message.name}.{signal.name}"
        factor = _unit_factor(doc, where, entry, canonical, signal, name, vehicle)
        sign = entry.get("sign", 1)
        if isinstance(sign, bool) or sign not in (1, -1):
            raise doc.error(where + ("sign",), f"must be 1 or -1, got {sign!r}")
        scale = doc.number(where, entry, "scale", limits.SIGNAL["scale"], 1.0)
        offset = doc.number(where, entry, "offset", limits.SIGNAL["offset"], 0.0)
        stuck_after = doc.number(where, entry, "stuck_after", limits.SIGNAL["stuck_after"]) \
            if "stuck_after" in entry else None
        zero = entry.get("zero")
        if zero is not None and (zero != "learn" or canonical != "steering_wheel_angle"):
            raise doc.error(where + ("zero",), "only 'zero: learn' on steering_wheel_angle (a relative angle whose "
                                               f"zero is learned while driving straight), got {zero!r}")
        valid = _valid_when(doc, where + ("valid",), message, dbc_path, entry["valid"]) if "valid" in entry else None
        mux = int(signal.multiplexer_ids[0]) if signal.multiplexer_ids else None
        first = taken.setdefault((message.name, signal.name, mux), canonical)
        if first != canonical and not {first, canonical} <= set(sig.INPUT_GROUPS["wheel_speeds"]):
            raise doc.error(where + ("signal",), f"{name} is {first}'s already: two inputs read from one signal "
                                                 "(only the four wheel speeds may share one, a car that sends one "
                                                 "speed for all)")
        specs[canonical] = SignalSpec(canonical, message.name, signal.name, sign * scale * factor, offset, mux,
                                      parts=tuple(s.name for s in signals[1:]),
                                      range=_range(doc, where, entry, signals), range_given="range" in entry,
                                      valid=valid,
                                      stuck_after=stuck_after, learn_zero=zero == "learn")
    return specs


def read_message_checks(doc: Document, database, dbc_path: Path, specs: dict) -> dict:
    """Integrity checks and overrides of mapped messages (on a message no signal is taken from they would never run)."""
    key_path = ("input", "messages")
    section = doc.section(key_path, required=False)
    mapped = {spec.message for spec in specs.values()}
    checks = {}
    for name, entry in section.items():
        where = key_path + (name,)
        try:
            message = database.get_message_by_name(name)
        except KeyError:
            choices = [m.name for m in database.messages]
            raise doc.error(where, f"no message '{name}' in {dbc_path}; {suggestion(name, choices)}") from None
        if name not in mapped:
            raise doc.error(where, "no signal of input.signals comes from this message, so its checks would never "
                                   "run; map one of its signals or remove the entry")
        entry = doc.section(where)
        doc.reject_unknown(where, entry, MESSAGE_KEYS)
        names = [s.name for s in message.signals]
        roles = {}
        checksum = {}
        if "checksum" in entry:
            roles["checksum"], algorithm, crc = read_checksum(doc, where + ("checksum",), entry["checksum"],
                                                              message.length)
            checksum = {"checksum_algorithm": algorithm, "crc": crc}
        for role in SIGNAL_ROLES:
            signal_name = roles.get(role) or doc.text(where, entry, role)
            if signal_name is not None and signal_name not in names:
                raise doc.error(where + (role,), f"no signal '{signal_name}' in message '{name}' of {dbc_path}; "
                                                 f"{suggestion(signal_name, names)}")
            roles[role] = signal_name
        fd = entry.get("fd")
        if "fd" in entry and (not isinstance(fd, (bool, str)) or fd not in FD_CHOICES):
            raise doc.error(where + ("fd",), f"must be true (CAN FD frames), false (classic frames) or any; got {fd!r} "
                                             f"(the DBC says {'CAN FD' if message.is_fd else 'classic'})")
        cycle_time = doc.number(where, entry, "cycle_time", limits.MESSAGE["cycle_time"]) \
            if "cycle_time" in entry else None
        valid = _valid_when(doc, where + ("valid",), message, dbc_path, entry["valid"]) if "valid" in entry else None
        checks[name] = MessageChecks(**roles, **checksum, valid=valid, fd=FD_CHOICES[fd] if "fd" in entry else "dbc",
                                     cycle_time=cycle_time)
    return checks
