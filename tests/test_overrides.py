"""Per-message and per-signal overrides of what a DBC declares: CAN FD, cycle time, range, valid values,
stuck senders, and inputs that are the sum of several signals. Each is checked on load (file:line) and acts
on decoding, counted by cause."""
import math
import re

import can
import pytest

from canest.codec import integrity
from canest.codec.decode import InputDecoder
from canest.codec.encode import InputEncoder
from canest.config import load_config
from tests.test_codec import VALUES
from tests.test_config import error_of, write_variant

DEG = math.pi / 180.0


def variant(tmp_path, edit):
    return load_config(write_variant(tmp_path, edit))


def frame(encoder, frame_id, t=1.0, **values):
    return encoder.encode(frame_id, {**VALUES, **values}, t)


def test_fd_override_accepts_the_frames_the_car_sends(tmp_path):
    def fd(choice):
        def edit(data):
            data["input"]["messages"]["ESC_IMU"]["fd"] = choice
        return edit
    for choice, accepted in ((True, {True}), (False, {False}), ("any", {True, False})):
        config = variant(tmp_path, fd(choice))
        encoder, decoder = InputEncoder(config), InputDecoder(config)
        for is_fd in (True, False):
            msg = frame(encoder, 0x130)
            msg.is_fd = is_fd
            assert (decoder.decode(msg) is not None) == (is_fd in accepted), (choice, is_fd)
        assert decoder.counts["rejected_fd_mismatch"] == 2 - len(accepted)
    path = write_variant(tmp_path, fd("maybe"))
    assert re.match(rf"{re.escape(str(path))}:\d+: input\.messages\.ESC_IMU\.fd: must be true .* or any",
                    error_of(path))


def test_cycle_time_override_sets_the_timeout_and_its_source(tmp_path):
    def cycle(value):
        def edit(data):
            data["input"]["messages"]["ESC_IMU"]["cycle_time"] = value
        return edit
    decoder = InputDecoder(variant(tmp_path, cycle(0.04)))
    assert decoder.plans[0x130].cycle_time() == (0.04, "config")
    assert decoder.plans[0xC2].cycle_time() == (0.01, "DBC")
    assert decoder.timeouts(5)["yaw_rate"] == pytest.approx(0.2)
    path = write_variant(tmp_path, cycle(-0.01))
    assert re.match(rf"{re.escape(str(path))}:\d+: input\.messages\.ESC_IMU\.cycle_time: must be positive",
                    error_of(path))


def range_variant(tmp_path, value):
    def edit(data):
        data["input"]["signals"]["yaw_rate"]["range"] = value
    return write_variant(tmp_path, edit)


def test_range_override_replaces_the_dbc_range(tmp_path):
    fast = math.radians(100.0)  # inside the DBC's [-300|300] deg/s
    narrow = load_config(range_variant(tmp_path, [-50, 50]))
    encoder, decoder = InputEncoder(narrow), InputDecoder(narrow)
    assert decoder.decode(frame(encoder, 0x130, yaw_rate=fast)) is None
    assert decoder.counts["rejected_out_of_range"] == 1
    assert decoder.decode(frame(encoder, 0x130, t=1.01, yaw_rate=math.radians(50))) is not None
    assert decoder.last_saturated == {"yaw_rate"}  # at the limit of the overridden range
    assert narrow.signals["yaw_rate"].range == (-50.0, 50.0)
    assert load_config(range_variant(tmp_path, "none")).signals["yaw_rate"].range == (None, None)
    assert load_config(range_variant(tmp_path, None)).signals["yaw_rate"].range == (None, None)


def test_open_range_passes_what_a_raw_style_dbc_range_would_reject(tmp_path):
    path = range_variant(tmp_path, "none")
    dbc = path.parent.parent / "dbc" / "canest_vehicle.dbc"  # a Toyota-style range: raw [0|65535] on a signed signal
    dbc.write_text(dbc.read_text().replace('YawRate : 32|16@1- (0.01,0) [-300|300]', 'YawRate : 32|16@1- (0.01,0) [0|65535]'))
    config = load_config(path)
    decoder = InputDecoder(config)
    imu = decoder.plans[0x130].message
    values = {"LongAccel": 0.0, "LatAccel": 0.0, "YawRate": -11.5, "ESC_IMU_Valid": 1, "ESC_IMU_Counter": 0,
              "ESC_IMU_CRC": 0}
    data = integrity.seal(0x130, bytearray(imu.encode(values, strict=False)), 7)
    decoded = dict(decoder.decode(can.Message(arbitration_id=0x130, data=data, is_extended_id=False)))
    assert decoded["yaw_rate"] == pytest.approx(-11.5 * DEG)


@pytest.mark.parametrize("value, problem", [
    ([5, 1], "low must be below high"), ("wide", "must be \\[low, high\\]"), ([1], "must be \\[low"),
    ([0, float("inf")], "must be a finite number"), ([0, 10 ** 400], "must be a finite number")])
def test_bad_range_names_file_line_key(tmp_path, value, problem):
    path = range_variant(tmp_path, value)
    assert re.match(rf"{re.escape(str(path))}:\d+: input\.signals\.yaw_rate\.range: {problem}", error_of(path))


def test_valid_values_per_message_and_per_signal(tmp_path):
    def edit(data):
        data["input"]["messages"]["ESC_IMU"].pop("valid")
        data["input"]["signals"]["ay"]["valid"] = {"signal": "ESC_IMU_Valid", "values": [1]}
        data["input"]["messages"]["SAS_Status"]["valid"] = {"signal": "SAS_AngleValid", "values": 1}
    config = variant(tmp_path, edit)
    encoder, decoder = InputEncoder(config), InputDecoder(config)
    imu = decoder.plans[0x130].message

    def cleared(msg):
        values = imu.decode(msg.data, decode_choices=False)
        values["ESC_IMU_Valid"] = 0
        return can.Message(arbitration_id=0x130, data=integrity.seal(0x130, bytearray(imu.encode(values)), 7),
                           is_extended_id=False, timestamp=msg.timestamp)
    decoded = dict(decoder.decode(cleared(frame(encoder, 0x130))))
    assert set(decoded) == {"ax", "yaw_rate"}  # ay's own validity says no; the frame's other values are used
    assert decoder.counts["invalid_signal_samples"] == 1 and decoder.counts["decoded"] == 1
    assert decoder.decode(frame(encoder, 0xC2)) is not None  # the encoder writes the valid value


def test_valid_value_names_come_from_the_dbc(tmp_path):
    def edit(data):
        data["input"]["signals"]["ay"]["valid"] = {"signal": "ESC_IMU_Valid", "values": ["Fine"]}
    path = write_variant(tmp_path, edit)
    assert re.match(rf"{re.escape(str(path))}:\d+: input\.signals\.ay\.valid\.values: 'Fine' is neither a number "
                    r"nor a value name of ESC_IMU_Valid", error_of(path))

    def unknown(data):
        data["input"]["signals"]["ay"]["valid"] = "ESC_IMU_Vald"
    path = write_variant(tmp_path, unknown)
    assert "input.signals.ay.valid: no signal 'ESC_IMU_Vald'" in error_of(path) and "did you mean 'ESC_IMU_Valid'" \
        in error_of(path)


def test_stuck_value_is_dropped_only_while_the_car_moves(tmp_path):
    def edit(data):
        data["input"]["signals"]["steering_wheel_angle"]["stuck_after"] = 1.0
    config = variant(tmp_path, edit)

    def drive(speed, angles):
        encoder, decoder = InputEncoder(config), InputDecoder(config)
        used = 0
        for k, angle in enumerate(angles):
            t = 0.02 * k
            decoder.decode(encoder.encode(0xB4, {**VALUES, "wheel_speed_fl": speed, "wheel_speed_fr": speed}, t))
            decoder.decode(encoder.encode(0xB6, {**VALUES, "wheel_speed_rl": speed, "wheel_speed_rr": speed}, t))
            used += decoder.decode(encoder.encode(0xC2, {"steering_wheel_angle": angle}, t + 0.001)) is not None
        return used, decoder.counts
    used, counts = drive(50.0, [0.1] * 100)  # 2 s of the same value at 50 rad/s
    assert 45 <= used <= 55 and counts["stuck_samples"] == counts["rejected_stuck"] == 100 - used
    used, counts = drive(0.0, [0.1] * 100)  # standing: a steady wheel is no fault
    assert used == 100 and counts["stuck_samples"] == 0
    used, counts = drive(50.0, [0.1 + 0.002 * (k % 2) for k in range(100)])  # a sensor's noise
    assert used == 100 and counts["stuck_samples"] == 0


COMPOSITE = '''
BO_ 1574 STEER_ANGLE_SENSOR: 8 EPS
 SG_ STEER_ANGLE : 3|12@0- (1.5,0) [-1500|1500] "deg" CANEST
 SG_ STEER_FRACTION : 39|4@0- (0.1,0) [-0.7|0.7] "Deg" CANEST
'''


def test_an_input_may_be_the_sum_of_signals_of_one_message(tmp_path):
    def edit(data):
        data["input"]["signals"]["steering_wheel_angle"] = {
            "signal": ["STEER_ANGLE_SENSOR.STEER_ANGLE", "STEER_ANGLE_SENSOR.STEER_FRACTION"], "unit": "deg"}
        data["input"]["messages"].pop("SAS_Status")
    path = write_variant(tmp_path, edit)
    dbc = tmp_path / "dbc" / "canest_vehicle.dbc"
    dbc.write_text(dbc.read_text().replace("\nBO_ 180 ", COMPOSITE + "\nBO_ 180 ", 1))
    config = load_config(path)
    spec = config.signals["steering_wheel_angle"]
    assert spec.names == ("STEER_ANGLE", "STEER_FRACTION") and spec.range == (-1500.7, 1500.7)
    decoder = InputDecoder(config)
    message = decoder.plans[1574].message
    data = message.encode({"STEER_ANGLE": 45.0, "STEER_FRACTION": -0.3})
    decoded = dict(decoder.decode(can.Message(arbitration_id=1574, data=data, is_extended_id=False)))
    assert decoded["steering_wheel_angle"] == pytest.approx(44.7 * DEG)

    def two_messages(data):
        data["input"]["signals"]["steering_wheel_angle"] = {
            "signal": ["SAS_Status.SteeringWheelAngle", "ESC_IMU.YawRate"]}
    path = write_variant(tmp_path, two_messages)
    assert re.match(rf"{re.escape(str(path))}:\d+: input\.signals\.steering_wheel_angle\.signal: the signals of a "
                    r"sum must come from one message, got 'SAS_Status' and 'ESC_IMU'", error_of(path))
