"""Pictures of episode recordings: trajectories with the plans and predictions, A/B overlay (the animation:
pipelines.logs.animation).

Trajectories are drawn with crowdsim.plotting's figure and colours, so that a recorded run looks like a
simulated one; the plans and predictions, which only the recording holds, are drawn on top of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np

from pipelines.logs.ending import compare_labels, titled
from pipelines.logs.reader import Recording
from pipelines.logs.view import EpisodeView, episode_view
from pipelines.whole_files import save_figure


def robot_color(i: int) -> str:
    from crowdsim.plotting import ROBOT_COLORS

    return ROBOT_COLORS[i % len(ROBOT_COLORS)]


GOAL_COLOR: Final = "red"  # as crowdsim.plotting draws them
HUMAN_COLOR: Final = "0.35"


def default_times(view: EpisodeView, count: int = 3) -> list[float]:
    return [float(t) for t in np.linspace(view.times[0], view.times[-1], count + 1)[:-1]]


def _draw_plans(ax: Any, view: EpisodeView, row: int, *, label: bool) -> None:
    """Robot i's plan at state ``row`` from its position, one marker per planned step, above the agents
    (a plan that is followed would otherwise hide under the trajectory); predictions dotted grey."""
    step = int(view.steps[row])
    plan = view.plans.get(step)
    if plan is not None:
        for i, track in enumerate(plan):
            pts = np.vstack([view.robot_positions[row, i], track])
            ax.plot(pts[:, 0], pts[:, 1], "--o", color=robot_color(i), lw=1.2, ms=3, mfc="white", mew=0.8,
                    zorder=6, label="plan" if label and i == 0 else None)  # fmt: skip
    prediction = view.predictions.get(step)
    if prediction is not None:
        for j in range(prediction.shape[1]):
            pts = np.vstack([view.human_positions[row, j], prediction[:, j]])
            ax.plot(pts[:, 0], pts[:, 1], ":.", color=HUMAN_COLOR, lw=1.0, ms=3, zorder=6,
                    label="prediction" if label and j == 0 else None)  # fmt: skip


def plot_recording(rec: Recording, out: str | Path, times: Sequence[float] | None = None) -> str:
    """Trajectories (crowdsim.plotting.plot_episode) with the plans and predictions made at ``times`` (s).

    Returns what was drawn and when, as the figure's title ends: "plans and predictions at t = 0, 1.2 s"
    (the nearest recorded states with a plan or prediction, if any has), or "agents at t = ..." for a run
    that records neither; and the times asked for past the episode's end.
    """
    view = episode_view(rec)  # once: the figure and the episode's end read it
    fig, _ = _recording_figure(rec, view, times)
    save_figure(Path(out), lambda name: fig.savefig(name, dpi=120, bbox_inches="tight"))
    said = str(fig.axes[0].get_title()).splitlines()[-1]
    end = float(view.times[-1])
    late = [t for t in times or () if t > end]  # drawn at the last state: the title alone showed it moved
    if late:
        said += f"; --times {', '.join(f'{t:g}' for t in late)} past the episode's end at {end:g} s"
    return said


def recording_figure(rec: Recording, times: Sequence[float] | None = None) -> tuple[Any, list[float]]:
    """``plot_recording``'s figure and the times drawn."""
    return _recording_figure(rec, episode_view(rec), times)


def _recording_figure(
    rec: Recording, view: EpisodeView, times: Sequence[float] | None
) -> tuple[Any, list[float]]:
    from crowdsim.plotting import default_snapshots, plot_episode

    if times or view.plans or has_predictions(view):
        rows = sorted({view.planned_row_at(t) for t in (times if times else default_times(view))})
    else:  # nothing planned to show: the agents as simulate --plot draws them, the last state included
        rows = default_snapshots(len(view.times))
    fig = plot_episode(
        view.robot_positions,
        view.human_positions,
        view.robot_goals,
        snapshot_steps=rows,
        radius=view.radius,
        times=view.times,
    )
    ax = fig.axes[0]
    sensor = sensor_radius(rec)
    for k, row in enumerate(rows):
        _draw_plans(ax, view, row, label=k == 0)
    if sensor is not None:
        draw_sensor_ranges(ax, view.robot_positions, rows, sensor)
    drawn = [float(view.times[r]) for r in rows]
    # What the file holds: an ORCA or straight run records neither plans nor predictions, and its title
    # promised them all the same.
    shown = [what for what, has in (("plans", view.plans), ("predictions", has_predictions(view))) if has]
    ax.set_title(
        f"{titled(rec)}\n{' and '.join(shown) or 'agents'} at t = {', '.join(f'{t:g}' for t in drawn)} s"
    )
    if rec.truncated:
        ax.text(0.01, 0.01, "TRUNCATED FILE", transform=ax.transAxes, color="red", fontsize=9)
    _dedupe_legend(ax)
    return fig, drawn


def has_predictions(view: EpisodeView) -> bool:
    """Whether the file holds predictions of a human (a crowd-free run records empty ones)."""
    return bool(view.predictions) and view.human_positions.shape[1] > 0


def sensor_radius(rec: Recording) -> float | None:
    """The range of the sensor the controller was behind (its config's ``sensing``, pipelines.loop.sensing),
    None for a run that saw every human (or a file that does not say)."""
    from pipelines.loop.sensing import recorded_sensor_range

    return recorded_sensor_range(rec.config())


def draw_sensor_ranges(ax: Any, robot_positions: Any, rows: Sequence[int], radius: float) -> None:
    """Each robot's sensor range at each state of ``rows`` (``robot_positions`` ``(T, M, 2)`` m): a dashed
    circle in its colour (a human outside every circle was not seen then), named once in the legend."""
    drawn = ring_radius(ax, np.asarray(robot_positions)[list(rows)], radius)
    for k, row in enumerate(rows):
        for i, centre in enumerate(robot_positions[row]):
            label = f"sensor range ({radius:g} m)" if k == 0 and i == 0 else None
            ax.add_patch(sensor_circle(centre, drawn, i, label))


def ring_radius(ax: Any, centres: Any, radius: float) -> float:
    """The radius to draw a sensor ring of ``radius`` with around each of ``centres`` (``(..., 2)`` m) in the
    axes ``ax``, their limits set: ``radius`` itself, unless that is beyond twice the farthest corner of the
    view from any centre, where every such ring encloses the whole view and shows nothing; then that bound,
    as invisible. matplotlib dashes the whole circumference: a recording from before the sensor range had a
    bound (crowdsim.world.SENSOR_RANGE) at 1e6 m took 24 s a plot, at 1e300 m never ended."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    corners = np.array([[x0, y0], [x0, y1], [x1, y0], [x1, y1]])
    points = np.asarray(centres, dtype=float).reshape(-1, 1, 2)
    far = np.linalg.norm(points - corners, axis=-1)
    if not far.size or not np.isfinite(far).any():
        return radius
    return float(min(radius, 2.0 * np.nanmax(far)))


def sensor_circle(centre: Any, radius: float, robot: int, label: str | None = None) -> Any:
    """Robot ``robot``'s sensor range around ``centre``, dashed in its colour (plot and animation)."""
    from matplotlib.patches import Circle

    return Circle(
        centre, radius, fill=False, ls="--", lw=0.8, ec=robot_color(robot), alpha=0.5, zorder=2, label=label
    )


def _dedupe_legend(ax: Any, *, below: bool = False) -> None:
    """The legend, each label once, outside the axes so that it hides nothing drawn: below them, or at
    their right as crowdsim.plotting.plot_episode places its own (loc="best" inside the axes covered a
    12-robot team's goals and paths, having no free corner left)."""
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    if unique and below:
        ax.legend(
            unique.values(), unique.keys(), loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=7
        )
    elif unique:
        ax.legend(
            unique.values(),
            unique.keys(),
            loc="upper left",
            bbox_to_anchor=(1.01, 1.0),
            fontsize=7,
            framealpha=0.8,
        )


def plot_compare(a: Recording, b: Recording, out: str | Path) -> None:
    fig = compare_figure(a, b)
    save_figure(Path(out), lambda name: fig.savefig(name, dpi=120, bbox_inches="tight"))


def compare_figure(a: Recording, b: Recording) -> Any:
    """Both runs' trajectories on one axes: A solid, B dashed, robots in the same colours."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 7))
    ax = fig.add_subplot()
    labels = compare_labels(a, b)
    for rec, style, alpha in ((a, "-", 1.0), (b, "--", 0.8)):
        view = episode_view(rec)
        tag = "A" if rec is a else "B"
        for j in range(view.human_positions.shape[1]):
            ax.plot(*view.human_positions[:, j].T, style, color="0.6", lw=0.8, alpha=0.6,
                    label=f"{tag} humans" if j == 0 else None)  # fmt: skip
        for i in range(view.robot_positions.shape[1]):
            ax.plot(*view.robot_positions[:, i].T, style, color=robot_color(i), lw=2.0, alpha=alpha,
                    label=f"{tag}: {labels[tag]}" if i == 0 else None)  # fmt: skip
        ax.plot(*view.robot_goals.T, "*", color=GOAL_COLOR, mec="k", mew=0.5, ms=14)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_title("A solid, B dashed")
    _dedupe_legend(ax, below=True)
    return fig
