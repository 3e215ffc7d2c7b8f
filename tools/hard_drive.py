#!/usr/bin/env python3
"""The hard drive of issue 17: the nonlinear tire model without motor torques against the linear single track.

    python tools/hard_drive.py             # sine 90 deg at 80 km/h on mu 1.0, IMU vibration scale 1
    python tools/hard_drive.py --seed 2 --json

One simulated drive (canest.sim, ``vibration=1``: coloured body vibration and
road spikes on the IMUs) with ``configs/hard_drive.yaml``: the DICI-GFCKF EV
read like a car that sends no motor torques, so the tire-force model takes
its longitudinal forces from ax and the drive layout. The same frames are
replayed with that model and with the linear single-track model (same
filter, same noise); printed per model: frames rejected as implausible,
implausible samples, resets, and the RMSE of sideslip (every tick after the
first 0.5 s, and the valid ticks with their share), yaw rate and vx.
"""
import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from canest.apps.evaluate import score, table_of  # noqa: E402
from canest.config import load_config  # noqa: E402
from canest.pipeline import Pipeline  # noqa: E402
from canest.sim.simulate import simulate  # noqa: E402

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "hard_drive.yaml"
DRIVE = {"maneuver": "sine", "speed_kmh": 80.0, "mu": 1.0, "amplitude_deg": 90.0, "vibration": 1.0}
MODELS = ("tire_force", "single_track")
STATES = ("beta", "yaw_rate", "vx")
SKIP = 0.5  # s of filter convergence left out, as canest evaluate


def replay(config, model: str, sim) -> dict:
    """The drive's numbers for one model."""
    config = dataclasses.replace(config, estimator=dataclasses.replace(config.estimator, model=model))
    pipeline = Pipeline(config)
    estimates = [e for frame in sim.frames for e in pipeline.feed(frame)]
    summary = pipeline.summary()
    table = table_of(estimates)
    valid = {s.state: s for s in score(table, sim.truth, STATES, skip=SKIP)}
    every = {s.state: s for s in score(table, sim.truth, STATES, only_valid=False, skip=SKIP)}
    return {"rejected_implausible": summary.get("rejected_implausible", 0),
            "implausible_samples": summary.get("implausible_samples", 0), "resets": summary["resets"],
            "decoded": summary["decoded"], "frames": len(sim.frames),
            **{f"{s}_rmse": every[s].rmse for s in STATES},
            "beta_rmse_valid": valid["beta"].rmse, "beta_valid": valid["beta"].valid}


def hard_drive(seed: int = 1) -> dict:
    """Simulate the drive once and replay it with every model of :data:`MODELS`."""
    config = load_config(CONFIG)
    sim = simulate(config, DRIVE["maneuver"], DRIVE["speed_kmh"], DRIVE["mu"], amplitude_deg=DRIVE["amplitude_deg"],
                   seed=seed, vibration=DRIVE["vibration"])
    drive = {**DRIVE, "seed": seed, "max_ay": float(np.abs(sim.truth["ay"]).max()),
             "max_beta_deg": float(np.degrees(np.abs(sim.truth["beta"]).max()))}
    return {"drive": drive, **{model: replay(config, model, sim) for model in MODELS}}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=1, help="noise and vibration seed")
    parser.add_argument("--json", action="store_true", help="print the numbers as JSON")
    args = parser.parse_args()
    result = hard_drive(args.seed)
    if args.json:
        print(json.dumps(result))
        return
    d = result["drive"]
    print(f"{d['maneuver']} {d['amplitude_deg']:g} deg, {d['speed_kmh']:g} km/h, mu {d['mu']:g}, vibration "
          f"{d['vibration']:g}, seed {d['seed']}: max |ay| {d['max_ay']:.2f} m/s^2, max |sideslip| "
          f"{d['max_beta_deg']:.2f} deg ({CONFIG.name}, ckf)")
    print(f"{'model':<13} {'rejected':>8} {'implaus.':>8} {'resets':>6} | {'sideslip RMSE [deg]':>19} "
          f"{'valid ticks (share)':>20} | {'yaw rate [deg/s]':>16} {'vx [m/s]':>8}")
    for model in MODELS:
        r = result[model]
        print(f"{model:<13} {r['rejected_implausible']:>8} {r['implausible_samples']:>8} {r['resets']:>6} | "
              f"{r['beta_rmse']:>19.3f} {r['beta_rmse_valid']:>12.3f} ({r['beta_valid']:4.0%}) | "
              f"{r['yaw_rate_rmse']:>16.3f} {r['vx_rmse']:>8.3f}")


if __name__ == "__main__":
    main()
