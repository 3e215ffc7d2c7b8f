"""canest check: validate a config and its DBCs, and show the resolved signal map."""
from __future__ import annotations

import json

from canest.commands.common import FORMATTER, add_config, config_from_args
from canest.config import DEFAULT_CONFIG
from canest.errors import CanestError
from canest.codec.decode import InputDecoder
from canest.codec.encode import CALIBRATION_MESSAGE, EstimateEncoder
from canest.codec.raw_range import raw_range_warnings
from canest.codec.reach import input_shortfalls, output_shortfalls
from canest.estimation.catalog import losses
from canest.filters import factorization_of
from canest.signals import si_unit

EPILOG = """examples:
  canest check                                   # the built-in config
  canest check --config configs/ford_fusion_2017.yaml
  canest check --config my_car.yaml --json | jq .range_warnings

Every error names the file, the line and the key, message or signal.
Inputs the config does not map are listed with what each costs: the models
and filters of the catalog that need it, and the states not estimated then.
An output DBC without CE_Calibration still works: the online calibration
is learned and applied but not sent (one note says so). Signals whose range
stops short of what cars reach are warned about, and so
is each signal whose DBC range is in raw counts ([0|65535] for signed values)
where the config gives no range.
--json prints one object: config, vehicle, input, output, filter (name,
model, factorization: cholesky, svd or null for the EKFs, rate_hz,
min_speed, online_calibration), signals (canonical, message, signals, frame_id, cycle_time,
cycle_time_from, timeout, unit, factor, offset, overrides), integrity,
tolerated, missing_inputs, range_warnings, raw_range_warnings,
calibration_sent (the output DBC carries CE_Calibration and the learner is on), calibration_not_sent (the learned
parameters its CE_Calibration has no page for), ok (true). A config that is not
usable prints {config, ok: false, error} (the error also on stderr).
Exit status 0 when the config is usable, 2 when it is not."""


def register(subparsers) -> None:
    p = subparsers.add_parser("check", help="validate config and DBCs, print the resolved signal map",
                              description=__doc__, epilog=EPILOG, formatter_class=FORMATTER)
    add_config(p)
    p.add_argument("--json", action="store_true", help="print the findings as one JSON object (keys below)")
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


def _report(config, decoder, encoder) -> dict:
    """Everything ``check`` found, as ``--json`` prints it (stable keys, SI units)."""
    timeouts = decoder.timeouts(config.estimator.timeout_cycles)
    v, e = config.vehicle, config.estimator
    signals = []
    for plan in decoder.plans.values():
        seconds, source = plan.cycle_time()
        for spec in plan.specs:
            signals.append({"canonical": spec.canonical, "message": spec.message, "signals": list(spec.names),
                            "frame_id": plan.message.frame_id, "cycle_time": seconds, "cycle_time_from": source,
                            "timeout": timeouts[spec.canonical], "unit": si_unit(spec.canonical),
                            "factor": spec.factor, "offset": spec.offset, "overrides": _overrides(spec).strip(" ()")})
    return {
        "config": str(config.path),
        "vehicle": {"name": v.name, "mass": v.mass, "yaw_inertia": v.yaw_inertia, "cg_to_front": v.cg_to_front,
                    "cg_to_rear": v.cg_to_rear, "steering_ratio": v.steering_ratio},
        "input": {"dbc": str(config.input_dbc), "bus": _bus(config.input_bus)},
        "output": {"dbc": str(config.output_dbc), "bus": _bus(config.output_bus)},
        "filter": {"name": e.filter, "model": e.model, "factorization": factorization_of(e.filter, e.factorization),
                   "rate_hz": e.rate_hz, "min_speed": e.min_speed, "online_calibration": e.online_calibration},
        "signals": signals,
        "integrity": {name: _checks(c) for name, c in config.messages.items()},
        "tolerated": dict(config.tolerated),
        "missing_inputs": losses(config.signals),
        "range_warnings": input_shortfalls(config.signals) + output_shortfalls(encoder.database),
        "raw_range_warnings": raw_range_warnings(config.signals, decoder.database),
        "calibration_sent": encoder.has_calibration and e.online_calibration,
        "calibration_not_sent": encoder.calibration_missing,
        "ok": True,
    }


def _print(report: dict) -> None:
    v, f = report["vehicle"], report["filter"]
    print(f"config   {report['config']}")
    print(f"vehicle  {v['name']}: m={v['mass']:g} kg, Iz={v['yaw_inertia']:g} kg m^2, a={v['cg_to_front']:g} m, "
          f"b={v['cg_to_rear']:g} m, steering ratio {v['steering_ratio']:g}")
    print(f"input    {report['input']['dbc']} on {report['input']['bus']}")
    print(f"output   {report['output']['dbc']} on {report['output']['bus']}")
    root = f"{f['factorization']} square root of P" if f["factorization"] else "no square root, P propagated"
    print(f"filter   {f['name']} ({root}) on model {f['model']} at {f['rate_hz']:g} Hz, low-speed below "
          f"{f['min_speed']:g} m/s")
    print()
    print(f"{'canonical':<22} {'message.signal':<40} {'id':>6} {'cycle (from)':>14} {'timeout':>8}  "
          "SI = factor * DBC value + offset")
    for row in report["signals"]:
        overrides = f"  ({row['overrides']})" if row["overrides"] else ""
        where = " + ".join(f"{row['message']}.{name}" for name in row["signals"])
        cycle = f"{row['cycle_time'] * 1000:g}ms ({row['cycle_time_from']})"
        print(f"{row['canonical']:<22} {where:<40} {row['frame_id']:>#6x} {cycle:>14} {row['timeout']:>7.3f}s  "
              f"{row['unit']} = {row['factor']:.6g} * value + {row['offset']:g}{overrides}")
    checked = [f"{name} ({', '.join(checks)})" for name, checks in report["integrity"].items()]
    if checked:
        print("\nintegrity checks: " + "; ".join(checked))
    if any(row["cycle_time_from"] == "default" for row in report["signals"]):
        print("\ncycle (default): the DBC gives no GenMsgCycleTime; replay and run measure the cycle from the first "
              "frames and the timeouts follow it (input.messages.<message>.cycle_time fixes it)")
    for message, problem in report["tolerated"].items():
        print(f"tolerated in the input DBC ({f'no signal is taken from {message}' if message else 'lenient load'}): "
              f"{problem}")
    for title, lines in (("inputs not mapped, and what they cost:", report["missing_inputs"]),
                         ("warning: signal ranges short of what cars reach:", report["range_warnings"]),
                         ("warning: DBC ranges in raw counts, frames outside rejected:", report["raw_range_warnings"])):
        if lines:
            print(f"\n{title}")
            print("\n".join(f"  {line}" for line in lines))
    if not report["calibration_sent"] and report["filter"]["online_calibration"]:
        print(f"\nnote: {report['output']['dbc']} has no {CALIBRATION_MESSAGE} message: the online calibration is "
              "learned and applied but not sent (add the message from dbc/canest_estimates.dbc)")
    elif report["calibration_not_sent"] and report["filter"]["online_calibration"]:
        print(f"\nnote: {report['output']['dbc']}'s {CALIBRATION_MESSAGE} has no page for "
              f"{', '.join(report['calibration_not_sent'])} (a DBC of an older canest): learned and applied but not "
              "sent (add their signals from dbc/canest_estimates.dbc)")
    print("\nOK")


def run(args) -> int:
    try:
        config = config_from_args(args)
        report = _report(config, InputDecoder(config), EstimateEncoder(config.output_dbc))
    except CanestError as exc:
        if args.json:  # a script reading stdout learns it too, not only the one line on stderr
            print(json.dumps({"config": str(args.config or DEFAULT_CONFIG), "ok": False, "error": str(exc)}))
        raise
    if args.json:
        print(json.dumps(report))
    else:
        _print(report)
    return 0
