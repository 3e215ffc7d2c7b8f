#!/usr/bin/env python3
"""Live load: nominal traffic, then 2x, 4x and 8x, into a running estimation service.

    python tools/bench/live.py --bus virtual               # in-process, python-can virtual buses
    tools/vcan-guest -- python tools/bench/live.py --bus vcan   # canest run on real vcan0 -> vcan1

Traffic is a simulated slalom with every input message at its DBC cycle time,
played ``--seconds`` long at each multiple of the nominal rate. Reported per
rate: frames sent and received (drops), the latency from a tick's time (every
frame it used is stamped at or before it) to its estimate frames being sent
(p50, p99, max), the CPU share of the estimating process, and its resident
memory. On vcan the service is the ``canest run`` daemon and the figures come
from its own status line (SIGUSR1) and /proc; the UML guest's system calls are
much slower than a native kernel's, hence the virtual-bus figures as well.
"""
import argparse
import os
import signal
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.settings import BusConfig  # noqa: E402
from canest.apps.replay import play_messages  # noqa: E402
from canest.apps.service import Service  # noqa: E402
from canest.sim.simulate import simulate  # noqa: E402

HEADER = f"{'rate':>5} {'sent':>7} {'received':>9} {'dropped':>8} {'p50 ms':>7} {'p99 ms':>7} {'max ms':>7} " \
         f"{'CPU':>6} {'RSS MB':>7}"


def row(multiplier, sent, received, latency_ms, cpu, rss_mb):
    """One line of the table; ``latency_ms`` is (p50, p99, max)."""
    p50, p99, peak = latency_ms
    return (f"{multiplier:>4g}x {sent:>7} {received:>9} {sent - received:>8} {p50:>7.2f} {p99:>7.2f} {peak:>7.2f} "
            f"{cpu:>6.0%} {rss_mb:>7.1f}")


def percentiles(samples_ms):
    return tuple(np.percentile(samples_ms, q) for q in (50, 99, 100)) if len(samples_ms) else (np.nan,) * 3


def rss_mb(pid="self"):
    with open(f"/proc/{pid}/status") as handle:
        return next(int(line.split()[1]) for line in handle if line.startswith("VmRSS:")) / 1024


def cpu_seconds(pid):
    with open(f"/proc/{pid}/stat") as handle:
        fields = handle.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def virtual(config, frames, multipliers):
    config = config.with_buses(BusConfig("virtual", "bench-in"), BusConfig("virtual", "bench-out"))
    service = Service(config)
    thread = threading.Thread(target=service.run)
    thread.start()
    player = can.Bus(interface="virtual", channel="bench-in")
    if not service.wait_until_listening(30.0):
        raise SystemExit("the service did not open its buses")
    print("virtual bus, in process (CPU: the whole process, player included)\n" + HEADER)
    for multiplier in multipliers:
        before = service.summary().get("frames", 0)
        service.latency.clear()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        sent = play_messages(frames, player, speed=multiplier)
        time.sleep(0.3)
        cpu = (time.process_time() - cpu0) / (time.perf_counter() - wall0)
        received = service.summary().get("frames", 0) - before
        print(row(multiplier, sent, received, percentiles(np.array(service.latency) * 1e3), cpu, rss_mb()),
              flush=True)
    service.stop()
    thread.join()
    player.shutdown()


def vcan(frames, multipliers):
    from tests.live import Daemon

    daemon = Daemon()
    pid = daemon.process.pid
    player = can.Bus(interface="socketcan", channel="vcan0")
    time.sleep(0.5)
    print("vcan0 -> canest run -> vcan1, UML guest (CPU: the daemon)\n" + HEADER)
    for multiplier in multipliers:
        before = _frames(_status(daemon))
        cpu0, wall0 = cpu_seconds(pid), time.perf_counter()
        sent = play_messages(frames, player, speed=multiplier)
        time.sleep(0.5)
        cpu = (cpu_seconds(pid) - cpu0) / (time.perf_counter() - wall0)
        line = _status(daemon)
        latency = line.split("latency ")[1]  # "p50 1.23 ms, p99 4.56 ms, max 7.89 ms" since the previous line
        numbers = tuple(float(part.split()[1]) for part in latency.split(", ")) if "p50" in latency else (np.nan,) * 3
        print(row(multiplier, sent, _frames(line) - before, numbers, cpu, rss_mb(pid)), flush=True)
    player.shutdown()
    daemon.terminate()


def _status(daemon):
    count = daemon.stderr.count("latency ")
    daemon.signal(signal.SIGUSR1)
    daemon.wait_for("latency ", count=count + 1)
    return [line for line in daemon.stderr.splitlines() if "latency " in line][-1]


def _frames(status_line):
    return int(status_line.split("frames=")[1].split()[0])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bus", choices=("virtual", "vcan"), default="virtual")
    parser.add_argument("--seconds", type=float, default=10.0, help="traffic per rate")
    parser.add_argument("--multipliers", default="1,2,4,8")
    args = parser.parse_args()
    config = load_config(DEFAULT_CONFIG)
    frames = simulate(config, "slalom", 80.0, 0.85, seed=2, duration=args.seconds).frames
    multipliers = [float(m) for m in args.multipliers.split(",")]
    if args.bus == "virtual":
        virtual(config, frames, multipliers)
    else:
        vcan(frames, multipliers)


if __name__ == "__main__":
    main()
