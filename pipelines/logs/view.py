"""A recording's episode as arrays: the recorded states, goals, plans and predictions, for plots and checks.

The rows are the steps whose /robots and /humans states both made it into the file (a truncated file's last
state may lack one of them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from crowdsim.world import DT, RADIUS
from pipelines.errors import PipelineError
from pipelines.logs.reader import Recording
from predictors.text_table import counted


@dataclass(frozen=True)
class EpisodeView:
    """The recorded states and plans as arrays (state rows are the steps that made it into the file)."""

    times: np.ndarray  # (T,) s
    steps: np.ndarray  # (T,) int
    robot_positions: np.ndarray  # (T, M, 2) m
    human_positions: (
        np.ndarray
    )  # (T, N, 2) m; NaN where a replayed crowd's human is not tracked (/humans present)
    robot_goals: np.ndarray  # (M, 2) m
    human_goals: np.ndarray  # (N, 2) m
    plans: dict[int, np.ndarray]  # step -> (M, H, 2) m
    predictions: dict[int, np.ndarray]  # step -> (H, N, 2) m
    dt: float  # s
    radius: float  # m

    def row_at(self, t: float) -> int:
        """Index of the recorded state nearest to time ``t`` (s), ``t`` brought into the recorded span."""
        return int(np.argmin(np.abs(self.times - self._in_span(t))))

    def _in_span(self, t: float) -> float:
        """``t`` brought into the recorded span: past ~1e16 s every distance to a state rounded to ``t``
        itself (or to a float beside it), and the "nearest" state was the first (or an arbitrary one)."""
        return float(np.clip(t, self.times.min(), self.times.max()))

    def planned_row_at(self, t: float) -> int:
        """Index of the state nearest to time ``t`` (s) among those with a plan or a prediction, when the
        recording has any: the final state has neither (no step is taken from it), nor has a cut file's last
        state, so the nearest state of all could not show what is asked for."""
        planned = np.flatnonzero([int(s) in self.plans or int(s) in self.predictions for s in self.steps])
        if planned.size == 0:
            return self.row_at(t)
        return int(planned[np.argmin(np.abs(self.times[planned] - self._in_span(t)))])


def _points(rows: list[Any], n: int) -> np.ndarray:
    return np.asarray(rows, dtype=float).reshape(n, 2)


# m: no scene is larger (the gymnasium environment's bounds are tens of metres); past it a file is damaged
MAX_COORD = 1e6


def episode_view(rec: Recording) -> EpisodeView:
    """The arrays; PipelineError when the recorded states do not make one episode (sizes that change)."""
    try:
        return _episode_view(rec)
    except PipelineError:
        raise
    except ValueError as exc:  # a reshape that does not fit: another agent count in some message
        raise PipelineError(
            f"{rec.path}: the recorded states do not make one episode ({exc}); --check tells more"
        ) from None


def _episode_view(rec: Recording) -> EpisodeView:
    humans = rec.data("/humans")
    by_step = {h["step"]: h for h in humans}
    robots = [r for r in rec.data("/robots") if r["step"] in by_step]  # a cut can fall between the two
    if not robots:
        raise PipelineError(f"{rec.path} holds no complete state (/robots and /humans) to draw")
    steps = [r["step"] for r in robots]
    m, n = len(robots[0]["positions"]), len(humans[0]["positions"])
    ep = rec.episode()
    times = np.array([r["time"] for r in robots], dtype=float)
    # The "episode" record may lack dt or radius (a log from another writer, or a value that does not parse
    # or a radius beyond the simulator's, which Recording.episode drops): the recorded times tell dt, else
    # both are the default world's.
    dt = float(ep["dt"]) if "dt" in ep else float(np.median(np.diff(times))) if len(times) > 1 else DT
    plans = {p["step"]: np.asarray(p["positions"], dtype=float) for p in rec.data("/mpc/plan")}
    if any(len(plan) != m for plan in plans.values()):
        raise ValueError(f"a /mpc/plan is not for {counted(m, 'robot')}")
    human_positions = np.array([_points(by_step[s]["positions"], n) for s in steps]).reshape(len(steps), n, 2)
    for row, s in enumerate(steps):  # a replayed crowd: the humans not tracked then are not there
        present = by_step[s].get("present")
        if isinstance(present, list) and len(present) == n:
            human_positions[row, ~np.asarray(present, dtype=bool)] = np.nan
    robot_positions = np.array([_points(r["positions"], m) for r in robots])
    _check_positions(rec, robot_positions, human_positions)
    return EpisodeView(
        times=times,
        steps=np.array(steps, dtype=int),
        robot_positions=robot_positions,
        human_positions=human_positions,
        robot_goals=_points(robots[0]["goals"], m),
        human_goals=_points(humans[0]["goals"], n),
        plans=plans,
        predictions={
            p["step"]: np.asarray(p["positions"], dtype=float).reshape(len(p["positions"]), n, 2)
            for p in rec.data("/mpc/prediction")
        },
        dt=dt,
        radius=float(ep.get("radius", RADIUS)),
    )


def _check_positions(rec: Recording, robots: np.ndarray, humans: np.ndarray) -> None:
    """PipelineError for positions no episode has: a robot's not finite, or anyone's beyond ``MAX_COORD``
    (a human's NaN is one not there, in a replayed crowd). A damaged file drew nothing of use, with numpy's
    overflow warnings and their source lines."""
    if np.isfinite(robots).all() and np.all(np.abs(robots) <= MAX_COORD):
        if not np.any(np.abs(np.nan_to_num(humans, nan=0.0)) > MAX_COORD):  # inf is beyond too
            return
    raise PipelineError(
        f"{rec.path}: its /robots or /humans positions hold values no episode has (inf, NaN or beyond "
        f"{MAX_COORD:g} m): a damaged recording; --check names the messages"
    )
