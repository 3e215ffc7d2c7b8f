"""The live service in-process on python-can's virtual bus: same estimates as offline replay."""
import dataclasses
import io
import threading
import subprocess
import sys
import time

import can
import numpy as np
import pytest

from canest.settings import BusConfig
from canest.apps.demo import run_demo
from canest.apps.replay import paced, play_messages, replay
from canest.apps import service as service_module
from canest.apps.service import Service
from canest.errors import BusOpenError
from canest.io.sinks import CallbackSink
from tests.conftest import run_service_playing


def test_live_service_matches_offline_replay(config, dlc_run):
    """Frames played onto a bus in real time give the estimates replay gives, tick for tick.

    The player shares this process and a busy machine delays it; what canest guarantees (a tick uses every frame
    stamped before it) is tested apart from that: the frames keep their log timestamps and the service's idle
    clock is the log time the player has reached, so the loop never runs a tick ahead of frames the player has
    not sent yet. How live ticking copes with a late bus (``late_frames``) is tested in the SocketCAN lane."""
    log, _, _ = dlc_run
    offline = []
    replay(config, log, progress=False, on_estimate=offline.append)
    frames = list(can.LogReader(log))  # the replayed frames, with the same timestamps
    reached = [frames[0].timestamp]  # log time of the newest frame sent (set before sending it: never ahead)
    live_config = config.with_buses(BusConfig("virtual", "svc-in"), BusConfig("virtual", "svc-out"))
    live = []
    service = Service(live_config, sinks=[CallbackSink(live.append)], clock=lambda: reached[0])
    listener = can.Bus(interface="virtual", channel="svc-out")
    player_bus = can.Bus(interface="virtual", channel="svc-in", preserve_timestamps=True)

    def play():
        for frame in paced(frames):
            reached[0] = frame.timestamp
            player_bus.send(frame)
        time.sleep(0.2)

    summary = run_service_playing(service, play)
    received = []
    while (msg := listener.recv(timeout=0)) is not None:
        received.append(msg)
    listener.shutdown()
    player_bus.shutdown()
    assert summary["decoded"] == len(frames)
    assert summary["send_dropped"] == 0 and "late_frames" not in summary
    # Replay ticks up to its last frame; live runs the idle ticks before it too: one more at most.
    assert len(offline) - 1 <= len(live) <= len(offline)
    n = len(live)
    assert [e.t for e in live] == [e.t for e in offline[:n]]
    for state in ("yaw_rate", "beta", "vx", "yaw_rate_std"):
        np.testing.assert_array_equal([e.values[state] for e in live], [e.values[state] for e in offline[:n]])
    assert [e.valid_flags for e in live] == [e.valid_flags for e in offline[:n]]
    # One frame set per loop pass: ticks completed together send only the newest.
    assert sum(1 for m in received if m.arbitration_id == 0x501) == len(live) - summary["superseded"]
    assert summary["superseded"] < 0.05 * len(live)


def test_a_stop_still_estimates_the_frames_the_bus_delivered(config, dlc_run, monkeypatch):
    """Stopped the moment the last of 8 s of frames is sent (far faster than real time, so most are still queued),
    the service decodes every one and runs the ticks replay runs. A frame of an ID the config does not map sits
    half way: the virtual bus's software filter drops it, and a drain that stopped at the first empty read stopped
    there (2235 of 4470 decoded). Frames the bus goes on delivering after the stop are not read (a live bus never
    falls silent: the stop would wait out DRAIN_SECONDS, raised here so a busy machine cannot end the drain)."""
    log, _, _ = dlc_run
    offline = []
    replay(config, log, progress=False, on_estimate=offline.append)
    frames = list(can.LogReader(log))
    reached = [frames[0].timestamp]
    half = len(frames) // 2
    monkeypatch.setattr(service_module, "DRAIN_SECONDS", 60.0)  # a busy machine's drain is not what is tested
    unmapped = can.Message(arbitration_id=0x7AB, data=bytes(8), is_extended_id=False,
                           timestamp=frames[half].timestamp)
    live = []
    service = Service(config.with_buses(BusConfig("virtual", "drain-in"), BusConfig("virtual", "drain-out")),
                      sinks=[CallbackSink(live.append)], clock=lambda: reached[0])
    player_bus = can.Bus(interface="virtual", channel="drain-in", preserve_timestamps=True)

    def play():
        for frame in frames[:half] + [unmapped] + frames[half:]:
            reached[0] = frame.timestamp
            player_bus.send(frame)
        service.stop()
        for frame in frames[:300]:  # after the stop
            player_bus.send(can.Message(arbitration_id=frame.arbitration_id, data=frame.data,
                                        timestamp=frame.timestamp + 100.0, is_extended_id=frame.is_extended_id))

    summary = run_service_playing(service, play)
    player_bus.shutdown()
    # the loop may take one more frame before it sees the stop, if it had caught up with the player
    assert len(frames) <= summary["decoded"] <= len(frames) + 1
    assert summary["after_stop"] == 1  # the first frame after the stop, read and counted, ends the drain
    assert len(offline) - 1 <= len(live) <= len(offline)
    assert [e.t for e in live] == [e.t for e in offline[:len(live)]]
    np.testing.assert_array_equal([e.values["beta"] for e in live], [e.values["beta"] for e in offline[:len(live)]])


def test_demo_runs_and_reports_accuracy(config):
    scores = {s.state: s for s in run_demo(config, playback_speed=4.0, out=open("/dev/null", "w"))}
    assert scores["vx"].rmse < 0.2
    assert scores["beta"].rmse < 1.0
    assert scores["yaw_rate"].samples > 100
    # the published std reaches the table: its coverage and NEES are the filter's, not an empty column's
    assert all(scores[state].cov3 > 0.5 and np.isfinite(scores[state].nees) for state in ("vx", "yaw_rate"))


def test_idle_bus_keeps_ticking_and_reports_missing_inputs(config, dlc_run):
    _, _, sim = dlc_run
    live_config = config.with_buses(BusConfig("virtual", "idle-in"), BusConfig("virtual", "idle-out"))
    live = []
    service = Service(live_config, sinks=[CallbackSink(live.append)])
    player_bus = can.Bus(interface="virtual", channel="idle-in")
    first_second = [f for f in sim.frames if f.timestamp < sim.frames[0].timestamp + 1.0]

    def play():
        play_messages(first_second, player_bus)
        time.sleep(1.0)  # the bus goes quiet

    run_service_playing(service, play)
    player_bus.shutdown()
    assert len(live) > 170  # ~1 s of traffic plus ~0.9 s of idle ticks at 100 Hz
    assert live[-1].mode == "no_input"
    assert set(live[-1].missing) == {"steering", "wheel_speeds", "motor_torques", "imu", "imu_2"}
    assert not any(live[-1].valid.values())


class RecordingNotifier:
    """The sd_notify messages a service sends, kept in order (no systemd socket needed)."""

    watchdog_interval = None

    def __init__(self):
        self.sent = []

    def notify(self, **fields) -> None:
        self.sent.append(fields)


def test_a_silent_input_bus_says_no_input_from_the_start_then_ticks_on_the_frames_grid(config, dlc_run, monkeypatch):
    """Vehicle off, cable not yet connected: the daemon published nothing before the first input frame (its ticks
    were anchored there), so ``canest monitor --once`` said it was not running, and a consumer could not tell a dead
    daemon from a parked car. From the start it ticks on its clock at the estimator's rate, every tick ``no_input``,
    and says so on the output bus and in systemd's STATUS. Then frames come on another time base than that clock
    (the log's, as an adapter's own clock would be): the frames' grid is anchored on the first of them as replay's
    is, with no time jump, step back, late frame or reset, and every tick from there is replay's."""
    from canest.apps.monitor import run_monitor
    from canest.codec.dbc import load_database

    monkeypatch.setattr(service_module, "NOTIFY_STATUS_EVERY", 0.1)
    log, _, _ = dlc_run
    offline = []
    replay(config, log, progress=False, on_estimate=offline.append)
    frames = list(can.LogReader(log))
    frames = [f for f in frames if f.timestamp < frames[0].timestamp + 2.0]
    reached = [None]  # the log time of the newest frame sent, once the player starts; the wall clock before
    live_config = config.with_buses(BusConfig("virtual", "silent-in"), BusConfig("virtual", "silent-out"))
    live, notifier = [], RecordingNotifier()
    service = Service(live_config, sinks=[CallbackSink(live.append)], notifier=notifier,
                      clock=lambda: time.time() if reached[0] is None else reached[0])
    watcher = can.Bus(interface="virtual", channel="silent-out")
    player_bus = can.Bus(interface="virtual", channel="silent-in", preserve_timestamps=True)
    view, silent = io.StringIO(), {}

    def play():
        started = time.monotonic()
        silent["monitor"] = run_monitor(watcher, load_database(config.output_dbc, "test"), "virtual:silent-out",
                                        view, once=True, duration=3.0)
        time.sleep(max(0.0, 1.0 - (time.monotonic() - started)))
        silent["seconds"], silent["ticks"] = time.monotonic() - started, list(live)
        silent["notified"] = list(notifier.sent)
        for frame in paced(frames):
            reached[0] = frame.timestamp
            player_bus.send(frame)
        time.sleep(0.2)

    summary = run_service_playing(service, play)
    watcher.shutdown()
    player_bus.shutdown()
    assert silent["monitor"].complete(), "no estimate frames on a silent input bus"
    assert " mode no_input " in view.getvalue()
    idle, dt = silent["ticks"], 1.0 / config.estimator.rate_hz
    assert len(idle) > 0.5 * silent["seconds"] / dt, f"{len(idle)} ticks in {silent['seconds']:.2f} s"
    assert np.allclose(np.diff([e.t for e in idle]), dt, rtol=0, atol=1e-6), "one tick per period"
    assert {e.mode for e in idle} == {"no_input"} and not any(e.valid_flags for e in idle)
    assert all(set(e.causes.values()) == {"no_input"} and np.isnan(e.values["vx"]) for e in idle)
    status = [fields["STATUS"] for fields in silent["notified"] if "STATUS" in fields][-1]
    assert status.startswith("mode no_input, input 0 frames/s, ") and float(status.split()[-2]) > 0.5 / dt
    assert not any("READY" in fields for fields in silent["notified"]), "ready only once an estimate is valid"
    assert summary["decoded"] == len(frames) and summary["resets"] == 0
    assert not {"time_jumps", "time_backwards", "late_frames"} & set(summary), summary
    first = next(i for i, e in enumerate(live) if e.t == offline[0].t)
    assert {e.mode for e in live[:first]} == {"no_input"}
    real = live[first:]
    assert len(real) >= 2.0 / dt - 2
    assert [e.t for e in real] == [e.t for e in offline[:len(real)]]
    for state in ("yaw_rate", "beta", "vx", "vx_std"):
        np.testing.assert_array_equal([e.values[state] for e in real], [e.values[state] for e in offline[:len(real)]])
    assert [e.valid_flags for e in real] == [e.valid_flags for e in offline[:len(real)]]
    assert sum("READY" in fields for fields in notifier.sent) == 1


def test_time_jump_and_backwards_timestamps_are_counted_not_stepped(config, dlc_run):
    from canest.pipeline import Pipeline

    _, _, sim = dlc_run
    pipeline = Pipeline(config)
    frames = sim.frames[:300]
    for frame in frames:
        pipeline.feed(frame)
    ticks_before = pipeline.clock.k
    late = [can.Message(timestamp=f.timestamp + 3600.0, arbitration_id=f.arbitration_id, data=f.data,
                        is_extended_id=False) for f in sim.frames[300:400]]
    estimates = [e for f in late for e in pipeline.feed(f)]
    assert pipeline.counts["time_jumps"] == 1
    assert len(estimates) < 30, "an hour's gap must not be stepped through tick by tick"
    old = can.Message(timestamp=frames[0].timestamp, arbitration_id=0x7FF, data=b"", is_extended_id=False)
    assert pipeline.feed(old) == []
    assert pipeline.counts["time_backwards"] == 1
    assert ticks_before > 0


def test_frame_read_after_its_tick_ran_on_an_idle_bus_is_counted_late(config, dlc_run):
    """A live source advances the ticks on an idle bus; a frame stamped before a tick that already ran is used
    in the next one and counted, so a difference from the offline replay is the machine's, and said."""
    from canest.pipeline import Pipeline

    _, _, sim = dlc_run
    offline = Pipeline(config)
    for frame in sim.frames:  # frames stamped on the tick grid itself (t0 + k dt, rounded apart) included
        offline.feed(frame)
    assert offline.counts["late_frames"] == 0
    frames = sim.frames[:400]
    live = Pipeline(config)
    for frame in frames[:300]:
        live.feed(frame)
    ran = live.advance(frames[310].timestamp)  # the socket held frames 300.. while the clock ran on
    assert ran
    last_tick = ran[-1].t
    for frame in frames[300:]:
        live.feed(frame)
    assert live.counts["late_frames"] == sum(f.timestamp <= last_tick for f in frames[300:]) > 0
    assert live.counts["time_backwards"] == 0


def test_monitor_shows_estimates_and_health_of_a_running_service(config, dlc_run):
    from canest.codec.dbc import load_database
    from canest.apps.monitor import run_monitor

    _, _, sim = dlc_run
    live_config = config.with_buses(BusConfig("virtual", "mon-in"), BusConfig("virtual", "mon-out"))
    service = Service(live_config)
    watcher = can.Bus(interface="virtual", channel="mon-out")
    player_bus = can.Bus(interface="virtual", channel="mon-in")
    out = io.StringIO()

    monitor = threading.Thread(target=lambda: run_monitor(watcher, load_database(config.output_dbc, "test"),
                                                          "virtual:mon-out", out, refresh=0.5, duration=3.5))
    monitor.start()
    run_service_playing(service, lambda: play_messages(sim.frames[:2500], player_bus))
    monitor.join()
    watcher.shutdown()
    player_bus.shutdown()
    last = out.getvalue().strip().split("\n\n")[-1]
    assert "filter ckf  mode normal  resets 0" in last
    assert "CRC errors 0  counter gaps 0" in last
    vx_line = next(line for line in last.splitlines() if line.startswith("vx "))
    assert 21.5 < float(vx_line.split()[1]) < 23.0 and vx_line.endswith("yes")


def test_a_player_waiting_for_the_buses_returns_when_they_cannot_open(config):
    """A thread that plays frames in waits until the service listens (a bus gives a frame only to the receivers
    open when it is sent); a service whose bus does not open tells it at once instead of leaving it waiting."""
    service = Service(config.with_buses(BusConfig("virtual", "wait-in"), BusConfig("no-such-interface", "x")))
    waited = []
    waiter = threading.Thread(target=lambda: waited.append(service.wait_until_listening(60.0)))
    waiter.start()
    started = time.monotonic()
    with pytest.raises(BusOpenError):
        service.run()
    waiter.join(10.0)
    assert waited == [False] and time.monotonic() - started < 10.0
    running = Service(config.with_buses(BusConfig("virtual", "wait-in"), BusConfig("virtual", "wait-out")))
    thread = threading.Thread(target=running.run)
    thread.start()
    assert running.wait_until_listening(10.0)
    running.stop()
    thread.join()


def reload_then_play(before, after, count: str, frames, input_channel: str, output_channel: str):
    """Run a service on config ``before``, ask it to reload ``after``, wait until ``count`` (``reloads`` or
    ``reload_failed``) is 1, play ``frames`` onto ``input_channel`` and wait until they are decoded; stop it.
    Returns the service, whether it still ran after the reload and the first frame it sent on
    ``output_channel`` (None if none)."""
    service = Service(before, reload_config=lambda: after)
    listener = can.Bus(interface="virtual", channel=output_channel)
    player_bus = can.Bus(interface="virtual", channel=input_channel)
    thread = threading.Thread(target=service.run)
    thread.start()
    def wait_for(done):
        deadline = time.monotonic() + 10
        while thread.is_alive() and not done() and time.monotonic() < deadline:
            time.sleep(0.02)

    try:
        assert service.wait_until_listening(10)
        service.reload_requested.set()
        wait_for(lambda: service.counts[count] > 0)
        play_messages(frames, player_bus)
        wait_for(lambda: service.summary().get("decoded", 0) >= len(frames))
        return service, thread.is_alive(), listener.recv(timeout=2.0)
    finally:
        service.stop()
        thread.join()
        listener.shutdown()
        player_bus.shutdown()


@pytest.mark.parametrize("one_handle", (False, True))
def test_a_reload_whose_buses_do_not_open_keeps_the_running_ones(config, dlc_run, monkeypatch, one_handle):
    """SIGHUP with a config naming a bus that does not open: the daemon logs it and runs on with its config and
    buses (it had closed them first, and the open's error ended the daemon). ``one_handle``: as on an adapter
    that takes one handle per channel, the running buses are closed first and opened again."""
    if one_handle:
        monkeypatch.setattr(service_module, "SHARED_CHANNEL_INTERFACES", ())
    _, _, sim = dlc_run
    live_config = config.with_buses(BusConfig("virtual", "reload-in"), BusConfig("virtual", "reload-out"))
    broken = live_config.with_buses(BusConfig("no-such-interface", "x"), BusConfig("virtual", "reload-out"))
    frames = sim.frames[:300]
    service, running, sent = reload_then_play(live_config, broken, "reload_failed", frames, "reload-in", "reload-out")
    assert running, "the reload ended the service"
    assert service.counts["reload_failed"] == 1 and service.config is live_config
    assert service.summary()["decoded"] == len(frames) and sent is not None


def test_a_reload_to_other_buses_moves_the_service_to_them(config, dlc_run):
    """One bus for both ways, reloaded to an input and an output bus: the frames on the new input are decoded,
    the estimates go out on the new output, and the old bus is closed."""
    _, _, sim = dlc_run
    shared = config.with_buses(BusConfig("virtual", "move-a"), BusConfig("virtual", "move-a"))
    moved = config.with_buses(BusConfig("virtual", "move-in"), BusConfig("virtual", "move-out"))
    service, running, sent = reload_then_play(shared, moved, "reloads", sim.frames[:300], "move-in", "move-out")
    assert running and service.config is moved and service.summary()["decoded"] == 300 and sent is not None
    assert "move-a" not in can.interfaces.virtual.channels


def test_a_reload_on_the_same_buses_receives_the_messages_the_new_config_maps(config, dlc_run):
    """A config that maps more messages, reloaded on the same buses: the input bus passes them (it kept the
    first config's filters: 36 of 400 frames decoded)."""
    _, _, sim = dlc_run
    full = config.with_buses(BusConfig("virtual", "remap-in"), BusConfig("virtual", "remap-out"))
    first = sorted({spec.message for spec in full.signals.values()})[:1]
    small = dataclasses.replace(full, signals={k: v for k, v in full.signals.items() if v.message in first},
                                messages={k: v for k, v in full.messages.items() if k in first})
    service, running, _ = reload_then_play(small, full, "reloads", sim.frames[:300], "remap-in", "remap-out")
    assert running and service.config is full and service.summary()["decoded"] == 300


def test_signals_while_the_daemon_starts_neither_kill_it_nor_are_lost():
    """SIGHUP and SIGUSR1 end a process by default: sent while canest run read its config (1-2 s), they killed the
    daemon (exit 129, 138); a SIGTERM then ended it without its summary. Sent here from inside the config's
    loading, the stop is kept: the daemon opens its buses, stops at once and prints its summary."""
    script = (
        "import os, signal, sys\n"
        "import canest.commands.run as command\n"
        "load = command.config_from_args\n"
        "def loading(args):\n"
        "    for number in (signal.SIGHUP, signal.SIGUSR1, signal.SIGTERM):\n"
        "        os.kill(os.getpid(), number)\n"
        "    return load(args)\n"
        "command.config_from_args = loading\n"
        "from canest.cli import main\n"
        "main(['run', '-i', 'virtual', '-c', 'startup-signals'])\n")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("frames=0"), result.stderr
