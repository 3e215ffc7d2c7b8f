"""Where the tools cache their simulated drives: a folder per config and per simulator source.

``tools/honesty.py`` and ``tools/calibration.py`` simulate each drive once and replay it many times. Keyed by the
config's bytes alone, a changed plant replayed stale drives; keyed by all of canest, every estimator change (what
the tools measure) would simulate anew. So the key is the config file, the input DBC it names and the files the
drives are made of: every canest module the simulator imports, asked of a fresh interpreter (a tool imports the
estimators too), and the config loader's, which builds the Config the simulator is given.
"""
from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SIMULATOR = ("canest.sim.simulate", "canest.sim.mismatch")  # the modules the drives are made with
LOADER = ("canest/config/*.py", "canest/yamldoc.py", "canest/limits.py")  # importing it would load the estimators


def simulator_sources() -> list:
    """The canest source files the simulated drives are made of (module docstring)."""
    listing = (f"import sys; sys.path.insert(0, {str(ROOT)!r}); import {', '.join(SIMULATOR)}; "
               "print('\\n'.join(sorted(m.__file__ for n, m in sys.modules.items() if n.split('.')[0] == 'canest')))")
    run = subprocess.run([sys.executable, "-c", listing], capture_output=True, text=True)
    if run.returncode:
        raise RuntimeError(f"listing the simulator's modules failed: {run.stderr.strip()}")
    loader = sorted(path for pattern in LOADER for path in ROOT.glob(pattern))
    return sorted({Path(line) for line in run.stdout.splitlines()} | set(loader))


def folder(workdir: Path, config_file: Path, input_dbc: Path, sources=None) -> Path:
    """The cache folder of a config's drives under ``workdir``: named by the config's bytes, its input DBC's and the
    ``sources`` (default :func:`simulator_sources`)."""
    digest = hashlib.sha1(Path(config_file).read_bytes())
    for path in [Path(input_dbc), *(simulator_sources() if sources is None else sources)]:
        digest.update(path.read_bytes())
    return Path(workdir) / digest.hexdigest()[:8]
