"""The errors canest raises for problems of its input, not of its code.

As python-can's ``CanError`` and cantools' ``database/errors.py``: one base,
:class:`CanestError`, whose text is complete for a user (it names the file,
line, key, message or signal and, where there is one, the remedy). The
command line prints such an error as one line and exits 2; any other
exception is a bug and keeps its traceback.
"""


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
