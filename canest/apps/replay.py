"""Offline replay of a log through the pipeline, and real-time playback onto a bus.

Readers and writers are python-can's, chosen by file suffix (.log candump,
.asc, .blf, .trc, .csv, ...), so any log python-can reads can be replayed.
What cannot be read is skipped, counted in the summary (``log_<cause>``) and
warned about (logger ``canest.replay``); the outputs are staged and appear
under their names only when the replay ends well (:mod:`canest.io.outputs`).
"""
from __future__ import annotations

import logging
import math
import sys
import time
from contextlib import ExitStack

import can

from canest.apps.progress import LogTimeBar, terminal_bar
from canest.estimation.estimate import OUTPUT_STATES
from canest.io.logfiles import open_log
from canest.io.outputs import is_stdio
from canest.io.sinks import CallbackSink, CsvSink, LogSink
from canest.pipeline import Pipeline
from canest.settings import Config

PROGRESS_EVERY = 2000  # frames between progress-bar updates
LOG = logging.getLogger("canest.replay")


def replay(config: Config, log_path, out_log=None, out_csv=None, progress: bool = True, on_estimate=None,
           step_times=None, stop=None, log_format=None, log_channel=None) -> dict:
    """Run a log through the pipeline as fast as possible; return the frame summary.

    ``log_path`` ``-`` reads standard input as it arrives (``log_format``, ``log_channel``: see
    :class:`canest.io.logfiles.LogSource`);
    ``out_log`` or ``out_csv`` ``-`` writes standard output. ``progress``: a bar of log seconds and frames on
    stderr, left on screen, when stderr is a terminal and no output goes to a terminal on standard output.

    ``step_times``, a list, receives the CPU seconds (of the replaying thread) of every filter predict + update. ``stop``, anything with
    ``is_set()`` (a ``threading.Event``): once set, reading stops after the current frame, the outputs are
    completed up to the last tick and the summary says ``stopped=1``.
    """
    pipeline = Pipeline(config, output_channel=config.output_bus.channel)
    pipeline.estimator.step_times = step_times
    source = open_log(log_path, log_format, log_channel)
    frames = iter(source)
    stopped = False
    try:
        with ExitStack() as stack:
            states = OUTPUT_STATES + pipeline.estimator.extra_states
            sinks = [stack.enter_context(sink) for sink in (
                CsvSink(out_csv, states, staged=True, calibration=pipeline.calibration.enabled)
                if out_csv else None,
                LogSink(out_log, pipeline.encoder, staged=True) if out_log else None,
                CallbackSink(on_estimate) if on_estimate else None) if sink is not None]
            rows_on_screen = (is_stdio(out_csv) or is_stdio(out_log)) and sys.stdout.isatty()  # a bar would cut in
            bar = stack.enter_context(LogTimeBar(source, "replay", progress and not rows_on_screen))
            count = 0
            for count, msg in enumerate(frames, 1):
                estimates = pipeline.feed(msg)
                if estimates:
                    for sink in sinks:
                        sink.publish(estimates)
                if count % PROGRESS_EVERY == 1:
                    bar.at(count, msg.timestamp)
                if stop is not None and stop.is_set():
                    stopped = True
                    break
            if count:
                bar.at(count, msg.timestamp)
            if not stopped:
                bar.finish()
    finally:
        frames.close()
        source.stop()
        pipeline.close()  # the online calibration saved
    for warning in source.warnings():
        LOG.warning(warning)
    summary = {"frames": 0, **pipeline.summary(), **source.summary(), **({"stopped": 1} if stopped else {})}
    if summary.get("decoded"):  # none decoded: the replay command's error says why
        never_arrived(config, log_path, pipeline.resampler.never_held())
    return summary


def never_arrived(config: Config, log_path, names: list) -> None:
    """One warning naming the mapped inputs of which the log held no value, by message: the states that need them
    were never estimated (or only from the others), which a summary of counts does not show."""
    if not names:
        return
    by_message = {}
    for name in names:
        by_message.setdefault(config.signals[name].message, []).append(name)
    listed = "; ".join(f"{message}: {', '.join(inputs)}" for message, inputs in by_message.items())
    LOG.warning(f"{log_path}: no value of {len(names)} mapped input(s) in the whole log ({listed}); the states "
                "that need them are not estimated: compare the log's IDs with the config's input DBC (canest check "
                "--config ...) or leave the inputs the car does not send unmapped")


def play(log_path, bus: can.BusABC, speed: float = 1.0, progress: bool = True, log_format=None,
         log_channel=None) -> int:
    """Send a log's frames onto ``bus`` at their recorded timing (like canplayer); return frames sent.

    A frame without a finite timestamp has no place in time and is not sent; those and what could not be read
    are warned about (logger ``canest.replay``)."""
    reader = open_log(log_path, log_format, log_channel)
    try:
        timed = (msg for msg in reader if math.isfinite(msg.timestamp))
        sent = play_messages(timed, bus, speed, progress, desc=f"play {reader.path.name}")
    finally:
        reader.stop()
    for warning in reader.warnings():
        LOG.warning(warning)
    if reader.frames > sent:
        LOG.warning(f"{log_path}: {reader.frames - sent} frame(s) without a finite timestamp were not sent")
    return sent


def paced(messages, speed: float = 1.0, stop=None):
    """Yield each message once its time since the first, divided by ``speed``, has passed on the wall clock;
    ``stop`` (an Event) ends early."""
    start_wall = start_log = None
    for msg in messages:
        if stop is not None and stop.is_set():
            return
        if start_wall is None:
            start_wall, start_log = time.perf_counter(), msg.timestamp
        delay = (msg.timestamp - start_log) / speed - (time.perf_counter() - start_wall)
        if delay > 0:
            time.sleep(delay)
        yield msg


def play_messages(messages, bus: can.BusABC, speed: float = 1.0, progress: bool = False, desc: str = "play",
                  stop=None) -> int:
    """Send messages at the spacing of their timestamps divided by ``speed`` (:func:`paced`), stamped when sent;
    ``stop`` (an Event) ends early. ``progress``: a bar of frames sent, on a terminal only."""
    sent = 0
    with terminal_bar(progress, desc=desc, unit=" frames") as bar:
        for msg in paced(messages, speed, stop):
            bus.send(can.Message(timestamp=time.time(), arbitration_id=msg.arbitration_id,
                                 is_extended_id=msg.is_extended_id, is_remote_frame=msg.is_remote_frame,
                                 is_fd=msg.is_fd, bitrate_switch=msg.bitrate_switch, dlc=msg.dlc, data=msg.data))
            sent += 1
            bar.update()
    return sent
