"""Episode pictures in the style of the paper's Fig. 2: robots filled, humans hollow, robot goals as stars.

Figures are built with ``matplotlib.figure.Figure`` (no pyplot, no global state), which renders with the Agg
backend whatever backend the process has selected.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, cast

import matplotlib
import numpy as np
from matplotlib.axes import Axes
from matplotlib.backend_bases import FigureCanvasBase
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from crowdsim.errors import SimulationError
from crowdsim.world import RADIUS

if TYPE_CHECKING:
    from crowdsim.metrics import Trajectory

# Okabe and Ito's colour-blind-safe palette first (robots 0-7: blue, orange, bluish green, reddish purple, sky
# blue, vermillion, yellow, black; tab10's green and red for robots 2 and 3 look alike to the red-green
# colour-blind, about one man in twelve), then brown, wine, olive and indigo for up to
# MAX_ROBOTS = 12, none of them the humans' grey. pipelines.logs.scene colours robot i alike.
ROBOT_COLORS = (
    "#0072B2",
    "#E69F00",
    "#009E73",
    "#CC79A7",
    "#56B4E9",
    "#D55E00",
    "#F0E442",
    "#000000",
    "#8C564B",
    "#882255",
    "#999933",
    "#332288",
)
HUMAN_COLOR = "0.35"
GOAL_COLOR = "red"


def check_figure_path(path: str | Path, option: str) -> None:
    """Raise SimulationError unless matplotlib can write a figure named ``path`` (``option``: the CLI flag).

    Commands check before their (long) runs: ``savefig`` only complains about the format at the very end.
    """
    refusal = figure_refusal(path)
    if refusal is not None:
        raise SimulationError(f"{option} {path}: {refusal}")


def figure_refusal(path: str | Path) -> str | None:
    """Why matplotlib cannot write a figure named ``path`` on this machine, or None. A ``.pgf`` figure is
    typeset by a TeX system matplotlib runs (``pgf.texsystem``), so it needs one installed."""
    suffix = Path(path).suffix.lower().lstrip(".")
    supported = set(FigureCanvasBase.get_supported_filetypes())
    tex = str(matplotlib.rcParams["pgf.texsystem"])
    if shutil.which(tex) is None:
        if suffix == "pgf":
            return f"a .pgf figure is typeset by {tex}, which is not installed here; name it .pdf or .svg"
        supported.discard("pgf")  # not offered where it would be refused
    if suffix not in supported:
        kind = suffix or "(no suffix)"
        return f"cannot write a figure of type {kind!r}; name it with one of {sorted(supported)}"
    return None


def frame_axes(ax: Axes, *points: np.ndarray) -> None:
    """Equal-aspect metric axes showing every ``(..., 2)`` point given, with a 1 m margin."""
    everything = np.concatenate([np.reshape(p, (-1, 2)) for p in points])
    # nanmin: a replayed crowd's absent humans are NaN (plot_episode)
    lo, hi = np.nanmin(everything, axis=0) - 1.0, np.nanmax(everything, axis=0) + 1.0
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)


def default_snapshots(n_rows: int, count: int = 5) -> list[int]:
    """``count`` evenly spaced rows from the first to the last (fewer if the episode is short)."""
    return sorted({int(round(x)) for x in np.linspace(0, n_rows - 1, min(count, n_rows))})


def plot_episode(
    robot_positions: np.ndarray,
    human_positions: np.ndarray,
    robot_goals: np.ndarray,
    ax: Axes | None = None,
    title: str | None = None,
    snapshot_steps: Sequence[int] | None = None,
    *,
    radius: float = RADIUS,
    dt: float | None = None,
    times: np.ndarray | Sequence[float] | None = None,
    human_present: np.ndarray | None = None,
) -> Figure:
    """Trajectories of one episode with the agents drawn to scale at a few snapshot steps.

    robot_positions ``(T, M, 2)``, human_positions ``(T, N, 2)``, robot_goals ``(M, 2)`` in m. Snapshots
    (rows of the arrays; default five evenly spaced, first and last included) are drawn fainter the earlier
    they are; with ``dt`` the legend gives their times in seconds, row * dt, or with ``times`` (s, one per
    row) those (a log that lost states has rows that are not steps). Returns the figure (``ax.figure`` if
    ``ax`` is given). ``human_present`` ``(T, N)`` bool: a replayed crowd's tracked humans at each row
    (crowdsim.replay); the others are not drawn there.
    """
    robot_positions = np.asarray(robot_positions, dtype=float)
    human_positions = np.asarray(human_positions, dtype=float)
    if human_present is not None:
        human_positions = np.where(np.asarray(human_present, dtype=bool)[..., None], human_positions, np.nan)
    robot_goals = np.asarray(robot_goals, dtype=float)
    n_rows, n_robots = robot_positions.shape[:2]
    n_humans = human_positions.shape[1]
    if ax is None:
        fig = Figure(figsize=(7, 7))
        ax = fig.add_subplot()
    else:
        # Typed "Figure | SubFigure"; callers pass axes of a top-level Figure (an axes of a SubFigure would
        # get that SubFigure back, unchanged at run time).
        fig = cast(Figure, ax.figure)
    snaps = default_snapshots(n_rows) if snapshot_steps is None else sorted({int(s) for s in snapshot_steps})
    snaps = [s for s in snaps if 0 <= s < n_rows]

    for j in range(n_humans):
        ax.plot(*human_positions[:, j].T, color=HUMAN_COLOR, lw=0.8, alpha=0.5, zorder=1)
    for i in range(n_robots):
        color = ROBOT_COLORS[i % len(ROBOT_COLORS)]
        ax.plot(*robot_positions[:, i].T, color=color, lw=1.5, zorder=2, label=f"robot {i}")
    for k, row in enumerate(snaps):
        alpha = 0.25 + 0.75 * (k + 1) / len(snaps)
        for j in range(n_humans):
            if np.isnan(human_positions[row, j]).any():  # not tracked at that row
                continue
            ring = Circle(human_positions[row, j], radius, fill=False, ec=HUMAN_COLOR, lw=1.0, alpha=alpha)
            ring.set_zorder(3)
            ax.add_patch(ring)
        for i in range(n_robots):
            color = ROBOT_COLORS[i % len(ROBOT_COLORS)]
            disc = Circle(robot_positions[row, i], radius, fc=color, ec="k", lw=0.5, alpha=alpha)
            disc.set_zorder(4)
            ax.add_patch(disc)
    ax.plot(*robot_goals.T, "*", color=GOAL_COLOR, ms=14, mec="k", mew=0.5, zorder=5, label="robot goals")
    if n_humans:  # no legend entry for what is not drawn (an episode without a crowd)
        ax.plot([], [], "o", mfc="none", mec=HUMAN_COLOR, label="humans")
    if snaps:
        if times is not None:
            when = [f"{float(times[row]):g} s" for row in snaps]
        elif dt is not None:
            when = [f"{row * dt:g} s" for row in snaps]
        else:
            when = [f"step {row}" for row in snaps]
        # Which ring is when: the snapshots are drawn fainter the earlier they are.
        order = ", faint to solid" if len(snaps) > 1 else ""
        ax.plot([], [], " ", label=f"snapshots{order}: " + ", ".join(when))

    frame_axes(ax, robot_positions, human_positions, robot_goals)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, framealpha=0.8)
    if title:
        ax.set_title(title)
    return fig


def render_frame(traj: Trajectory, title: str, *, size: tuple[float, float], dpi: int) -> np.ndarray:
    """``traj``'s trajectories and its agents at the last state, drawn on a figure of ``size`` inches at
    ``dpi`` into an RGB array, ``(height, width, 3)`` uint8: the gym environment's ``render()``."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = Figure(figsize=size, dpi=dpi)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes((0.09, 0.09, 0.6, 0.82))  # room on the right for plot_episode's legend
    plot_episode(
        traj.robot_positions,
        traj.human_positions,
        traj.robot_goals,
        ax=ax,
        title=title,
        snapshot_steps=[traj.n_steps],
        radius=traj.radius,
        dt=traj.dt,
        human_present=traj.human_present,
    )
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
