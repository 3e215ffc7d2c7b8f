#!/usr/bin/env python3
"""Which constant factor on a published std would put it within the honesty targets, on one grid or on several.

    python tools/honesty.py --filters all --seeds 3 --scales --json > exact.json
    python tools/honesty.py --filters all --seeds 3 --scales --json --car drawn > drawn.json
    python tools/honesty.py --filters all --seeds 3 --scales --json --car drawn --vibration 1 > vibrating.json
    python tools/std_scales.py exact.json drawn.json vibrating.json

A std that is only too wide or too narrow is mended by a factor ``k`` (publish ``k std``; 0.1-10 here).
``tools/honesty.py --scales`` pools, for every factor of :data:`FACTORS`, the sums the targets are judged on (within 2 std, mean
NEES, valid but wrong) over a grid's valid ticks, and prints the factors that would meet them all. Two ways to
find none:

- on one grid, errors heavier-tailed than a Gaussian's: keeping the valid-but-wrong share (more than 3 std off)
  at 0.1 % needs a std under which far more than 98 % of the ticks are within 2 std (a Laplace error needs
  ``k std >= 2.30`` of its scale, and then 99.0 % are within 2 std);
- across grids, the same rule's error scale differing between them (a car whose cornering stiffness is exactly
  the config's and one as wrong as the config admits): no factor fits both, only a std that tells the two
  apart, i.e. that knows more of the car or the road than the config says, can.

This script intersects the factors of several ``--scales --json`` outputs, per filter and state.
"""
from __future__ import annotations

import argparse
import json
import sys

import numpy as np

FACTORS = np.unique(np.round(np.geomspace(0.1, 10.0, 461), 3))  # k on the published std: 1 % steps, 1 included


def scale_sums(error: np.ndarray, std: np.ndarray, wrong_above: float) -> dict:
    """Additive sums, per factor of :data:`FACTORS`, of one run's scored ticks (``error`` and ``std`` as
    :func:`canest.apps.evaluate.scored` gives them): ticks, within 2 std, NEES, valid but wrong (more than 3 std
    and more than ``wrong_above`` off). From the sorted normalized errors ``z = error / std``, so no tick by
    factor table is built: within ``2 k std`` is ``z <= 2 k``, and the NEES under ``k std`` is ``z^2 / k^2``. Pool
    runs with :func:`canest.apps.evaluate.pool`."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(std > 0, error / std, np.inf)
    beyond = np.sort(z[error > wrong_above])
    return {"n": int(error.size), "cov2": np.searchsorted(np.sort(z), 2.0 * FACTORS, side="right"),
            "nees": np.sum(z**2) / FACTORS**2, "wrong": beyond.size - np.searchsorted(beyond, 3.0 * FACTORS, side="right")}


def meets_targets(sums: dict, within_two_std: tuple, nees: tuple, valid_but_wrong: float) -> np.ndarray:
    """Per factor, whether the pooled ``sums`` would meet the targets (shares of the scored ticks)."""
    n = max(sums["n"], 1)
    cov2, mean_nees, wrong = sums["cov2"] / n, sums["nees"] / n, sums["wrong"] / n
    return ((within_two_std[0] <= cov2) & (cov2 <= within_two_std[1]) & (nees[0] <= mean_nees)
            & (mean_nees <= nees[1]) & (wrong <= valid_but_wrong) & (sums["n"] > 0))


def ranges(mask: np.ndarray) -> list:
    """The factors where ``mask`` holds, as ``[first, last]`` runs of neighbouring factors."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [[float(FACTORS[start]), float(FACTORS[stop - 1])] for start, stop in zip(edges[0::2], edges[1::2])]


def mask_of(runs: list) -> np.ndarray:
    """The inverse of :func:`ranges`."""
    mask = np.zeros(FACTORS.size, dtype=bool)
    for first, last in runs:
        mask |= (FACTORS >= first - 1e-9) & (FACTORS <= last + 1e-9)
    return mask


def includes_published(runs: list) -> bool:
    """Whether the runs of factors hold 1: the std as published."""
    return any(first <= 1.0 <= last for first, last in runs)


def describe(runs: list) -> str:
    """Runs of factors as text: ``0.56-0.69``, several joined by commas, ``none``."""
    return ", ".join(f"{first:.2f}-{last:.2f}" for first, last in runs) or "none"


def common(grids: list) -> list:
    """``(filter, state, [runs per grid], common runs)`` of every filter and state all ``grids`` (the ``scales`` of
    ``honesty.py --scales --json`` outputs) hold."""
    rows = []
    for name, states in grids[0].items():
        for state in states:
            if all(state in grid.get(name, {}) for grid in grids):
                runs = [grid[name][state] for grid in grids]
                rows.append((name, state, runs, ranges(np.logical_and.reduce([mask_of(r) for r in runs]))))
    return rows


def markdown(rows: list, labels: list) -> str:
    """The rows of :func:`common` as a markdown table, a column per grid (``labels``) and, for several, their common
    factors; ``*`` marks the factors that include 1 (the std as published)."""
    def cell(runs):
        return describe(runs) + (" *" if includes_published(runs) else "")
    both = len(labels) > 1  # the common column, for several grids
    lines = [f"| filter | state | {' | '.join(labels)} |{' all |' if both else ''}",
             "|" + "---|" * (len(labels) + 2 + both)]
    lines += [f"| {name} | {state} | {' | '.join(cell(r) for r in runs)} |{f' {cell(runs_all)} |' if both else ''}"
              for name, state, runs, runs_all in rows]
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("outputs", nargs="+", help="JSON files of tools/honesty.py --scales --json, one per grid")
    p.add_argument("--all", action="store_true",
                   help="every filter and state (default: those outside the targets as published on some grid)")
    args = p.parse_args(argv)
    grids = []
    for path in args.outputs:
        try:
            with open(path) as f:
                grids.append(json.load(f)["scales"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            print(f"{path}: not a tools/honesty.py --scales --json output ({exc})", file=sys.stderr)
            return 2
    rows = common(grids)
    if not args.all:
        rows = [row for row in rows if not all(includes_published(runs) for runs in row[2])]
    print(markdown(rows, args.outputs))
    return 0


if __name__ == "__main__":
    sys.exit(main())
