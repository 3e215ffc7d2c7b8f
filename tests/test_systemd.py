"""The systemd units pass systemd-analyze verify, and their hardening scores as the README says."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT

UNITS = ROOT / "tools" / "systemd"
pytestmark = pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")


def installed_copy(tmp_path, name):
    """The unit with ExecStart pointing at this checkout's canest (verify checks the binary exists)."""
    canest = Path(sys.executable).with_name("canest")
    text = (UNITS / name).read_text().replace("/opt/canest/bin/canest", str(canest))
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name, unit", [("canest.service", "canest.service"),
                                        ("canest@.service", "canest@dici_ev.service")])
def test_units_verify_without_a_single_warning(tmp_path, name, unit):
    installed_copy(tmp_path, name)
    result = subprocess.run(["systemd-analyze", "verify", unit], cwd=tmp_path, capture_output=True, text=True)
    assert result.returncode == 0 and result.stdout == "" and result.stderr == "", result.stderr


def test_verify_would_catch_a_mistake(tmp_path):
    path = installed_copy(tmp_path, "canest.service")
    path.write_text(path.read_text().replace("Type=notify", "Typ=notify"))
    result = subprocess.run(["systemd-analyze", "verify", "canest.service"], cwd=tmp_path, capture_output=True,
                            text=True)
    assert "Unknown key" in result.stderr


def test_hardening_exposure_is_low(tmp_path):
    path = installed_copy(tmp_path, "canest.service")
    result = subprocess.run(["systemd-analyze", "security", "--offline=true", str(path)], capture_output=True,
                            text=True)
    line = next(line for line in result.stdout.splitlines() if "Overall exposure level" in line)
    assert float(line.split(":")[1].split()[0]) <= 1.5, line


def test_units_declare_notify_watchdog_and_the_unprivileged_sandbox():
    text = (UNITS / "canest@.service").read_text()
    for setting in ("Type=notify", "WatchdogSec=", "Restart=on-failure", "DynamicUser=yes", "NoNewPrivileges=yes",
                    "ProtectSystem=strict", "RestrictAddressFamilies=AF_CAN AF_UNIX", "CapabilityBoundingSet=\n",
                    "SystemCallFilter=@system-service", "ExecReload=/bin/kill -HUP $MAINPID"):
        assert setting in text, setting
