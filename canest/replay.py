"""Offline replay of a log through the pipeline, and real-time playback onto a bus.

Readers and writers are python-can's, chosen by file suffix (.log candump,
.asc, .blf, .trc, .csv, ...), so any log python-can reads can be replayed.
"""
from __future__ import annotations

import os
import struct
import time
from contextlib import ExitStack
from pathlib import Path

import can
from tqdm import tqdm

from canest.config import Config
from canest.outputs import EstimateCsvWriter
from canest.pipeline import Pipeline

PROGRESS_EVERY = 2000  # frames between progress-bar updates


def open_log(path) -> can.LogReader:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: log file not found")
    try:
        return can.LogReader(str(path))
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def _byte_position(reader):
    """A callable giving how far into its file ``reader`` is, or None if it cannot tell."""
    handle = getattr(reader, "file", None)
    handle = getattr(handle, "buffer", handle)  # text readers: the binary buffer can still tell
    if handle is None or not hasattr(handle, "tell"):
        return None
    try:
        handle.tell()
    except OSError:
        return None
    return handle.tell


def _frames(reader, log_path):
    """The reader's frames; a frame it cannot parse ends the replay with the file and frame number."""
    count = 0
    iterator = iter(reader)
    while True:
        try:
            msg = next(iterator)
        except StopIteration:
            return
        except (ValueError, IndexError, KeyError, struct.error) as exc:
            raise ValueError(f"{log_path}: frame {count + 1} is unreadable ({type(exc).__name__}: {exc})") from None
        count += 1
        yield msg


def replay(config: Config, log_path, out_log=None, out_csv=None, progress: bool = True, on_estimate=None,
           step_times=None) -> dict:
    """Run a log through the pipeline as fast as possible; return the frame summary.

    ``step_times``, a list, receives the seconds of every filter predict + update.
    """
    pipeline = Pipeline(config, output_channel=config.output_bus.channel)
    pipeline.estimator.step_times = step_times
    reader = open_log(log_path)
    with ExitStack() as stack:
        writer = stack.enter_context(can.Logger(str(out_log))) if out_log else None
        csv_writer = stack.enter_context(EstimateCsvWriter(out_csv)) if out_csv else None
        bar = stack.enter_context(tqdm(total=os.path.getsize(log_path), unit="B", unit_scale=True,
                                       desc=f"replay {Path(log_path).name}", disable=None if progress else True, leave=False))
        position = _byte_position(reader)
        for count, msg in enumerate(_frames(reader, log_path), 1):
            for estimate in pipeline.feed(msg):
                if csv_writer:
                    csv_writer.write(estimate)
                if writer:
                    for frame in pipeline.encoder.encode(estimate):
                        writer.on_message_received(frame)
                if on_estimate:
                    on_estimate(estimate)
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
