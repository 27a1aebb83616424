"""A robot team that sees only the humans near it: any controller, fed what a range-limited tracker gives.

The simulator hands a controller every human, observed since the episode began. A robot's sensors see the
people within some range, and its tracker starts a track when someone comes into view. ``RangeLimited``
wraps a controller so that it sees, each step, only the humans within ``radius`` of some robot, each with
the rows of history since its track began: the rows before are padded with the first tracked position, as
a tracker pads, and ``obs.human_observed`` holds the track lengths (``report_tracks=False``: None, so the
padding reads as the human's past, as it does for a tracker that does not report them). Only the history is
the tracker's: ``human_velocities`` and ``human_goals`` stay the simulator's, exact from a human's first
step in view (the networks read the history alone; the ORCA robots and the ORCA oracle read both, and so
see more than a tracker could). A human who leaves the range and comes back starts a new track. A human in
range at the episode's first step counts as tracked through the whole history: the simulator's humans
stood there before it, in view. (So per-class margins,
conformal-motion and -shortfall, class such a human by its motion from the first step, where the full
observation counts it ``step + 1`` times observed, "new", for 8 steps: a range that sees everyone plans as
the full observation only with margins of no classes, or without the track lengths.) The episode's metrics
stay the simulator's, over every human.

In a replayed crowd (``obs.human_present``, crowdsim.replay) a human is in view only while the recording
tracks it: its track begins when it appears. ``RangeLimited(inner, math.inf)`` is that alone, every tracked
human at any distance (what the closed loop wraps a controller in for a replayed crowd; no sensor, so it
adds nothing to the controller's description).

The number of humans in view changes from step to step, and an MPC builds an NLP per number: prepare them
first (``MPCController.prepare(n_robots, range(n_humans + 1))``), or the first step meeting each size builds
it. What the wrapped controller predicts for the humans it saw goes back to their places among every human:
``prediction`` and ``iteration_predictions`` are ``(H, N, 2)`` with NaN for the humans out of view (not
predicted), so that a recording shows them and calibration scores them; ``extra["visible"]`` lists the
humans it planned around and ``extra["tracked"]`` their track lengths as the controller was given them (None
with ``report_tracks=False``), by which calibration's scorer classes them as the controller did.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdsim.world import is_sensor_range, sensor_range_beyond
from pipelines.errors import PipelineError
from pipelines.loop.contract import called, checked_description, checked_output
from pipelines.loop.controllers import check_controller

if TYPE_CHECKING:
    from crowdsim.control import ControlOutput
    from crowdsim.env import Observation
    from pipelines.loop.controllers import Controller


def recorded_sensor_range(config: object) -> float | None:
    """The range a controller's recorded config says it was behind (``describe()``'s ``sensing.radius_m``,
    which ``RangeLimited`` adds), None for one that saw every human or a config that does not say."""
    sensing = config.get("sensing") if isinstance(config, dict) else None
    radius = sensing.get("radius_m") if isinstance(sensing, dict) else None
    return float(radius) if isinstance(radius, int | float) and is_sensor_range(radius) else None


class RangeLimited:
    """``inner`` fed the humans within ``radius`` metres of some robot (module docstring)."""

    def __init__(self, inner: Controller, radius: float, report_tracks: bool = True):
        check_controller(inner, "RangeLimited")  # a spec or a name in its place failed on inner.name
        radius = radius.item() if isinstance(radius, np.generic) else radius  # np.int64(3) read as no range
        if not (is_sensor_range(radius) or radius == math.inf):  # inf: the tracked humans of a replay
            raise PipelineError(f"sensor radius must be a finite number of metres > 0, got {radius!r}")
        beyond = None if radius == math.inf else sensor_range_beyond(radius)
        if beyond is not None:  # what a run's checks refuse, for whoever builds one in Python
            raise PipelineError(f"sensor radius {beyond}")
        if not isinstance(report_tracks, bool):  # a truthy "no" would report them
            raise PipelineError(f"report_tracks must be True or False, got {report_tracks!r}")
        self.inner, self.radius, self.report_tracks = inner, float(radius), report_tracks
        self.name, self.predictor = inner.name, inner.predictor
        # the simulator it was built for, which the loops check (pipelines.loop.controllers.check_built_for)
        self.env_config = getattr(inner, "env_config", None)
        self._in_view: np.ndarray = np.zeros(0, dtype=bool)  # per human, at the last step sensed
        self._track_start: np.ndarray = np.zeros(0, dtype=int)  # per human in view: the step its track began
        self._tracked: list[int] | None = None  # the track lengths handed on at the last step sensed

    def reset(self, obs: Observation) -> None:
        self._in_view = self._visible(obs)
        # in view before the episode too, standing where the history has them; in a replayed crowd, tracked
        # as long as the recording says
        length = len(obs.history)
        before = length if obs.human_observed is None else np.minimum(obs.human_observed, length)
        self._track_start = obs.step - before + 1 + np.zeros(obs.n_humans, dtype=int)
        called(self.inner, "reset", self.sensed(obs))

    def act(self, obs: Observation) -> ControlOutput:
        # The inner controller through the loop's contract, as if unwrapped: a plugin's error or broken
        # output is its own one-line PipelineError, a shipped controller's exception a bug with its traceback
        sensed = self.sensed(obs)
        out = checked_output(self.inner, called(self.inner, "act", sensed), sensed)
        visible = np.flatnonzero(self._in_view)
        return dataclasses.replace(
            out,
            prediction=None
            if out.prediction is None
            else _every_human(out.prediction, visible, obs.n_humans),
            iteration_predictions=tuple(
                _every_human(p, visible, obs.n_humans) for p in out.iteration_predictions
            ),
            extra={**out.extra, "visible": visible.tolist(), "tracked": self._tracked},
        )

    def describe(self) -> dict[str, Any]:
        described = checked_description(self.inner)
        if self.radius == math.inf:  # no sensor: the replay's tracks, which the simulator's config names
            return described
        sensing = {"radius_m": self.radius, "report_tracks": self.report_tracks}
        return {**described, "config": {**described.get("config", {}), "sensing": sensing}}

    def close(self) -> None:
        called(self.inner, "close")

    def sensed(self, obs: Observation) -> Observation:
        """``obs`` as the tracker gives it: the visible humans, their padded tracks and track lengths."""
        visible = self._visible(obs)
        if len(self._in_view) != obs.n_humans:  # act without reset: no track yet
            self._in_view, self._track_start = np.zeros(obs.n_humans, bool), np.zeros(obs.n_humans, int)
        # a track goes on while its human stays in view; one who left and came back starts a new one
        self._track_start = np.where(self._in_view, self._track_start, obs.step)
        self._in_view = visible
        humans = np.flatnonzero(visible)
        tracked = obs.step - self._track_start[humans] + 1  # positions observed, the current one included
        self._tracked = tracked.tolist() if self.report_tracks else None
        m, length = obs.n_robots, len(obs.history)
        history = np.concatenate([obs.history[:, :m], obs.history[:, m + humans]], axis=1)
        for column, k in enumerate(tracked, start=m):
            if k < length:
                history[: length - k, column] = history[length - k, column]
        return dataclasses.replace(
            obs,
            human_positions=obs.human_positions[humans],
            human_velocities=obs.human_velocities[humans],
            human_goals=obs.human_goals[humans],
            history=history,
            human_observed=tracked.astype(np.int64) if self.report_tracks else None,
            human_present=None,  # every human handed on is there
        )

    def _visible(self, obs: Observation) -> np.ndarray:
        """``(N,)`` bool: the humans within ``radius`` of some robot, and tracked now in a replayed crowd."""
        return obs.humans_in_view(self.radius)


def _every_human(prediction: np.ndarray, visible: np.ndarray, n_humans: int) -> np.ndarray:
    """``(H, n_humans, 2)``: the ``(H, len(visible), 2)`` prediction of the humans in view at their places
    among every human, NaN for the others (not predicted: pipelines.loop.contract)."""
    every = np.full((len(prediction), n_humans, 2), np.nan)
    every[:, visible] = prediction
    return every
