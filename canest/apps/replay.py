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
from tqdm import tqdm

from canest.estimation.estimate import OUTPUT_STATES
from canest.io.logfiles import open_log
from canest.io.sinks import CallbackSink, CsvSink, LogSink
from canest.pipeline import Pipeline
from canest.settings import Config

PROGRESS_EVERY = 2000  # frames between progress-bar updates
LOG = logging.getLogger("canest.replay")


def progress_bar(source, desc: str, progress: bool):
    """A bar on stderr that stays when done: bytes of a log file (with its total), else frames; none when
    ``progress`` is off or stderr is not a terminal (a redirected stderr gets no bar)."""
    size = source.size()
    return tqdm(total=size, unit="B" if size else " frames", unit_scale=bool(size), desc=f"{desc} {source.path.name}",
                disable=not (progress and sys.stderr.isatty()), leave=True)


def replay(config: Config, log_path, out_log=None, out_csv=None, progress: bool = True, on_estimate=None,
           step_times=None, stop=None, log_format=None, log_channel=None) -> dict:
    """Run a log through the pipeline as fast as possible; return the frame summary.

    ``log_path`` ``-`` reads standard input as it arrives (``log_format``, ``log_channel``: see
    :class:`canest.io.logfiles.LogSource`);
    ``out_log`` or ``out_csv`` ``-`` writes standard output.

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
                CsvSink(out_csv, states, staged=True) if out_csv else None,
                LogSink(out_log, pipeline.encoder, staged=True) if out_log else None,
                CallbackSink(on_estimate) if on_estimate else None) if sink is not None]
            bar = stack.enter_context(progress_bar(source, "replay", progress))
            by_bytes = bar.total is not None
            for count, msg in enumerate(frames, 1):
                estimates = pipeline.feed(msg)
                if estimates:
                    for sink in sinks:
                        sink.publish(estimates)
                if count % PROGRESS_EVERY == 0:
                    bar.update(source.position() - bar.n if by_bytes else PROGRESS_EVERY)
                if stop is not None and stop.is_set():
                    stopped = True
                    break
    finally:
        frames.close()
        source.stop()
        pipeline.close()  # the online calibration saved
    for warning in source.warnings():
        LOG.warning(warning)
    return {"frames": 0, **pipeline.summary(), **source.summary(), **({"stopped": 1} if stopped else {})}


def play(log_path, bus: can.BusABC, speed: float = 1.0, progress: bool = True, log_format=None,
         log_channel=None) -> int:
    """Send a log's frames onto ``bus`` at their recorded timing (like canplayer); return frames sent.

    A frame without a finite timestamp has no place in time and is not sent; those and what could not be read
    are warned about (logger ``canest.replay``)."""
    reader = open_log(log_path, log_format, log_channel)
    try:
        timed = (msg for msg in reader if math.isfinite(msg.timestamp))
        sent = play_messages(timed, bus, speed, progress and sys.stderr.isatty(), desc=f"play {reader.path.name}")
    finally:
        reader.stop()
    for warning in reader.warnings():
        LOG.warning(warning)
    if reader.frames > sent:
        LOG.warning(f"{log_path}: {reader.frames - sent} frame(s) without a finite timestamp were not sent")
    return sent


def play_messages(messages, bus: can.BusABC, speed: float = 1.0, progress: bool = False, desc: str = "play",
                  stop=None) -> int:
    """Send messages at the spacing of their timestamps divided by ``speed``; ``stop`` (an Event) ends early."""
    sent = 0
    start_wall = start_log = None
    with tqdm(desc=desc, unit=" frames", disable=not progress, leave=True) as bar:
        for msg in messages:
            if stop is not None and stop.is_set():
                break
            if start_wall is None:
                start_wall, start_log = time.perf_counter(), msg.timestamp
            delay = (msg.timestamp - start_log) / speed - (time.perf_counter() - start_wall)
            if delay > 0:
                time.sleep(delay)
            bus.send(can.Message(timestamp=time.time(), arbitration_id=msg.arbitration_id,
                                 is_extended_id=msg.is_extended_id, is_remote_frame=msg.is_remote_frame,
                                 is_fd=msg.is_fd, bitrate_switch=msg.bitrate_switch, dlc=msg.dlc, data=msg.data))
            sent += 1
            bar.update()
    return sent
