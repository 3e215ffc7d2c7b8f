"""What a config says, as typed values: buses, the signal map, integrity checks, the estimator.

Pure data (no YAML, no DBC): the stages take these; :mod:`canest.config`
reads and validates them from a file.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from canest.params import VehicleParams


@dataclass(frozen=True)
class BusConfig:
    """Arguments for ``can.Bus``: interface, channel and the config's python-can ``options``."""

    interface: str = "socketcan"
    channel: str = "vcan0"
    options: dict = field(default_factory=dict)

    def kwargs(self) -> dict:
        return {"interface": self.interface, "channel": self.channel, **self.options}


@dataclass(frozen=True)
class ValidWhen:
    """A signal of the same message saying whether a value (or the whole frame) may be used.

    ``values``: the DBC physical values that mean valid; empty: any value but 0 (a validity bit)."""

    signal: str
    values: tuple = ()

    def accepts(self, decoded: dict) -> bool:
        value = decoded.get(self.signal, 1)
        return value in self.values if self.values else bool(value)


@dataclass(frozen=True)
class SignalSpec:
    """Where a canonical signal lives and how its DBC value becomes SI: si = factor * value + offset.

    ``value`` is the DBC physical value of ``signal`` plus those of ``parts`` (a composite: coarse + fine
    steering); it must lie in ``range`` (low, high; None: unbounded), the DBC's unless the config overrides it.
    """

    canonical: str
    message: str
    signal: str
    factor: float
    offset: float = 0.0
    multiplexer_value: int | None = None
    parts: tuple = ()
    range: tuple = (None, None)
    range_given: bool = False  # the config's range replaces the DBC's (a DBC range that is wrong for the car)
    valid: ValidWhen | None = None
    stuck_after: float | None = None  # s: the same raw value this long while the car moves is a stuck sender
    learn_zero: bool = False  # a relative angle: its zero is learned while driving straight

    @property
    def names(self) -> tuple:
        """Every DBC signal that adds up to the value."""
        return (self.signal, *self.parts)


@dataclass(frozen=True)
class CrcParameters:
    """A CRC in the Rocksoft model (as the CRC catalogue names them) and what it covers of a frame.

    Covered: data bytes ``first_byte`` to ``last_byte`` (inclusive) but the checksum's own, with ``data_id``
    (bytes) fed before them (``data_id_at: start``) or after them (``end``, as AUTOSAR E2E profiles 2 and 5)."""

    width: int
    polynomial: int
    init: int = 0
    xor_out: int = 0
    reflect_in: bool = False
    reflect_out: bool = False
    data_id: tuple = ()
    data_id_at: str = "end"
    first_byte: int = 0
    last_byte: int | None = None  # None: the frame's last


@dataclass(frozen=True)
class MessageChecks:
    """Optional integrity checks and overrides of an input message.

    ``fd``: which frames are accepted, ``dbc`` (as its DBC declares), ``classic``, ``fd`` or ``any``;
    ``cycle_time`` (s) overrides the DBC's ``GenMsgCycleTime`` for the timeouts. ``checksum_algorithm``:
    ``canest`` (CRC-8/SAE-J1850 over the frame ID and data), an opendbc brand's (``toyota``, ...) or ``crc``
    (described by ``crc``), see :mod:`canest.codec.checksums`."""

    counter: str | None = None
    checksum: str | None = None
    checksum_algorithm: str = "canest"
    crc: CrcParameters | None = None
    valid: ValidWhen | None = None
    fd: str = "dbc"
    cycle_time: float | None = None


@dataclass(frozen=True)
class EstimatorConfig:
    filter: str = "ckf"
    model: str = "single_track"  # single_track, tire_force (7 states) or two_track (7-DOF + friction)
    factorization: str | None = None  # None: the filter's own default (svd for svd-fckf, else cholesky)
    filter_options: dict = field(default_factory=dict)
    rate_hz: float = 100.0
    min_speed: float = 3.0
    speed_hysteresis: float = 1.0
    timeout_cycles: float = 5.0
    friction_excitation: float = 1500.0  # N per unit mu: |dF/dmu| at mu - 3 std that makes a wheel excited
    friction_correlation: float = 0.9  # prior correlation of the four wheels' frictions (same road)
    # rad/s, 1 std: the gyro's bias beyond what measurement_noise.yaw_rate admits (noise the filter averages, not an
    # offset every tick shares); the published yaw rate carries it until the online calibration applies its own
    gyro_bias_std: float = 0.0
    # m/s^2 of the ay channels' noise per m/s^2 of |ay|, in quadrature with measurement_noise.ay and ay_2 (the
    # sensors'): the model's lateral error, which grows with ay (the tires' degressive stiffness, body roll)
    lateral_model_error: float = 0.05
    latency_compensation: bool = False
    online_calibration: bool = True  # learn sensor biases and parameters while driving (estimation.online_calibration)
    state_file: str | None = None  # where the online calibration is saved and reloaded from; None: not saved
    process_noise: dict = field(default_factory=lambda: {
        "yaw_rate": 0.05, "beta": 0.01, "vx": 0.3, "vx_from_ax": 0.1, "vx_from_wheel_states": 0.05,
        "lateral_force": 300.0, "wheel_speed": 5.0, "friction": 0.1})
    measurement_noise: dict = field(default_factory=lambda: {
        "ay": 0.15, "yaw_rate": 0.005, "vx_wheel": 0.15, "ax": 0.15, "ax_2": 0.3, "ay_2": 0.3, "yaw_rate_2": 0.01,
        "wheel_speed": 0.1, "yaw_acceleration": 0.1, "vx_reference": 0.05})
    initial_std: dict = field(default_factory=lambda: {
        "yaw_rate": 0.05, "beta": 0.05, "vx": 2.0, "lateral_force": 1000.0, "wheel_speed": 1.0, "friction": 0.3})


@dataclass(frozen=True)
class Config:
    path: Path
    vehicle: VehicleParams
    input_dbc: Path
    output_dbc: Path
    input_bus: BusConfig
    output_bus: BusConfig
    signals: dict  # canonical -> SignalSpec
    messages: dict  # message name -> MessageChecks
    estimator: EstimatorConfig
    tolerated: dict = field(default_factory=dict)  # input DBC message no signal is taken from -> why a strict load refuses it

    def with_buses(self, input_bus: BusConfig | None = None, output_bus: BusConfig | None = None) -> "Config":
        return dataclasses.replace(self, input_bus=input_bus or self.input_bus, output_bus=output_bus or self.output_bus)
