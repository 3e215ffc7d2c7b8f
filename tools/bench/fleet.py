#!/usr/bin/env python3
"""Fleet throughput of canest batch with 1 and 2 local workers.

    python tools/bench/fleet.py                      # 16 logs of 60 s
    python tools/bench/fleet.py --logs 4 --seconds 5 # smoke run

Simulates the drives once (sine steer and double lane changes, 80 km/h),
then times ``run_batch`` from scratch with each worker count and prints logs
per minute, drive-hours per minute and the scaling efficiency
(throughput with n workers / (n x throughput with 1)).
"""
import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from canest.apps.batch import run_batch  # noqa: E402
from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.sim.simulate import simulate  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", type=int, default=16)
    parser.add_argument("--seconds", type=float, default=60.0, help="length of each drive")
    parser.add_argument("--workers", default="1,2")
    args = parser.parse_args()
    config = load_config(DEFAULT_CONFIG)
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        for i in range(args.logs):
            sim = simulate(config, "sine" if i % 2 else "slalom", 80.0, 0.85, seed=i, duration=args.seconds)
            (root / "logs").mkdir(exist_ok=True)
            sim.write_log(root / "logs" / f"d{i:03d}.log")
            sim.write_truth(root / "logs" / f"d{i:03d}.truth.csv")
        hours = args.logs * args.seconds / 3600.0
        base = None
        print(f"{args.logs} logs x {args.seconds:g} s = {hours:.3f} drive-hours")
        print(f"{'workers':>7} {'seconds':>8} {'logs/min':>9} {'drive-h/min':>12} {'efficiency':>11}")
        for workers in (int(w) for w in args.workers.split(",")):
            out = root / f"out{workers}"
            started = time.perf_counter()
            run_batch(config, [str(root / "logs" / "*.log")], out, ["ckf"], workers=workers, progress=False,
                      report=lambda m: None)
            elapsed = time.perf_counter() - started
            rate = args.logs / elapsed * 60
            base = base or rate
            print(f"{workers:>7} {elapsed:>8.1f} {rate:>9.1f} {hours / elapsed * 60:>12.3f} "
                  f"{rate / (workers * base):>10.0%}")
            shutil.rmtree(out)


if __name__ == "__main__":
    main()
