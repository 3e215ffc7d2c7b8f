"""A YAML document that remembers the line of every key, so every config error can name it."""
from __future__ import annotations

from pathlib import Path

import yaml

from canest.errors import ConfigError


class Document:
    """A YAML mapping with the line of every key, for error messages."""

    def __init__(self, path: Path):
        self.path = path
        try:
            node = yaml.compose(path.read_text())
        except FileNotFoundError:
            raise ConfigError(f"{path}: config file not found") from None
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path}: invalid YAML: {exc}") from None
        self.lines: dict = {}
        self.data = self._convert(node, ()) if node is not None else {}
        if not isinstance(self.data, dict):
            raise ConfigError(f"{path}: the top level must be a mapping of sections")

    def _convert(self, node, key_path):
        if isinstance(node, yaml.MappingNode):
            result = {}
            for key_node, value_node in node.value:
                key = key_node.value
                self.lines[key_path + (key,)] = key_node.start_mark.line + 1
                result[key] = self._convert(value_node, key_path + (key,))
            return result
        if isinstance(node, yaml.SequenceNode):
            return [self._convert(item, key_path) for item in node.value]
        return yaml.safe_load(yaml.serialize(node))

    def error(self, key_path: tuple, message: str) -> ConfigError:
        line = next((self.lines[key_path[:n]] for n in range(len(key_path), 0, -1) if key_path[:n] in self.lines), None)
        where = f"{self.path}:{line}" if line else str(self.path)
        return ConfigError(f"{where}: {'.'.join(key_path)}: {message}")

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

    def number(self, key_path: tuple, section: dict, key: str, default=None, positive=True) -> float:
        if key not in section:
            if default is None:
                raise self.error(key_path + (key,), "missing value")
            return float(default)
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key_path + (key,), f"must be a number, got {value!r}")
        if positive and value <= 0:
            raise self.error(key_path + (key,), f"must be positive, got {value}")
        return float(value)

    def reject_unknown(self, key_path: tuple, section: dict, known) -> None:
        unknown = sorted(set(section) - set(known))
        if unknown:
            raise self.error(key_path + (unknown[0],), f"unknown key; known keys: {', '.join(sorted(known))}")
