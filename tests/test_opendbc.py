"""opendbc as canest's DBC library: ``opendbc:NAME``, messy DBCs, brand checksums and a generic CRC.

Frames are built with opendbc's own ``CANPacker`` (its brands' checksums and
counters as a car sends them), so canest's checks are tested against
opendbc's code, not against themselves.
"""
import math
import os
import subprocess
import sys
from pathlib import Path

import can
import cantools
import pytest
import yaml

from canest.codec.checksums import GenericCrc
from canest.codec.decode import InputDecoder
from canest.codec.encode import InputEncoder
from canest.config import load_config
from canest.errors import ConfigError, DbcError
from canest.settings import CrcParameters
from tests.conftest import ROOT

opendbc = pytest.importorskip("opendbc", reason="the opendbc extra (pip install canest[opendbc]) is part of the test "
                                                "extra on Python 3.11 and 3.12")
from opendbc.can.packer import CANPacker  # noqa: E402  (after the extra is known to be installed)

TOYOTA_CONFIG = ROOT / "configs" / "toyota_rav4_opendbc.yaml"


def write_config(tmp_path, data, name="car.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def toyota(tmp_path, edit=None):
    """The Toyota config with ``edit`` applied to its dict, written to ``tmp_path`` (builtin: and opendbc: names
    need no path change)."""
    data = yaml.safe_load(TOYOTA_CONFIG.read_text())
    if edit:
        edit(data)
    return write_config(tmp_path, data)


def canest(*args, env=None):
    return subprocess.run([sys.executable, "-m", "canest", *args], capture_output=True, text=True, cwd=ROOT,
                          env=env, timeout=120)


def frame(address, data):
    return can.Message(arbitration_id=address, data=data, is_extended_id=address > 0x7FF, timestamp=0.0)


def corrupted(data, byte):
    """``data`` with one bit of ``byte`` flipped."""
    wrong = bytearray(data)
    wrong[byte] ^= 0x04
    return bytes(wrong)


# --- opendbc:NAME --------------------------------------------------------------------------------------------------

def test_generated_opendbc_dbc_loads_by_name_with_its_tolerated_problems(tmp_path):
    config = load_config(toyota(tmp_path))
    assert config.input_dbc.read_text() == opendbc.get_generated_dbcs()["toyota_nodsu_pt_generated"]
    assert config.signals["steering_wheel_angle"].names == ("STEER_ANGLE", "STEER_FRACTION")
    assert set(config.tolerated) == {"PCS_HUD"}  # the one message cantools' strict check refuses
    assert "PCS_TEMP and SET_ME_X10 are overlapping" in config.tolerated["PCS_HUD"]
    with pytest.raises(cantools.database.Error, match="overlapping in message PCS_HUD"):
        cantools.database.load_file(str(config.input_dbc), strict=True)


def test_static_opendbc_dbc_is_used_where_opendbc_installed_it(tmp_path):
    data = yaml.safe_load((ROOT / "configs" / "ford_fusion_2017.yaml").read_text())
    data["input"]["dbc"] = "opendbc:ford_lincoln_base_pt"
    config = load_config(write_config(tmp_path, data))
    assert config.input_dbc == Path(opendbc_file("ford_lincoln_base_pt")).resolve()
    assert config.signals["yaw_rate"].message == "Yaw_Data_FD1" and config.tolerated == {}


def test_check_reports_what_it_tolerated(tmp_path):
    result = canest("check", "--config", str(toyota(tmp_path)))
    assert result.returncode == 0, result.stderr
    assert "tolerated in the input DBC (no signal is taken from PCS_HUD): The signals PCS_TEMP and SET_ME_X10 are " \
           "overlapping in message PCS_HUD." in result.stdout
    assert "STEER_ANGLE_SENSOR.STEER_ANGLE + STEER_ANGLE_SENSOR.STEER_FRACTION" in result.stdout
    assert "PCS_HUD" in result.stderr and "tolerated" in result.stderr  # the warning of every command


def test_a_used_malformed_message_is_a_dbc_error_naming_file_message_and_signals(tmp_path):
    def map_pcs_hud(data):
        data["input"]["signals"]["ax"] = {"signal": "PCS_HUD.PCS_TEMP", "unit": "m/s^2"}
    path = toyota(tmp_path, map_pcs_hud)
    with pytest.raises(DbcError, match=r"car.yaml:\d+: input.signals.ax.signal: message 'PCS_HUD' of .*"
                                       r"toyota_nodsu_pt_generated.dbc is malformed: The signals PCS_TEMP and "
                                       r"SET_ME_X10 are overlapping"):
        load_config(path)
    result = canest("check", "--config", str(path))
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and "PCS_HUD" in result.stderr


def test_unknown_opendbc_name_names_file_key_and_the_closest_names(tmp_path):
    path = toyota(tmp_path, lambda d: d["input"].update(dbc="opendbc:toyota_nodsu_pt"))
    with pytest.raises(ConfigError, match=r"car.yaml:\d+: input.dbc: opendbc has no DBC 'toyota_nodsu_pt'; "
                                          r"closest: toyota_nodsu_pt_generated"):
        load_config(path)


HIDE_OPENDBC = ("import sys; sys.modules['opendbc'] = None; from canest.cli import main; "
                "main(['check', '--config', sys.argv[1]])")


@pytest.mark.parametrize("needs", ["dbc", "checksum"])
def test_without_the_extra_one_line_names_the_install_command(tmp_path, needs):
    if needs == "dbc":
        path = toyota(tmp_path)
    else:  # a brand's checksum on a DBC file that needs no opendbc
        path = write_config(tmp_path, vw_config(tmp_path, {"signal": "CHECKSUM", "algorithm": "vw_mqb"}))
    result = subprocess.run([sys.executable, "-c", HIDE_OPENDBC, str(path)], capture_output=True, text=True,
                            cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    errors = [line for line in result.stderr.splitlines() if line.startswith("canest: error:")]
    assert result.returncode == 69 and len(errors) == 1 and errors[0] == result.stderr.splitlines()[-1]
    assert "pip install 'canest[opendbc]'" in errors[0] and str(path) in errors[0]


# --- checksums -----------------------------------------------------------------------------------------------------

def decode_all(config, frames):
    decoder = InputDecoder(config)
    decoded = [decoder.decode(f) for f in frames]
    return decoder.counts, decoded


def good_and_wrong(packer, message, values_of, corrupt_byte, count=20):
    """Frames ``packer`` builds (counter and checksum by opendbc), and the number of wrong ones: every third good
    frame comes after a copy of it with one bit of ``corrupt_byte`` flipped (so the good ones' counters stay in
    sequence)."""
    frames, wrong = [], 0
    for i in range(count):
        address, data, _ = packer.make_can_msg(message, 0, values_of(i))
        if i % 3 == 1:
            frames.append(frame(address, corrupted(data, corrupt_byte)))
            wrong += 1
        frames.append(frame(address, data))
    return frames, wrong


def test_toyota_checksum_accepts_opendbcs_frames_and_rejects_wrong_ones(tmp_path):
    def steering_from_torque_sensor(data):
        data["input"]["signals"]["steering_wheel_angle"] = {"signal": "STEER_TORQUE_SENSOR.STEER_ANGLE", "unit": "deg"}
        data["input"]["messages"]["STEER_TORQUE_SENSOR"] = {"checksum": {"signal": "CHECKSUM", "algorithm": "toyota"}}
        del data["input"]["messages"]["STEER_ANGLE_SENSOR"]
    config = load_config(toyota(tmp_path, steering_from_torque_sensor))
    packer = CANPacker("toyota_nodsu_pt_generated")
    frames, wrong = good_and_wrong(packer, "STEER_TORQUE_SENSOR", lambda i: {"STEER_ANGLE": 2.0 * i}, corrupt_byte=3)
    counts, decoded = decode_all(config, frames)
    assert counts["rejected_checksum"] == wrong == 7 and counts["decoded"] == 20
    angles = [dict(d)["steering_wheel_angle"] for d in decoded if d]
    assert angles == pytest.approx([math.radians(0.0573 * round(2.0 * i / 0.0573)) for i in range(20)])


def vw_config(tmp_path, checksum):
    """A VW Golf MK7 (vw_mqb, as opendbc ships it: it does not load strictly) mapping ESP_02 with ``checksum``."""
    data = yaml.safe_load(TOYOTA_CONFIG.read_text())
    data["input"]["dbc"] = str(opendbc_file("vw_mqb"))
    data["input"]["signals"] = {
        "steering_wheel_angle": "LWI_01.LWI_Lenkradwinkel",
        **{f"wheel_speed_{w}": f"ESP_19.ESP_{v}_Radgeschw_02"
           for w, v in (("fl", "VL"), ("fr", "VR"), ("rl", "HL"), ("rr", "HR"))},
        "yaw_rate": "ESP_02.ESP_Gierrate", "ax": "ESP_02.ESP_Laengsbeschl", "ay": "ESP_02.ESP_Querbeschleunigung"}
    data["input"]["messages"] = {"ESP_02": {"counter": "COUNTER", "checksum": checksum}}
    return data


def opendbc_file(name):
    return os.path.join(opendbc.DBC_PATH, f"{name}.dbc")


# The same VW CRC described by parameters: AUTOSAR's CRC-8H2F over bytes 1-7, then ESP_02's data ID 0xAA
VW_AS_GENERIC_CRC = {"signal": "CHECKSUM", "algorithm": "crc", "width": 8, "polynomial": 0x2F, "init": 0xFF,
                     "xor_out": 0xFF, "bytes": [1, 7], "data_id": [0xAA]}


@pytest.mark.parametrize("checksum", [{"signal": "CHECKSUM", "algorithm": "vw_mqb"}, VW_AS_GENERIC_CRC],
                         ids=["vw_mqb", "generic_crc"])
def test_vw_crc_with_data_id_accepts_opendbcs_frames_and_rejects_wrong_ones(tmp_path, checksum):
    config = load_config(write_config(tmp_path, vw_config(tmp_path, checksum)))
    assert "PLA_01" in config.tolerated  # vw_mqb's own overlap, in a message not used
    packer = CANPacker("vw_mqb")
    frames, wrong = good_and_wrong(packer, "ESP_02", lambda i: {"ESP_Laengsbeschl": 0.5 * i - 4.0}, corrupt_byte=3)
    counts, decoded = decode_all(config, frames)
    assert counts["rejected_checksum"] == wrong and counts["decoded"] == 20 and counts["rejected_counter_sequence"] == 0
    assert [dict(d)["ax"] for d in decoded if d] == pytest.approx([0.5 * i - 4.0 for i in range(20)])


def test_generic_crc_with_another_data_id_rejects_every_frame(tmp_path):
    config = load_config(write_config(tmp_path, vw_config(tmp_path, {**VW_AS_GENERIC_CRC, "data_id": [0xAB]})))
    frames = [frame(*CANPacker("vw_mqb").make_can_msg("ESP_02", 0, {"ESP_Laengsbeschl": 1.0})[:2]) for _ in range(5)]
    counts, _ = decode_all(config, frames)
    assert counts["rejected_checksum"] == 5 and counts["decoded"] == 0


def rocksoft(data, width, poly, init, refin, refout, xor_out):
    """The CRC catalogue's model bit by bit: the test's independent reference."""
    def reflect(value, bits):
        return int(f"{value:0{bits}b}"[::-1], 2)
    top, mask, register = 1 << (width - 1), (1 << width) - 1, init
    for byte in data:
        register ^= (reflect(byte, 8) if refin else byte) << (width - 8)
        for _ in range(8):
            register = ((register << 1) ^ poly if register & top else register << 1) & mask
    return (reflect(register, width) if refout else register) ^ xor_out


CATALOGUE = [  # name, width, poly, init, refin, refout, xor_out, check of b"123456789" (reveng.sourceforge.io)
    ("CRC-8/SAE-J1850", 8, 0x1D, 0xFF, False, False, 0xFF, 0x4B),
    ("CRC-8/AUTOSAR", 8, 0x2F, 0xFF, False, False, 0xFF, 0xDF),
    ("CRC-8/ROHC", 8, 0x07, 0xFF, True, True, 0x00, 0xD0),
    ("CRC-16/ARC", 16, 0x8005, 0x0000, True, True, 0x0000, 0xBB3D),
    ("CRC-16/RIELLO", 16, 0x1021, 0xB2AA, True, True, 0x0000, 0x63D0),
    ("CRC-16/IBM-3740", 16, 0x1021, 0xFFFF, False, False, 0x0000, 0x29B1),
    ("CRC-32/ISO-HDLC", 32, 0x04C11DB7, 0xFFFFFFFF, True, True, 0xFFFFFFFF, 0xCBF43926),
    ("CRC-32/AUTOSAR", 32, 0xF4ACFB13, 0xFFFFFFFF, True, True, 0xFFFFFFFF, 0x1697D06A),
]


def crc_over_check_string(width, poly, init, refin, refout, xor_out):
    """GenericCrc of b"123456789" in a frame whose last width/8 bytes hold the CRC (little endian)."""
    length = 9 + width // 8
    signal = cantools.database.can.Signal("CRC", start=72, length=width, byte_order="little_endian")
    crc = GenericCrc(CrcParameters(width, poly, init, xor_out, refin, refout), signal, length)
    data = bytearray(b"123456789" + bytes(width // 8))
    sealed = crc.seal(0x123, data)
    assert crc.ok(0x123, sealed) and not crc.ok(0x123, corrupted(sealed, 4))
    return int.from_bytes(sealed[9:], "little")


@pytest.mark.parametrize("name, width, poly, init, refin, refout, xor_out, check", CATALOGUE,
                         ids=[c[0] for c in CATALOGUE])
def test_generic_crc_matches_the_crc_catalogue(name, width, poly, init, refin, refout, xor_out, check):
    assert rocksoft(b"123456789", width, poly, init, refin, refout, xor_out) == check  # the reference is right
    assert crc_over_check_string(width, poly, init, refin, refout, xor_out) == check


@pytest.mark.parametrize("width, poly, init, xor_out", [(8, 0x2F, 0x5A, 0x00), (16, 0x1021, 0xB2AA, 0x1234),
                                                         (32, 0x04C11DB7, 0x12345678, 0xFFFFFFFF)])
@pytest.mark.parametrize("refin, refout", [(True, False), (False, True)])
def test_generic_crc_with_reflection_of_input_or_output_only(width, poly, init, xor_out, refin, refout):
    assert rocksoft(b"123456789", 12, 0x80F, 0, False, True, 0) == 0xDAF  # CRC-12/UMTS: refin != refout, catalogued
    expected = rocksoft(b"123456789", width, poly, init, refin, refout, xor_out)
    assert crc_over_check_string(width, poly, init, refin, refout, xor_out) == expected


def test_unknown_checksum_algorithm_lists_the_valid_ones(tmp_path):
    path = write_config(tmp_path, vw_config(tmp_path, {"signal": "CHECKSUM", "algorithm": "vw_mqbb"}))
    with pytest.raises(ConfigError, match=r"car.yaml:\d+: input.messages.ESP_02.checksum.algorithm: unknown checksum "
                                          r"algorithm 'vw_mqbb'; valid: canest, crc, toyota, honda, .*vw_mqb, "):
        load_config(path)


@pytest.mark.parametrize("checksum, problem", [
    ({**VW_AS_GENERIC_CRC, "width": 12}, r"checksum.width: must be 8, 16, 24 or 32 bits, got 12"),
    ({**VW_AS_GENERIC_CRC, "polynomial": 0x12F}, r"checksum.polynomial: must be the generator without its top bit"),
    ({**VW_AS_GENERIC_CRC, "bytes": [1, 8]}, r"checksum.bytes: must be a data byte of the message"),
    ({**VW_AS_GENERIC_CRC, "reflect_in": "yes"}, r"checksum.reflect_in: must be true or false"),
    ({"signal": "CHECKSUM", "algorithm": "toyota", "width": 8}, r"checksum.width: unknown key.*algorithm: crc"),
    ({**VW_AS_GENERIC_CRC, "width": 16}, r"checksum: checksum signal CHECKSUM must fill 2 whole byte"),
])
def test_generic_crc_parameters_are_checked(tmp_path, checksum, problem):
    path = write_config(tmp_path, vw_config(tmp_path, checksum))
    with pytest.raises(ConfigError, match=problem):
        InputDecoder(load_config(path))


@pytest.mark.parametrize("degrees", [10.3, -7.45, 0.05, -123.4])
def test_simulator_splits_coarse_plus_fine_steering_as_a_toyota_sends_it(tmp_path, degrees):
    config = load_config(toyota(tmp_path))
    encoder = InputEncoder(config)
    sent = encoder.encode(0x25, {"steering_wheel_angle": math.radians(degrees)}, 0.0)
    raw = encoder.decoder_plans[0x25].message.decode(sent.data)
    assert abs(raw["STEER_FRACTION"]) <= 0.7 and raw["STEER_ANGLE"] % 1.5 == pytest.approx(0.0, abs=1e-9)
    assert raw["STEER_ANGLE"] + raw["STEER_FRACTION"] == pytest.approx(degrees, abs=0.05 + 1e-9)
    decoded = dict(InputDecoder(config).decode(sent))
    assert math.degrees(decoded["steering_wheel_angle"]) == pytest.approx(degrees, abs=0.05 + 1e-9)
