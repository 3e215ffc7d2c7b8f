"""Run several filters on the same log and compare them as the papers do.

Each filter replays the log through the full pipeline (so each sees exactly
the decoded, resampled inputs the daemon would), its estimates are scored
against the truth (:mod:`canest.apps.evaluate`), and the wall time of every
predict + update is recorded.
"""
from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass

import numpy as np

from canest.errors import ConfigError, UsageError
from canest.apps.evaluate import DISPLAY, as_json, score, table_of
from canest.apps.replay import replay
from canest.estimation import catalog
from canest.filters import FILTERS
from canest.settings import Config

STATES = ("vx", "yaw_rate", "beta")


@dataclass
class FilterRun:
    name: str
    table: dict  # t and states, as numpy arrays
    scores: dict  # state -> Score
    step_us: float  # median CPU microseconds per predict + update (this thread's: not the machine's load)
    repairs: int


def with_filter(config: Config, name: str) -> Config:
    """The config with another filter, its own default factorization and no filter-specific options.

    The configured model stays where the filter runs on it (so ``ckf`` and ``gfckf`` run on the
    tire-force model for the DICI-GFCKF comparison); otherwise the catalog's model for the filter
    (the single-track model, or the one the filter needs: ``dckf``, ``dici-gfckf``).
    A filter whose model needs inputs the config does not map (``jckf`` and ``dckf`` the motor torques) is a
    ConfigError naming them: run without them, it read every missing input as 0.
    """
    model, missing = model_of(config, name)
    if missing:
        raise ConfigError(f"{config.path}: filter '{name}' (on model '{model}') needs {', '.join(missing)}; "
                          f"map them in input.signals or choose another filter")
    est = dataclasses.replace(config.estimator, filter=name, model=model, factorization=None, filter_options={})
    return dataclasses.replace(config, estimator=est)


def model_of(config: Config, name: str) -> tuple[str, list]:
    """The model filter ``name`` runs on in a comparison (the configured one where it fits, else the catalog's),
    and the inputs the two need that the config does not map."""
    model = config.estimator.model
    model = model if not catalog.misfit(name, model) else catalog.model_for(name)
    return model, catalog.unmet(catalog.CATALOG[model].inputs_for(name), config.signals)


def runnable(config: Config, text: str) -> list:
    """The filters of a ``--filters`` value (:func:`parse_filters`) the config's inputs can run. With ``all`` the
    others are left out, saying so on stderr; a named one that cannot run is a ConfigError naming what it needs."""
    run, skipped = [], []
    for name in parse_filters(text):
        model, missing = model_of(config, name)
        if missing:
            skipped.append(f"{name} (on model {model}) needs {', '.join(missing)}")
        else:
            run.append(name)
    if skipped and text != "all":
        raise ConfigError(f"{config.path}: cannot run {'; '.join(skipped)}")
    if skipped:
        print("not run, inputs not mapped: " + "; ".join(skipped), file=sys.stderr)
    return run


def run_filter(config: Config, log_path, truth: dict, name: str, skip: float = 0.5, only_valid: bool = True,
               **reading) -> FilterRun:
    """One filter's replay of the log (``reading``: how, see :func:`canest.apps.replay.replay`), scored over its valid
    ticks (``only_valid``) or all of them."""
    estimates = []
    step_times = []

    def collect(estimate):
        estimates.append(estimate)

    config = with_filter(config, name) if name != config.estimator.filter else config
    repairs = replay(config, log_path, progress=False, on_estimate=collect, step_times=step_times, **reading)["repairs"]
    table = table_of(estimates)
    states = [s for s in DISPLAY if s in table and s in truth and s != "vy"]  # forces and friction where estimated
    scores = {s.state: s for s in score(table, truth, states, only_valid, skip)}
    return FilterRun(name, table, scores, float(np.median(step_times)) * 1e6 if step_times else float("nan"), repairs)


def parse_filters(text: str) -> list:
    names = list(FILTERS) if text == "all" else [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise UsageError(f"--filters {text!r}: name at least one filter (comma-separated), or all")
    unknown = [n for n in names if n not in FILTERS]
    if unknown:
        raise UsageError(f"--filters: unknown filter {unknown[0]!r}; available: all, {', '.join(FILTERS)}")
    return names


STATES_PER_BLOCK = 3  # states side by side in one block of the table: lines stay under ~100 characters


def format_comparison(runs, title: str = "") -> str:
    """RMSE and MAE per state and filter, in blocks of ``STATES_PER_BLOCK`` states; states a filter does not
    estimate (forces, friction) show '-'. The first block ends with the CPU time per step."""
    states = [s for s in DISPLAY if any(s in run.scores for run in runs)]
    lines = [title] if title else []
    for first in range(0, len(states), STATES_PER_BLOCK):
        block = states[first:first + STATES_PER_BLOCK]
        timed = first == 0
        header = " | ".join(f"{state} [{DISPLAY[state][0]}] RMSE   MAE " for state in block)
        lines.append(f"{'filter':<10} | {header}" + (" | CPU us/step" if timed else ""))
        for run in runs:
            cells = " | ".join(
                f"{run.scores[s].rmse:>{len(s) + len(DISPLAY[s][0]) + 8}.4f} {run.scores[s].mae:.4f}"
                if s in run.scores else f"{'-':>{len(s) + len(DISPLAY[s][0]) + 15}}" for s in block)
            lines.append(f"{run.name:<10} | {cells}" + (f" | {run.step_us:11.1f}" if timed else ""))
        lines.append("")
    return "\n".join(lines).rstrip("\n")


def comparison_json(runs) -> list:
    """Per filter: ``filter``, ``cpu_us_per_step``, ``repairs`` and ``scores`` as ``canest evaluate --json``
    gives them (stable keys; NaN as null)."""
    return [{"filter": run.name, "cpu_us_per_step": run.step_us if math.isfinite(run.step_us) else None,
             "repairs": run.repairs, "scores": as_json(run.scores.values())} for run in runs]


COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
           "#17becf", "#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173", "#3182bd", "#e6550d", "#31a354",
           "#756bb1", "#636363")  # matplotlib's tab10, then tab20b/c's darker tones: 20 distinct colours
DASHES = ("-", "--", "-.", ":")


def line_style(i: int) -> dict:
    """Filter ``i``'s colour and dash: 13 filters never share a look, and neighbours differ in both."""
    return {"color": COLOURS[i % len(COLOURS)], "linestyle": DASHES[i % len(DASHES)]}


def comparison_figure(runs, truth: dict):
    """Estimate vs truth (left) and error (right) for each state, one line per filter (a matplotlib Figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(STATES), 2, figsize=(13, 3 * len(STATES)), sharex=True)
    for row, state in zip(axes, STATES):
        unit, factor = DISPLAY[state]
        row[0].plot(truth["t"], truth[state] * factor, "k-", lw=1.6, label="truth")
        for i, run in enumerate(runs):
            t = run.table["t"]
            estimate = run.table[state] * factor
            row[0].plot(t, estimate, lw=0.9, label=run.name, **line_style(i))
            row[1].plot(t, estimate - np.interp(t, truth["t"], truth[state]) * factor, lw=0.9, **line_style(i))
        row[0].set_ylabel(f"{state} [{unit}]")
        row[1].set_ylabel(f"{state} error [{unit}]")
        row[0].set_title(f"{state}: estimate and truth", fontsize=9)
        row[1].set_title(f"{state}: estimate - truth", fontsize=9)
        for ax in row:
            ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=7, ncol=2)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def plot_comparison(runs, truth: dict, path) -> None:
    """:func:`comparison_figure` as a PNG at ``path``."""
    import matplotlib.pyplot as plt

    fig = comparison_figure(runs, truth)
    fig.savefig(path, dpi=110)
    plt.close(fig)
