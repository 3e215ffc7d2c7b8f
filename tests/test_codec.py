"""Decoding and encoding through the signal map, and the integrity checks."""
import math

import can
import pytest

from canest.codec import integrity
from canest.codec.decode import InputDecoder
from canest.codec.encode import InputEncoder
from canest.config import load_config
from tests.conftest import ROOT

VALUES = {"steering_wheel_angle": 0.5, "ax": 1.25, "ay": -3.5, "yaw_rate": 0.2, "ax_2": 0.9, "ay_2": -1.1,
          "yaw_rate_2": -0.3, **{f"wheel_speed_{w}": 50.0 + i for i, w in enumerate(("fl", "fr", "rl", "rr"))},
          **{f"motor_torque_{w}": -200.0 + 10 * i for i, w in enumerate(("fl", "fr", "rl", "rr"))}}


def roundtrip(config):
    encoder, decoder = InputEncoder(config), InputDecoder(config)
    decoded = {}
    for message in encoder.messages:
        for _ in range(2):  # both pages of a multiplexed message
            frame = encoder.encode(message.frame_id, VALUES, 1.0)
            decoded.update(decoder.decode(frame))
    return decoded, decoder


@pytest.mark.parametrize("name", ["dici_ev.yaml", "production_example.yaml"])
def test_encode_decode_roundtrip_within_dbc_resolution(name):
    config = load_config(ROOT / "configs" / name)
    decoded, decoder = roundtrip(config)
    assert set(decoded) == set(config.signals)
    for canonical, value in decoded.items():
        resolution = abs(config.signals[canonical].factor) * 0.1  # every scaling used is finer than 0.1 unit
        assert value == pytest.approx(VALUES[canonical], abs=resolution), canonical
    assert decoder.counts["decoded"] == decoder.counts["frames"]


def test_crc8_sae_j1850_check_value():
    assert integrity._crc8(b"123456789") == 0x4B


@pytest.fixture
def pair(config):
    return InputEncoder(config), InputDecoder(config)


def imu_frame(encoder, **overrides):
    frame = encoder.encode(0x130, VALUES, 1.0)
    for key, value in overrides.items():
        setattr(frame, key, value)
    return frame


def test_rejects_corrupted_checksum(pair):
    encoder, decoder = pair
    frame = imu_frame(encoder)
    frame.data = bytearray(frame.data)
    frame.data[0] ^= 0x01
    assert decoder.decode(frame) is None
    assert decoder.counts["rejected_checksum"] == 1


def test_rejects_repeated_counter_and_counts_jumps(pair):
    encoder, decoder = pair
    first = imu_frame(encoder)
    assert decoder.decode(first) is not None
    assert decoder.decode(first) is None
    assert decoder.counts["rejected_counter_repeated"] == 1
    encoder.encode(0x130, VALUES, 1.0)  # a lost frame
    assert decoder.decode(imu_frame(encoder)) is not None
    assert decoder.counts["counter_jumps"] == 1


def test_rejects_wrong_dlc_remote_error_and_fd_frames_and_ignores_unknown_ids(pair):
    encoder, decoder = pair
    assert decoder.decode(can.Message(arbitration_id=0x130, data=b"\x00" * 4, is_extended_id=False)) is None
    assert decoder.decode(can.Message(arbitration_id=0x130, is_remote_frame=True, dlc=8, is_extended_id=False)) is None
    assert decoder.decode(can.Message(arbitration_id=0, is_error_frame=True)) is None
    fd = imu_frame(encoder, is_fd=True)
    assert decoder.decode(fd) is None
    assert decoder.decode(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False)) is None
    assert decoder.decode(can.Message(arbitration_id=0x130, data=bytes(8), is_extended_id=True)) is None
    c = decoder.counts
    assert (c["rejected_dlc"], c["rejected_remote_frame"], c["rejected_error_frame"], c["rejected_fd_mismatch"],
            c["ignored_id"]) == (1, 1, 1, 1, 2)
    assert c["frames"] == 6


def test_rejects_cleared_validity_bit(config, pair):
    encoder, decoder = pair
    db = encoder.decoder_plans[0x130].message
    values = db.decode(imu_frame(encoder).data)
    values["ESC_IMU_Valid"] = 0
    data = integrity.seal(0x130, bytearray(db.encode(values)), 7)
    assert decoder.decode(can.Message(arbitration_id=0x130, data=data, is_extended_id=False)) is None
    assert decoder.counts["rejected_invalid_flag"] == 1


def test_kernel_filters_cover_exactly_the_mapped_ids(config):
    decoder = InputDecoder(config)
    assert sorted(f["can_id"] for f in decoder.can_filters()) == [0xB4, 0xB6, 0xC2, 0x130, 0x140, 0x1D0, 0x1D2]
    assert all(f["can_mask"] == 0x7FF and not f["extended"] for f in decoder.can_filters())


def test_decoded_values_are_si_and_iso_signed(config):
    encoder, decoder = InputEncoder(config), InputDecoder(config)
    decoded = dict(decoder.decode(encoder.encode(0xC2, {"steering_wheel_angle": math.radians(90)}, 0.0)))
    assert decoded["steering_wheel_angle"] == pytest.approx(math.radians(90), abs=1e-3)


def test_not_finite_values_of_a_float_signal_are_rejected(tmp_path):
    import struct

    dbc = tmp_path / "float.dbc"
    dbc.write_text('''VERSION ""
NS_ :
BS_:
BU_: A
BO_ 256 FLOAT_IMU: 8 A
 SG_ YawRateF : 0|32@1- (1,0) [-10|10] "rad/s" A
 SG_ LatAccF : 32|32@1- (1,0) [-50|50] "m/s^2" A
SIG_VALTYPE_ 256 YawRateF : 1;
SIG_VALTYPE_ 256 LatAccF : 1;
''')
    config = load_config(ROOT / "configs" / "dici_ev.yaml")
    import dataclasses

    from canest.settings import SignalSpec

    signals = {**config.signals, "yaw_rate": SignalSpec("yaw_rate", "FLOAT_IMU", "YawRateF", 1.0),
               "ay": SignalSpec("ay", "FLOAT_IMU", "LatAccF", 1.0)}
    decoder = InputDecoder(dataclasses.replace(config, input_dbc=dbc, signals={k: v for k, v in signals.items()
                                                                               if k in ("yaw_rate", "ay")}, messages={}))
    for value in (float("nan"), float("inf")):
        assert decoder.decode(can.Message(arbitration_id=256, data=struct.pack("<ff", value, 1.0),
                                          is_extended_id=False)) is None
    assert dict(decoder.decode(can.Message(arbitration_id=256, data=struct.pack("<ff", 0.5, 1.0),
                                           is_extended_id=False))) == {"yaw_rate": 0.5, "ay": 1.0}
    assert decoder.counts["rejected_non_finite"] == 2
