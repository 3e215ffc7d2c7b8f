#!/usr/bin/env python3
"""Tire-force and friction accuracy on the simulator: the README's paper-style tables.

    python tools/forces_friction.py              # both tables, seed 0
    python tools/forces_friction.py --only forces --seeds 3

Forces (DICI-GFCKF paper Tables 1 and 3): ``dici-gfckf``, ``gfckf`` and ``ckf``
on the 7-state tire-force model; RMSE of yaw rate, sideslip and the four
lateral forces on the 80 km/h double lane change and a 65 km/h slalom, mu 0.85.

Friction (``jckf`` and ``dckf``): per wheel, the time from the start of
excitation (the first tick at which the true tire uses more than half its
friction) until the estimate is first within 0.1 of the truth, and the RMSE
from the excitation start on; on high (0.85) and low (0.35) friction, a
split-mu road (left 0.85, right 0.35), a straight acceleration ramp
(longitudinal excitation) on high and low friction, and a jump from 0.85 to
0.35 at 6 s into a 60 km/h sine (timed from the first excitation after the jump).
The simulator's plant is not the estimators' model (tire parameters, load
sensitivity, load-transfer lag, relaxation, combined slip all differ).
"""
import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from canest.apps.compare import with_filter  # noqa: E402
from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.pipeline import Pipeline  # noqa: E402
from canest.signals import WHEELS  # noqa: E402
from canest.sim.simulate import simulate  # noqa: E402

FORCE_FILTERS = ("dici-gfckf", "gfckf", "ckf")
FORCE_CASES = (("dlc", 80, 0.85), ("slalom", 65, 0.85))
FRICTION_FILTERS = ("jckf", "dckf")
FRICTION_CASES = (("sine", 80, 0.85, None), ("sine", 50, 0.35, None), ("step", 60, [0.85, 0.35, 0.85, 0.35], None),
                  ("launch", 40, 0.85, None), ("launch", 40, 0.35, None), ("sine", 60, 0.85, (6.0, 0.35)))
SKIP = 0.5  # s
EXCITED_USAGE = 0.5
CONVERGED = 0.1


def estimates(config, sim):
    pipeline = Pipeline(config)
    rows = [e for frame in sim.frames for e in pipeline.feed(frame)]
    t = np.array([e.t for e in rows])
    return t, {name: np.array([e.values[name] for e in rows]) for name in rows[-1].values}


def force_rmse(config, sim, name):
    tire_model = dataclasses.replace(config, estimator=dataclasses.replace(config.estimator, model="tire_force"))
    t, values = estimates(with_filter(tire_model, name), sim)
    keep = t >= SKIP
    out = {}
    for state in ("yaw_rate", "beta", *(f"fy_{w}" for w in WHEELS)):
        error = values[state][keep] - np.interp(t[keep], sim.truth["t"], sim.truth[state])
        out[state] = float(np.sqrt(np.mean(error**2))) * (180 / np.pi if state in ("yaw_rate", "beta") else 1.0)
    return out


def friction_scores(config, sim, name, since=0.0):
    """Per wheel (time to within 0.1, RMSE, final estimate), counted from the first excitation after ``since`` s."""
    t, values = estimates(with_filter(config, name), sim)
    truth = sim.truth
    out = {}
    for w in WHEELS:
        usage = np.hypot(truth[f"fx_{w}"], truth[f"fy_{w}"]) / (truth[f"mu_{w}"] * np.maximum(truth[f"fz_{w}"], 1.0))
        excited = np.flatnonzero((usage > EXCITED_USAGE) & (truth["t"] >= since))
        if excited.size == 0:
            out[w] = (np.nan, np.nan, values[f"mu_{w}"][-1])
            continue
        start = truth["t"][excited[0]]
        after = t >= start
        error = values[f"mu_{w}"][after] - np.interp(t[after], truth["t"], truth[f"mu_{w}"])
        inside = np.flatnonzero(np.abs(error) < CONVERGED)
        converge = t[after][inside[0]] - start if inside.size else np.inf
        out[w] = (converge, float(np.sqrt(np.mean(error**2))), values[f"mu_{w}"][-1])
    return out


def forces_table(config, seeds):
    print("Lateral forces (7-state tire-force model), RMSE, median over seeds")
    for maneuver, speed, mu in FORCE_CASES:
        print(f"\n{maneuver} {speed} km/h mu {mu}")
        print(f"{'state':10s}" + "".join(f"{name:>12s}" for name in FORCE_FILTERS))
        runs = {name: [] for name in FORCE_FILTERS}
        for seed in range(seeds):
            sim = simulate(config, maneuver, speed, mu, seed=seed)
            for name in FORCE_FILTERS:
                runs[name].append(force_rmse(config, sim, name))
        for state in runs[FORCE_FILTERS[0]][0]:
            unit = "deg/s" if state == "yaw_rate" else "deg" if state == "beta" else "N"
            cells = "".join(f"{np.median([r[state] for r in runs[name]]):12.3f}" for name in FORCE_FILTERS)
            print(f"{state + ' ' + unit:10s}{cells}")


def friction_table(config, seeds):
    print("\nFriction: time to within 0.1 after excitation starts (s), RMSE after it, final estimate (true)")
    for maneuver, speed, mu, jump in FRICTION_CASES:
        jump_text = f" jump to {jump[1]} at {jump[0]:g} s" if jump else ""
        for seed in range(seeds):
            sim = simulate(config, maneuver, speed, mu, seed=seed, mu_jump=jump)
            for name in FRICTION_FILTERS:
                scores = friction_scores(config, sim, name, since=jump[0] if jump else 0.0)
                cells = "  ".join(f"{w}: {c:5.2f} s {r:5.3f} -> {e:4.2f} ({sim.truth[f'mu_{w}'][-1]:.2f})"
                                  for w, (c, r, e) in scores.items())
                print(f"{maneuver} {speed} km/h mu {mu}{jump_text} seed {seed} {name}: {cells}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--config", default=str(DEFAULT_CONFIG), help="vehicle config (default: the built-in EV)")
    parser.add_argument("--seeds", type=int, default=1, help="sensor-noise seeds per case (default 1)")
    parser.add_argument("--only", choices=("forces", "friction"), help="one of the two tables")
    args = parser.parse_args()
    config = load_config(args.config)
    if args.only != "friction":
        forces_table(config, args.seeds)
    if args.only != "forces":
        friction_table(config, args.seeds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
