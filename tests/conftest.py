"""Shared fixtures, and the SocketCAN lane.

Tests marked ``socketcan`` need vcan0 and vcan1 up. Where they are missing the
tests are skipped with the reason, unless CANEST_REQUIRE_SOCKETCAN=1 (set by
``make test`` inside the UML guest), where a missing bus is a failure: CI
must never pass with the real-vcan tests skipped.
"""
import os
import socket
import threading
from pathlib import Path

import pytest
import yaml

from canest.config import load_config
from canest.sim.simulate import simulate

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "dici_ev.yaml"
REALDATA_ENV = "CANEST_REALDATA"  # the folder of the shared real data, where it is not above the checkout


def realdata(*parts) -> Path:
    """A path inside the shared real data: ``$CANEST_REALDATA``, else the first ``shared/realdata`` in a folder
    above this file (a checkout in /work/main and a worktree anywhere deeper both find it).

    Absent data fails the test, naming every place looked in: a skipped real-data test would hide a gap."""
    given = os.environ.get(REALDATA_ENV)
    places = [Path(given)] if given else [folder / "shared" / "realdata" for folder in Path(__file__).resolve().parents]
    for place in places:
        if place.joinpath(*parts).exists():
            return place.joinpath(*parts)
    pytest.fail(f"real data {Path(*parts)} not found in {', '.join(map(str, places))}; set {REALDATA_ENV} to the "
                "folder holding it (shared/realdata)", pytrace=False)


FORD = "ford_fusion_2017"  # the Ford Fusion's recorded drive and opendbc's DBC, in the real data
FORD_CONFIG = ROOT / "configs" / "ford_fusion_2017.yaml"


def ford_dbc() -> Path:
    """opendbc's ``ford_lincoln_base_pt.dbc`` as the Ford's real data holds it, unedited."""
    return realdata(FORD, "ford_lincoln_base_pt.dbc")


def ford_config(folder, edit=None) -> Path:
    """The Ford config written into ``folder`` with its DBC found by :func:`realdata` (the config's own relative
    path holds only in a checkout that sits beside shared/) and ``edit`` applied to its dict."""
    data = yaml.safe_load(FORD_CONFIG.read_text())
    data["input"]["dbc"] = str(ford_dbc())
    if edit is not None:
        edit(data)
    path = Path(folder) / "ford.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def run_service_playing(service, play) -> dict:
    """Run ``service`` (in this thread) while another calls ``play()`` once its buses listen, then stops it; the
    service's summary. If the buses never open, ``play`` is not called and the service's error is raised."""
    def player():
        try:
            if service.wait_until_listening(10):
                play()
        finally:
            service.stop()

    thread = threading.Thread(target=player)
    thread.start()
    try:
        return service.run()
    finally:
        thread.join()


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
