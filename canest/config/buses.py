"""The ``bus`` sections: a python-can interface, a channel and options python-can would not silently ignore."""
from __future__ import annotations

import importlib
import inspect

from can.interfaces import BACKENDS, VALID_INTERFACES

from canest.settings import BusConfig
from canest.yamldoc import Document, suggestion

BUS_KEYS = ("interface", "channel", "options")
SET_BY_CANEST = ("interface", "channel", "can_filters")  # never a bus option: canest filters on the mapped IDs
CHECKED_INTERFACES = ("socketcan", "virtual")  # python-can buses that silently ignore any keyword they do not name


def _bus_keywords(interface: str) -> dict | None:
    """The keywords (with defaults) python-can's bus class of ``interface`` names, if it ignores all others.

    None for the other interfaces: their drivers take keywords of their own
    (python-can's interface documentation lists them), passed on unchecked.
    """
    if interface not in CHECKED_INTERFACES:
        return None
    module, name = BACKENDS[interface]
    parameters = inspect.signature(getattr(importlib.import_module(module), name).__init__).parameters.values()
    return {p.name: p.default for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
            and p.name not in ("self", *SET_BY_CANEST)}


def _bus_options(doc: Document, key_path: tuple, interface: str) -> dict:
    options = doc.section(key_path, required=False)
    keywords = _bus_keywords(interface)
    for key, value in options.items():
        if key in SET_BY_CANEST:
            raise doc.error(key_path + (key,), "set by canest, not an option (interface and channel go one level up)")
        if keywords is not None and key not in keywords:
            raise doc.error(key_path + (key,), f"not an option of python-can's {interface} bus; "
                                               f"{suggestion(key, keywords)}")
        if keywords is not None and isinstance(keywords[key], bool) and not isinstance(value, bool):
            raise doc.error(key_path + (key,), f"must be true or false, got {value!r}")
    return dict(options)


def read_bus(doc: Document, key_path: tuple, default_channel: str) -> BusConfig:
    section = doc.section(key_path, required=False)
    doc.reject_unknown(key_path, section, BUS_KEYS, " (python-can keywords go under 'options:')")
    interface = doc.text(key_path, section, "interface", "socketcan")
    if interface not in VALID_INTERFACES:
        raise doc.error(key_path + ("interface",), f"no python-can interface '{interface}'; "
                                                   f"{suggestion(interface, VALID_INTERFACES)}")
    channel = section.get("channel", default_channel)
    if isinstance(channel, bool) or not isinstance(channel, (str, int)):
        raise doc.error(key_path + ("channel",), f"must be a channel name or number, got {channel!r}")
    return BusConfig(interface, str(channel), _bus_options(doc, key_path + ("options",), interface))


def same_bus(first: BusConfig, second: BusConfig) -> bool:
    """Whether two bus settings name one bus (interface and channel)."""
    return (first.interface, first.channel) == (second.interface, second.channel)


def id_clash(input_db, output_db) -> str | None:
    """Where the output DBC sends an ID the input DBC's car sends too (on one bus: two senders of one ID, each
    garbling the other's frames, and canest decoding its own), the first such pair as a sentence; None if none."""
    car = {(m.frame_id, m.is_extended_frame): m.name for m in input_db.messages}
    for message in output_db.messages:
        name = car.get((message.frame_id, message.is_extended_frame))
        if name is not None:
            return (f"output message {message.name} has ID 0x{message.frame_id:X}, which the input DBC's {name} "
                    "has too, on the same bus: put the output on a bus of its own or give the output DBC's "
                    "messages IDs the car does not send")
    return None
