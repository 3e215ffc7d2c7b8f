#!/usr/bin/env python3
"""Filter step cost: median and p99 microseconds per predict + update, per model.

    python tools/bench/filters.py                 # every filter on every model, 2000 steps each
    python tools/bench/filters.py --steps 200     # the CI smoke run

Each filter runs the estimator's own Transition and Measurement on inputs of a
sine steer, every measurement every step:

* 3-DOF single track (RK4; ay, yaw rate, wheel speed, second gyro): every filter but the
  parameter filters jckf and dckf;
* 7-state tire-force model (RK4; ax, ay, yaw rate, wheel speed): the
  sigma-point filters (the EKF family needs Jacobians this model does not
  have); ``dici-gfckf`` updates its two local filters with one IMU each
  (ax, ay, yaw rate of IMU 1 or 2, plus the wheel speed);
* 7-DOF two-track model with friction (11 states; ax, ay, yaw rate, yaw
  acceleration, reference speed, four wheel speeds, second gyro): ``jckf`` and ``dckf``.

filterpy's UnscentedKalmanFilter runs the same model functions (one point at a
time, as its API requires) in the same run as the reference; it is a
benchmark-only dependency (pip install filterpy).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.filters import FILTERS, Measurement, Transition, make_filter  # noqa: E402
from canest.models.single_track import SingleTrackModel  # noqa: E402
from canest.models.tire_force import TireForceModel  # noqa: E402
from canest.models.two_track import TwoTrackModel  # noqa: E402

LINEARIZING = ("ekf", "dekf", "lmrwekf")


PARAMETER_FILTERS = ("jckf", "dckf")  # they estimate the last states as parameters: the two-track case only


def steering(steps):
    t = np.arange(steps) * 0.01
    return np.radians(3.0) * np.sin(2 * np.pi * t / 4.0)


def single_track_case(vehicle, steps):
    model = SingleTrackModel(vehicle)
    us = [np.array([d, 0.1, 1.0]) for d in steering(steps)]
    x0, P0 = np.array([0.0, 0.0, 22.0]), np.diag([0.05, 0.05, 2.0]) ** 2
    Q, R = np.diag([0.05, 0.01, 0.3]) ** 2 * 0.01, np.diag([0.15, 0.005, 0.15, 0.01]) ** 2  # ay, gyro, wheels, gyro 2
    names = [n for n in FILTERS if n not in PARAMETER_FILTERS]
    return model, us, x0, P0, Q, R, np.array([0.5, 0.02, 22.0, 0.02]), names, slice(0, 4)


def tire_force_case(vehicle, steps):
    model = TireForceModel(vehicle)
    us = [np.array([d, 0.1, 22.0 * d * 5.0, 0.0, 30.0, 30.0, 30.0, 30.0]) for d in steering(steps)]
    x0, P0 = np.array([0.0, 0.0, 22.0, 0.0, 0.0, 0.0, 0.0]), np.diag([0.05, 0.05, 2.0, 1e3, 1e3, 1e3, 1e3]) ** 2
    Q = np.diag([0.05, 0.01, 0.3, 3e3, 3e3, 3e3, 3e3]) ** 2 * 0.01
    R = np.diag([0.15, 0.15, 0.005, 0.15]) ** 2
    names = [n for n in FILTERS if n not in LINEARIZING + PARAMETER_FILTERS]
    return model, us, x0, P0, Q, R, np.array([0.1, 0.5, 0.02, 22.0]), names, slice(0, 4)


def two_track_case(vehicle, steps):
    model = TwoTrackModel(vehicle)
    us = [np.array([d, 0.1, 22.0 * d * 5.0, 0.0, 50.0, 50.0, 50.0, 50.0]) for d in steering(steps)]
    w0 = 22.0 / vehicle.wheel_radius
    x0 = np.array([0.0, 0.0, 22.0, w0, w0, w0, w0, 0.9, 0.9, 0.9, 0.9])
    P0 = np.diag([0.05, 0.05, 2.0, 1.0, 1.0, 1.0, 1.0, 0.3, 0.3, 0.3, 0.3]) ** 2
    Q = np.diag([0.05, 0.01, 0.3, 5.0, 5.0, 5.0, 5.0, 0.1, 0.1, 0.1, 0.1]) ** 2 * 0.01
    R = np.diag([0.15, 0.15, 0.005, 0.1, 0.05, 0.1, 0.1, 0.1, 0.1, 0.01]) ** 2
    z = np.array([0.1, 0.5, 0.02, 0.0, 22.0, w0, w0, w0, w0, 0.02])
    return model, us, x0, P0, Q, R, z, list(PARAMETER_FILTERS), slice(0, 10)


CASES = {"3-DOF single track": single_track_case, "7-state tire forces": tire_force_case,
         "7-DOF two track + friction": two_track_case}


def timed(step, us):
    times = np.empty(len(us))
    for i, u in enumerate(us):
        start = time.perf_counter()
        step(u)
        times[i] = time.perf_counter() - start
    return np.median(times) * 1e6, np.percentile(times, 99) * 1e6


def bench_canest(name, model, us, x0, P0, Q, R, z, rows):
    transition = Transition(model.transition, getattr(model, "transition_jacobian", None))
    measurement = Measurement(lambda X, u: model.measure(X, u)[:, rows], getattr(model, "measure_jacobian", None),
                              tuple(range(z.size)), getattr(model, "measure_parameter_jacobian", None))
    filt = make_filter(name, x0, P0, model)
    if "sensor_sets" in filt.needs and isinstance(model, TireForceModel):  # one IMU per local filter
        imu_2 = Measurement(lambda X, u: model.measure(X, u)[:, [4, 5, 6, 3]])
        sets = [(z, measurement, R), (z, imu_2, R * 2.0)]

        def step(u):
            filt.predict(transition, u, 0.01, Q)
            filt.update_sets(sets, u)
    else:
        def step(u):
            filt.predict(transition, u, 0.01, Q)
            filt.update(z, measurement, u, R)

    return timed(step, us)


def bench_filterpy(model, us, x0, P0, Q, R, z, rows):
    from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

    holder = {}
    n = x0.size
    ukf = UnscentedKalmanFilter(dim_x=n, dim_z=z.size, dt=0.01,
                                fx=lambda x, dt: model.transition(x[None, :], holder["u"], dt)[0],
                                hx=lambda x: model.measure(x[None, :], holder["u"])[0, rows],
                                points=MerweScaledSigmaPoints(n, alpha=1.0, beta=2.0, kappa=3.0 - n))
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
    vehicle = load_config(DEFAULT_CONFIG).vehicle
    for title, case in CASES.items():
        model, us, x0, P0, Q, R, z, names, rows = case(vehicle, args.steps)
        if args.filters != "all":
            names = [n for n in args.filters.split(",") if n in names]
        if names:
            report(title, [(name, *bench_canest(name, model, us, x0, P0, Q, R, z, rows)) for name in names],
                   model, us, x0, P0, Q, R, z, rows)


def report(title, rows, *case):
    try:
        reference = bench_filterpy(*case)
    except ImportError:
        reference = None
    print(f"\n{title}")
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
