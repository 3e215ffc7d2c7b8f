"""A live terminal view of a running daemon's output, decoded through the output DBC.

Like ``cantools monitor`` but for canest's contract: the latest value,
standard deviation and validity of each estimate, the status message (filter,
mode, missing inputs, resets, NIS), the online calibration (each learned
parameter's value, std and state) and the health of the output stream itself
(frame rate, CRC failures, counter gaps).
"""
from __future__ import annotations

import math
import time
from collections import Counter

import can

from canest.codec import integrity
from canest.codec.encode import (CALIBRATION_MESSAGE, CALIBRATION_PAGE, OUTPUT_MESSAGES, STATUS_MESSAGE,
                                 calibration_signal, integrity_signals)
from canest.estimation.learned_parameters import NAMES
from canest.signals import INPUT_GROUPS

# (label, message, signal stem, display unit, factor from SI)
ROWS = [
    ("vx", "CE_Velocity", "Vx", "m/s", 1.0),
    ("vy", "CE_Velocity", "Vy", "m/s", 1.0),
    ("yaw rate", "CE_YawSideslip", "YawRate", "deg/s", 180 / math.pi),
    ("sideslip", "CE_YawSideslip", "Sideslip", "deg", 180 / math.pi),
    *[(f"Fy {w}", f"CE_LateralForces{'Front' if w[0] == 'f' else 'Rear'}", f"Fy{w.upper()}", "N", 1.0)
      for w in ("fl", "fr", "rl", "rr")],
    *[(f"mu {w}", "CE_Friction", f"Mu{w.upper()}", "", 1.0) for w in ("fl", "fr", "rl", "rr")],
]
CALIBRATION_WAIT = 1.2  # s: once the estimates are complete, how long --once waits for the 1 Hz calibration
STALE_AFTER = 1.0  # s without an estimate frame after which the values shown are a stopped daemon's last ones
DEG = 180 / math.pi
# learned parameter: (display unit, factor from SI); speed, ratio, front and rear are factors on the configured values
CALIBRATION_UNITS = {"speed": ("x", 1.0), "gyro_bias": ("deg/s", DEG), "ay_bias": ("m/s^2", 1.0),
                     "steering_offset": ("deg", DEG), "ratio": ("x", 1.0), "understeer": ("deg/(m/s^2)", DEG),
                     "ax_bias": ("m/s^2", 1.0), "front": ("x", 1.0), "rear": ("x", 1.0), "gyro_bias_2": ("deg/s", DEG)}


def calibration_state(page: dict) -> str:
    """``converged`` (its posterior std below its threshold; the published std of the stiffnesses, the steering
    ratio and the understeer gradient also holds the linear tires' model error), ``learning`` (driving excited it)
    or ``prior`` (not yet)."""
    return "converged" if page["CalConverged"] else "learning" if page["CalLearned"] else "prior"


class Monitor:
    def __init__(self, database):
        self.database = database
        self.messages = {m.frame_id: m for m in database.messages
                         if m.name in (*OUTPUT_MESSAGES, STATUS_MESSAGE, CALIBRATION_MESSAGE)}
        # per frame ID: (counter signal name, counter modulus, checksum byte), as the sender sets them
        self.integrity = {}
        for frame_id, message in self.messages.items():
            counter, checksum = integrity_signals(message)
            self.integrity[frame_id] = (counter.name, 2 ** counter.length, integrity.checksum_byte(checksum))
        self.names = {m.name for m in self.messages.values()}
        self.completed_at = None  # when complete() first held
        self.latest = {}
        self.calibration = {}  # learned parameter -> its latest CE_Calibration page
        self.counts = Counter()
        self.counters = {}
        self.started = time.monotonic()
        self.last_frame = None  # time.monotonic() of the last estimate frame
        self.rate_since = (self.started, 0)  # (time, frames) of the last render: its frame rate is since then

    def age(self) -> float | None:
        """Seconds since the last estimate frame (None before the first)."""
        return None if self.last_frame is None else time.monotonic() - self.last_frame

    def stale(self) -> bool:
        """Frames came, then stopped for ``STALE_AFTER`` s: what is shown is no longer the car's (a daemon stopped
        or its bus down kept its last values on screen, flagged valid, for as long as the monitor ran)."""
        age = self.age()
        return age is not None and age > STALE_AFTER

    def receive(self, msg: can.Message) -> None:
        message = self.messages.get(msg.arbitration_id)
        if message is None:
            self.counts["foreign"] += 1
            return
        self.counts["frames"] += 1
        self.last_frame = time.monotonic()
        counter_name, modulus, crc_index = self.integrity[msg.arbitration_id]
        if not integrity.checksum_ok(msg.arbitration_id, msg.data, crc_index):
            self.counts["crc_errors"] += 1
            return
        values = message.decode(msg.data, decode_choices=True)
        counter = int(values[counter_name])
        last = self.counters.get(message.name)
        if last is not None and (counter - last) % modulus != 1:
            self.counts["counter_gaps"] += 1
        self.counters[message.name] = counter
        if message.name == CALIBRATION_MESSAGE:
            self.calibration[str(values[CALIBRATION_PAGE])] = values
        else:
            self.latest[message.name] = values

    def calibration_rows(self):
        """(name, value, std, unit, state) of each learned parameter received, in display units."""
        for name in NAMES:
            page = self.calibration.get(name)
            if page is not None:
                unit, factor = CALIBRATION_UNITS[name]
                signal = calibration_signal(name)
                yield name, page[signal] * factor, page[f"{signal}Std"] * factor, unit, calibration_state(page)

    def complete(self) -> bool:
        """Whether the status message and the velocity and yaw-rate estimates have arrived."""
        return all(name in self.latest for name in (STATUS_MESSAGE, "CE_Velocity", "CE_YawSideslip"))

    def settled(self) -> bool:
        """Complete, and every learned parameter's page arrived or one calibration cycle waited for it (a DBC
        without ``CE_Calibration`` or a daemon whose learner is off sends none)."""
        if not self.complete():
            return False
        if self.completed_at is None:
            self.completed_at = time.monotonic()
        return (len(self.calibration) == len(NAMES) or CALIBRATION_MESSAGE not in self.names
                or time.monotonic() - self.completed_at >= CALIBRATION_WAIT)

    def line(self) -> str:
        """The view as one line of ``key=value`` words, for a pipe or a log; an invalid state's value ends in ?."""
        age = self.age()
        words = [f"t={time.time():.3f}", f"frames={self.counts['frames']}", f"crc_errors={self.counts['crc_errors']}",
                 f"counter_gaps={self.counts['counter_gaps']}", *([f"age={age:.1f}"] if age is not None else [])]
        stale = self.stale()
        status = self.latest.get(STATUS_MESSAGE)
        if status is not None:
            words += [f"mode={status['Mode']}", f"resets={status['ResetCount']}"]
        for label, message, stem, unit, factor in ROWS:
            values = self.latest.get(message)
            if values is not None:
                mark = "" if values[f"{stem}Valid"] and not stale else "?"
                words.append(f"{label.replace(' ', '_')}={values[stem] * factor:.4g}{mark}")
        for name, value, std, _, state in self.calibration_rows():
            words += [f"calib_{name}={value:.6g}", f"calib_{name}_std={std:.3g}", f"calib_{name}_state={state}"]
        return " ".join(words)

    def render(self, title: str) -> str:
        now, c = time.monotonic(), self.counts
        since, frames_then = self.rate_since
        rate = (c["frames"] - frames_then) / max(now - since, 1e-9)  # since the last view: frames stopping show
        self.rate_since = (now, c["frames"])
        lines = [f"canest monitor  {title}  frames {c['frames']} ({rate:.0f}/s)  "
                 f"CRC errors {c['crc_errors']}  counter gaps {c['counter_gaps']}"]
        stale = self.stale()
        if stale:
            lines.append(f"no estimate frames for {self.age():.1f} s: the values below are the last received; "
                         "is the daemon running and its bus up?")
        status = self.latest.get(STATUS_MESSAGE)
        if status is None:
            lines.append("no status message yet")
        else:
            missing = [name for i, name in enumerate(INPUT_GROUPS) if int(status["MissingInputs"]) >> i & 1]
            lines.append(f"filter {status['FilterId']}  mode {status['Mode']}  resets {status['ResetCount']}  "
                         f"NIS {status['InnovationNis']:.2f}  missing: {', '.join(missing) or '-'}")
        lines.append(f"{'state':<10} {'value':>12} {'std':>10}  valid")
        for label, message, stem, unit, factor in ROWS:
            values = self.latest.get(message)
            if values is None:
                continue
            valid = "stale" if stale else "yes" if values[f"{stem}Valid"] else "no"
            lines.append(f"{label:<10} {values[stem] * factor:>9.3f} {unit:<5}{values[stem + 'Std'] * factor:>8.3f}"
                         f"  {valid}")
        rows = list(self.calibration_rows())
        if rows:
            lines.append(f"{'learned':<16} {'value':>10} {'std':>19}  state")
            lines += [f"{name:<16} {value:>10.5f} {unit:<11}{std:>8.5f}  {state}"
                      for name, value, std, unit, state in rows]
        return "\n".join(lines)


def run_monitor(bus: can.BusABC, database, title: str, out, refresh: float = 0.5, duration=None, clear=False,
                lines: bool = False, once: bool = False):
    """Print the view every ``refresh`` s until ``duration`` s have passed (or forever); ``lines``: one line each
    time (:meth:`Monitor.line`); ``once``: print once, when the estimates are complete and the calibration too
    (:meth:`Monitor.settled`)."""
    monitor = Monitor(database)
    end = math.inf if duration is None else time.monotonic() + duration
    next_draw = time.monotonic()
    while time.monotonic() < end:
        msg = bus.recv(timeout=min(refresh, max(end - time.monotonic(), 0.0)))
        if msg is not None:
            monitor.receive(msg)
        if once and not monitor.settled():
            continue
        if once or time.monotonic() >= next_draw:
            next_draw += refresh
            view = monitor.line() if lines else ("\x1b[H\x1b[J" if clear else "\n") + monitor.render(title)
            out.write(view + "\n")
            out.flush()
            if once:
                break
    return monitor
