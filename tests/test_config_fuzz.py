"""Fuzzing the config loader: any YAML gives a usable config or one ConfigError line, never another exception."""
import copy
import math

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from canest import limits
from canest.config import ConfigError, load_config
from tests.test_config import write_variant

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

PATHS = ["", ".", "/", "\0", "builtin:", "builtin:canest_vehicle.dbc", "../dbc/canest_vehicle.dbc", "car.yaml"]
scalars = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=20), st.sampled_from(PATHS))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                       st.dictionaries(st.text(max_size=10), inner, max_size=3)),
                      max_leaves=8)


def key_paths(data, prefix=()):
    """Every key path of the nested mappings in ``data``."""
    for key, value in data.items():
        yield prefix + (key,)
        if isinstance(value, dict):
            yield from key_paths(value, prefix + (key,))


def mutate(data, draw) -> None:
    """Replace, delete, add or rename one key somewhere in the config ``data``."""
    path = draw(st.sampled_from(sorted(key_paths(data))))
    parent = data
    for key in path[:-1]:
        parent = parent[key]
    names = sorted({key for p in key_paths(data) for key in p})
    new_key = draw(st.one_of(st.text(max_size=12), st.sampled_from(names)))
    action = draw(st.sampled_from(["replace", "delete", "add", "rename"]))
    if action == "replace":
        parent[path[-1]] = draw(values)
    elif action == "delete":
        del parent[path[-1]]
    elif action == "add":
        parent[new_key] = draw(values)
    else:
        parent[new_key] = parent.pop(path[-1])


def loads_or_one_line(path) -> None:
    """The property: a config whose numbers all lie in their ranges, or a ConfigError of one line naming the file."""
    try:
        config = load_config(path)
    except ConfigError as exc:
        message = str(exc)
        assert message.startswith(str(path)) and "\n" not in message, message
        return
    vehicle = config.vehicle
    assert all(allowed.violation(getattr(vehicle, name)) is None for name, allowed in limits.VEHICLE.items())
    assert all(allowed.violation(getattr(vehicle.tire, name)) is None for name, allowed in limits.TIRE.items())
    assert all(allowed.violation(getattr(config.estimator, name)) is None for name, allowed in limits.ESTIMATOR.items())
    assert all(math.isfinite(spec.factor) and math.isfinite(spec.offset) for spec in config.signals.values())


@pytest.fixture(scope="module")
def valid(tmp_path_factory):
    """A valid config beside copies of its DBCs (written once: the DBCs stay parsed), its text and its data."""
    path = write_variant(tmp_path_factory.mktemp("fuzz"), lambda d: None)
    text = path.read_text()
    return path, text, yaml.safe_load(text)


@FUZZ
@given(st.data())
def test_any_edit_of_a_valid_config_loads_or_is_one_error_line(valid, data):
    path, _, original = valid
    config = copy.deepcopy(original)
    for _ in range(data.draw(st.integers(1, 3))):
        mutate(config, data.draw)
    path.write_text(yaml.safe_dump(config))
    loads_or_one_line(path)


@FUZZ
@given(st.integers(0, 10_000), st.integers(0, 40), st.text(max_size=40))
def test_any_splice_into_the_config_text_loads_or_is_one_error_line(valid, at, cut, insert):
    path, text, _ = valid
    at %= len(text)
    path.write_text(text[:at] + insert + text[at + cut:])
    loads_or_one_line(path)


@FUZZ
@given(st.one_of(st.text(), st.binary()))
def test_any_text_or_bytes_is_one_error_line(valid, content):
    path = valid[0]
    if isinstance(content, str):
        path.write_text(content)
    else:
        path.write_bytes(content)
    loads_or_one_line(path)

