"""Output that cannot keep up: frames dropped and counted, the loop never blocks."""
import time

import can

from canest.settings import BusConfig
from canest.apps.replay import paced
from canest.apps.service import Service
from canest.io.sinks import CallbackSink
from tests.conftest import run_service_playing


def test_a_full_output_queue_drops_frames_without_blocking(config, dlc_run):
    """A receiver on the output bus that never reads fills its 5-frame queue: python-can's virtual
    bus then refuses every send, as SocketCAN does with ENOBUFS."""
    _, _, sim = dlc_run
    live_config = config.with_buses(BusConfig("virtual", "full-in"), BusConfig("virtual", "full-out"))
    stuck = can.Bus(interface="virtual", channel="full-out", rx_queue_size=5)
    ticks = []
    service = Service(live_config, sinks=[CallbackSink(lambda e: ticks.append(time.monotonic()))])
    player = can.Bus(interface="virtual", channel="full-in")

    def play():
        for frame in paced(sim.frames[:1500]):
            player.send(frame)

    summary = run_service_playing(service, play)
    player.shutdown()
    stuck.shutdown()
    assert summary["sent"] == 5 and summary["send_dropped"] > 500  # the 5 that fit the queue, then drops
    assert "output_bus_lost" not in summary, "a full queue is not a lost bus"
    # A send that waited for room (python-can's default) would hold the loop on every tick, for good without a
    # timeout; a busy machine's scheduler pauses it far less than a second.
    assert max(b - a for a, b in zip(ticks, ticks[1:])) < 1.0, "the loop blocked on the full output"
    assert summary["ticks"] > 250
