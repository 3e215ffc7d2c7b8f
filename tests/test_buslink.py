"""Output that cannot keep up: frames dropped and counted, the loop never blocks."""
import threading
import time

import can

from canest.settings import BusConfig
from canest.apps.service import Service
from canest.io.sinks import CallbackSink, Sink

STOP_TIMEOUT = 60.0  # s for the loop to notice stop(): only a loop stuck in a send never does


class NewestOfEachPass(Sink):
    """What the service hands its output bus: the newest estimate of each loop pass."""

    def __init__(self):
        self.newest = []

    def publish(self, estimates: list) -> None:
        self.newest.append(estimates[-1])


def test_a_full_output_queue_drops_frames_without_blocking(config, dlc_run):
    """A receiver on the output bus that never reads fills its 5-frame queue: python-can's virtual
    bus then refuses every send, as SocketCAN does with ENOBUFS. Every frame the loop meant to send
    is either sent or counted dropped, and the loop still stops when asked: it never waited on the
    output. (How evenly it ticks meanwhile is the machine's; ``tools/bench/live.py`` measures latency.)"""
    _, _, sim = dlc_run
    live_config = config.with_buses(BusConfig("virtual", "full-in"), BusConfig("virtual", "full-out"))
    stuck = can.Bus(interface="virtual", channel="full-out", rx_queue_size=5)
    ticks = []
    passes = NewestOfEachPass()
    service = Service(live_config, sinks=[CallbackSink(ticks.append), passes])
    result = {}
    loop = threading.Thread(target=lambda: result.update(service.run()), daemon=True)
    loop.start()
    player = can.Bus(interface="virtual", channel="full-in")
    time.sleep(0.2)
    start = time.perf_counter()
    for frame in sim.frames[:1500]:
        delay = frame.timestamp - sim.frames[0].timestamp - (time.perf_counter() - start)
        if delay > 0:
            time.sleep(delay)
        player.send(frame)
    service.stop()
    loop.join(timeout=STOP_TIMEOUT)
    player.shutdown()
    stuck.shutdown()
    assert not loop.is_alive(), "the loop blocked on the full output"
    summary = result
    assert summary["sent"] == 5 and summary["send_dropped"] > 500  # the 5 that fit the queue, then drops
    assert "output_bus_lost" not in summary, "a full queue is not a lost bus"
    intended = sum(len(service.pipeline.encoder.encode(estimate)) for estimate in passes.newest)
    assert summary["sent"] + summary["send_dropped"] == intended, "every output frame is sent or counted dropped"
    assert len(passes.newest) == summary["ticks"] - summary["superseded"] and summary["ticks"] == len(ticks)
    assert summary["ticks"] > 250
