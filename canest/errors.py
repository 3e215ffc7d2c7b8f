"""The errors canest raises for problems of its input or its environment, not of its code.

As python-can's ``CanError`` and cantools' ``database/errors.py``: one base,
:class:`CanestError`, whose text is complete for a user (it names the file,
line, key, message or signal and, where there is one, the remedy). The
command line prints such an error as one line and exits with the class's
``exit_status``, after the BSD ``sysexits.h`` convention:

== ========================================================================
 2 usage or config: arguments, config file, DBC, bus (argparse's own 2)
65 input data (EX_DATAERR): a log or table canest cannot read
66 no input (EX_NOINPUT): an input file that does not exist or may not be read
69 unavailable (EX_UNAVAILABLE): an optional package a feature needs
73 cannot create (EX_CANTCREAT): an output file that cannot be created
74 I/O error (EX_IOERR): reading or writing failed midway (disk full, device)
== ========================================================================

Any other exception is a bug: it keeps its traceback and exits 1.
"""
import importlib


class CanestError(Exception):
    """A problem with what the user gave canest: a config, a DBC, a log, a bus or an argument."""

    exit_status = 2


class ConfigError(CanestError):
    """A config problem, with the file, line and key it concerns."""


class DbcError(ConfigError):
    """A DBC that cannot be loaded or lacks what canest needs of it."""


class BusOpenError(CanestError):
    """A CAN bus that cannot be opened (interface, channel or driver)."""


class UsageError(CanestError, ValueError):
    """Command-line arguments that do not fit together."""


class SimulationError(CanestError):
    """A simulated drive the plant cannot follow (the options ask for more than it models)."""


class LogError(CanestError):
    """A CAN log that cannot be recognized or read."""

    exit_status = 65


class TableError(CanestError):
    """A CSV table (estimates, truth) that cannot be read or lacks a column."""

    exit_status = 65


class InputFileError(CanestError):
    """An input file (log, table) that does not exist or that canest may not read."""

    exit_status = 66


class DependencyError(CanestError):
    """An optional package that the requested feature needs is not installed."""

    exit_status = 69

    @classmethod
    def require(cls, module: str, feature: str, install: str):
        """Import ``module`` for ``feature``, or raise naming the command that installs it."""
        try:
            return importlib.import_module(module)
        except ImportError:
            raise cls(f"{feature} needs the Python package '{module}', which is not installed: {install}") from None


class OutputFileError(CanestError):
    """An output file that cannot be created (folder missing or read-only, a folder named as file, ...)."""

    exit_status = 73


class FileIOError(CanestError):
    """Reading or writing a file failed midway (disk full, file size limit, device error)."""

    exit_status = 74


class ClusterError(CanestError):
    """A Dask scheduler that cannot be reached or refuses the connection."""

    exit_status = 69
