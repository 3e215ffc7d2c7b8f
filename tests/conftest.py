"""Shared fixtures, and the SocketCAN lane.

Tests marked ``socketcan`` need vcan0 and vcan1 up. Where they are missing the
tests are skipped with the reason, unless CANEST_REQUIRE_SOCKETCAN=1 (set by
``make test`` inside the UML guest), where a missing bus is a failure: CI
must never pass with the real-vcan tests skipped.
"""
import os
import socket
from pathlib import Path

import pytest

from canest.config import load_config
from canest.sim.simulate import simulate

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "dici_ev.yaml"


def vcan_missing():
    """None if vcan0 and vcan1 can be bound, else the reason."""
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no AF_CAN"
    for channel in ("vcan0", "vcan1"):
        try:
            with socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW) as sock:
                sock.bind((channel,))
        except OSError as exc:
            return f"no SocketCAN interface {channel} ({exc}); run: tools/vcan-guest -- python -m pytest -m socketcan"
    return None


def pytest_collection_modifyitems(config, items):
    reason = vcan_missing()
    if reason is None:
        return
    if os.environ.get("CANEST_REQUIRE_SOCKETCAN") == "1":
        raise pytest.UsageError(f"CANEST_REQUIRE_SOCKETCAN=1 but {reason}")
    for item in items:
        if "socketcan" in item.keywords:
            item.add_marker(pytest.mark.skip(reason=reason))


@pytest.fixture(scope="session")
def config():
    return load_config(CONFIG)


def write_log_and_truth(sim, log_path, truth_path):
    sim.write_log(log_path)
    sim.write_truth(truth_path)


@pytest.fixture(scope="session")
def dlc_run(config, tmp_path_factory):
    """A simulated ISO 3888-1 double lane change at 80 km/h on mu 0.85: (log, truth CSV, Simulation)."""
    folder = tmp_path_factory.mktemp("dlc")
    sim = simulate(config, "dlc", 80.0, 0.85, seed=3)
    write_log_and_truth(sim, folder / "drive.log", folder / "truth.csv")
    return folder / "drive.log", folder / "truth.csv", sim
