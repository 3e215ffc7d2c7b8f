#!/usr/bin/env python3
"""Accuracy of the configured estimator over simulated maneuvers and sensor-noise seeds.

    python tools/accuracy.py                       # the README's table
    python tools/accuracy.py --config configs/dckf_1525kg.yaml --seeds 10

For each case: simulate (canest.sim), replay the frames through the same
pipeline the daemon runs, score against truth (valid ticks, first 0.5 s
skipped). Prints the median and the worst RMSE over the seeds.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.apps.evaluate import score, table_of  # noqa: E402
from canest.pipeline import Pipeline  # noqa: E402
from canest.sim.simulate import simulate  # noqa: E402

CASES = [("dlc", 80, 0.85), ("sine", 80, 0.85), ("slalom", 80, 0.85), ("step", 80, 0.85), ("dlc", 50, 0.35),
         ("sine", 50, 0.35)]
STATES = ("vx", "yaw_rate", "beta")


def run_case(config, maneuver, speed, mu, seed):
    sim = simulate(config, maneuver, speed, mu, seed=seed)
    pipeline = Pipeline(config)
    estimates = [e for frame in sim.frames for e in pipeline.feed(frame)]
    return {s.state: s.rmse for s in score(table_of(estimates), sim.truth, STATES, skip=0.5)}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default=str(DEFAULT_CONFIG))
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    config = load_config(args.config)
    print(f"{config.estimator.filter} on {config.vehicle.name}, {args.seeds} seeds; RMSE median (worst)")
    print(f"{'maneuver':<8} {'km/h':>5} {'mu':>5} | {'vx [m/s]':>15} | {'yaw rate [deg/s]':>17} | {'sideslip [deg]':>15}")
    for maneuver, speed, mu in CASES:
        runs = [run_case(config, maneuver, speed, mu, seed) for seed in range(args.seeds)]
        cells = []
        for state in STATES:
            values = np.array([r[state] for r in runs])
            cells.append(f"{np.median(values):7.3f} ({values.max():5.3f})")
        print(f"{maneuver:<8} {speed:>5} {mu:>5} | {cells[0]:>15} | {cells[1]:>17} | {cells[2]:>15}", flush=True)


if __name__ == "__main__":
    main()
