"""An output DBC that lacks what canest sends is refused with one line naming the file and every gap."""
import subprocess
import sys

import cantools
import pytest
import yaml

from canest.codec.encode import EstimateEncoder
from canest.errors import DbcError
from tests.conftest import CONFIG, ROOT

REFERENCE = ROOT / "dbc" / "canest_estimates.dbc"


def without_message(db, name):
    db.messages.remove(db.get_message_by_name(name))


def without_signal(message, signal):
    def edit(db):
        msg = db.get_message_by_name(message)
        msg.signals.remove(msg.get_signal_by_name(signal))
    return edit


def without_mode_value(value):
    def edit(db):
        mode = db.get_message_by_name("CE_Status").get_signal_by_name("Mode")
        mode.choices = {k: v for k, v in mode.choices.items() if str(v) != value}
    return edit


def edited_dbc(path, edit):
    db = cantools.database.load_file(str(REFERENCE))
    edit(db)
    db.refresh()
    path.write_text(db.as_dbc_string())
    return path


@pytest.mark.parametrize("edit, gap", [
    (lambda db: without_message(db, "CE_Status"), "message CE_Status"),
    (lambda db: without_message(db, "CE_Friction"), "message CE_Friction"),
    (without_signal("CE_Velocity", "VxStd"), "signal CE_Velocity.VxStd"),
    (without_signal("CE_Status", "InnovationNis"), "signal CE_Status.InnovationNis"),
    (without_signal("CE_YawSideslip", "CE_YawSideslip_Counter"), "a *_Counter signal in CE_YawSideslip"),
    (without_signal("CE_Friction", "CE_Friction_CRC"), "a *_CRC signal in CE_Friction"),
    (without_mode_value("no_input"), "value 'no_input' of CE_Status.Mode"),
])
def test_encoder_names_the_file_and_the_gap(tmp_path, edit, gap):
    dbc = edited_dbc(tmp_path / "mine.dbc", edit)
    with pytest.raises(DbcError) as caught:
        EstimateEncoder(dbc)
    message = str(caught.value)
    assert message.startswith(f"{dbc}: output DBC lacks ") and gap in message
    assert "\n" not in message


def test_every_gap_is_named_at_once(tmp_path):
    def edit(db):
        without_message(db, "CE_Status")
        without_signal("CE_Velocity", "VyValid")(db)

    message = str(pytest.raises(DbcError, EstimateEncoder, edited_dbc(tmp_path / "mine.dbc", edit)).value)
    assert "message CE_Status" in message and "signal CE_Velocity.VyValid" in message


def test_the_reference_dbc_is_complete():
    assert EstimateEncoder(REFERENCE).senders.keys() >= {"CE_Status", "CE_Velocity"}


@pytest.mark.parametrize("command", ["check", "replay"])
def test_command_line_error_is_one_line(tmp_path, command):
    dbc = edited_dbc(tmp_path / "no_status.dbc", lambda db: without_message(db, "CE_Status"))
    doc = yaml.safe_load(CONFIG.read_text())
    if ":" not in doc["input"]["dbc"]:  # a path relative to the config's folder; else a built-in's name
        doc["input"]["dbc"] = str((CONFIG.parent / doc["input"]["dbc"]).resolve())
    doc["output"]["dbc"] = str(dbc)
    config = tmp_path / "car.yaml"
    config.write_text(yaml.safe_dump(doc))
    log = tmp_path / "drive.log"
    log.write_text("(0.000000) vcan0 130#0000000000000000\n")
    args = ["check", "--config", config] if command == "check" else \
        ["replay", log, "--config", config, "--csv", tmp_path / "est.csv", "-q"]
    result = subprocess.run([sys.executable, "-m", "canest", *map(str, args)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2, result.stderr
    assert result.stderr.splitlines() == [f"canest: error: {dbc}: output DBC lacks message CE_Status; "
                                          "start from dbc/canest_estimates.dbc (README 'DBC contract')"]
