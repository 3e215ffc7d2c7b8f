"""canest calibrate: fit the car's stiffnesses, steering, wheel radius and sensor biases to logged drives."""
from __future__ import annotations

import math
import sys
from pathlib import Path

from tqdm import tqdm

from canest.models.output_error import calibrate, optimizer
from canest.apps.calibrated_config import bank_lines, check_new, write_calibrated
from canest.apps.drive_signals import check_signals, read_drive
from canest.commands.common import (FORMATTER, add_config, add_log_reading, config_from_args, log_reading,
                                    warnings_to_stderr)
from canest.config import DEFAULT_CONFIG
from canest.errors import LogError
from canest.estimation.learned_parameters import parameters
from canest.io.logfiles import expand_logs
from canest.io.outputs import check_outputs

EPILOG = """examples:
  canest calibrate drive1.log drive2.log drive3.log --config my_car.yaml --out my_car.calibrated.yaml
  canest calibrate 'logs/*.blf' --config my_car.yaml          # print the fit only

Fits the linear single-track model to every log at once (output error, scipy
least squares): each axle's cornering stiffness, the steering ratio and the
steering angle sensor's offset, the gyro and lateral accelerometer biases, the
effective wheel radius, and each log's road bank; where the logs have a second
gyro (yaw_rate_2), its bias too. Each value is printed with
its 95 % confidence interval; the stiffnesses' also hold the linear tires' own
error (5 %, 1 std), the steering ratio's 2 %, which no amount of driving
averages away. A constant bank cannot be told from an ay bias: the logs' mean
bank is taken as 0 (drive a road both ways, or flat roads; one log: its bank
is 0). Best data: a few minutes of country road at 50-100 km/h,
bends of both directions, straights, braking and accelerating, below 4 m/s^2
of lateral acceleration. --out writes the config with the calibrated values,
each commented (never over an existing file); `canest check --config` loads it.
A parameter the logs do not pin down is marked: "at its bound" (the fit ran to
the edge of its physical range) or "no better known than before driving" (its
std no narrower than the prior the online calibration starts from); a straight
drive leaves the stiffnesses and the steering so. --out then writes nothing
and says which (exit 65)."""

UNITS = {  # parameter -> (config key or label, unit, factor from the fit's value)
    "front": ("cornering_stiffness_front", "N/rad"), "rear": ("cornering_stiffness_rear", "N/rad"),
    "ratio": ("steering_ratio", "-"), "speed": ("wheel_radius", "m"),
    "steering_offset": ("steering offset", "deg"), "gyro_bias": ("gyro bias", "deg/s"), "ay_bias": ("ay bias", "m/s^2"),
    "gyro_bias_2": ("second gyro bias", "deg/s"),
}


def register(subparsers) -> None:
    p = subparsers.add_parser("calibrate",
                              help="fit stiffnesses, steering, wheel radius and sensor biases to logged drives",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    p.add_argument("logs", nargs="+", metavar="LOG",
                   help="logged drives (any format replay reads), or quoted glob patterns of them ('**' recurses)")
    add_config(p)
    add_log_reading(p)
    p.add_argument("--out", "-o", help="write the config with the calibrated values to this new file")
    p.set_defaults(func=run)


def parameter_rows(config, fit) -> list:
    """(name, label, config value, calibrated value, 95 % half-width, unit) of each shared parameter, and of the
    second gyro's bias where the logs have one."""
    v = config.vehicle
    bases = {"front": v.cornering_stiffness_front, "rear": v.cornering_stiffness_rear, "ratio": v.steering_ratio,
             "speed": v.wheel_radius}
    rows = []
    for name in (n for n in fit.names if n in UNITS):  # the banks are reported apart
        label, unit = UNITS[name]
        value, half = fit.value(name), fit.half_width(name)
        if name in bases:
            base = bases[name]
            rows.append((name, label, base, base * value, base * half, unit))
        else:
            factor = 1.0 if unit == "m/s^2" else math.degrees(1.0)
            rows.append((name, label, 0.0, value * factor, half * factor, unit))
    return rows


def format_fit(config, fit, logs: list) -> list:
    """The report's lines: what was fitted over how much driving, each value with its interval, the banks."""
    lines = [f"calibrated {config.vehicle.name} over {len(logs)} log(s), {fit.seconds:.0f} s of driving; residual "
             f"RMS yaw rate {math.degrees(fit.rms['yaw_rate']):.3f} deg/s, ay {fit.rms['ay']:.3f} m/s^2",
             f"  {'parameter':<28} {'config':>12} {'calibrated':>12} {'95 % CI':>12}  unit"]
    undetermined = undetermined_parameters(config, fit)
    for name, label, base, value, half, unit in parameter_rows(config, fit):
        note = f"  (not pinned down: {undetermined[name]})" if name in undetermined else ""
        lines.append(f"  {label:<28} {base:>12.6g} {value:>12.6g} {'+-' + format(half, '.3g'):>12}  {unit}{note}")
    lines += bank_lines(fit, logs)
    lines.append("  (the logs' mean bank is held at 0: a constant bank cannot be told from an ay bias)")
    return lines


def undetermined_parameters(config, fit) -> dict:
    """name -> why the logs do not pin it down (:meth:`canest.calibration.Fit.undetermined`), against the prior the
    online calibration starts from for this config."""
    return fit.undetermined({p.name: p.std for p in parameters(config.vehicle, config.estimator.gyro_bias_std)})


def refuse_undetermined(config, fit, logs: list, out) -> None:
    """A LogError (65) naming the parameters the logs do not pin down: a config holding them would take a guess
    for a measurement."""
    undetermined = undetermined_parameters(config, fit)
    if undetermined:
        named = [f"{label} ({undetermined[name]})" for name, label, *_ in parameter_rows(config, fit)
                 if name in undetermined]
        raise LogError(f"{', '.join(map(str, logs))}: {out} not written: the drive does not pin down "
                       f"{', '.join(named)}; calibrate over driving with bends of both directions, straights, "
                       "braking and accelerating (see --help)")


def run(args) -> int:
    optimizer()  # missing scipy is said before the logs are read, not after
    warnings_to_stderr()  # a damaged log's warnings as replay gives them
    args.logs = expand_logs(args.logs)
    config = config_from_args(args)
    check_signals(config)
    if args.out:
        check_outputs({"--out": args.out}, {"the config": args.config or DEFAULT_CONFIG,
                                            "the input DBC": config.input_dbc, "the output DBC": config.output_dbc,
                                            **{f"log {i + 1}": log for i, log in enumerate(args.logs)}})
        check_new(args.out)
    show = sys.stderr.isatty()
    drives = []
    for log in tqdm(args.logs, desc="read logs", unit="log", disable=not show, leave=False):
        drives.append(read_drive(config, log, **log_reading(args)))
    with tqdm(desc="fit", unit=" evaluations", disable=not show, leave=False) as bar:
        fit = calibrate(config.vehicle, drives, progress=lambda n: bar.update(n - bar.n)).with_model_error()
    lines = format_fit(config, fit, args.logs)
    print("\n".join(lines))
    if args.out:
        refuse_undetermined(config, fit, args.logs, args.out)
        header = [f"canest calibrate of {Path(config.path).name} over {', '.join(map(str, args.logs))}", *lines]
        write_calibrated(config, fit, args.out, header)
        print(f"wrote the calibrated config to {args.out}")
    return 0
