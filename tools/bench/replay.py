#!/usr/bin/env python3
"""Replay throughput with a stage profile, and resident memory over a long replay.

    python tools/bench/replay.py                          # 10-minute drive, default and heaviest filter
    python tools/bench/replay.py --minutes 1 --hours 0    # smoke run

Simulates a drive with the full input DBC traffic (every message at its cycle
time), writes it as a candump log, and replays it offline exactly as
``canest replay --out est.log --csv est.csv`` does, timing each stage by
wrapping the pipeline's own objects: read (python-can's log reader), decode
(DBC, signal map, integrity, plausibility), estimate (resample and filter
step), encode (output DBC, counter, CRC) and write (estimate log and CSV).
Then, for ``--hours``, it streams the same log again and again with shifted
timestamps through one pipeline and samples the resident memory (of the
whole benchmark process, interpreter and libraries included).
"""
import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import can

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from canest.apps.compare import with_filter  # noqa: E402
from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.io.sinks import CsvSink  # noqa: E402
from canest.pipeline import Pipeline  # noqa: E402
from canest.io.logfiles import open_log  # noqa: E402
from canest.sim.simulate import simulate  # noqa: E402

STAGES = ("read", "decode", "estimate", "encode", "write")


class Stopwatch:
    def __init__(self):
        self.seconds = defaultdict(float)

    def wrap(self, stage, function):
        def timed(*args, **kwargs):
            started = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                self.seconds[stage] += time.perf_counter() - started
        return timed

    def iterate(self, stage, iterable):
        iterator = iter(iterable)
        while True:
            started = time.perf_counter()
            try:
                item = next(iterator)
            except StopIteration:
                return
            finally:
                self.seconds[stage] += time.perf_counter() - started
            yield item


def timed_replay(config, log_path, folder):
    """The replay loop of canest.apps.replay with every stage timed; returns (seconds, frames, ticks, stages)."""
    watch = Stopwatch()
    pipeline = Pipeline(config, output_channel="vcan1")
    pipeline.decoder.decode = watch.wrap("decode", pipeline.decoder.decode)
    pipeline.estimator.step = watch.wrap("estimate", pipeline.estimator.step)
    encode = watch.wrap("encode", pipeline.encoder.encode)
    frames = ticks = 0
    started = time.perf_counter()
    with can.Logger(str(folder / "est.log")) as log_writer, CsvSink(folder / "est.csv") as csv_writer:
        write_frame = watch.wrap("write", log_writer.on_message_received)
        write_row = watch.wrap("write", csv_writer.write)
        reader = open_log(log_path)
        for msg in watch.iterate("read", reader):
            frames += 1
            for estimate in pipeline.feed(msg):
                ticks += 1
                write_row(estimate)
                for frame in encode(estimate):
                    write_frame(frame)
    return time.perf_counter() - started, frames, ticks, dict(watch.seconds)


def rss_mb():
    with open("/proc/self/status") as handle:
        return next(int(line.split()[1]) for line in handle if line.startswith("VmRSS:")) / 1024


def memory_run(config, log_path, span, hours):
    """Stream the drive's log repeatedly (timestamps shifted) through one pipeline for ``hours``; RSS samples."""
    pipeline = Pipeline(config)
    repeats = max(1, round(hours * 3600 / span))
    samples = [rss_mb()]
    for k in range(repeats):
        for frame in open_log(log_path):
            shifted = can.Message(timestamp=frame.timestamp + k * span, arbitration_id=frame.arbitration_id,
                                  data=frame.data, is_extended_id=frame.is_extended_id)
            for estimate in pipeline.feed(shifted):
                pipeline.encoder.encode(estimate)
        samples.append(rss_mb())
    return samples, repeats * span


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--filters", default="ckf,dici-gfckf", help="default filter first, then the heaviest")
    parser.add_argument("--hours", type=float, default=1.0, help="length of the memory run (0: skip)")
    args = parser.parse_args()
    config = load_config(DEFAULT_CONFIG)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        started = time.perf_counter()
        sim = simulate(config, "slalom", 80.0, 0.85, seed=1, duration=args.minutes * 60)
        log_path = folder / "drive.log"
        sim.write_log(log_path)
        drive = sim.frames[-1].timestamp - sim.frames[0].timestamp
        print(f"drive {drive / 60:.1f} min, {len(sim.frames)} frames ({len(sim.frames) / drive:.0f}/s), "
              f"{os.path.getsize(log_path) / 1e6:.1f} MB candump (simulated in {time.perf_counter() - started:.0f} s)")
        del sim  # the memory figures below are the pipeline's, not the simulation's
        print(f"{'filter':<8} {'seconds':>8} {'frames/s':>9} {'ticks/s':>8} {'x real time':>11} | "
              + " ".join(f"{s:>8}" for s in (*STAGES, "other")))
        for name in args.filters.split(","):
            seconds, frames, ticks, stages = timed_replay(with_filter(config, name), log_path, folder)
            other = seconds - sum(stages.values())
            shares = " ".join(f"{100 * stages.get(s, 0.0) / seconds:>7.1f}%" for s in STAGES)
            print(f"{name:<8} {seconds:>8.2f} {frames / seconds:>9.0f} {ticks / seconds:>8.0f} "
                  f"{drive / seconds:>11.1f} | {shares} {100 * other / seconds:>7.1f}%")
        if args.hours > 0:
            samples, covered = memory_run(config, log_path, drive + 0.01, args.hours)
            print(f"memory over {covered / 3600:.2f} h of traffic in one pipeline: start {samples[0]:.1f} MB, "
                  f"peak {max(samples):.1f} MB, end {samples[-1]:.1f} MB")


if __name__ == "__main__":
    main()
