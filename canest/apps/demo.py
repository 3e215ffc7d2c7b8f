"""The built-in demonstration: simulator -> virtual CAN -> live service -> virtual CAN -> display.

Three parties share two python-can virtual buses, exactly as on a vehicle:
a player sends the simulated vehicle's frames onto the input bus in real
time; the estimation service (the same :class:`~canest.apps.service.Service` the
daemon runs) estimates and sends its frames onto the output bus; a monitor
decodes those frames with the output DBC and prints them next to the truth.
At the end the estimates are scored against the truth.
"""
from __future__ import annotations

import math
import threading
import time

import can
import numpy as np

from canest.settings import BusConfig, Config
from canest.apps.evaluate import format_table, score, table_of
from canest.pipeline import format_summary
from canest.apps.replay import play_messages
from canest.apps.service import Service
from canest.io.sinks import CallbackSink
from canest.sim.simulate import simulate

INPUT_CHANNEL = "canest-demo-in"
OUTPUT_CHANNEL = "canest-demo-out"
DISPLAY_EVERY = 0.5  # s of drive time between display lines


class _Monitor(threading.Thread):
    """Decode estimate frames from the output bus and print them beside the truth."""

    def __init__(self, config: Config, truth: dict, clock: dict, speed: float, out):
        super().__init__(daemon=True)
        from canest.codec.dbc import load_database

        self.db = load_database(config.output_dbc, "demo")
        self.truth, self.clock, self.speed, self.out = truth, clock, speed, out
        self.bus = can.Bus(interface="virtual", channel=OUTPUT_CHANNEL)
        self.done = threading.Event()
        self.latest = {}

    def _truth(self, name, t):
        return float(np.interp(t, self.truth["t"], self.truth[name]))

    def _shown(self, name, valid, factor, width) -> str:
        """The latest decoded value, or dashes while its validity bit is clear."""
        if not self.latest.get(valid, 0):
            return "--".rjust(width)
        return f"{self.latest[name] * factor:{width}.2f}"

    def run(self) -> None:
        next_line = 0.0
        print(f"{'t [s]':>6} | {'vx [m/s] est (true)':>20} | {'yaw rate [deg/s]':>18} | {'sideslip [deg]':>16} | mode",
              file=self.out)
        while not self.done.is_set():
            msg = self.bus.recv(timeout=0.1)
            if msg is None or "wall0" not in self.clock:
                continue
            try:
                self.latest.update(self.db.decode_message(msg.arbitration_id, msg.data, decode_choices=True))
            except KeyError:
                continue
            t = (msg.timestamp - self.clock["wall0"]) * self.speed + self.truth["t"][0]
            if t >= next_line and {"Vx", "Sideslip", "Mode"} <= set(self.latest):
                next_line = t + DISPLAY_EVERY
                vx = self._shown("Vx", "VxValid", 1.0, 8)
                yaw = self._shown("YawRate", "YawRateValid", 180 / math.pi, 7)
                beta = self._shown("Sideslip", "SideslipValid", 180 / math.pi, 6)
                print(f"{t:6.2f} | {vx} ({self._truth('vx', t):8.2f})  | "
                      f"{yaw} ({math.degrees(self._truth('yaw_rate', t)):7.2f}) | "
                      f"{beta} ({math.degrees(self._truth('beta', t)):6.2f}) | {self.latest['Mode']}",
                      file=self.out, flush=True)
        self.bus.shutdown()


def run_demo(config: Config, maneuver="dlc", speed_kmh=80.0, mu=0.85, seed=0, playback_speed=1.0, out=None,
             sinks=()) -> list:
    """Run the demonstration; return the accuracy scores (``canest.apps.evaluate.Score``).

    ``sinks`` (:mod:`canest.io.sinks`) also receive every estimate."""
    config = config.with_buses(BusConfig("virtual", INPUT_CHANNEL), BusConfig("virtual", OUTPUT_CHANNEL))
    print(f"simulating {maneuver} at {speed_kmh:g} km/h, mu {mu} ({config.vehicle.name}) ...", file=out, flush=True)
    sim = simulate(config, maneuver, speed_kmh, mu, seed=seed, channel=INPUT_CHANNEL)
    estimates = []
    service = Service(config, sinks=[CallbackSink(estimates.append), *sinks])
    clock = {}
    monitor = _Monitor(config, sim.truth, clock, playback_speed, out)
    player_bus = can.Bus(interface="virtual", channel=INPUT_CHANNEL)

    def player():
        if not service.wait_until_listening(30.0):  # a virtual bus gives a frame only to the buses open then
            return service.stop()
        clock["wall0"] = time.time()
        try:
            play_messages(sim.frames, player_bus, speed=playback_speed, stop=service.stopping)
        finally:
            time.sleep(0.2)
            service.stop()

    pace = "in real time" if playback_speed == 1 else f"at {playback_speed:g}x real time"
    print(f"playing {len(sim.frames)} frames {pace} on virtual bus '{INPUT_CHANNEL}'; "
          f"estimates on '{OUTPUT_CHANNEL}'", file=out, flush=True)
    monitor.start()
    thread = threading.Thread(target=player, daemon=True)
    thread.start()
    summary = service.run()
    thread.join()
    monitor.done.set()
    monitor.join()
    player_bus.shutdown()
    # Ticks are anchored at the first frame: map them onto the simulation clock.
    t0_wall, t0_log = service.pipeline.clock.t0, sim.frames[0].timestamp
    table = table_of(estimates)
    table["t"] = (table["t"] - t0_wall) * playback_speed + t0_log
    scores = score(table, sim.truth, ("vx", "vy", "beta", "yaw_rate"), skip=0.5)
    print(f"\n{format_summary(summary)}", file=out)
    print(format_table(scores, f"\naccuracy of {config.estimator.filter} against the simulator's truth"), file=out)
    return scores
