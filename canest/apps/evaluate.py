"""Accuracy of an estimate CSV against a truth CSV: RMSE and MAE per state.

Truth is interpolated linearly onto the estimate's tick times; only ticks
inside the truth's time span and whose state is flagged valid are scored
(``--all`` scores every tick). Angles are reported in degrees, speeds in m/s.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass

import numpy as np

from canest.errors import TableError
from canest.estimation.estimate import VALID_BITS
from canest.signals import WHEELS

# state -> (display unit, factor from SI)
DISPLAY = {
    "vx": ("m/s", 1.0),
    "vy": ("m/s", 1.0),
    "beta": ("deg", 180.0 / math.pi),
    "yaw_rate": ("deg/s", 180.0 / math.pi),
    **{f"fy_{w}": ("N", 1.0) for w in WHEELS},
    **{f"mu_{w}": ("-", 1.0) for w in WHEELS},
}


def read_table(path) -> dict:
    """A CSV with a header as {column: np.ndarray}; non-numeric columns are kept as strings."""
    with open(path, newline="") as handle:
        reader = csv.reader(handle)
        try:
            header = next(reader)
        except StopIteration:
            raise TableError(f"{path}: empty file") from None
        rows = list(reader)
    if "t" not in header:
        raise TableError(f"{path}: no 't' column in header {header}")
    table = {}
    for i, name in enumerate(header):
        column = [row[i] for row in rows]
        try:
            table[name] = np.array(column, dtype=float)
        except ValueError:
            table[name] = np.array(column)
    return table


@dataclass
class Score:
    state: str
    unit: str
    rmse: float
    mae: float
    max_error: float
    samples: int


def score(estimate: dict, truth: dict, states=None, only_valid: bool = True, skip: float = 0.0) -> list:
    """RMSE/MAE per state; ``skip`` seconds at the start are ignored (filter convergence)."""
    t = estimate["t"]
    inside = (t >= truth["t"][0] + skip) & (t <= truth["t"][-1])
    scores = []
    for state in states or [s for s in DISPLAY if s in estimate and s in truth]:
        unit, factor = DISPLAY.get(state, ("", 1.0))
        use = inside & np.isfinite(estimate[state])
        if only_valid and "valid" in estimate and state in VALID_BITS:
            use &= (estimate["valid"].astype(int) >> VALID_BITS.index(state)) & 1 == 1
        error = (estimate[state][use] - np.interp(t[use], truth["t"], truth[state])) * factor
        if error.size == 0:
            scores.append(Score(state, unit, math.nan, math.nan, math.nan, 0))
            continue
        scores.append(Score(state, unit, float(np.sqrt(np.mean(error**2))), float(np.mean(np.abs(error))),
                            float(np.max(np.abs(error))), int(error.size)))
    return scores


def format_table(scores, title: str = "") -> str:
    lines = [title] if title else []
    lines.append(f"{'state':<10} {'unit':<6} {'RMSE':>10} {'MAE':>10} {'max':>10} {'ticks':>7}")
    for s in scores:
        lines.append(f"{s.state:<10} {s.unit:<6} {s.rmse:>10.4f} {s.mae:>10.4f} {s.max_error:>10.4f} {s.samples:>7d}")
    return "\n".join(lines)


def plot(estimate: dict, truth: dict, states, path) -> None:
    """PNG of estimate vs truth, one panel per state, with the +-2 sigma band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(states), 1, figsize=(9, 2.4 * len(states)), sharex=True)
    for ax, state in zip(np.atleast_1d(axes), states):
        unit, factor = DISPLAY.get(state, ("", 1.0))
        ax.plot(truth["t"], truth[state] * factor, "k-", lw=1.2, label="truth")
        ax.plot(estimate["t"], estimate[state] * factor, "C0-", lw=1.0, label="estimate")
        if f"{state}_std" in estimate:
            band = 2 * estimate[f"{state}_std"] * factor
            ax.fill_between(estimate["t"], estimate[state] * factor - band, estimate[state] * factor + band,
                            color="C0", alpha=0.2, lw=0, label="±2σ")
        ax.set_ylabel(f"{state} [{unit}]")
        ax.grid(True, alpha=0.3)
    np.atleast_1d(axes)[0].legend(loc="upper right", fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
