"""opendbc's car DBCs by name (``input.dbc: opendbc:NAME``), from the optional package ``opendbc``.

opendbc ships two kinds: files under ``opendbc.DBC_PATH`` and DBCs it
generates in memory from brand parts (``opendbc.get_generated_dbcs()``, names
ending ``_generated``). A static one is used where it lies; a generated one is
written once to canest's cache folder (one folder per opendbc version), so
every stage, the batch fingerprint and a SIGHUP reload see an ordinary file.
Only ``import opendbc`` is needed (no numpy or capnp).
"""
from __future__ import annotations

import difflib
import os
import tempfile
from importlib import metadata
from pathlib import Path

from canest.errors import DependencyError

PREFIX = "opendbc:"
INSTALL = "pip install 'canest[opendbc]' (opendbc needs Python 3.11 or 3.12)"


def _opendbc(feature: str):
    return DependencyError.require("opendbc", feature, INSTALL)


def _cache_dir() -> Path:
    """Where generated DBCs are written: ``$XDG_CACHE_HOME/canest`` (else ``~/.cache/canest``), per opendbc version."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "canest" / f"opendbc-{metadata.version('opendbc')}"


def opendbc_names(feature: str) -> list:
    """Every DBC name opendbc ships, static and generated, sorted."""
    opendbc = _opendbc(feature)
    static = [f[:-4] for f in os.listdir(opendbc.DBC_PATH) if f.endswith(".dbc")]
    return sorted({*static, *opendbc.get_generated_dbcs()})


def closest_names(name: str, feature: str) -> str:
    """``closest: a, b, c`` of opendbc's names, or how many there are when none is close."""
    names = opendbc_names(feature)
    close = difflib.get_close_matches(name, names, n=3, cutoff=0.5)
    if close:
        return f"closest: {', '.join(close)}"
    return f"opendbc ships {len(names)} DBCs, e.g. {', '.join(names[:3])}"


def _write_once(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` unless it already holds it (atomically: a concurrent reader sees old or new)."""
    if path.is_file() and path.read_text() == text:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(handle, "w") as out:
        out.write(text)
    os.replace(temporary, path)


def _temp_cache_dir() -> Path:
    """Where generated DBCs go when the cache folder is not writable: a folder of this user's in the temp dir."""
    return Path(tempfile.gettempdir()) / f"canest-{os.getuid()}" / _cache_dir().name


def opendbc_name_of(path) -> str | None:
    """``NAME`` if ``path`` is a file of opendbc's DBCs (in its package or canest's cache of generated ones, both
    folders that move with an install or a cache clean), else None; None also without opendbc."""
    try:
        import opendbc
    except ImportError:
        return None
    path = Path(path).resolve()
    folders = {Path(opendbc.DBC_PATH).resolve(), _cache_dir().resolve(), _temp_cache_dir().resolve()}
    return path.stem if path.suffix == ".dbc" and path.parent in folders else None


def opendbc_path(name: str, feature: str) -> Path | None:
    """The file of opendbc's DBC ``name`` (a generated one written to the cache first); None if opendbc has none."""
    opendbc = _opendbc(feature)
    generated = opendbc.get_generated_dbcs().get(name)
    if generated is not None:
        path = _cache_dir() / f"{name}.dbc"
        try:
            _write_once(path, generated)
        except OSError:  # no writable cache (a service user without a home): a folder of its own in the temp dir
            path = _temp_cache_dir() / path.name
            _write_once(path, generated)
        return path
    path = Path(opendbc.DBC_PATH) / f"{name}.dbc"
    return path if "/" not in name and path.is_file() else None
