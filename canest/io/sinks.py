"""Where estimates go: one small protocol, one class per destination (python-can's ``Listener`` for estimates).

Every sink gets each tick's estimates in order through :meth:`Sink.publish`
(a list: after a stall several ticks complete at once) and is closed at the
end: :meth:`Sink.close` after a run that ended well, :meth:`Sink.abort`
after one that failed. The live service and replay both just iterate over
their sinks:

- :class:`CsvSink`: one row per tick (every tick);
- :class:`LogSink`: the estimate frames of every tick into a CAN log, its
  format chosen by python-can from the suffix (``can.Logger``), candump text
  on standard output for ``-`` (:func:`open_frame_writer`);
- :class:`BusSink`: the newest tick's frames onto a bus link, never a burst
  (older ticks of the same pass are counted ``superseded``);
- :class:`CallbackSink`: a function called with every estimate.

The file sinks write through :class:`~canest.io.outputs.OutputFile`:
``staged=True`` (replay) writes a temporary file that only a clean close
renames to the final name; ``staged=False`` (the live service, whose CSV is
followed while it runs) writes in place and keeps what was written. Either
way a failing disk is one line naming the file (exit 73 or 74), never a
traceback.

Frame sinks take an encoder (anything with ``encode(estimate) -> [can.Message]``).
"""
from __future__ import annotations

import csv
import math
from datetime import datetime, timezone

import can

from canest.errors import DependencyError, UsageError
from canest.estimation.estimate import CAUSE_GROUPS
from canest.estimation.learned_parameters import NAMES
from canest.io.logfiles import KNOWN_SUFFIXES, log_format
from canest.io.outputs import OutputFile


class Sink:
    def publish(self, estimates: list) -> None:
        for estimate in estimates:
            self.write(estimate)

    def write(self, estimate) -> None:
        raise NotImplementedError

    def close(self) -> None:
        """Flush and release what the sink holds (nothing by default)."""

    def abort(self) -> None:
        """Release what the sink holds after a failed run (by default as :meth:`close`)."""
        self.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        if exc_type is None:
            self.close()
        else:
            self.abort()


class FileSink(Sink):
    """A sink writing one :class:`OutputFile`; an ``OSError`` becomes a one-line error naming the file."""

    def __init__(self, path, staged: bool):
        self.output = OutputFile(path, staged)

    def write(self, estimate) -> None:
        try:
            self._write(estimate)
        except OSError as exc:
            raise self.output.error(exc) from None

    def _write(self, estimate) -> None:
        raise NotImplementedError

    def _release(self) -> None:
        """Flush and close the file."""
        raise NotImplementedError

    def close(self) -> None:
        try:
            self._release()
        except OSError as exc:
            self.output.discard()
            raise self.output.error(exc) from None
        self.output.commit()

    def abort(self) -> None:
        try:
            self._release()
        except OSError:
            pass  # the run failed already; that error is the one to report
        self.output.discard()


class CsvSink(FileSink):
    """One row per tick: ``t``, the states, their ``_std`` columns, ``valid`` (bit mask), ``mode`` and
    ``why_vx``, ``why_yaw_rate``, ``why_beta``, ``why_forces``, ``why_friction`` (why a bit is clear).

    ``valid`` bits: 0 vx, 1 vy, 2 beta, 3 yaw rate, 4 lateral forces, 5 friction, 6 friction observable now,
    7-10 lateral force fl, fr, rl, rr, 11-14 friction fl, fr, rl, rr (``canest.estimation.estimate.VALID_BITS``).
    With the online calibration running, each row ends in ``calib_<name>`` and ``calib_<name>_std`` per learned
    parameter (:data:`~canest.estimation.learned_parameters.NAMES`, SI units).
    Given ``states`` (and ``calibration``: whether the learner runs), the header is written at once, so a run without
    a tick still leaves a CSV with its header; otherwise the first estimate's states and calibration make it.
    """

    def __init__(self, path, states=(), staged: bool = False, calibration: bool = False):
        super().__init__(path, staged)
        try:
            self.handle = self.output.open_text()
            self.writer = csv.writer(self.handle)
            self.columns = None
            if states:
                self._header(list(states), calibration)
        except OSError as exc:
            self.output.discard()
            raise self.output.error(exc) from None

    def _header(self, states: list, calibration: bool) -> None:
        self.columns = states + [f"{k}_std" for k in states]
        self.calibration = [f"calib_{name}{suffix}" for name in NAMES for suffix in ("", "_std")] if calibration else []
        self.writer.writerow(["t", *self.columns, "valid", "mode", *(f"why_{g}" for g in CAUSE_GROUPS),
                              *self.calibration])

    def _write(self, estimate) -> None:
        if self.columns is None:
            self._header([k for k in estimate.values if not k.endswith("_std")], bool(estimate.calibration))
        self.writer.writerow([f"{estimate.t:.6f}", *(f"{estimate.values[c]:.9g}" for c in self.columns),
                              estimate.valid_flags, estimate.mode, *(estimate.causes.get(g, "") for g in CAUSE_GROUPS),
                              *(f"{estimate.calibration[c]:.9g}" for c in self.calibration)])

    def _release(self) -> None:
        self.handle.close()


class LogSink(FileSink):
    """Every tick's estimate frames into a CAN log (``.log`` candump, ``.asc``, ``.blf``, ... by suffix)."""

    def __init__(self, path, encoder, staged: bool = False):
        super().__init__(path, staged)
        self.encoder = encoder
        self.logger = open_frame_writer(self.output)

    def _write(self, estimate) -> None:
        for frame in self.encoder.encode(estimate):
            self.logger.on_message_received(frame)

    def _release(self) -> None:
        self.logger.stop()


def exact_mf4_writer(path):
    """python-can's MF4 writer, its start time the first frame's second instead of the wall clock.

    MF4 stores each timestamp relative to the file's start time. python-can's
    writer takes the start from the clock when it opens, so a log whose clock
    starts at 0 (a simulation) comes back 1e-7 s off; from a whole second at or
    before the first frame every timestamp is written and read back exactly.
    """
    from can.io.mf4 import MF4Writer

    class ExactMF4Writer(MF4Writer):
        started = False

        def on_message_received(self, msg: can.Message) -> None:
            if not self.started and msg.timestamp is not None and math.isfinite(msg.timestamp):
                start = float(math.floor(msg.timestamp))
                self._mdf.header.start_time = datetime.fromtimestamp(start, timezone.utc)
                self.last_timestamp = self._start_time = start
            self.started = True
            super().on_message_received(msg)

    return ExactMF4Writer(path)


def open_frame_writer(output: OutputFile):
    """python-can's writer for ``output`` (a ``can.Listener``): by suffix, or candump ``-L`` text on stdout."""
    suffix, _ = log_format(output.path)
    if not output.stdout and suffix in can.io.logger.MESSAGE_WRITERS and suffix not in KNOWN_SUFFIXES:
        output.discard()
        raise UsageError(f"{output.path}: python-can writes '{suffix}' as a printout no reader (canest's either) reads "
                         "back; name a log: .log (candump), .asc, .blf, .trc, .csv, .mf4")
    try:
        if output.stdout:
            return can.CanutilsLogWriter(output.open_text())
        if output.path.suffix.lower() == ".mf4":
            return exact_mf4_writer(str(output.write_path))
        return can.Logger(str(output.write_path))
    except (ImportError, NotImplementedError) as exc:  # python-can's MF4 writer without asammdf
        output.discard()
        raise DependencyError(f"{output.path}: {exc}; pip install 'canest[mf4]'") from None
    except ValueError as exc:
        output.discard()
        raise UsageError(f"{output.path}: {exc}; name a log python-can writes (.log, .asc, .blf, .trc, .csv, "
                         ".mf4), or - for candump text on standard output") from None
    except OSError as exc:
        output.discard()
        raise output.error(exc) from None


class BusSink(Sink):
    """The newest estimate of each pass onto a bus link; ``counts`` gets sent, send_dropped and superseded."""

    def __init__(self, link, encoder, counts):
        self.link = link
        self.encoder = encoder
        self.counts = counts

    def publish(self, estimates: list) -> None:
        self.counts["superseded"] += len(estimates) - 1
        for frame in self.encoder.encode(estimates[-1]):
            self.counts["sent" if self.link.send(frame) else "send_dropped"] += 1


class CallbackSink(Sink):
    """Calls ``function(estimate)`` for every tick."""

    def __init__(self, function):
        self.function = function

    def write(self, estimate) -> None:
        self.function(estimate)
