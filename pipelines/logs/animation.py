"""An episode recording as an animation (``crowdmpc review --animate``): a GIF (Pillow) or an MP4 (ffmpeg),
a frame per recorded state with the paths so far, the plans and predictions the file holds and the sensor's
range, in the colours of pipelines.logs.plots' pictures."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np

from pipelines.errors import PipelineError
from pipelines.logs.ending import frame_texts
from pipelines.logs.plots import (
    GOAL_COLOR,
    HUMAN_COLOR,
    has_predictions,
    ring_radius,
    robot_color,
    sensor_circle,
    sensor_radius,
)
from pipelines.logs.reader import Recording
from pipelines.logs.view import EpisodeView, episode_view
from pipelines.whole_files import save_figure

ANIMATION_SUFFIXES: Final = (".gif", ".mp4")


# Pillow's GIF writer holds every frame (about 1.3 MB each at the dpi used): a 10 000-step gym episode
# needed 13 GB. 300 frames are two minutes of a 0.4 s step at simulated speed.
MAX_FRAMES: Final[int] = 300
# The longest a frame is shown, s: a GIF stores a frame's duration as a 16-bit count of centiseconds (a
# 700 s step, which simulate accepts, overflowed Pillow's writer); an MP4 is held to it too, to play alike.
MAX_FRAME_S: Final[float] = 655.35
# The shortest, s: no screen shows 1 000 frames a second, and a hand-edited dt of 1e-300 would give ffmpeg an
# infinite frame rate. A GIF holds whole centiseconds, and viewers show a frame of 0 or 1 for 0.1 s: 0.02 s.
MIN_FRAME_S: Final[float] = 1e-3
MIN_GIF_FRAME_S: Final[float] = 0.02


@dataclass(frozen=True)
class AnimationFacts:
    """What ``animate_recording`` wrote."""

    frames: int
    every: int  # one recorded state in ``every`` is a frame
    frame_s: float  # how long each frame is shown: as the file holds it (a GIF's in centiseconds)
    asked_s: float  # how long it would be at the asked speed
    least_s: float  # the shortest frame the format shows as asked (MIN_GIF_FRAME_S, MIN_FRAME_S)

    @property
    def pace_note(self) -> str | None:
        """How much faster or slower than asked it plays, when a bound held it (not a GIF's rounding)."""
        ratio = self.asked_s / self.frame_s
        if self.asked_s > MAX_FRAME_S:
            return f"plays {ratio:.3g}x faster than asked: a frame is shown at most {MAX_FRAME_S:g} s"
        if self.asked_s < self.least_s:
            return f"plays {1 / ratio:.3g}x slower than asked: a frame is shown at least {self.least_s:g} s"
        return None


def check_animation_path(out: str | Path, option: str = "--animate") -> None:
    """PipelineError unless ``out`` names an animation this machine can write (.gif; .mp4 with ffmpeg):
    checked before the work, as ``crowdsim.plotting.check_figure_path`` is for figures."""
    suffix = Path(out).suffix.lower()
    if suffix not in ANIMATION_SUFFIXES:
        raise PipelineError(f"{option} writes .gif or .mp4, got {Path(out).name!r}")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise PipelineError("an .mp4 needs ffmpeg, which is not installed here; ask for a .gif instead")


def _animation_legend(fig: Any, view: EpisodeView, sensor: float | None = None) -> dict[str, list[Any]]:
    """What each mark is, under the axes (nothing drawn is hidden): robots in their own colours (robot 0's
    stands for all), humans, goals, the paths so far, plans and predictions when the file has them, and the
    range of the sensor the controller was behind. Returns the handle and text of each entry by label, so
    that a frame shows only those of what it draws (``_show_drawn``)."""
    from matplotlib.lines import Line2D

    robot = robot_color(0)
    entries = [Line2D([], [], ls="none", marker="o", ms=9, mfc=robot, mec="k", mew=0.5, label="robot")]
    if view.human_positions.shape[1]:  # an episode without a crowd draws none
        entries.append(
            Line2D([], [], ls="none", marker="o", ms=9, mfc="none", mec=HUMAN_COLOR, mew=1.2, label="human")
        )
    entries += [
        Line2D([], [], ls="none", marker="*", ms=12, mfc=GOAL_COLOR, mec="k", mew=0.5, label="robot goal"),
        Line2D([], [], ls="-", color=robot, lw=1.0, alpha=0.6, label="robot path"),
    ]
    if view.plans:
        entries.append(Line2D([], [], ls="--", color=robot, lw=1.2, label="robot plan"))
    if has_predictions(view):
        entries.append(Line2D([], [], ls=":", color=HUMAN_COLOR, lw=1.0, label="predicted human path"))
    if sensor is not None:
        entries.append(
            Line2D([], [], ls="--", color=robot, lw=0.8, alpha=0.5, label=f"sensor range ({sensor:g} m)")
        )
    legend = fig.legend(handles=entries, loc="outside lower center", ncol=3, fontsize=7, frameon=False)
    return {t.get_text(): [h, t] for h, t in zip(legend.legend_handles, legend.get_texts(), strict=True)}


def _show_drawn(entries: dict[str, list[Any]], drawn: dict[str, bool]) -> list[Any]:
    """Hides the legend entries of marks that a frame does not draw (frame 0 listed a "robot path" before
    any path was drawn); hidden, not removed, so the legend keeps its place from frame to frame."""
    for label, visible in drawn.items():
        for artist in entries.get(label, ()):
            artist.set_visible(visible)
    return [artist for label in drawn for artist in entries.get(label, ())]


def _leaves(start: np.ndarray, points: np.ndarray) -> bool:
    """Whether a line from ``start`` through ``points`` (m, broadcast together) strays over a millimetre."""
    # under a pixel here, where a standing crowd's first prediction strays 5e-7 m; NaN compares False
    return bool(np.any(np.abs(points - start) > 1e-3))


def animation_figure(rec: Recording) -> tuple[Any, Callable[[int], list[Any]], EpisodeView]:
    """The animation's figure, its frame function (recorded state ``row`` -> changed artists) and the view."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from crowdsim.plotting import frame_axes

    view = episode_view(rec)
    m, n = view.robot_positions.shape[1], view.human_positions.shape[1]

    fig = Figure(figsize=(6, 6.5), layout="constrained")
    ax = fig.add_subplot()
    frame_axes(ax, view.robot_positions, view.human_positions, view.robot_goals)
    ax.set_title(rec.label, fontsize=9)  # the end's only on the last frame (frame_texts)
    ax.plot(*view.robot_goals.T, "*", color=GOAL_COLOR, mec="k", mew=0.5, ms=14, zorder=1)
    robots = [Circle((0, 0), view.radius, fc=robot_color(i), ec="k", lw=0.5, zorder=3) for i in range(m)]
    humans = [Circle((0, 0), view.radius, fill=False, ec=HUMAN_COLOR, lw=1.2, zorder=3) for _ in range(n)]
    sensor = sensor_radius(rec)
    # a ring that encloses the whole view at every state is drawn at a bound beyond it (ring_radius)
    drawn = None if sensor is None else ring_radius(ax, view.robot_positions, sensor)
    ranges = [] if drawn is None else [sensor_circle((0, 0), drawn, i) for i in range(m)]
    for patch in robots + humans + ranges:
        ax.add_patch(patch)
    trails = [ax.plot([], [], "-", color=robot_color(i), lw=1.0, alpha=0.6)[0] for i in range(m)]
    plans = [ax.plot([], [], "--", color=robot_color(i), lw=1.2)[0] for i in range(m)]
    predictions = [ax.plot([], [], ":", color=HUMAN_COLOR, lw=1.0)[0] for _ in range(n)]
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=9)
    entries = _animation_legend(fig, view, sensor)
    texts = frame_texts(rec, view.times, view.dt)

    def draw(row: int) -> list[Any]:
        step = int(view.steps[row])
        for i, patch in enumerate(robots):
            patch.center = view.robot_positions[row, i]
        for i, patch in enumerate(ranges):
            patch.center = view.robot_positions[row, i]
        for i in range(m):
            trails[i].set_data(view.robot_positions[: row + 1, i, 0], view.robot_positions[: row + 1, i, 1])
        for j, patch in enumerate(humans):
            patch.center = view.human_positions[row, j]
            patch.set_visible(not np.isnan(view.human_positions[row, j]).any())  # a replay's, not tracked
        plan = view.plans.get(step)
        for i, line in enumerate(plans):
            pts = np.vstack([view.robot_positions[row, i], plan[i]]) if plan is not None else np.empty((0, 2))
            line.set_data(pts[:, 0], pts[:, 1])
        prediction = view.predictions.get(step)
        for j, line in enumerate(predictions):
            pts = (
                np.vstack([view.human_positions[row, j], prediction[:, j]])
                if prediction is not None
                else np.empty((0, 2))
            )
            line.set_data(pts[:, 0], pts[:, 1])
        title, said = texts(row)
        ax.title.set_text(title)
        clock.set_text(said)
        drawn = {  # a line of some length: a constant-velocity prediction of a standing crowd is none
            "robot path": _leaves(view.robot_positions[0][None], view.robot_positions[: row + 1]),
            "robot plan": plan is not None and _leaves(view.robot_positions[row][:, None], plan),
            "predicted human path": prediction is not None
            and _leaves(view.human_positions[row][None], prediction),
        }
        return [
            *robots,
            *ranges,
            *humans,
            *trails,
            *plans,
            *predictions,
            *_show_drawn(entries, drawn),
            ax.title,
            clock,
        ]

    return fig, draw, view


def animate_recording(
    rec: Recording, out: str | Path, *, speed: float = 1.0, progress: bool | None = None
) -> AnimationFacts:
    """The episode as a GIF (Pillow) or, for a ``.mp4`` name, an MP4 (needs ffmpeg).

    One frame per recorded state, played at ``speed`` times simulated time; an episode of more than
    ``MAX_FRAMES`` states gets every k-th (and its last), played k times faster, so that it keeps its length
    in seconds. A frame is shown no longer than ``MAX_FRAME_S`` (a GIF's longest) and no shorter than
    ``MIN_FRAME_S`` (a GIF's: ``MIN_GIF_FRAME_S``, in whole centiseconds): an episode of longer (shorter)
    steps plays faster (slower) than asked, which the returned ``AnimationFacts`` say. ``progress``: a bar
    of the frames drawn (None: on a terminal only), as drawing them takes seconds to a minute.
    """
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter

    from predictors.progress import progress_bar

    out = Path(out)
    check_animation_path(out)
    fig, draw, view = animation_figure(rec)
    every = -(-len(view.times) // MAX_FRAMES)
    rows = list(range(0, len(view.times), every))
    if rows[-1] != len(view.times) - 1:
        rows.append(len(view.times) - 1)
    asked_s = every * view.dt / speed
    gif = out.suffix.lower() == ".gif"
    least_s = MIN_GIF_FRAME_S if gif else MIN_FRAME_S
    frame_s = min(max(asked_s, least_s), MAX_FRAME_S)
    fps = 1.0 / frame_s
    if gif:  # whole centiseconds, as the file holds them: matplotlib passes int(1000 / fps) ms, Pillow // 10
        centiseconds = round(frame_s * 100)
        frame_s, fps = centiseconds / 100, 1000 / (10 * centiseconds + 0.5)
    animation = FuncAnimation(fig, draw, frames=rows, blit=False)
    # matplotlib's stubs say fps: int, but the writers take any positive number (Pillow: 1000 / fps ms a
    # frame, ffmpeg: -r fps); 1 / frame_s is fractional (e.g. 2.5) and must not be rounded.
    writer = (
        PillowWriter(fps=fps)  # type: ignore[arg-type]
        if gif
        else FFMpegWriter(fps=fps)  # type: ignore[arg-type]
    )
    with progress_bar(
        total=len(rows), desc=f"animating {out.name}", unit="frame", leave=False, show=progress
    ) as bar:

        def drawn(_frame: int, _total: int) -> None:
            bar.update()

        save_figure(out, lambda name: animation.save(name, writer=writer, dpi=80, progress_callback=drawn))
    return AnimationFacts(len(rows), every, frame_s, asked_s, least_s)
