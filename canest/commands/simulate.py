"""canest simulate: a simulated drive as a CAN log plus a truth CSV."""
from __future__ import annotations

import math
import sys

from tqdm import tqdm

from canest import limits
from canest.calibration import BOUNDS
from canest.config import DEFAULT_CONFIG
from canest.errors import UsageError
from canest.commands.common import FORMATTER, add_config, config_from_args
from canest.io.outputs import OutputFile, check_outputs, is_stdio
from canest.io.sinks import open_frame_writer
from canest.sim.maneuvers import MANEUVERS
from canest.sim.mismatch import PlantMismatch, grade_angle
from canest.sim.simulate import simulate

EPILOG = """examples:
  canest simulate --maneuver dlc --speed 80 --mu 0.85 --out drive.log --truth truth.csv
  canest simulate --maneuver sine --speed 80 --mu 0.35 --out sine.blf --truth sine.csv --outliers 0.02
  canest simulate --maneuver step --vibration 1 --out rough.log --truth rough.csv   # an IMU on a real car's body
  canest simulate --maneuver launch --crosswind 1 --out gusty.log --truth gusty.csv   # a gusty day's side wind
  canest simulate --maneuver step --mu 0.85,0.3,0.85,0.3 --out split.log --truth split.csv   # split mu: right side on ice
  canest simulate --maneuver sine --speed 60 --mu 0.85 --mu-jump 6:0.35 --out jump.log --truth jump.csv
  canest simulate --out - --truth truth.csv | canest replay - --csv est.csv    # candump text through a pipe
  canest simulate -m country --seed 3 --stiffness-scale 0.7,1.3 --steering-offset 1.5 --steering-ratio-scale 1.08 \
      --gyro-bias 0.5 --ay-bias 0.2 --wheel-radius-scale 1.03 --bank 3 -o wrong.log --truth wrong.csv

The car options (--stiffness-scale ... --pitch-gradient) make the simulated car differ
from the config, which then is wrong the way a real car's config is (what
`canest calibrate` corrects); the log is still encoded through the config.
The log is encoded through the config's input DBC and signal map, each message
at its DBC cycle time; its format follows the suffix (.log candump, .asc,
.blf, .trc, .csv, .mf4), candump text on standard output for --out -. The
truth CSV has the estimate CSV's columns (t, vx, vy, beta, yaw_rate; SI units,
rad) plus ax, ay, delta, and per wheel fx_, fy_, fz_, mu_, alpha_, kappa_, w_
(wheel speed, rad/s), torque_ (fl, fr, rl, rr). Both are written to a
temporary file and renamed when complete; an existing
file is replaced, an input (config, DBC) never."""


MIN_SPEED_KMH = 2.0  # the car starts at the target speed; the plant is valid from 0.5 m/s (1.8 km/h)
MAX_SPEED_KMH = 300.0
MAX_VIBRATION = 10.0  # times a real car's IMU vibration (canest.sim.sensors); at 10 ay's alone is 14 m/s^2, beyond any car
MAX_CROSSWIND = 5.0  # times a gusty day's side wind (canest.sim.wind): gusts of 10 m/s in RMS, a storm's
MAX_NOISE_SCALE = 10.0  # times the simulated sensors' noise and biases
MIN_DURATION = 0.1  # s: ten of the fastest message's cycles
# maneuver -> (what its --amplitude is, lowest, highest): a steering wheel's lock, a car's traction
AMPLITUDES = {"sine": ("steering wheel deg", -720.0, 720.0), "step": ("steering wheel deg", -720.0, 720.0),
              "launch": ("a peak acceleration in m/s^2", 0.0, 15.0)}


def check_scale(option: str, value: float, maximum: float, one: str) -> None:
    """Refuse a scale outside 0 to ``maximum`` (and nan), naming the option and what 1 means (``one``)."""
    if not 0.0 <= value <= maximum:
        raise UsageError(f"{option}: a scale from 0 to {maximum:g} (1: {one}), got {value}")


def register(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="simulate a maneuver into a CAN log and a truth CSV",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p)
    p.add_argument("--maneuver", "-m", choices=MANEUVERS, default="dlc",
                   help="dlc: ISO 3888-1 double lane change; slalom; sine: 4 s period steering; step; "
                        "launch: straight acceleration ramp with traction control; country: a minute of country "
                        "road drawn from --seed, bends both ways, straights, braking and accelerating at "
                        "50-100 km/h (default dlc)")
    p.add_argument("--speed", type=float, default=80.0,
                   help=f"target speed in km/h, {MIN_SPEED_KMH:g} to {MAX_SPEED_KMH:g} (default 80)")
    p.add_argument("--mu", default="0.85", help="road friction, one value or four (fl,fr,rl,rr) (default 0.85)")
    p.add_argument("--mu-jump", metavar="T:MU",
                   help="the friction changes to MU (one value or four) at T s, e.g. 6:0.35 (default: no change)")
    p.add_argument("--duration", type=float,
                   help=f"seconds to simulate, from {MIN_DURATION:g} (default: per maneuver)")
    p.add_argument("--amplitude", type=float,
                   help="steering wheel amplitude in deg for sine/step (default 60/45, -720 to 720); peak "
                        "acceleration demand in m/s^2 for launch (default 6, 0 to 15); the others follow their own "
                        "path")
    p.add_argument("--noise-scale", type=float, default=1.0,
                   help=f"multiply every sensor noise and bias, 0 to {MAX_NOISE_SCALE:g} (default 1)")
    p.add_argument("--outliers", type=float, default=0.0,
                   help="probability per sample of a heavy-tailed (Student-t) outlier (default 0)")
    p.add_argument("--vibration", type=float, default=0.0, metavar="SCALE",
                   help="the IMU's body vibration (coloured noise) and road spikes, as a real car's at 1: about one "
                        f"10 ms step of ay in six beyond 2 m/s^2; 0 to {MAX_VIBRATION:g} (default 0: none)")
    p.add_argument("--crosswind", type=float, default=0.0, metavar="SCALE",
                   help="gusts of side wind, a gusty day's at 1: 2 m/s of lateral wind in RMS, correlated over 2 s, "
                        f"180 N of side force at 80 km/h that no estimator's model has; 0 to {MAX_CROSSWIND:g} "
                        "(default 0: calm)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--start-time", type=float, default=0.0, help="timestamp of the first frame in s (default 0)")
    car = p.add_argument_group("the simulated car, where it differs from the config")
    car.add_argument("--stiffness-scale", default="1,1", metavar="FRONT,REAR",
                     help="the tires' cornering stiffness, times the plant's own, front and rear (default 1,1)")
    car.add_argument("--steering-ratio-scale", type=float, default=1.0,
                     help="true steering ratio / config's (default 1)")
    car.add_argument("--wheel-radius-scale", type=float, default=1.0,
                     help="true effective wheel radius / config's (default 1)")
    car.add_argument("--steering-offset", type=float, metavar="DEG",
                     help="steering wheel angle sensor bias in deg (measured = true + offset; default the sensor's)")
    car.add_argument("--gyro-bias", type=float, metavar="DEG/S", help="yaw rate sensor bias in deg/s (default 0.05)")
    car.add_argument("--gyro-bias-2", type=float, metavar="DEG/S",
                     help="the second (airbag unit's) yaw rate sensor's bias in deg/s (default -0.1)")
    car.add_argument("--ay-bias", type=float, metavar="M/S2",
                     help="lateral accelerometer bias in m/s^2 (default -0.03)")
    car.add_argument("--bank", type=float, default=0.0, metavar="DEG",
                     help="road bank in deg, positive when the road falls to the left (default 0)")
    car.add_argument("--grade", type=float, default=0.0, metavar="PCT",
                     help="road grade in %% (rise per 100 m run), positive uphill (default 0; a motorway's steepest "
                          "is 4-6, a mountain road's 10-15)")
    car.add_argument("--roll-gradient", type=float, metavar="DEG/G",
                     help="body roll per g of lateral acceleration, read by the accelerometers fixed to the body "
                          "(a passenger car: 3-6; 0: the ESC publishes ay level; default the config's "
                          "accelerometer_roll_gradient)")
    car.add_argument("--pitch-gradient", type=float, metavar="DEG/G",
                     help="nose-up pitch per g of longitudinal acceleration, as --roll-gradient (a passenger "
                          "car: 1-3; default the config's accelerometer_pitch_gradient)")
    p.add_argument("--out", "-o", required=True, help="CAN log to write (- for candump text on standard output)")
    p.add_argument("--truth", required=True, help="truth CSV to write")
    p.set_defaults(func=run)


def parse_mu(text: str, option: str = "--mu"):
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise UsageError(f"{option}: expected a number or four comma-separated numbers, got '{text}'") from None
    if len(values) not in (1, 4) or not all(0.05 <= v <= 1.5 for v in values):
        raise UsageError(f"{option}: expected one or four values in [0.05, 1.5], got '{text}'")
    return values[0] if len(values) == 1 else values


def parse_mu_jump(text):
    """``T:MU`` -> (T, mu), T a number of seconds from 0 (:func:`canest.sim.simulate.simulate` checks it falls
    within the drive); None stays None."""
    if text is None:
        return None
    when, _, mu = text.partition(":")
    try:
        jump_time = float(when)
    except ValueError:
        raise UsageError(f"--mu-jump: expected T:MU with T in seconds, e.g. 6:0.35, got '{text}'") from None
    if not mu or not 0.0 <= jump_time < math.inf:  # also refuses nan
        raise UsageError(f"--mu-jump: expected T:MU with T >= 0 s, e.g. 6:0.35, got '{text}'")
    return jump_time, parse_mu(mu, "--mu-jump")


SCALE_RANGE = (0.3, 3.0)  # a car's stiffness, ratio or radius off by more is another car
MAX_BANK_DEG = 15.0
MAX_GRADE_PCT = 30.0  # steeper is a ramp, not a road
# sensor bias options: (unit, largest magnitude in that unit): what a calibration may find (canest.calibration)
SENSOR_BIASES = {"--steering-offset": ("deg", math.degrees(BOUNDS["steering_offset"][1])),
                 "--gyro-bias": ("deg/s", math.degrees(BOUNDS["gyro_bias"][1])),
                 "--gyro-bias-2": ("deg/s", math.degrees(BOUNDS["gyro_bias"][1])),
                 "--ay-bias": ("m/s^2", BOUNDS["ay_bias"][1])}


def parse_mismatch(args) -> PlantMismatch:
    """The car options as a :class:`PlantMismatch`, each within a range a car can be off by."""
    try:
        scales = [float(v) for v in args.stiffness_scale.split(",")]
    except ValueError:
        scales = []
    low, high = SCALE_RANGE
    if len(scales) != 2:
        raise UsageError(f"--stiffness-scale: expected FRONT,REAR (two numbers), got '{args.stiffness_scale}'")
    for option, values in (("--stiffness-scale", scales), ("--steering-ratio-scale", [args.steering_ratio_scale]),
                           ("--wheel-radius-scale", [args.wheel_radius_scale])):
        if not all(low <= v <= high for v in values):  # also refuses nan
            raise UsageError(f"{option}: a factor from {low:g} to {high:g}, got {', '.join(map(str, values))}")
    for option, (unit, largest) in SENSOR_BIASES.items():
        value = getattr(args, option[2:].replace("-", "_"))
        if value is not None and not abs(value) <= largest:  # also refuses nan
            raise UsageError(f"{option}: {unit} from -{largest:g} to {largest:g}, got {value}")
    if not abs(args.bank) <= MAX_BANK_DEG:
        raise UsageError(f"--bank: degrees from -{MAX_BANK_DEG:g} to {MAX_BANK_DEG:g}, got {args.bank}")
    if not abs(args.grade) <= MAX_GRADE_PCT:
        raise UsageError(f"--grade: percent from -{MAX_GRADE_PCT:g} to {MAX_GRADE_PCT:g}, got {args.grade}")
    for axis in ("roll", "pitch"):
        value = getattr(args, f"{axis}_gradient")
        problem = None if value is None else limits.ATTITUDE[f"accelerometer_{axis}_gradient"].violation(value)
        if problem:
            raise UsageError(f"--{axis}-gradient: {problem}, got {value}")
    radians = lambda value: None if value is None else math.radians(value)  # noqa: E731
    return PlantMismatch(scales[0], scales[1], args.steering_ratio_scale, args.wheel_radius_scale,
                         radians(args.steering_offset), radians(args.gyro_bias), args.ay_bias, math.radians(args.bank),
                         args.roll_gradient, args.pitch_gradient, grade_angle(args.grade), radians(args.gyro_bias_2))


def check_speed_and_seed(speed: float, seed: int) -> None:
    """``--speed`` (km/h) within what the plant drives, ``--seed`` one numpy takes (simulate, demo)."""
    if not MIN_SPEED_KMH <= speed <= MAX_SPEED_KMH:  # also refuses nan
        raise UsageError(f"--speed: a target speed from {MIN_SPEED_KMH:g} to {MAX_SPEED_KMH:g} km/h, got {speed}")
    if not 0 <= seed < 2**32:
        raise UsageError(f"--seed: an integer from 0 to {2**32 - 1}, got {seed}")


def check_drive_options(args) -> None:
    """The drive's numbers, each within what the plant and the encoder take (nan refused everywhere)."""
    if not 0.0 <= args.outliers < 1.0:
        raise UsageError(f"--outliers: a probability per sample in [0, 1), got {args.outliers}")
    check_scale("--vibration", args.vibration, MAX_VIBRATION, "a real car's")
    check_scale("--crosswind", args.crosswind, MAX_CROSSWIND, "a gusty day's")
    check_scale("--noise-scale", args.noise_scale, MAX_NOISE_SCALE, "series-production sensors'")
    check_speed_and_seed(args.speed, args.seed)
    if args.duration is not None and not MIN_DURATION <= args.duration < math.inf:
        raise UsageError(f"--duration: seconds from {MIN_DURATION:g}, got {args.duration}")
    if not 0.0 <= args.start_time < math.inf:
        raise UsageError(f"--start-time: seconds from 0 (a log's clock; e.g. 1712345678.0), got {args.start_time}")
    if args.amplitude is not None:
        if args.maneuver not in AMPLITUDES:
            raise UsageError(f"--amplitude: {args.maneuver} follows its own path; only {', '.join(AMPLITUDES)} "
                             "take an amplitude")
        unit, low, high = AMPLITUDES[args.maneuver]
        if not low <= args.amplitude <= high:
            raise UsageError(f"--amplitude: {args.maneuver} takes {unit} from {low:g} to {high:g}, got {args.amplitude}")


def run(args) -> int:
    config = config_from_args(args)
    mu = parse_mu(args.mu)
    mismatch = parse_mismatch(args)
    check_drive_options(args)
    mu_jump = parse_mu_jump(args.mu_jump)
    if is_stdio(args.truth):
        raise UsageError("--truth -: the truth CSV goes to a file; only --out may be - (standard output)")
    check_outputs({"--out": args.out, "--truth": args.truth},
                  {"the config": args.config or DEFAULT_CONFIG, "the input DBC": config.input_dbc,
                   "the output DBC": config.output_dbc})
    outputs = []  # staged: created now (a folder that cannot take them fails before the simulation), renamed at the end
    try:
        for path in (args.out, args.truth):
            outputs.append(OutputFile(path))
        with tqdm(total=100, desc=f"simulate {args.maneuver}", unit="%", leave=False,
                  disable=not sys.stderr.isatty()) as bar:
            result = simulate(config, args.maneuver, args.speed, mu, duration=args.duration,
                              amplitude_deg=args.amplitude, seed=args.seed, noise_scale=args.noise_scale,
                              outliers=args.outliers, start_time=args.start_time, channel=config.input_bus.channel,
                              progress=lambda f: bar.update(round(100 * f) - bar.n), mu_jump=mu_jump,
                              mismatch=mismatch, vibration=args.vibration, crosswind=args.crosswind)
        for output, write in zip(outputs, (write_log, write_truth)):
            try:
                write(result, output)
            except OSError as exc:
                raise output.error(exc) from None
        for output in outputs:
            output.commit()
    finally:
        for output in outputs:
            output.discard()
    duration = result.truth["t"][-1] - result.truth["t"][0]
    report = sys.stderr if is_stdio(args.out) or is_stdio(args.truth) else sys.stdout
    print(f"wrote {len(result.frames)} frames ({duration:.1f} s) to {args.out} and truth to {args.truth}", file=report)
    return 0


def write_log(result, output: OutputFile) -> None:
    """The drive's frames into ``output`` (by suffix, or candump text on standard output)."""
    with open_frame_writer(output) as writer:
        for frame in result.frames:
            writer.on_message_received(frame)


def write_truth(result, output: OutputFile) -> None:
    result.write_truth(output.write_path)
