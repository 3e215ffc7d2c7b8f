"""A YAML document that remembers the line of every key, so every config error can name it.

Read with limits, so no file can keep canest busy: at most ``MAX_BYTES``, keys
nested at most ``MAX_DEPTH`` deep, and at most ``MAX_NODES`` values once every
alias is expanded (a "billion laughs" file repeats one anchor through aliases
until it would fill the memory). The data is built by walking the composed
node tree, where each alias is met again and counted again. A key given twice
in one mapping is an error, not a silent override.
"""
from __future__ import annotations

import difflib
import math
import re
from pathlib import Path

import yaml

from canest.errors import ConfigError
from canest.limits import Range

MAX_BYTES = 1 << 20  # a full config is a few kilobytes
MAX_NODES = 10_000  # values after alias expansion; a full config has a few hundred
MAX_DEPTH = 32  # nesting of mappings and lists; a config needs five
PLAIN_COLLECTIONS = ("tag:yaml.org,2002:map", "tag:yaml.org,2002:seq")
MERGE_TAG = "tag:yaml.org,2002:merge"


class ConfigLoader(yaml.SafeLoader):
    """PyYAML's safe loader reading YAML 1.2's exponent floats too (``1.05e5``, ``2e-3``): YAML 1.1, which PyYAML
    follows, wants a dot and a signed exponent (``1.05e+5``), and read the others as text ("must be a number")."""


ConfigLoader.add_implicit_resolver("tag:yaml.org,2002:float",
                                   re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
                                   list("-+0123456789"))


def suggestion(word: str, choices, listing: str = "available", hint: str = "") -> str:
    """``did you mean 'x'?`` for the nearest of ``choices``, else ``available: <all of them>`` and ``hint``."""
    choices = sorted(str(c) for c in choices)
    close = difflib.get_close_matches(str(word), choices, n=1)
    return f"did you mean '{close[0]}'?" if close else f"{listing}: {', '.join(choices)}{hint}"


def _read(path: Path) -> bytes:
    try:
        with open(path, "rb") as stream:
            raw = stream.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(f"{path}: config file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.strerror}") from None
    if len(raw) > MAX_BYTES:
        raise ConfigError(f"{path}: config larger than {MAX_BYTES // 1024} KiB; a config is a few kilobytes")
    return raw


class Document:
    """A YAML mapping with the line of every key, for error messages."""

    def __init__(self, path: Path):
        self.path = path
        raw = _read(path)
        try:
            node = yaml.compose(raw, Loader=ConfigLoader)
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark or exc.context_mark
            where = f", line {mark.line + 1}" if mark else ""
            raise ConfigError(f"{path}: invalid YAML{where}: {', '.join(filter(None, (exc.context, exc.problem)))}") from None
        except yaml.reader.ReaderError as exc:  # bytes that are not text
            line = raw[:exc.position].count(b"\n") + 1
            remedy = "" if exc.encoding == "unicode" else f" ({exc.encoding}): save the file as UTF-8"
            raise ConfigError(f"{path}:{line}: invalid YAML: {exc.reason} at position {exc.position}{remedy}") \
                from None
        except RecursionError:
            raise ConfigError(f"{path}: YAML nested too deeply (more than {MAX_DEPTH} levels)") from None
        self.lines: dict = {}
        self.nodes = 0
        self.constructor = yaml.constructor.SafeConstructor()
        self.data = self._convert(node, ()) if node is not None else {}
        if not isinstance(self.data, dict):
            raise ConfigError(f"{path}: the top level must be a mapping of sections")

    def _convert(self, node, key_path):
        """The Python value of ``node``, counting every node met (aliases again each time)."""
        self.nodes += 1
        if self.nodes > MAX_NODES:
            raise ConfigError(f"{self.path}: YAML expands to more than {MAX_NODES} values "
                              "(aliases repeating an anchor?); a config needs a few hundred")
        if len(key_path) > MAX_DEPTH:
            raise self.error(key_path[:1], f"nested more than {MAX_DEPTH} levels deep (or an alias inside its own anchor)")
        if isinstance(node, yaml.CollectionNode) and node.tag not in PLAIN_COLLECTIONS:
            raise self.error(key_path, f"the tag {node.tag} is not supported; write a plain mapping or list")
        if isinstance(node, yaml.MappingNode):
            return self._mapping(node, key_path)
        if isinstance(node, yaml.SequenceNode):
            return [self._convert(item, key_path + (f"[{index}]",)) for index, item in enumerate(node.value)]
        try:
            return self.constructor.construct_object(node)
        except (yaml.YAMLError, ValueError) as exc:  # ValueError: an integer of more digits than Python reads
            raise self.error(key_path, str(getattr(exc, "problem", exc)), node.start_mark.line + 1) from None

    def _mapping(self, node, key_path) -> dict:
        result = {}
        for key_node, value_node in node.value:
            line = key_node.start_mark.line + 1
            if not isinstance(key_node, yaml.ScalarNode):
                raise self.error(key_path, "a key must be a name", line)
            key = key_node.value
            if key_node.tag == MERGE_TAG:
                raise self.error(key_path, "merge keys (<<) are not supported; write the keys out", line)
            if key in result:
                raise self.error(key_path + (key,), f"given twice (first at line {self.lines[key_path + (key,)]})", line)
            self.lines[key_path + (key,)] = line
            result[key] = self._convert(value_node, key_path + (key,))
        return result

    def error(self, key_path: tuple, message: str, line: int | None = None) -> ConfigError:
        """One line: the file, the line of the key (else of its nearest parent), the dotted key path, ``message``."""
        if line is None:
            line = next((self.lines[key_path[:n]] for n in range(len(key_path), 0, -1) if key_path[:n] in self.lines),
                        None)
        where = f"{self.path}:{line}" if line else str(self.path)
        text = f"{where}: {'.'.join(key_path) or 'top level'}: {message}"
        return ConfigError("".join(c if c.isprintable() else repr(c)[1:-1] for c in text))  # a newline in a key too

    def section(self, key_path: tuple, required: bool = True) -> dict:
        value = self.data
        for key in key_path:
            if not isinstance(value, dict) or key not in value:
                if required:
                    raise self.error(key_path, "missing section")
                return {}
            value = value[key]
        if not isinstance(value, dict):
            raise self.error(key_path, "must be a mapping")
        return value

    def number(self, key_path: tuple, section: dict, key: str, allowed: Range, default=None) -> float:
        """``section[key]`` as a float within ``allowed`` (``default`` when absent and given)."""
        if key not in section:
            if default is None:
                raise self.error(key_path + (key,), f"missing value ({allowed})")
            return float(default)
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key_path + (key,), f"must be a number, got {value!r}")
        try:
            number = float(value)
        except OverflowError:  # an integer no float can hold
            number = value = math.inf if value > 0 else -math.inf
        problem = allowed.violation(number)
        if problem:
            raise self.error(key_path + (key,), f"{problem}, got {value}")
        return number

    def text(self, key_path: tuple, section: dict, key: str, default: str | None = None) -> str | None:
        """``section[key]``, which must be a text (``default`` when absent)."""
        value = section.get(key, default)
        if value is not None and not isinstance(value, str):
            raise self.error(key_path + (key,), f"must be a text, got {value!r}")
        return value

    def reject_unknown(self, key_path: tuple, section: dict, known, hint: str = "") -> None:
        """A key not in ``known`` is an error naming the nearest known one (the first such key, in file order)."""
        unknown = next((key for key in section if key not in known), None)
        if unknown is not None:
            raise self.error(key_path + (unknown,), f"unknown key; {suggestion(unknown, known, 'valid keys', hint)}")
