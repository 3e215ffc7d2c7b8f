"""The errors canest raises for problems of its input, not of its code.

As python-can's ``CanError`` and cantools' ``database/errors.py``: one base,
:class:`CanestError`, whose text is complete for a user (it names the file,
line, key, message or signal and, where there is one, the remedy). The
command line prints such an error as one line and exits 2; any other
exception is a bug and keeps its traceback.
"""
import importlib


class CanestError(Exception):
    """A problem with what the user gave canest: a config, a DBC, a log, a bus or an argument."""


class ConfigError(CanestError):
    """A config problem, with the file, line and key it concerns."""


class DbcError(ConfigError):
    """A DBC that cannot be loaded or lacks what canest needs of it."""


class BusOpenError(CanestError):
    """A CAN bus that cannot be opened (interface, channel or driver)."""


class LogError(CanestError):
    """A CAN log that cannot be found, recognized or read."""


class TableError(CanestError):
    """A CSV table (estimates, truth) that cannot be read or lacks a column."""


class UsageError(CanestError, ValueError):
    """Command-line arguments that do not fit together."""


class DependencyError(CanestError):
    """An optional package that the requested feature needs is not installed."""

    @classmethod
    def require(cls, module: str, feature: str, install: str):
        """Import ``module`` for ``feature``, or raise naming the command that installs it."""
        try:
            return importlib.import_module(module)
        except ImportError:
            raise cls(f"{feature} needs the Python package '{module}', which is not installed: {install}") from None


class ClusterError(CanestError):
    """A Dask scheduler that cannot be reached or refuses the connection."""
