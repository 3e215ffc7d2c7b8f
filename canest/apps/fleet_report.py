"""The fleet summary of a batch: a table per filter, the summary CSV, and a plot of the errors over the logs."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from canest.apps.batch_plan import replacing
from canest.apps.evaluate import DISPLAY, plain

STATES = ("vx", "yaw_rate", "beta")


def unit(state: str) -> str:
    """The unit a state's errors are scored in (:data:`canest.apps.evaluate.DISPLAY`): m/s, deg/s, deg."""
    return DISPLAY[state][0]


def rmse_key(state: str) -> str:
    """A task's RMSE of ``state``, the unit in the name: vx_rmse_m_s, yaw_rate_rmse_deg_s, beta_rmse_deg."""
    return f"{state}_rmse_{unit(state).replace('/', '_')}"


def fleet_table(rows) -> str:
    """Per filter: logs done, failed and stopped, drive hours, mean share valid, median and p95 RMSE."""
    headers = [f"{s} RMSE [{unit(s)}] median / p95" for s in STATES]
    lines = [f"{'filter':<9} {'logs':>5} {'failed':>6} {'stopped':>7} {'hours':>7} {'valid':>6} | " + " | ".join(headers)]
    for name in sorted({r["filter"] for r in rows}):
        mine = [r for r in rows if r["filter"] == name]
        ok = [r for r in mine if r["status"] == "ok"]
        failed = sum(r["status"] == "failed" for r in mine)
        hours = sum(r["duration_s"] for r in ok) / 3600.0
        valid = np.mean([r["valid_share"] for r in ok]) if ok else math.nan
        cells = []
        for state in STATES:
            values = np.array([r[rmse_key(state)] for r in ok if rmse_key(state) in r])
            cells.append(f"{np.median(values):.4f} / {np.percentile(values, 95):.4f}" if values.size else "-")
        lines.append(f"{name:<9} {len(ok):>5} {failed:>6} {len(mine) - len(ok) - failed:>7} {hours:>7.3f} "
                     f"{valid:>6.1%} | " + " | ".join(f"{c:>{len(h)}}" for h, c in zip(headers, cells)))
    return "\n".join(lines)


COLUMNS = ("log", "filter", "status", "result", "duration_s", "ticks", "frames", "decoded", "resets", "valid_share",
           *map(rmse_key, STATES), "rejected", "error")  # of the fleet summary CSV, and of a task in batch --json


def write_fleet_summary(rows, path: Path) -> None:
    with replacing(path) as partial, open(partial, "w", newline="") as handle:
        writer = csv.DictWriter(handle, COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({**row, "rejected": json.dumps(row.get("rejected", {}))})


def totals(rows, seconds: float) -> dict:
    """The batch as a whole: tasks by status, drive hours and frames of the tasks done, and the rates over the
    ``seconds`` the batch took."""
    ok = [r for r in rows if r["status"] == "ok"]
    hours = sum(r["duration_s"] for r in ok) / 3600.0
    return {"tasks": len(rows), **{status: sum(r["status"] == status for r in rows)
                                   for status in ("ok", "failed", "stopped")},
            "drive_hours": hours, "frames": sum(r["frames"] for r in ok), "seconds": seconds,
            "tasks_per_min": 60 * len(rows) / seconds if seconds > 0 else None,
            "drive_hours_per_min": 60 * hours / seconds if seconds > 0 else None}


def fleet_json(rows, seconds: float) -> dict:
    """``{tasks: [{COLUMNS}], totals: {...}}`` (stable keys; a key a task lacks, e.g. the RMSE without a truth file,
    and NaN as null)."""
    tasks = [{key: plain(row.get(key, {} if key == "rejected" else None)) for key in COLUMNS} for row in rows]
    return {"tasks": tasks, "totals": totals(rows, seconds)}


def errors_figure(rows):
    """Box plot of the RMSE of each state over the logs, one box per filter (a matplotlib Figure)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({r["filter"] for r in rows})
    fig, axes = plt.subplots(1, len(STATES), figsize=(4.5 * len(STATES), 4))
    for ax, state in zip(axes, STATES):
        data = [[r[rmse_key(state)] for r in rows if r["filter"] == n and rmse_key(state) in r] for n in names]
        ax.boxplot(data, tick_labels=names)
        ax.set_title(f"{state} RMSE over logs")
        ax.set_ylabel(f"{state} RMSE [{unit(state)}]")
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return fig


def plot_errors(rows, path) -> None:
    """:func:`errors_figure` as a PNG at ``path``."""
    import matplotlib.pyplot as plt

    fig = errors_figure(rows)
    fig.savefig(path, dpi=100)
    plt.close(fig)
