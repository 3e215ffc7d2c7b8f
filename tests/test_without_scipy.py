"""canest without scipy (a plain `pip install canest`): every filter runs, the command line starts, and what
needs scipy (calibrate, fusing more than two estimates) says in one line how to install it.

The subprocesses block scipy with a ``sitecustomize`` that sets ``sys.modules["scipy"] = None``: any
``import scipy...`` then raises ImportError, as in an environment without it.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

from canest.errors import DependencyError
from canest.filters.fusion import fuse_many
from tests.conftest import CONFIG, ROOT

INSTALL = "pip install 'canest[calibrate]'"

EVERY_PAIR = f"""
import math
import sys
assert sys.modules["scipy"] is None
from canest.apps.replay import replay
from canest.config import load_config
from canest.estimation import catalog
from canest.sim.simulate import simulate
from tests.test_config import write_variant
from pathlib import Path

folder = Path(sys.argv[1])
simulate(load_config({str(CONFIG)!r}), "sine", 60.0, 0.85, duration=1.5, seed=5).write_log(folder / "drive.log")
for model, entry in catalog.CATALOG.items():
    for name in entry.filters:
        estimates, variant = [], folder / f"{{model}}-{{name}}"
        variant.mkdir()
        config = load_config(write_variant(variant, lambda d: d["estimator"].update(filter=name, model=model)))
        replay(config, folder / "drive.log", progress=False, on_estimate=estimates.append)
        normal = [e for e in estimates if e.mode == "normal"]
        finite = all(math.isfinite(e.values["yaw_rate"]) and math.isfinite(e.values["beta"]) for e in normal)
        print(model, name, len(normal), finite)
"""


def blocked(tmp_path) -> dict:
    """The environment of a Python that cannot import scipy."""
    site = tmp_path / "site"
    site.mkdir(exist_ok=True)
    (site / "sitecustomize.py").write_text('import sys\nsys.modules["scipy"] = None\n')
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)])}


def run(tmp_path, *args):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=600,
                          cwd=tmp_path, env=blocked(tmp_path))


def test_the_block_stops_scipy(tmp_path):
    for module in ("scipy", "scipy.linalg", "scipy.special"):
        result = run(tmp_path, "-c", f"import {module}")
        assert result.returncode == 1 and "Error: " in result.stderr and "scipy" in result.stderr, result.stderr


def test_every_filter_runs_on_every_model_it_fits(tmp_path):
    from canest.estimation import catalog
    expected = {(model, name) for model, entry in catalog.CATALOG.items() for name in entry.filters}
    (tmp_path / "pairs").mkdir()
    result = run(tmp_path, "-c", EVERY_PAIR, tmp_path / "pairs")
    assert result.returncode == 0, result.stderr
    rows = [line.split() for line in result.stdout.splitlines()]
    assert {(model, name) for model, name, _, _ in rows} == expected
    for model, name, normal, finite in rows:
        assert int(normal) > 100 and finite == "True", f"{name} on {model}: {normal} normal ticks, finite {finite}"


@pytest.mark.parametrize("option", ["--version", "--help"])
def test_the_command_line_starts(tmp_path, option):
    result = run(tmp_path, "-m", "canest", option)
    assert result.returncode == 0, result.stderr
    assert "canest" in result.stdout and result.stderr == ""


@pytest.mark.parametrize("log", ["drive.log", "not_recorded_yet.log"])
def test_calibrate_names_the_extra_in_one_line_before_reading_a_log(tmp_path, config, log):
    from canest.sim.simulate import simulate
    simulate(config, "sine", 60.0, 0.85, duration=5.0, seed=5).write_log(tmp_path / "drive.log")
    result = run(tmp_path, "-m", "canest", "calibrate", tmp_path / log, "--config", CONFIG)
    assert result.returncode == DependencyError.exit_status
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("canest: error: canest calibrate needs")
    assert INSTALL in result.stderr


def test_fusing_three_estimates_names_the_extra_without_scipy(monkeypatch):
    xs = [np.zeros(2), np.ones(2), np.full(2, 2.0)]
    Ps = [np.eye(2), 2.0 * np.eye(2), np.diag([1.0, 3.0])]
    monkeypatch.setitem(sys.modules, "scipy.optimize", None)
    with pytest.raises(DependencyError, match=r"fusing 3 estimates needs .*" + r"pip install 'canest\[calibrate\]'"):
        fuse_many("ici", xs, Ps)
    given = fuse_many("ci", xs, Ps, weights=np.full(3, 1.0 / 3.0))  # given weights need no optimizer
    np.testing.assert_allclose(given.P, np.linalg.inv(sum(np.linalg.inv(P) for P in Ps) / 3.0))


def test_the_online_calibration_learns_without_scipy_and_says_at_the_first_window_that_the_stiffnesses_are_not(
        tmp_path):
    """Said once, when a window of driving would be fitted: not at start (``canest demo``, 8 s, never needs it)."""
    code = f"""
import sys
import numpy as np
from canest.config import load_config
from canest.pipeline import Pipeline
config = load_config({str(CONFIG)!r})
first, second = Pipeline(config), Pipeline(config)
print("started", file=sys.stderr, flush=True)
t = np.arange(0.0, 30.0, 0.02)
for pipeline in (first, second):
    window = pipeline.calibration.window
    window.t = 30.0
    for ti in t:
        window.rows.add(ti, 0.1, 0.05, 1.0, 20.0)
    window._submit()
    print(pipeline.calibration.enabled, window.enabled, window.worker is None)
"""
    result = run(tmp_path, "-c", code)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["True", "False", "True"] * 2
    before, after = result.stderr.split("started")
    assert "scipy" not in before
    assert after.count("the cornering stiffnesses are not learned online without the Python package 'scipy'") == 1
    assert INSTALL in after
