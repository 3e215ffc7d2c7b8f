#!/usr/bin/env python3
"""Is what canest publishes honest? Accuracy against the published std and validity bits, over a grid.

    python tools/honesty.py --filters ckf,jckf                    # 5 maneuvers x mu 0.35, 0.85 x 2 seeds
    python tools/honesty.py --small --filters all                 # 2 maneuvers x 2 frictions x 1 seed, 4 s each
    python tools/honesty.py --filters all --seeds 3 --json > honesty.json
    python tools/honesty.py --filters ckf,jckf --vibration 1     # the IMU vibrating as on a real car
    python tools/honesty.py --filters ckf,jckf --crosswind 1     # gusts of side wind, a gusty day's
    python tools/honesty.py --filters all --seeds 3 --car drawn   # each seed a car as wrong as its config admits
    python tools/honesty.py --filters all --grade 6               # uphill at 6 %
    python tools/honesty.py --filters ckf --per-case vx            # and vx per drive: which cases make the pool
    python tools/honesty.py --small --check                        # exit status 1 if a state misses the targets
    python tools/honesty.py --filters all --seeds 3 --scales      # and the factors on each std that would meet them

For every case of maneuvers x speeds x frictions x noise seeds it simulates
one drive (cached in ``--workdir``: tools/drive_cache.py), replays it with every filter (each on
the model the catalog gives it, as ``canest compare`` does) and pools, per
filter and published state (vx, yaw rate, sideslip, and forces and frictions
where estimated), the sums of :func:`canest.apps.evaluate.counts`: RMSE of the
valid ticks, share valid, coverage of +-1/2/3 std, mean NEES, the "valid but
wrong" share and yaw rates of the wrong sign (README "How far to trust the
output" says what each means and the targets). ``--scales`` also prints, per filter and state, the constant
factors on the published std that would meet the targets (tools/std_scales.py: what they tell, and how to
intersect several grids).
"""
from __future__ import annotations

import argparse
import concurrent.futures
import dataclasses
import json
import math
import sys
import time
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from canest.apps.compare import runnable, with_filter  # noqa: E402
from canest.apps.evaluate import DISPLAY, WRONG_ABOVE, counts, pool, read_table, scored, summarize, table_of  # noqa: E402
from canest.apps.replay import replay  # noqa: E402
from canest.config import DEFAULT_CONFIG, load_config  # noqa: E402
from canest.errors import CanestError, SimulationError  # noqa: E402
from canest.sim.mismatch import PlantMismatch, drawn_mismatch, grade_angle  # noqa: E402
from canest.sim.simulate import simulate  # noqa: E402
from drive_cache import folder  # noqa: E402  (tools/, beside this file)
import std_scales  # noqa: E402

SKIP = 0.5  # s of filter convergence left out, as canest evaluate
SMALL = {"maneuvers": "sine,step", "mu": "0.35,0.85", "seeds": 1, "duration": 4.0}
STATES = [s for s in DISPLAY if s != "vy"]


@dataclasses.dataclass(frozen=True)
class Case:
    maneuver: str
    speed: float  # km/h
    mu: float
    seed: int
    duration: float | None = None  # s; None: the maneuver's own
    vibration: float = 0.0  # scale of the IMU's body vibration and road spikes (canest.sim.sensors; 0 none)
    car: str = "exact"  # "exact": the config's car; "drawn": per seed, one as wrong as the config admits
    grade: float = 0.0  # road grade, % (positive uphill)
    crosswind: float = 0.0  # scale of the side wind's gusts (canest.sim.wind; 0 calm)

    def mismatch(self, config) -> PlantMismatch:
        car = (drawn_mismatch(config.vehicle, self.seed, config.estimator.gyro_bias_std) if self.car == "drawn"
               else PlantMismatch())
        return dataclasses.replace(car, grade=grade_angle(self.grade))

    @property
    def key(self) -> str:
        length = f"-{self.duration:g}s" if self.duration else ""
        car = "" if self.car == "exact" else f"-{self.car}"
        grade = f"-grade{self.grade:g}" if self.grade else ""
        wind = f"-wind{self.crosswind:g}" if self.crosswind else ""
        return (f"{self.maneuver}-{self.speed:g}kmh-mu{self.mu:g}-s{self.seed}{length}-vib{self.vibration:g}{car}{grade}"
                f"{wind}")


def drive(config, case: Case, workdir: Path):
    """(log, truth CSV) of a case, simulated once; None if the plant leaves its valid range (a spin to rest)."""
    log, truth = workdir / f"{case.key}.log", workdir / f"{case.key}.truth.csv"
    if not truth.exists():
        try:
            sim = simulate(config, case.maneuver, case.speed, case.mu, seed=case.seed, duration=case.duration,
                           vibration=case.vibration, mismatch=case.mismatch(config), crosswind=case.crosswind)
        except SimulationError:
            return None
        sim.write_log(log)
        sim.write_truth(f"{truth}.tmp")
        Path(f"{truth}.tmp").rename(truth)
    return log, truth


def replayed(config, name: str, log: Path) -> tuple:
    """(the estimates as :func:`table_of`'s columns, the replay's summary) of filter ``name`` on ``log``."""
    estimates = []
    summary = replay(with_filter(config, name), log, progress=False, on_estimate=estimates.append)
    return table_of(estimates), summary


def run_case(config_path, filters, case: Case, workdir: Path, scales: bool = False) -> dict:
    """{filter: {state: sums}} of one case (empty if the drive could not be simulated), and seconds per filter;
    with ``scales`` also {filter: {state: sums per factor on the std}} (:func:`std_scales.scale_sums`)."""
    config = load_config(config_path)
    paths = drive(config, case, workdir)
    if paths is None:
        return {"case": case, "failed": True}
    truth = read_table(paths[1])
    result = {"case": case, "sums": {}, "seconds": {}, "resets": {}, "scales": {}}
    for name in filters:
        started = time.perf_counter()
        table, summary = replayed(config, name, paths[0])
        result["seconds"][name] = time.perf_counter() - started
        result["resets"][name] = summary.get("resets", 0)
        result["sums"][name] = {s: counts(table, truth, s, skip=SKIP) for s in STATES if s in table and s in truth}
        if scales:
            result["scales"][name] = {s: std_scales.scale_sums(*scored(table, truth, s, skip=SKIP)[2:],
                                                               WRONG_ABOVE.get(s, 0.0)) for s in result["sums"][name]}
    return result


def grid(config_path, filters, cases, workdir: Path, jobs: int = 1, report=print, scales: bool = False) -> list:
    """Every case's result (cases run ``jobs`` at a time in separate processes; ``scales``: :func:`run_case`'s)."""
    workdir.mkdir(parents=True, exist_ok=True)
    with concurrent.futures.ProcessPoolExecutor(max(1, jobs)) as executor:
        futures = [executor.submit(run_case, config_path, filters, case, workdir, scales) for case in cases]
        results = []
        for future in concurrent.futures.as_completed(futures):
            results.append(future.result())
            report(f"{len(results)}/{len(cases)} {results[-1]['case'].key}")
    return sorted(results, key=lambda r: r["case"].key)


def pooled_sums(results, kind: str, name: str) -> dict:
    """{state: sums} of filter ``name`` pooled over every simulated case, from each result's ``kind`` of sums
    (``"sums"``: :func:`canest.apps.evaluate.counts`'; ``"scales"``: :func:`std_scales.scale_sums`')."""
    runs = [r[kind][name] for r in results if not r.get("failed")]
    return {s: pool(run[s] for run in runs if s in run) for s in STATES if any(s in run for run in runs)}


def pooled(results, filters) -> dict:
    """{filter: {state: Score}} over every simulated case."""
    return {name: {s: summarize(s, sums) for s, sums in pooled_sums(results, "sums", name).items()}
            for name in filters}


def pooled_scales(results, filters) -> dict:
    """{filter: {state: [[first, last], ...]}}: the runs of factors on the std that would put the pooled score
    within the targets (:func:`std_scales.meets_targets`); a state never valid is not judged, as in
    :func:`outside_targets`."""
    return {name: {s: std_scales.ranges(std_scales.meets_targets(
                       sums, WITHIN_TWO_STD_TARGET, NEES_TARGET, VALID_BUT_WRONG_TARGET))
                   for s, sums in pooled_sums(results, "scales", name).items() if sums["n"] > 0}
            for name in filters}


def per_case(results, filters, state: str) -> list:
    """(case key, filter, Score) of ``state`` on every simulated case: which drives make a pooled number."""
    return [(r["case"].key, name, summarize(state, r["sums"][name][state]))
            for r in results if not r.get("failed") for name in filters if state in r["sums"][name]]


# issue 15's targets for every filter and published state (README "How far to trust the output")
VALID_BUT_WRONG_TARGET = 0.001  # share of the valid ticks at most
WITHIN_TWO_STD_TARGET = (0.90, 0.98)  # share of the valid ticks, both ends included
NEES_TARGET = (0.5, 2.0)  # mean NEES of the valid ticks


def outside_targets(scores: dict) -> list:
    """(filter, state, reasons) of every pooled score outside the targets; a state never valid is not judged."""
    out = []
    for name, states in scores.items():
        for state, s in states.items():
            if not s.valid > 0.0:
                continue
            reasons = []
            if s.vbw > VALID_BUT_WRONG_TARGET:
                reasons.append(f"valid but wrong {100 * s.vbw:.2f} %")
            if not WITHIN_TWO_STD_TARGET[0] <= s.cov2 <= WITHIN_TWO_STD_TARGET[1]:
                reasons.append(f"within 2 std {_pct(s.cov2)}")
            if not NEES_TARGET[0] <= s.nees <= NEES_TARGET[1]:
                reasons.append(f"NEES {s.nees:.3g}")
            if s.wrong_sign:
                reasons.append(f"{s.wrong_sign} valid ticks of the wrong sign")
            if reasons:
                out.append((name, state, reasons))
    return out


def outside_markdown(outside: list) -> str:
    head = (f"Outside the targets (valid but wrong at most {_pct(VALID_BUT_WRONG_TARGET)}, within 2 std "
            f"{_pct(WITHIN_TWO_STD_TARGET[0])} to {_pct(WITHIN_TWO_STD_TARGET[1])}, mean NEES {NEES_TARGET[0]:g} to "
            f"{NEES_TARGET[1]:g}, no valid yaw rate of the wrong sign)")
    if not outside:
        return head + ": none"
    return head + ":\n" + "\n".join(f"- {name} {state}: {', '.join(reasons)}" for name, state, reasons in outside)


SCORE_COLUMNS = ("RMSE", "valid", "<=1 std", "<=2 std", "<=3 std", "NEES", "valid but wrong", "wrong sign")


def _table(columns, rows) -> str:
    """A markdown table of ``columns`` (labels) and ``rows`` (lists of cell texts)."""
    return "\n".join([f"| {' | '.join(columns)} |", "|" + "---|" * len(columns)] +
                      [f"| {' | '.join(row)} |" for row in rows])


def _score_cells(s) -> list:
    """A Score's cells under :data:`SCORE_COLUMNS`."""
    return [f"{s.rmse:.3g}", _pct(s.valid), _pct(s.cov1), _pct(s.cov2), _pct(s.cov3), f"{s.nees:.3g}", _pct(s.vbw),
            str(s.wrong_sign) if s.state == "yaw_rate" else ""]


def per_case_markdown(rows) -> str:
    return _table(("case", "filter", *SCORE_COLUMNS, "largest error"),
                  [[key, name, *_score_cells(s), f"{s.max_error:.3g}"] for key, name, s in rows])


def markdown(scores: dict) -> str:
    return _table(("filter", "state", "unit", *SCORE_COLUMNS),
                  [[name, s.state, s.unit, *_score_cells(s)] for name, states in scores.items() for s in states.values()])


def _pct(share: float) -> str:
    return "-" if math.isnan(share) else f"{100 * share:.1f} %"


def cases_of(args) -> list:
    split = (lambda text: [p.strip() for p in str(text).split(",") if p.strip()])
    return [Case(m, float(v), float(mu), seed, args.duration, args.vibration, args.car, args.grade, args.crosswind)
            for m in split(args.maneuvers)
            for v in split(args.speed) for mu in split(args.mu) for seed in range(args.seeds)]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--filters", default="all",
                   help="comma list or 'all' (default all: every filter the config's inputs can run)")
    p.add_argument("--maneuvers", default="dlc,sine,slalom,step,launch", help="comma list (default all five)")
    p.add_argument("--speed", default="80", help="km/h, comma list (default 80)")
    p.add_argument("--mu", default="0.35,0.85", help="road frictions, comma list (default 0.35,0.85)")
    p.add_argument("--seeds", type=int, default=2, help="noise seeds 0..N-1 per case (default 2)")
    p.add_argument("--duration", type=float, help="seconds per drive (default: each maneuver's own)")
    p.add_argument("--vibration", type=float, default=0.0,
                   help="IMU body vibration and road spikes, scale (default 0: white noise; 1: as on a real car, "
                        "README 'How far to trust the output')")
    p.add_argument("--crosswind", type=float, default=0.0, metavar="SCALE",
                   help="gusts of side wind (default 0: calm; 1: a gusty day's, canest simulate --crosswind)")
    p.add_argument("--car", choices=("exact", "drawn"), default="exact",
                   help="exact: the simulated car is the config's (default); drawn: each seed drives a car as wrong as "
                        "the config admits (cornering stiffnesses off by its cornering_stiffness_uncertainty, "
                        "accelerometer and gyro biases, the gyro's also by estimator.gyro_bias_std, the wheel radius by "
                        "wheel_radius_uncertainty: canest.sim.mismatch.drawn_mismatch)")
    p.add_argument("--grade", type=float, default=0.0, metavar="PCT",
                   help="road grade in %%, positive uphill (default 0: flat)")
    p.add_argument("--config", default=str(DEFAULT_CONFIG), help="vehicle config (default: the built-in one)")
    p.add_argument("--workdir", default="honesty-work", help="cache of simulated drives, per config and simulator source (default ./honesty-work)")
    p.add_argument("--jobs", type=int, default=1, help="cases in parallel processes (default 1)")
    p.add_argument("--json", action="store_true", help="print JSON instead of the markdown table")
    p.add_argument("--per-case", metavar="STATE",
                   help="also print STATE (vx, yaw_rate, beta, fy_fl, mu_fl, ...) per case and filter: which drives "
                        "make a pooled number (JSON: under the key 'per_case')")
    p.add_argument("--check", action="store_true",
                   help="exit with status 1 when a filter's state is outside the targets (listed below the table; "
                        "JSON: under the key 'outside')")
    p.add_argument("--scales", action="store_true",
                   help="also print, per filter and state, the constant factors on the published std that would meet "
                        "the targets (JSON: under the key 'scales'; tools/std_scales.py intersects several grids)")
    p.add_argument("--small", action="store_true", help="quick subset: sine, step; mu 0.35, 0.85; 1 seed; 4 s")
    args = p.parse_args(argv)
    if args.small:
        args.maneuvers, args.mu, args.seeds, args.duration = (SMALL[k] for k in ("maneuvers", "mu", "seeds", "duration"))
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    config = Path(args.config).resolve()
    try:
        loaded = load_config(config)
        filters = runnable(loaded, args.filters)
    except CanestError as exc:
        print(exc, file=sys.stderr)
        return 2
    if args.per_case and args.per_case not in STATES:
        print(f"--per-case: no published state {args.per_case!r} (one of {', '.join(STATES)})", file=sys.stderr)
        return 2
    workdir = folder(Path(args.workdir), config, loaded.input_dbc)
    cases = cases_of(args)
    started = time.perf_counter()
    results = grid(config, filters, cases, workdir, args.jobs, report=lambda text: print(text, file=sys.stderr),
                   scales=args.scales)
    scores = pooled(results, filters)
    failed = [r["case"].key for r in results if r.get("failed")]
    rows = per_case(results, filters, args.per_case) if args.per_case else []
    outside = outside_targets(scores)
    if args.json:
        out = {name: {s: dataclasses.asdict(score) for s, score in states.items()} for name, states in scores.items()}
        out["outside"] = [{"filter": name, "state": state, "reasons": reasons} for name, state, reasons in outside]
        if args.per_case:
            out["per_case"] = [{"case": key, "filter": name, **dataclasses.asdict(score)} for key, name, score in rows]
        if args.scales:
            out["scales"] = pooled_scales(results, filters)
        print(json.dumps(out, indent=1))
    else:
        print(f"{len(cases) - len(failed)} cases x {len(filters)} filters in {time.perf_counter() - started:.0f} s"
              + (f"; not simulated (the plant spun to rest): {', '.join(failed)}" if failed else ""))
        print(markdown(scores))
        print("\n" + outside_markdown(outside))
        if args.per_case:
            print(f"\n{args.per_case} per case:\n" + per_case_markdown(rows))
        if args.scales:
            print("\nConstant factors on the published std that would meet the targets (* the std as published):\n"
                  + std_scales.markdown(std_scales.common([pooled_scales(results, filters)]), ["this grid"]))
    return 1 if args.check and outside else 0


if __name__ == "__main__":
    sys.exit(main())
