"""Offline replay of a log through the pipeline, and real-time playback onto a bus.

Readers and writers are python-can's, chosen by file suffix (.log candump,
.asc, .blf, .trc, .csv, ...), so any log python-can reads can be replayed.
"""
from __future__ import annotations

import os
import time
from contextlib import ExitStack
from pathlib import Path

import can
from tqdm import tqdm

from canest.io.logfiles import byte_position, frames, open_log
from canest.io.sinks import CallbackSink, CsvSink, LogSink
from canest.pipeline import Pipeline
from canest.settings import Config

PROGRESS_EVERY = 2000  # frames between progress-bar updates


def replay(config: Config, log_path, out_log=None, out_csv=None, progress: bool = True, on_estimate=None,
           step_times=None) -> dict:
    """Run a log through the pipeline as fast as possible; return the frame summary.

    ``step_times``, a list, receives the seconds of every filter predict + update.
    """
    pipeline = Pipeline(config, output_channel=config.output_bus.channel)
    pipeline.estimator.step_times = step_times
    reader = open_log(log_path)
    with ExitStack() as stack:
        sinks = [stack.enter_context(sink) for sink in (
            CsvSink(out_csv) if out_csv else None,
            LogSink(out_log, pipeline.encoder) if out_log else None,
            CallbackSink(on_estimate) if on_estimate else None) if sink is not None]
        bar = stack.enter_context(tqdm(total=os.path.getsize(log_path), unit="B", unit_scale=True,
                                       desc=f"replay {Path(log_path).name}", disable=None if progress else True, leave=False))
        position = byte_position(reader)
        for count, msg in enumerate(frames(reader, log_path), 1):
            estimates = pipeline.feed(msg)
            if estimates:
                for sink in sinks:
                    sink.publish(estimates)
            if position is not None and count % PROGRESS_EVERY == 0:
                bar.update(position() - bar.n)
        reader.stop()
    return pipeline.summary()


def play(log_path, bus: can.BusABC, speed: float = 1.0, progress: bool = True) -> int:
    """Send a log's frames onto ``bus`` at their recorded timing (like canplayer); return frames sent."""
    reader = open_log(log_path)
    try:
        return play_messages(reader, bus, speed, progress, desc=f"play {Path(log_path).name}")
    finally:
        reader.stop()


def play_messages(messages, bus: can.BusABC, speed: float = 1.0, progress: bool = False, desc: str = "play",
                  stop=None) -> int:
    """Send messages at the spacing of their timestamps divided by ``speed``; ``stop`` (an Event) ends early."""
    sent = 0
    start_wall = start_log = None
    with tqdm(desc=desc, unit=" frames", disable=None if progress else True, leave=False) as bar:
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
