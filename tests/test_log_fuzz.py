"""Fuzzing the log readers: any mutation of a valid candump, ASC, BLF or TRC log replays to a summary that
accounts for every frame and every line, or ends in one clear line (exit 65) with no output left; never a
traceback. In process (canest.apps.replay.replay and the CLI's mapping of CanestError to an exit status)."""
import tempfile
from pathlib import Path

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from canest.apps.replay import replay
from canest.errors import CanestError
from canest.io.logfiles import open_log
from canest.sim.simulate import simulate

FORMATS = [".log", ".asc", ".blf", ".trc"]

mutation = st.tuples(st.sampled_from(["flip", "insert", "delete", "truncate", "duplicate"]),
                     st.floats(0.0, 1.0), st.binary(min_size=1, max_size=24), st.integers(1, 200))


def mutate(data: bytes, operations) -> bytes:
    for operation, where, payload, length in operations:
        at = int(where * len(data))
        if operation == "flip":
            data = data[:at] + payload + data[at + len(payload):]
        elif operation == "insert":
            data = data[:at] + payload + data[at:]
        elif operation == "delete":
            data = data[:at] + data[at + length:]
        elif operation == "truncate":
            data = data[:at]
        else:
            data = data[:at] + data[at:at + length] + data[at:]
    return data


@pytest.fixture(scope="module")
def valid_logs(config, tmp_path_factory):
    """A 0.3 s drive (about 165 frames) in each format, as bytes."""
    frames = simulate(config, "dlc", 80.0, 0.85, duration=0.3, seed=7).frames
    folder = tmp_path_factory.mktemp("valid")
    logs = {}
    for suffix in FORMATS:
        writer = can.BLFWriter(str(folder / "d.blf"), max_container_size=2048) if suffix == ".blf" else \
            can.Logger(str(folder / f"d{suffix}"))
        with writer:
            for frame in frames:
                writer.on_message_received(frame)
        logs[suffix] = (folder / f"d{suffix}").read_bytes()
    return logs


def lines_in(data: bytes) -> int:
    return data.count(b"\n") + (1 if data and not data.endswith(b"\n") else 0)


@pytest.mark.parametrize("suffix", FORMATS)
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                 HealthCheck.function_scoped_fixture])
@given(operations=st.lists(mutation, min_size=1, max_size=4))
def test_any_mutated_log_gives_an_accounted_summary_or_one_clear_line(config, valid_logs, suffix, operations):
    data = mutate(valid_logs[suffix], operations)
    with tempfile.TemporaryDirectory() as folder:
        log, csv = Path(folder) / f"fuzz{suffix}", Path(folder) / "est.csv"
        log.write_bytes(data)
        try:
            summary = replay(config, log, out_csv=csv, progress=False)
        except CanestError as exc:  # what the command line prints as one line, with this exit status
            assert exc.exit_status == 65 and "\n" not in str(exc) and str(exc).startswith(str(log))
            assert sorted(p.name for p in Path(folder).iterdir()) == [log.name], "no output, no temporary file"
            return
        assert summary["frames"] == summary.get("decoded", 0) + summary.get("ignored_id", 0) + sum(
            v for k, v in summary.items() if k.startswith("rejected_"))
        assert sorted(p.name for p in Path(folder).iterdir()) == sorted([log.name, csv.name])
        assert csv.read_text().startswith("t,vx,")
        source = open_log(log)
        frames = sum(1 for _ in source)
        damage = source.damage
        assert frames == summary["frames"] and damage.summary() == {k: v for k, v in summary.items()
                                                                     if k.startswith("log_")}
        if suffix == ".blf":
            assert not damage or damage.stopped, "a damaged BLF says how far it was read"
        else:  # every line is a frame, a quiet (blank, header, comment, event) line or counted by cause
            assert damage.lines == lines_in(data)
            assert frames + damage.quiet_lines + sum(damage.counts[c] for c in ("bad_lines", "junk_lines",
                                                                                "torn_line")) == damage.lines
