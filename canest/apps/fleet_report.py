"""The fleet summary of a batch: a table per filter, the summary CSV, and a plot of the errors over the logs."""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from canest.apps.batch_plan import replacing

STATES = ("vx", "yaw_rate", "beta")


def fleet_table(rows) -> str:
    """Per filter: logs done, failed and stopped, drive hours, mean share valid, median and p95 RMSE."""
    lines = [f"{'filter':<9} {'logs':>5} {'failed':>6} {'stopped':>7} {'hours':>7} {'valid':>6} | "
             + " | ".join(f"{s} RMSE median / p95" for s in STATES)]
    for name in sorted({r["filter"] for r in rows}):
        mine = [r for r in rows if r["filter"] == name]
        ok = [r for r in mine if r["status"] == "ok"]
        failed = sum(r["status"] == "failed" for r in mine)
        hours = sum(r["duration_s"] for r in ok) / 3600.0
        valid = np.mean([r["valid_share"] for r in ok]) if ok else math.nan
        cells = []
        for state in STATES:
            values = np.array([r[f"rmse_{state}"] for r in ok if f"rmse_{state}" in r])
            cells.append(f"{np.median(values):.4f} / {np.percentile(values, 95):.4f}" if values.size else "-")
        lines.append(f"{name:<9} {len(ok):>5} {failed:>6} {len(mine) - len(ok) - failed:>7} {hours:>7.3f} "
                     f"{valid:>6.1%} | " + " | ".join(f"{c:>22}" for c in cells))
    return "\n".join(lines)


def write_fleet_summary(rows, path: Path) -> None:
    columns = ["log", "filter", "status", "duration_s", "frames", "decoded", "resets", "valid_share",
               *[f"rmse_{s}" for s in STATES], "rejected", "error"]
    with replacing(path) as partial, open(partial, "w", newline="") as handle:
        writer = csv.DictWriter(handle, columns, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({**row, "rejected": json.dumps(row.get("rejected", {}))})


def plot_errors(rows, path) -> None:
    """Box plot of the RMSE of each state over the logs, one box per filter."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({r["filter"] for r in rows})
    fig, axes = plt.subplots(1, len(STATES), figsize=(4.5 * len(STATES), 4))
    for ax, state in zip(axes, STATES):
        data = [[r[f"rmse_{state}"] for r in rows if r["filter"] == n and f"rmse_{state}" in r] for n in names]
        ax.boxplot(data, tick_labels=names)
        ax.set_title(f"{state} RMSE over logs")
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
