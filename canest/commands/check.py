"""canest check: validate a config and its DBCs, and show the resolved signal map."""
from __future__ import annotations

from canest.commands.common import FORMATTER, add_config, config_from_args
from canest.codec.decode import InputDecoder
from canest.codec.encode import EstimateEncoder
from canest.codec.reach import input_shortfalls, output_shortfalls
from canest.estimation.catalog import losses
from canest.signals import si_unit

EPILOG = """Every error names the file, the line and the key, message or signal.
Inputs the config does not map are listed with what each costs: the models
and filters of the catalog that need it, and the states not estimated then.
Exit status 0 when the config is usable, 2 when it is not."""


def register(subparsers) -> None:
    p = subparsers.add_parser("check", help="validate config and DBCs, print the resolved signal map",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p)
    p.set_defaults(func=run)


def _bus(bus) -> str:
    """``interface:channel`` and the python-can options the bus is opened with."""
    options = ", ".join(f"{key}={value!r}" for key, value in bus.options.items())
    return f"{bus.interface}:{bus.channel}" + (f" ({options})" if options else "")


def _overrides(spec) -> str:
    """What the signal map adds to the DBC: range, validity, stuck detection, learned zero."""
    notes = []
    if spec.range != (None, None):
        notes.append(f"range [{spec.range[0]}, {spec.range[1]}]")
    if spec.valid:
        notes.append(f"valid when {spec.valid.signal}" + (f" in {list(spec.valid.values)}" if spec.valid.values else " != 0"))
    if spec.stuck_after:
        notes.append(f"stuck after {spec.stuck_after:g} s")
    if spec.learn_zero:
        notes.append("zero learned")
    return f"  ({'; '.join(notes)})" if notes else ""


def _checks(checks) -> list:
    """What is checked on a message: ``counter``, ``checksum`` (with its algorithm unless canest's), ``fd=...``."""
    out = []
    for key, value in vars(checks).items():
        if not value or value == "dbc" or key in ("checksum_algorithm", "crc"):
            continue
        if key == "checksum" and checks.checksum_algorithm != "canest":
            out.append(f"checksum={checks.checksum_algorithm}")
        else:
            out.append(f"{key}={value}" if key in ("fd", "cycle_time") else key)
    return out


def run(args) -> int:
    config = config_from_args(args)
    decoder = InputDecoder(config)
    encoder = EstimateEncoder(config.output_dbc)
    timeouts = decoder.timeouts(config.estimator.timeout_cycles)
    v = config.vehicle
    print(f"config   {config.path}")
    print(f"vehicle  {v.name}: m={v.mass:g} kg, Iz={v.yaw_inertia:g} kg m^2, a={v.cg_to_front:g} m, "
          f"b={v.cg_to_rear:g} m, steering ratio {v.steering_ratio:g}")
    print(f"input    {config.input_dbc} on {_bus(config.input_bus)}")
    print(f"output   {config.output_dbc} on {_bus(config.output_bus)}")
    e = config.estimator
    print(f"filter   {e.filter} ({e.factorization}) at {e.rate_hz:g} Hz, low-speed below {e.min_speed:g} m/s")
    print()
    print(f"{'canonical':<22} {'message.signal':<40} {'id':>6} {'cycle (from)':>14} {'timeout':>8}  "
          "SI = factor * DBC value + offset")
    for plan in decoder.plans.values():
        seconds, source = plan.cycle_time()
        for spec in plan.specs:
            print(f"{spec.canonical:<22} {' + '.join(f'{spec.message}.{n}' for n in spec.names):<40} "
                  f"{plan.message.frame_id:>#6x} {f'{seconds * 1000:g}ms ({source})':>14} "
                  f"{timeouts[spec.canonical]:>7.3f}s  {si_unit(spec.canonical)} = "
                  f"{spec.factor:.6g} * value + {spec.offset:g}{_overrides(spec)}")
    checked = [f"{name} ({', '.join(_checks(c))})" for name, c in config.messages.items()]
    if checked:
        print("\nintegrity checks: " + "; ".join(checked))
    for message, problem in config.tolerated.items():
        print(f"tolerated in the input DBC ({f'no signal is taken from {message}' if message else 'lenient load'}): "
              f"{problem}")
    missing = losses(config.signals)
    if missing:
        print("\ninputs not mapped, and what they cost:")
        print("\n".join(f"  {line}" for line in missing))
    shortfalls = input_shortfalls(config.signals) + output_shortfalls(encoder.database)
    if shortfalls:
        print("\nwarning: signal ranges short of what cars reach:")
        print("\n".join(f"  {line}" for line in shortfalls))
    print("\nOK")
    return 0
