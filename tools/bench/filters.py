#!/usr/bin/env python3
"""Filter step cost: median and p99 microseconds per predict + update on the 3-DOF model.

    python tools/bench/filters.py                 # every filter, 2000 steps each
    python tools/bench/filters.py --steps 200     # the CI smoke run

Each filter runs the estimator's own Transition and Measurement (RK4 single-
track model, measurements ay, yaw rate, wheel speed, all three every step) on
inputs from a simulated sine steer. filterpy's UnscentedKalmanFilter runs the
same model functions (one point at a time, as its API requires) in the same
run as the reference; it is a benchmark-only dependency (pip install filterpy).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.filters import FILTERS, Measurement, Transition  # noqa: E402
from canest.models.single_track import SingleTrackModel  # noqa: E402


def inputs(steps):
    t = np.arange(steps) * 0.01
    delta = np.radians(3.0) * np.sin(2 * np.pi * t / 4.0)
    return [np.array([d, 0.1, 1.0]) for d in delta]


def timed(step, us):
    times = np.empty(len(us))
    for i, u in enumerate(us):
        start = time.perf_counter()
        step(u)
        times[i] = time.perf_counter() - start
    return np.median(times) * 1e6, np.percentile(times, 99) * 1e6


def bench_canest(name, model, us, x0, P0, Q, R, z):
    mask = np.ones(3, dtype=bool)
    transition = Transition(model.transition, model.transition_jacobian)
    measurement = Measurement(model.measure, model.measure_jacobian, (0, 1, 2), model.measure_parameter_jacobian)
    filt = FILTERS[name](x0, P0)

    def step(u):
        filt.predict(transition, u, 0.01, Q)
        filt.update(z, measurement, u, R)

    assert mask.all()
    return timed(step, us)


def bench_filterpy(model, us, x0, P0, Q, R, z):
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    holder = {}
    ukf = UnscentedKalmanFilter(dim_x=3, dim_z=3, dt=0.01,
                                fx=lambda x, dt: model.transition(x[None, :], holder["u"], dt)[0],
                                hx=lambda x: model.measure(x[None, :], holder["u"])[0],
                                points=MerweScaledSigmaPoints(3, alpha=1.0, beta=2.0, kappa=0.0))
    ukf.x, ukf.P, ukf.Q, ukf.R = x0.copy(), P0.copy(), Q, R

    def step(u):
        holder["u"] = u
        ukf.predict()
        ukf.update(z)

    return timed(step, us)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--filters", default="all")
    args = parser.parse_args()
    model = SingleTrackModel(load_config(DEFAULT_CONFIG).vehicle)
    us = inputs(args.steps)
    x0, P0 = np.array([0.0, 0.0, 22.0]), np.diag([0.05, 0.05, 2.0]) ** 2
    Q, R = np.diag([0.05, 0.01, 0.3]) ** 2 * 0.01, np.diag([0.15, 0.005, 0.15]) ** 2
    z = np.array([0.5, 0.02, 22.0])
    names = list(FILTERS) if args.filters == "all" else args.filters.split(",")
    rows = [(name, *bench_canest(name, model, us, x0, P0, Q, R, z)) for name in names]
    try:
        reference = bench_filterpy(model, us, x0, P0, Q, R, z)
    except ImportError:
        reference = None
    print(f"{'filter':<22} {'median us':>10} {'p99 us':>9} {'vs filterpy UKF':>16}")
    for name, median, p99 in rows:
        ratio = f"{median / reference[0]:.2f}x" if reference else "-"
        print(f"{name:<22} {median:>10.1f} {p99:>9.1f} {ratio:>16}")
    if reference:
        print(f"{'filterpy UKF':<22} {reference[0]:>10.1f} {reference[1]:>9.1f} {'1.00x':>16}")
    else:
        print("filterpy not installed: pip install filterpy for the reference row")


if __name__ == "__main__":
    main()
