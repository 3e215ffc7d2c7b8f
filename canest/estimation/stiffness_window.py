"""The cornering stiffnesses learned online: the offline output-error fit run on windows of the drive.

No steady identity sees the stiffnesses' scale (a steady bend fixes only
their balance, the understeer gradient), and a transient identity fitted
tick by tick aliases every lag (relaxation, sensor and resampling delays) into
it (README "Online calibration"). The output-error fit of ``canest calibrate``
(:func:`canest.models.output_error.calibrate`: the single-track model with
tire relaxation, driven by the measured steering and wheel speed, fitted to
the measured yaw rate and ay) recovers both axles' stiffness from half a
minute of country road. So the learner collects the raw inputs at the fit's
``STEP`` (means of ``STEP`` s of ticks: :class:`canest.estimation.calibration_blocks.BlockMeans`),
and after each ``WINDOW`` s of usable driving (above
:data:`canest.models.output_error.MIN_SPEED`) fits that window alone: windows never overlap, so each
fit is independent evidence for the learner's Kalman update.

The fit (0.5-1 s of CPU for 30 s of driving) runs in a worker: a Python
subprocess of this module (:class:`FitWorker`), off the estimator's loop and
its GIL. Not :mod:`multiprocessing`: its spawned children re-import the
caller's main script, which breaks any script that uses canest without an
``if __name__ == "__main__"`` guard. Its result is taken ``LATENCY`` s of drive
time after the window closed, waiting for it then if need be: a replay learns
the same values at the same tick on any machine, and a live daemon waits only
if a fit took longer than that (a window is checked for bends before it is
fitted, and the worker runs single-threaded BLAS at a lower priority). A worker
that dies turns the window off for the run, with one warning; the estimator
goes on. Off, and saying so once, without scipy (the ``calibrate`` extra) or
at a tick rate that is not a multiple of 50 Hz (the fit's ``STEP``); without scipy it says so at the
first window (a short drive, as ``canest demo``'s, never needs it).
"""
from __future__ import annotations

import importlib.util
import logging
import os
import pickle
import socket
import subprocess
import sys
import traceback
from dataclasses import dataclass

import numpy as np

from canest.calibration import CONFIDENCE, STIFFNESSES
from canest.estimation.calibration_blocks import BlockMeans
from canest.models import output_error
from canest.params import VehicleParams

log = logging.getLogger("canest.calibration")

WINDOW = 30.0  # s of usable driving per fit
LATENCY = 5.0  # s of drive time between a window's end and taking its fit
MIN_BENDS = 2.0  # s of a window turning (v r) between BEND_AY and the fit's linear limit: fewer saw no yaw dynamics
BEND_AY = 0.5  # m/s^2
MAX_HALF_WIDTH = 0.3  # a fit whose 95 % interval of a stiffness factor is wider saw too few bends: not used
FITTED = (*STIFFNESSES, "ratio", "steering_offset", "gyro_bias", "ay_bias", "speed")  # the learner's too
CLOSE_WAIT = 1.0  # s
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}  # one core at most
WORKER_NICE = 5


@dataclass
class WindowFit:
    """One window's parameters (:data:`FITTED`, the stiffness factors first), their covariance, its seconds."""

    names: tuple
    values: np.ndarray
    covariance: np.ndarray
    seconds: float


def fit_window(vehicle: VehicleParams, drive: output_error.Drive) -> WindowFit | None:
    """The output-error fit of one window (in the worker): the parameters it shares with the online calibration
    (:data:`FITTED`; the bank is held at 0, so ``ay_bias`` is the bias less the bank's gravity, as the learner's),
    or None when the window cannot pin the stiffnesses down: fewer than ``MIN_BENDS`` s of bends (not fitted: a
    straight's Jacobian is singular, and its pseudo-inverse called the stiffnesses certain), an interval of either
    wider than ``MAX_HALF_WIDTH`` or not above 0, or a factor at its bound."""
    turning = np.abs(output_error.turning_ay(drive))
    bends = (turning >= BEND_AY) & (turning < output_error.LINEAR_AY)
    if bends.sum() * output_error.STEP < MIN_BENDS:
        return None
    fit = output_error.calibrate(vehicle, [drive])
    index = [fit.names.index(name) for name in STIFFNESSES]
    half = fit.half_widths[index]
    bounds = [p for p in output_error.SHARED if p.name in STIFFNESSES]
    values = fit.values[index]
    if not np.all((half > 0.0) & (half < MAX_HALF_WIDTH)) or any(not p.low < v < p.high
                                                                  for p, v in zip(bounds, values)):
        return None
    fitted = [fit.names.index(name) for name in FITTED]
    std = fit.half_widths[fitted] / CONFIDENCE
    covariance = fit.correlation[np.ix_(fitted, fitted)] * np.outer(std, std)
    return WindowFit(FITTED, fit.values[fitted], covariance, drive.seconds)


class WorkerLost(Exception):
    """The worker process ended or its pipe broke."""


class FitWorker:
    """A Python subprocess running :func:`fit_window` on each pickled ``(vehicle, drive)`` it reads on stdin,
    answering with the pickled result on stdout, in order. Its stderr is the caller's; its own session, so a
    terminal's Ctrl-C reaches only the caller (whose close ends it; a caller that dies closes its stdin).

    Its stdin is one end of a socket pair, not a pipe: the command line restores SIGPIPE's default (so that
    ``canest check | head`` ends quietly), and a write into the pipe of a dead worker then killed the daemon
    without a word; a socket is written with ``MSG_NOSIGNAL``, and a dead reader is an error to handle."""

    def __init__(self):
        path = os.pathsep.join(p for p in sys.path if p)  # the caller's canest, wherever it was imported from
        self.requests, worker_end = socket.socketpair()
        with worker_end:
            self.process = subprocess.Popen([sys.executable, "-c", f"from {__name__} import serve; serve()"],
                                            stdin=worker_end, stdout=subprocess.PIPE, start_new_session=True,
                                            env={**os.environ, **WORKER_ENV, "PYTHONPATH": path})

    def submit(self, vehicle: VehicleParams, drive: output_error.Drive) -> None:
        try:
            self.requests.sendall(pickle.dumps((vehicle, drive)), socket.MSG_NOSIGNAL)
        except OSError as exc:
            raise WorkerLost(f"{exc}, exit status {self.process.poll()}") from None

    def result(self) -> WindowFit | None:
        """The oldest submission's fit, waiting for it."""
        try:
            return pickle.load(self.process.stdout)
        except (EOFError, OSError, pickle.UnpicklingError) as exc:
            raise WorkerLost(f"{exc or type(exc).__name__}, exit status {self.process.poll()}") from None

    def close(self) -> None:
        """End the worker: it leaves its loop when stdin closes; one still fitting (a result nobody waits for) is
        killed after ``CLOSE_WAIT``, well inside a service's stop timeout."""
        self.requests.close()
        try:
            self.process.wait(timeout=CLOSE_WAIT)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.process.stdout.close()


def serve() -> None:
    """The worker's loop (:class:`FitWorker` starts it): until stdin closes. A fit that raises answers None (its
    traceback on stderr): one bad window must not end the learning."""
    os.nice(WORKER_NICE)
    while True:
        try:
            vehicle, drive = pickle.load(sys.stdin.buffer)
        except EOFError:
            return
        try:
            fit = fit_window(vehicle, drive)
        except Exception:  # noqa: BLE001 - reported, and the window counts as not used
            traceback.print_exc()
            fit = None
        pickle.dump(fit, sys.stdout.buffer)
        sys.stdout.buffer.flush()


class StiffnessWindow:
    """Collects windows of usable driving, fits each in the worker, hands each fit over ``LATENCY`` s later."""

    def __init__(self, vehicle: VehicleParams, names: tuple, dt: float):
        self.vehicle = vehicle
        ticks = output_error.STEP / dt
        self.blocks = BlockMeans(names, vehicle, max(1, round(ticks)))
        self.rows = output_error.DriveRows()
        self.t = None  # drive time of the last tick
        self.due = []  # the drive time each submitted window's fit is taken, oldest first
        self.worker = None  # started with the first window
        self.enabled = _usable_rate(dt, ticks)
        self.fits = {"used": 0, "unexcited": 0, "short": 0, "lost": 0}

    def add(self, sample) -> WindowFit | None:
        """Take one tick's raw sample; a fit that is due now, or None."""
        if not self.enabled:
            return None
        if self.t is not None and sample.t < self.t:  # the clock stepped back: the window restarts, fits stay due
            self.rows = output_error.DriveRows()
            self.due = [sample.t + LATENCY for _ in self.due]
        self.t = sample.t
        block = self.blocks.add(sample)
        if block is not None:
            self.rows.add(sample.t, block.steering_wheel_angle, block.yaw_rate, block.ay, block.wheel_speed)
            if self.rows.seconds >= WINDOW:
                self._submit()
        return self._take() if self.due and self.t >= self.due[0] else None

    def _submit(self) -> None:
        drive = self.rows.drive("online window")
        self.rows = output_error.DriveRows()
        if drive.seconds < WINDOW / 2:
            self.fits["short"] += 1
            return
        if importlib.util.find_spec("scipy") is None:  # said at the first window: a short drive never needs it
            _warn_once(f"without the Python package 'scipy', which is not installed: {output_error.INSTALL}")
            self.enabled = False
            return
        try:
            if self.worker is None:
                self.worker = FitWorker()
            self.worker.submit(self.vehicle, drive)
        except (OSError, WorkerLost) as exc:
            self._lose(exc)
            return
        self.due.append(self.t + LATENCY)

    def _take(self) -> WindowFit | None:
        self.due.pop(0)
        try:
            fit = self.worker.result()
        except WorkerLost as exc:
            self._lose(exc)
            return None
        self.fits["used" if fit is not None else "unexcited"] += 1
        return fit

    def _lose(self, exc) -> None:
        """The worker is gone: the window is off for the rest of the run, the estimator goes on."""
        log.warning("the cornering stiffnesses' worker is gone (%s): they are no longer learned in this run", exc)
        self.fits["lost"] += 1 + len(self.due)
        self.close()
        self.enabled = False

    def close(self) -> None:
        """Stop the worker; fits not yet due are dropped."""
        if self.worker is not None:
            self.worker.close()
            self.worker = None
        self.due = []


def _usable_rate(dt: float, ticks: float) -> bool:
    """The tick period divides the fit's ``STEP``; else False, warned (once per process)."""
    if abs(ticks - round(ticks)) < 1e-6:
        return True
    _warn_once(f"at {1.0 / dt:g} Hz: the fit needs a sample every {output_error.STEP:g} s, a tick rate that is a "
               f"multiple of {1.0 / output_error.STEP:g} Hz")
    return False


def _warn_once(reason: str) -> None:
    global _warned
    if not _warned:
        log.warning("the cornering stiffnesses are not learned online %s; the other parameters are learned", reason)
        _warned = True


_warned = False
