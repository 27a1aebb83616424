"""The report's plots against the number of humans: success rate and travel time, ours beside the paper's.

One line per method (bars when the experiment has a single crowd size), our 95% intervals as error bars, the
paper's figures dashed. The safety plots (closest approaches, the success / collision trade-off) are
pipelines.experiments.safety_report's.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Final

import numpy as np

from pipelines.experiments.cells import Experiment
from pipelines.experiments.summary import CellSummary

SUCCESS_PNG: Final[str] = "success_vs_humans.png"
TRAVEL_TIME_PNG: Final[str] = "travel_time_vs_humans.png"


def plot_vs_humans(experiment: Experiment, summaries: Sequence[CellSummary], out: Path) -> list[Path]:
    """Success rate and travel time against the number of humans, one line per method (bars when the
    experiment has a single crowd size), our 95% intervals as error bars and the paper's figures dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = [m for m in experiment.method_labels if any(s.cell.method == m for s in summaries)]
    humans = sorted({s.cell.n_humans for s in summaries})
    written = []
    panels = (
        ("success", "Success rate (%)", SUCCESS_PNG),
        ("travel_time", "Average travel time (s)", TRAVEL_TIME_PNG),
    )
    for name, ylabel, filename in panels:
        fig, ax = plt.subplots(figsize=(6.4, 4.2), layout="constrained")
        for k, method in enumerate(methods):
            cells = sorted((s for s in summaries if s.cell.method == method), key=lambda s: s.cell.n_humans)
            x = np.array([s.cell.n_humans for s in cells], dtype=float)
            if name == "success":
                y = np.array([s.success.percent for s in cells])
                ci = np.array([s.success.interval for s in cells]).T
                err = np.abs(ci - y)
            else:
                y = np.array([s.travel_time_mean for s in cells])
                err = np.array([s.travel_time_ci for s in cells])
            color = f"C{k}"
            if len(humans) == 1:
                ax.bar(
                    k, y[0], yerr=None if np.isnan(err).all() else err.reshape(-1, 1), color=color, capsize=4
                )
            else:
                ax.errorbar(x, y, yerr=err, marker="o", capsize=3, color=color, label=f"{method} (ours)")
            paper = [(s.cell.n_humans, getattr(s.paper, name)) for s in cells if s.paper]
            if paper:
                px, py = zip(*paper, strict=True)
                ax.plot(px, py, ls="--", marker="s", mfc="none", color=color, label=f"{method} (paper)")
        if len(humans) == 1:
            ax.set_xticks(range(len(methods)), methods, rotation=30, ha="right")
            ax.set_xlabel(f"method ({humans[0]} humans)")
        else:
            ax.set_xticks(humans)
            ax.set_xlabel("number of humans")
            ax.legend(fontsize="small")
        ax.set_ylabel(ylabel)
        ax.set_title(experiment.title, fontsize="medium")
        ax.grid(alpha=0.3)
        path = out / filename
        fig.savefig(path, dpi=120)
        plt.close(fig)
        written.append(path)
    return written
