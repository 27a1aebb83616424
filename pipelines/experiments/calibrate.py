"""Closed-loop calibration data: a predictor's errors inside the MPC, with the humans reacting to the robots.

Real scenes (``predictors.real_data.real_errors``) measure a predictor where it was trained; the
controller meets it elsewhere: ORCA humans who yield to robots and then close the gap again. So the default
calibration source is the closed loop itself: CMPC episodes with the paper's method (no margins) on seeds
disjoint from every evaluation seed, recording at each step the prediction the final solve used and, once
the episode is over, where each human really was ``k`` steps later.

Only humans within ``near`` metres of some robot at prediction time are scored. The margin acts only where
the robot-human penalty is active; a human walking alone on the far side of the scene is predicted almost
perfectly by any model, and counting such samples would shrink the quantile without making a crossing any
safer. ``near = inf`` scores everyone (stored as ``"near": null`` in a block's details: JSON has no
infinity).

Seeds: calibration episodes use ``seed, seed + 1, ...`` from ``CALIBRATION_SEED`` (one million); sweeps and
``simulate`` use small seeds (a 1000-episode cell uses 0..499), so the two never share a crowd.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any, Final, NamedTuple, cast

import numpy as np

from crowdsim.scenarios import MAX_HUMANS
from crowdsim.world import is_sensor_range, sensor_range_refused
from pipelines.errors import PipelineError
from pipelines.loop.margins import MarginSpec
from pipelines.loop.motion_classes import observed_classes
from predictors.progress import progress_bar

if TYPE_CHECKING:
    from crowdsim.env import Observation
    from pipelines.loop.controllers import ControllerSpec, ControlOutput
    from pipelines.loop.episode import EpisodeResult
    from pipelines.loop.spec import ControllerName

CALIBRATION_SEED: Final[int] = 1_000_000  # first seed of calibration episodes (module docstring)
NEAR: Final[float] = 3.0  # m, humans scored: within this distance of a robot when predicted (docstring)
SCENARIOS: Final[tuple[str, str]] = ("circle", "perpendicular")


class PredictionErrors:
    """An episode observer that turns each step's prediction into displacement errors ``(n, H)`` (NaN where
    the episode ended before step ``k``), appended to ``errors`` at the end of every episode, each row's
    motion class at prediction time (``predictors.conformal_classes``) to ``classes``, and each row's distance
    shortfall to ``shortfall``.

    The shortfall at step ``k`` is how much closer the human really came to a robot than predicted, measured
    at the robot's realised position ``r``: ``max_j (|r_j - predicted| - |r_j - realised|)`` over the robots
    within ``near`` of the prediction, clipped at 0 (NaN when no robot is that near). It is the score that
    safety needs: if it is at most ``m_k`` and the plan keeps ``d_min + m_k`` from the prediction, the human
    is at least ``d_min`` away (the triangle inequality makes the displacement error an upper bound of it).
    """

    def __init__(self, near: float = NEAR):
        if not near > 0:
            raise PipelineError(f"near must be > 0 m, got {near!r}")
        self.near = near
        self.rows: list[np.ndarray] = []
        self.class_rows: list[np.ndarray] = []
        self.shortfall_rows: list[np.ndarray] = []
        self._made: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []

    @property
    def errors(self) -> np.ndarray:
        return np.concatenate(self.rows) if self.rows else np.zeros((0, 0))

    @property
    def shortfall(self) -> np.ndarray:
        return np.concatenate(self.shortfall_rows) if self.shortfall_rows else np.zeros((0, 0))

    @property
    def classes(self) -> np.ndarray:
        return np.concatenate(self.class_rows) if self.class_rows else np.zeros(0, dtype=np.int64)

    def on_reset(self, obs: Observation, meta: Mapping[str, Any]) -> None:
        self._made = []

    def on_step(self, obs: Observation, out: ControlOutput, next_obs: Observation) -> None:
        if out.prediction is None or obs.n_humans == 0:
            return
        prediction = np.asarray(out.prediction, dtype=float)
        # the humans predicted: all of them, or those in view (a replayed crowd's tracked people, NaN else)
        predicted = np.isfinite(prediction).all(axis=(0, 2))
        gaps = np.linalg.norm(obs.human_positions[:, None] - obs.robot_positions[None], axis=-1)
        close = gaps.min(axis=1) <= self.near if obs.n_robots else np.ones(obs.n_humans, dtype=bool)
        close &= predicted
        if close.any():
            # what the controller saw, as the controller classifies it: behind a sensor, by the tracker's
            # track lengths (classed by the simulator's, a person just come into view was not "new")
            shown = _of_humans(obs, np.flatnonzero(predicted))
            if "tracked" in out.extra:
                shown = dataclasses.replace(shown, human_observed=_tracked(out.extra, predicted))
            classes = observed_classes(shown)
            self._made.append((obs.step, prediction, close, classes[close[predicted]]))

    def on_end(self, result: EpisodeResult) -> None:
        truth = np.asarray(result.human_positions, dtype=float)  # (T+1, N, 2)
        robots = np.asarray(result.robot_positions, dtype=float)  # (T+1, M, 2)
        if result.human_present is not None:  # a replayed crowd: no truth where a person is not tracked
            truth = np.where(np.asarray(result.human_present, dtype=bool)[..., None], truth, math.nan)
        last = len(truth) - 1
        for step, prediction, close, classes in self._made:
            horizon = len(prediction)
            errors = np.full((int(close.sum()), horizon), math.nan)
            shortfall = np.full_like(errors, math.nan)
            for k in range(1, horizon + 1):
                if step + k <= last:
                    predicted, realised = prediction[k - 1, close], truth[step + k, close]
                    errors[:, k - 1] = np.linalg.norm(predicted - realised, axis=-1)
                    shortfall[:, k - 1] = _shortfall(predicted, realised, robots[step + k], self.near)
            self.rows.append(errors)
            self.class_rows.append(classes)
            self.shortfall_rows.append(shortfall)
        self._made = []


@dataclass(frozen=True)
class ClosedLoopPlan:
    """Which episodes a closed-loop calibration runs."""

    predictor: str
    episodes: int = 200
    seed: int = CALIBRATION_SEED
    humans: tuple[int, ...] = (5, 6, 7, 8, 9)
    controller: str = "cmpc"
    profile: str = "paper"
    visibility: str = "visible"
    near: float = NEAR
    # The robots behind a sensor of this range (m; pipelines.loop.sensing), None: they see every human. Its
    # margins then cover the people who come into view, predicted from short tracks, as such a robot meets
    # them (docs/replayed_crowds.md, "Behind a sensor"); recorded in a block's details only when set.
    sensor_range: float | None = None
    # With sensor_range: whether its tracker reports track lengths (False: the controller classes the people
    # it sees from their padded tracks, as one behind `--no-sensor-tracks` does); recorded only when False.
    sensor_tracks: bool = True
    # What the controller plans with while the errors are measured: none for a calibration (the paper's
    # method); a held-out check may plan with the calibrated margins, to see whether the coverage survives
    # the change they make to how the robots, and so the humans, move.
    margins: MarginSpec = MarginSpec()

    def __post_init__(self):
        if isinstance(self.episodes, bool) or not isinstance(self.episodes, int) or not 1 <= self.episodes:
            raise PipelineError(f"--episodes must be a positive integer, got {self.episodes!r}")
        if self.seed < 0:
            raise PipelineError(f"--seed must be >= 0, got {self.seed}")
        if not self.humans or min(self.humans) < 1:
            raise PipelineError(f"--humans must list positive numbers, got {self.humans}")
        if max(self.humans) > MAX_HUMANS:  # else the episode of that size failed after those before it ran
            raise PipelineError(f"--humans must be in 1..{MAX_HUMANS}, got {max(self.humans)}")
        # A set of crowd sizes, as a sweep's --humans: 7,5 gave the seeds other sizes than 5,7 (another
        # calibration of the same episodes' kind), and the block recorded the order as typed.
        object.__setattr__(self, "humans", tuple(sorted(self.humans)))
        if self.controller not in ("cmpc", "dmpc"):
            raise PipelineError(f"calibration runs cmpc or dmpc, got {self.controller!r}")
        if not self.near > 0:  # NaN too
            raise PipelineError(f"--near must be > 0 m (inf scores everyone), got {self.near!r}")
        if self.sensor_range is not None and not is_sensor_range(self.sensor_range):
            raise PipelineError(
                f"--sensor-range must be a finite number of metres > 0, got {self.sensor_range!r}"
            )
        refused = None if self.sensor_range is None else sensor_range_refused(self.sensor_range)
        if refused is not None:  # a plan of the command line's: no record reads back through it
            raise PipelineError(f"--sensor-range: {refused}")
        if not isinstance(self.sensor_tracks, bool):  # a truthy "no" would report them
            raise PipelineError(f"sensor_tracks must be True or False, got {self.sensor_tracks!r}")
        if not self.sensor_tracks and self.sensor_range is None:
            raise PipelineError("--no-sensor-tracks is a sensor's: give --sensor-range M too")

    def schedule(self) -> list[tuple[str, int, int]]:
        """``(scenario, n_humans, seed)`` of every episode: scenarios alternate, crowd sizes cycle."""
        return [
            (SCENARIOS[i % 2], self.humans[(i // 2) % len(self.humans)], self.seed + i)
            for i in range(self.episodes)
        ]


def _tracked(extra: Mapping[str, Any], predicted: np.ndarray) -> np.ndarray | None:
    """The track lengths a sensed controller was given (``pipelines.loop.sensing``: ``extra["tracked"]`` of
    the humans ``extra["visible"]``) of the humans ``predicted``; None where it was given none."""
    if extra["tracked"] is None:
        return None
    lengths = dict(zip(extra["visible"], extra["tracked"], strict=True))
    return np.array([lengths[i] for i in np.flatnonzero(predicted)], dtype=np.int64)


def _of_humans(obs: Observation, humans: np.ndarray) -> Observation:
    """``obs`` with only ``humans`` (indices), as a controller shown those alone sees it: their positions,
    velocities, history and track lengths (a replayed crowd's people in view, whose track lengths the
    recording gives as pipelines.loop.sensing's tracker counts them)."""
    if len(humans) == obs.n_humans:
        return obs
    m = obs.n_robots
    return dataclasses.replace(
        obs,
        human_positions=obs.human_positions[humans],
        human_velocities=obs.human_velocities[humans],
        human_goals=obs.human_goals[humans],
        history=np.concatenate([obs.history[:, :m], obs.history[:, m + humans]], axis=1),
        human_observed=None if obs.human_observed is None else obs.human_observed[humans],
        human_present=None,
    )


def _shortfall(predicted: np.ndarray, realised: np.ndarray, robots: np.ndarray, near: float) -> np.ndarray:
    """``(n,)`` distance shortfall of each human (``PredictionErrors``) against the robots at ``robots``."""
    planned = np.linalg.norm(robots[None] - predicted[:, None], axis=-1)  # (n, M)
    real = np.linalg.norm(robots[None] - realised[:, None], axis=-1)
    gap = np.where(planned <= near, planned - real, -np.inf).max(axis=1, initial=-np.inf)
    return np.where(np.isfinite(gap), np.maximum(gap, 0.0), np.nan)


class ClosedLoopErrors(NamedTuple):
    """What closed-loop calibration episodes measured (``PredictionErrors``)."""

    errors: np.ndarray  # (n, H) displacement errors, m
    classes: np.ndarray  # (n,) motion class at prediction time
    shortfall: np.ndarray  # (n, H) distance shortfall, m
    details: dict[str, Any]  # what identifies the episodes
    predictor_sha256: str | None  # of the weights they planned with, as their controller loaded them


def closed_loop_errors(
    plan: ClosedLoopPlan,
    progress: bool | None = None,
    check_weights: Callable[[str | None], None] | None = None,
) -> ClosedLoopErrors:
    """Run ``plan``'s episodes and return what they measured. ``check_weights``: called with the sha256 of
    the weights the controller loaded before any episode, so that its refusal (held-out episodes of other
    weights than the calibration's) costs none: made after them, it came minutes late."""
    from crowdsim.profiles import make_env_config
    from crowdsim.world import PAPER_ROBOTS
    from pipelines.loop.controllers import make_controller
    from pipelines.loop.episode import behind_sensor, run_episode

    env_config = make_env_config(plan.profile, plan.visibility)
    spec = _controller_spec(plan).behind(plan.sensor_range, plan.sensor_tracks)
    controller = make_controller(spec, env_config)
    sha256 = controller.describe()["predictor_sha256"]  # the zoo's entry, read again, may be newer weights
    if check_weights is not None:
        try:
            check_weights(sha256)
        except BaseException:
            controller.close()
            raise
    # behind the sensor, the NLP of every crowd size in view built before the first episode
    controller = behind_sensor(
        controller, plan.sensor_range, plan.sensor_tracks, PAPER_ROBOTS, max(plan.humans)
    )
    observer = PredictionErrors(plan.near)
    successes = 0
    try:
        bar = progress_bar(plan.schedule(), desc=f"calibrating {plan.predictor}", unit="ep", show=progress)
        for scenario, n_humans, seed in bar:
            result = run_episode(
                controller,
                seed=seed,
                scenario=scenario,
                n_humans=n_humans,
                env_config=env_config,
                observers=(observer,),
            )
            successes += result.metrics.success
    finally:
        controller.close()
    details = asdict(plan) | {
        "near": near_json(plan.near),
        "margins": plan.margins.label,
        "seeds": [plan.seed, plan.seed + plan.episodes - 1],
        "successes": successes,
    }
    if plan.sensor_range is None:  # the blocks of every robot seeing everyone, as made before the option
        del details["sensor_range"]
    if plan.sensor_tracks:  # a tracked sensor's blocks, as made before the option
        del details["sensor_tracks"]
    return ClosedLoopErrors(observer.errors, observer.classes, observer.shortfall, details, sha256)


def _controller_spec(plan: ClosedLoopPlan) -> ControllerSpec:
    from pipelines.loop.controllers import ControllerSpec

    # ClosedLoopPlan.__post_init__ admits "cmpc" and "dmpc" only.
    return ControllerSpec(cast("ControllerName", plan.controller), plan.predictor, margins=plan.margins)


def plan_horizon(plan: ClosedLoopPlan) -> int:
    """The steps ``plan``'s controller predicts, so the steps its errors cover: the MPC's horizon under the
    plan's profile, which calibration does not change."""
    from crowdsim.profiles import make_env_config
    from pipelines.loop.mpc import mpc_config

    world = make_env_config(plan.profile, plan.visibility).world()
    return mpc_config(_controller_spec(plan), world=world).horizon


def near_json(near: float) -> float | None:
    """``near`` as a block's details store it: JSON has no infinity, so null is ``inf`` (everyone scored)."""
    return near if math.isfinite(near) else None


def errors_sha256(errors: np.ndarray, details: dict[str, Any], classes: np.ndarray | None = None) -> str:
    """Identifies closed-loop calibration data: the errors themselves (with their motion classes) and the
    settings that produced them."""
    import hashlib
    import json

    digest = hashlib.sha256(np.ascontiguousarray(errors, dtype="<f8").tobytes())
    if classes is not None:
        digest.update(np.ascontiguousarray(classes, dtype="<i8").tobytes())
    digest.update(json.dumps(details, sort_keys=True, default=str).encode())
    return digest.hexdigest()
