"""Accuracy and honesty of an estimate CSV against a truth CSV, per published state.

Truth is interpolated linearly onto the estimate's tick times; only ticks
inside the truth's time span and whose state is flagged valid are scored
(``--all`` scores every tick). Angles are reported in degrees, speeds in m/s.

Beside RMSE and MAE, what a consumer of the standard deviation and the
validity bit needs to know (all over the scored ticks):

- ``valid``: share of ticks in the truth's span flagged valid;
- ``cov1``-``cov3``: share with ``|error| <= k std`` (a Gaussian's 68 / 95 / 99.7 %);
- ``nees``: mean ``error^2 / std^2`` (1 when the std is honest);
- ``vbw``, valid but wrong: share with ``|error| > 3 std`` and above :data:`WRONG_ABOVE`;
- ``wrong_sign`` (yaw rate): ticks more than 2 deg/s off with the sign of the truth wrong.

:func:`counts` are additive, so runs pool (:func:`pool`) before :func:`summarize`.
"""
from __future__ import annotations

import csv
import logging
import math
import sys
from dataclasses import asdict, dataclass

import numpy as np

from canest.errors import InputFileError, TableError
from canest.estimation.estimate import VALID_BITS
from canest.io.outputs import is_stdio
from canest.signals import WHEELS

log = logging.getLogger("canest.evaluate")

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
    """A CSV with a header as {column: np.ndarray}; non-numeric columns are kept as strings; ``-`` is stdin.

    A TableError (65) names the file, and the line where one is to blame, for what cannot be scored: no text, no
    header, no ``t`` column, no row, a text cell in a column of numbers (an empty cell there is nan). Rows whose
    field count is not the header's (a file cut mid-write) are left out with one warning naming the file, the
    first such line and how many, blank lines without one; a file that does not exist or may not be read is an
    InputFileError (66)."""
    try:
        with (open(sys.stdin.fileno(), newline="", closefd=False) if is_stdio(path)
              else open(path, newline="", encoding="utf-8")) as handle:
            reader = csv.reader(handle)
            header = next(reader, None)
            rows, torn = [], []
            for row in reader:
                if row:  # a blank line holds nothing
                    (rows if len(row) == len(header) else torn).append((reader.line_num, row))
    except UnicodeDecodeError as exc:
        raise TableError(f"{path}: not a text CSV (byte {exc.start} is not UTF-8): name a CSV such as canest replay "
                         "--csv or canest simulate --truth writes") from None
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read: {exc.strerror or exc}; name an existing CSV this user may read") \
            from None
    if header is None:
        raise TableError(f"{path}: empty file")
    if "t" not in header:
        raise TableError(f"{path}: no 't' column in header {header}")
    if torn:
        line, row = torn[0]
        log.warning("%s: left out %d line(s) whose field count is not the header's %d (first: line %d, %d fields; "
                    "a file cut mid-write?)", path, len(torn), len(header), line, len(row))
    if not rows:
        raise TableError(f"{path}: no rows under the header")
    table = {name: _column(path, name, [(line, row[i]) for line, row in rows]) for i, name in enumerate(header)}
    if table["t"].dtype.kind != "f":
        raise TableError(f"{path}: the 't' column holds no numbers")
    return table


def _column(path, name: str, cells: list) -> np.ndarray:
    """One column's cells ``(line, text)`` as floats, or as strings where no cell is a number (``mode``,
    ``why_*``); a TableError naming the line of a text cell among numbers."""
    try:
        return np.array([text for _, text in cells], dtype=float)
    except ValueError:
        pass
    numbers, texts = [], []
    for line, text in cells:
        try:
            numbers.append(float(text) if text.strip() else math.nan)
        except ValueError:
            texts.append((line, text))
    if len(texts) + sum(1 for _, text in cells if not text.strip()) == len(cells):  # no cell is a number
        return np.array([text for _, text in cells])
    if not texts:
        return np.array(numbers)
    line, text = texts[0]
    raise TableError(f"{path}:{line}: column '{name}' holds {text!r} where its other rows hold numbers")


def time_span(t: np.ndarray) -> str:
    """A table's times as ``first to last s`` (``no ticks`` when empty), for a message on why nothing was scored."""
    return f"{t[0]:.3f} to {t[-1]:.3f} s" if t.size else "no ticks"


def table_of(estimates) -> dict:
    """Estimates (:class:`canest.estimation.estimate.Estimate`) as the columns :func:`read_table` reads from a
    replay's CSV: ``t``, every published value and its ``_std``, and ``valid`` (the mask over ``VALID_BITS``)."""
    names = estimates[0].values if estimates else {}
    return {"t": np.array([e.t for e in estimates]), "valid": np.array([e.valid_flags for e in estimates]),
            **{name: np.array([e.values[name] for e in estimates]) for name in names}}


# "valid but wrong": more than 3 std off and more than this, in display units
WRONG_ABOVE = {"vx": 0.5, "vy": 0.5, "beta": 1.0, "yaw_rate": 1.0, **{f"fy_{w}": 300.0 for w in WHEELS},
               **{f"mu_{w}": 0.1 for w in WHEELS}}
SIGN_MARGIN = 2.0  # deg/s


@dataclass
class Score:
    state: str
    unit: str
    rmse: float
    mae: float
    max_error: float
    samples: int
    valid: float = math.nan  # share of ticks flagged valid
    cov1: float = math.nan
    cov2: float = math.nan
    cov3: float = math.nan
    nees: float = math.nan
    vbw: float = math.nan
    wrong_sign: int = 0


def valid_mask(estimate: dict, state: str) -> np.ndarray:
    """Per tick, whether the estimate flags ``state`` valid (every tick where the CSV has no bit for it)."""
    if "valid" not in estimate or state not in VALID_BITS:
        return np.ones(estimate["t"].size, dtype=bool)
    return (estimate["valid"].astype(np.int64) >> VALID_BITS.index(state)) & 1 == 1


def scored(estimate: dict, truth: dict, state: str, only_valid: bool = True, skip: float = 0.0) -> tuple:
    """``(inside, use, error, std)`` of one state on one run: the masks of the ticks inside the truth's span (after
    ``skip`` s, with a finite value) and of those scored (the valid ones unless ``only_valid`` is False), and the
    scored ticks' absolute error and published std in display units (NaN where the state has no std)."""
    _, factor = DISPLAY.get(state, ("", 1.0))
    t = estimate["t"]
    inside = (t >= truth["t"][0] + skip) & (t <= truth["t"][-1]) & np.isfinite(estimate[state])
    use = inside & valid_mask(estimate, state) if only_valid else inside
    error = np.abs(estimate[state][use] - np.interp(t[use], truth["t"], truth[state])) * factor
    std_column = estimate.get(f"{state}_std")
    std = std_column[use] * factor if std_column is not None else np.full(error.size, np.nan)
    return inside, use, error, std


def counts(estimate: dict, truth: dict, state: str, only_valid: bool = True, skip: float = 0.0) -> dict:
    """Additive sums of one state on one run, in display units (pool runs with :func:`pool`)."""
    inside, use, error, std = scored(estimate, truth, state, only_valid, skip)
    t = estimate["t"]
    with np.errstate(divide="ignore", invalid="ignore"):
        nees = np.where(std > 0, (error / std) ** 2, np.where(np.isnan(std), np.nan, np.inf))  # no std: no NEES
    sums = {"ticks": int(inside.sum()), "valid": int((inside & valid_mask(estimate, state)).sum()),
            "n": int(error.size), "sq": float(np.sum(error**2)), "abs": float(np.sum(error)),
            "max": float(error.max()) if error.size else math.nan,
            "cov1": int(np.sum(error <= std)), "cov2": int(np.sum(error <= 2 * std)),
            "cov3": int(np.sum(error <= 3 * std)), "nees": float(np.sum(nees)),
            "wrong": int(np.sum((error > 3 * std) & (error > WRONG_ABOVE.get(state, 0.0)))), "sign": 0}
    if state == "yaw_rate":
        estimated = estimate[state][use]
        true = np.interp(t[use], truth["t"], truth[state])
        sums["sign"] = int(np.sum((error > SIGN_MARGIN) & (np.sign(estimated) != np.sign(true))))
    return sums


def pool(items) -> dict:
    """The sums of several runs' :func:`counts` (the largest error for ``max``)."""
    total = {}
    for sums in items:
        for key, value in sums.items():
            if key == "max":
                total[key] = value if key not in total or math.isnan(total[key]) else max(total[key], value)
            else:
                total[key] = total.get(key, 0) + value
    return total


def summarize(state: str, sums: dict) -> Score:
    """Ratios of (pooled) sums."""
    n = sums["n"]
    share = (lambda x: x / n) if n else (lambda x: math.nan)
    return Score(state, DISPLAY.get(state, ("", 1.0))[0], math.sqrt(share(sums["sq"])), share(sums["abs"]),
                 sums["max"], n, sums["valid"] / sums["ticks"] if sums["ticks"] else math.nan,
                 share(sums["cov1"]), share(sums["cov2"]), share(sums["cov3"]), share(sums["nees"]),
                 share(sums["wrong"]), sums["sign"])


def score(estimate: dict, truth: dict, states=None, only_valid: bool = True, skip: float = 0.0) -> list:
    """A :class:`Score` per state; ``skip`` seconds at the start are ignored (filter convergence)."""
    states = states or [s for s in DISPLAY if s in estimate and s in truth]
    return [summarize(state, counts(estimate, truth, state, only_valid, skip)) for state in states]


def align(estimate: dict, truth: dict, mode: str, offset: float = 0.0) -> dict:
    """The estimate on the truth's clock: ``first`` moves its first tick onto the truth's first time, ``offset``
    subtracts ``offset`` seconds (a live CSV has epoch timestamps, a simulated truth starts at 0), ``none`` keeps it."""
    if mode == "none" or not estimate["t"].size:
        return estimate
    shift = estimate["t"][0] - truth["t"][0] if mode == "first" else offset
    return {**estimate, "t": estimate["t"] - shift}


def plain(value):
    """``value`` as JSON can hold it: a NaN or infinite float as None (null)."""
    return None if isinstance(value, float) and not math.isfinite(value) else value


def as_json(scores) -> dict:
    """``{state: {unit, rmse, mae, max_error, samples, valid, cov1, cov2, cov3, nees, vbw, wrong_sign}}``, NaN as
    null (JSON has no NaN)."""
    return {s.state: {k: plain(v) for k, v in asdict(s).items() if k != "state"} for s in scores}


def format_table(scores, title: str = "") -> str:
    lines = [title] if title else []
    lines.append(f"{'state':<10} {'unit':<6} {'RMSE':>9} {'MAE':>9} {'max':>9} {'ticks':>6} {'valid':>6} "
                 f"{'<=1std':>6} {'<=2std':>6} {'<=3std':>6} {'NEES':>8} {'wrong':>6}")
    for s in scores:
        lines.append(f"{s.state:<10} {s.unit:<6} {s.rmse:>9.4f} {s.mae:>9.4f} {s.max_error:>9.4f} {s.samples:>6d} "
                     f"{_percent(s.valid)} {_percent(s.cov1)} {_percent(s.cov2)} {_percent(s.cov3)} "
                     f"{s.nees:>8.3g} {_percent(s.vbw)}")
    return "\n".join(lines)


def _percent(share: float) -> str:
    return f"{'-':>6}" if math.isnan(share) else f"{100 * share:>5.1f}%"


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
