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
the same values at the same tick on any machine, and a live daemon never waits
(the fit is long done). Without scipy (the ``calibrate`` extra) the window is
off and says so once.
"""
from __future__ import annotations

import logging
import os
import pickle
import subprocess
import sys
from dataclasses import dataclass

import numpy as np

from canest.errors import DependencyError
from canest.estimation.calibration_blocks import BlockMeans
from canest.models import output_error
from canest.params import VehicleParams

log = logging.getLogger("canest.calibration")

WINDOW = 30.0  # s of usable driving per fit
LATENCY = 5.0  # s of drive time between a window's end and taking its fit
MAX_HALF_WIDTH = 0.3  # a fit whose 95 % interval of a stiffness factor is wider saw too few bends: not used
STIFFNESS = ("front", "rear")
CLOSE_WAIT = 1.0  # s


@dataclass
class StiffnessFit:
    """One window's stiffness factors (front, rear) on the configured ones, their covariance, its seconds."""

    values: np.ndarray
    covariance: np.ndarray
    seconds: float


def fit_window(vehicle: VehicleParams, drive: output_error.Drive) -> StiffnessFit | None:
    """The output-error fit of one window (in the worker): the two stiffness factors, or None when the window
    did not pin them down (an interval wider than ``MAX_HALF_WIDTH``, or a factor at its bound)."""
    fit = output_error.calibrate(vehicle, [drive])
    index = [fit.names.index(name) for name in STIFFNESS]
    half = fit.half_widths[index]
    bounds = [p for p in output_error.SHARED if p.name in STIFFNESS]
    values = fit.values[index]
    if not np.all(half < MAX_HALF_WIDTH) or any(not p.low < v < p.high for p, v in zip(bounds, values)):
        return None
    std = half / output_error.CONFIDENCE
    covariance = fit.correlation[np.ix_(index, index)] * np.outer(std, std)
    return StiffnessFit(values, covariance, drive.seconds)


class FitWorker:
    """A Python subprocess running :func:`fit_window` on each pickled ``(vehicle, drive)`` it reads on stdin,
    answering with the pickled result on stdout, in order. Its stderr is the caller's."""

    def __init__(self):
        path = os.pathsep.join(p for p in sys.path if p)  # the caller's canest, wherever it was imported from
        self.process = subprocess.Popen([sys.executable, "-c", f"from {__name__} import serve; serve()"],
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        env={**os.environ, "PYTHONPATH": path})

    def submit(self, vehicle: VehicleParams, drive: output_error.Drive) -> None:
        pickle.dump((vehicle, drive), self.process.stdin)
        self.process.stdin.flush()

    def result(self) -> StiffnessFit | None:
        """The oldest submission's fit (waiting for it); None, with a warning, if the worker died."""
        try:
            return pickle.load(self.process.stdout)
        except (EOFError, pickle.UnpicklingError) as exc:
            log.warning("the stiffness fit's worker ended (%s, exit status %s): the window's fit is lost", exc,
                        self.process.poll())
            return None

    def close(self) -> None:
        """End the worker: it leaves its loop when stdin closes; one still fitting (a result nobody waits for) is
        killed after ``CLOSE_WAIT``, well inside a service's stop timeout."""
        self.process.stdin.close()
        try:
            self.process.wait(timeout=CLOSE_WAIT)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.process.stdout.close()


def serve() -> None:
    """The worker's loop (:class:`FitWorker` starts it): until stdin closes."""
    while True:
        try:
            vehicle, drive = pickle.load(sys.stdin.buffer)
        except EOFError:
            return
        pickle.dump(fit_window(vehicle, drive), sys.stdout.buffer)
        sys.stdout.buffer.flush()


class StiffnessWindow:
    """Collects windows of usable driving, fits each in the worker, hands each fit over ``LATENCY`` s later."""

    def __init__(self, vehicle: VehicleParams, names: tuple, dt: float):
        self.vehicle = vehicle
        self.blocks = BlockMeans(names, vehicle, max(1, round(output_error.STEP / dt)))
        self.rows = []
        self.t = 0.0  # drive time of the last tick
        self.last_row = None
        self.due = []  # the drive time each submitted window's fit is taken, oldest first
        self.worker = None  # started with the first window
        self.enabled = _optimizer_available()
        self.fits = {"used": 0, "unexcited": 0}

    def add(self, sample) -> StiffnessFit | None:
        """Take one tick's raw sample; a fit that is due now, or None."""
        if not self.enabled:
            return None
        self.t = sample.t
        block = self.blocks.add(sample)
        if block is not None and block.wheel_speed >= output_error.MIN_SPEED:
            start = self.last_row is None or sample.t - self.last_row > 1.5 * output_error.STEP
            self.rows.append((sample.t, block.steering_wheel_angle, block.yaw_rate, block.ay, block.wheel_speed, start))
            self.last_row = sample.t
            if len(self.rows) * output_error.STEP >= WINDOW:
                self._submit()
        return self._take() if self.due and self.t >= self.due[0] else None

    def _submit(self) -> None:
        drive = output_error.drive_of_rows("online window", self.rows)
        self.rows, self.last_row = [], None
        if drive.seconds < WINDOW / 2:
            return
        if self.worker is None:
            self.worker = FitWorker()
        self.worker.submit(self.vehicle, drive)
        self.due.append(self.t + LATENCY)

    def _take(self) -> StiffnessFit | None:
        self.due.pop(0)
        fit = self.worker.result()
        self.fits["used" if fit is not None else "unexcited"] += 1
        return fit

    def close(self) -> None:
        """Stop the worker; fits not yet due are dropped."""
        if self.worker is not None:
            self.worker.close()
            self.worker = None
        self.due = []


def _optimizer_available() -> bool:
    """scipy's optimizer is there; else False, warned once per process (scipy is the ``calibrate`` extra)."""
    global _warned
    try:
        DependencyError.require("scipy.optimize", "learning the cornering stiffnesses online", output_error.INSTALL)
    except DependencyError as exc:
        if not _warned:
            log.warning("%s; the other parameters are learned", exc)
            _warned = True
        return False
    return True


_warned = False
