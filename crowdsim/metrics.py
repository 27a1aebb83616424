"""The paper's episode metrics (Section VI; DESIGN.md "Crowd simulator"), computed from a recorded trajectory.

Sampling. ``collision``, ``contact``, ``min_distance`` and the per-step counts evaluate distances at the
recorded states only, every ``dt = 0.4`` s. That is not what CrowdNav does: its ``step()`` (the paper
authors' fork, ``crowd_sim.py``, as upstream) takes the closest approach within each step, the relative
motion of robot and human a straight segment (``point_to_segment_dist``), and CrowdNav's collision is that
swept distance below the sum of the radii. The paper defines its collision rate as the % of simulations in
which the minimum robot-pedestrian distance is below 0.8 m and never says where that minimum is evaluated
(its MPC code is unpublished). ``collision`` stays sampled at the steps, so that episodes compare metric for
metric with earlier records and Table II runs; the ``*_between_steps`` fields give the between-step figure:
every agent moves in a straight line between its recorded positions, and the closest approach over each
step is taken. The between-step distance is never above the sampled one; with 0.4 s steps the two minima
differ by a few centimetres at most, enough to turn one episode in 20 to 40 into a collision (robots
accelerating within a step follow a parabola, which the segment approximates).

* success, under the trajectory's ``success_rule`` (``EnvConfig.success_rule``): "simultaneous" (paper
  profile, the authors' CrowdNav fork) when at some step every robot is within its radius of its goal
  (strictly closer than ``radius``) at once; "first_reach" (v1) when every robot came within its radius of
  its goal at some step, each at its own.
* travel time: the first step at which the rule holds, as a time (NaN unless success). Either way
  ``reach_times`` keeps each robot's own first reach.
* collision: the minimum robot-human centre distance over the recorded states is below ``d_min = 0.8`` m.
* contact: that minimum is below the sum of the radii (0.6 m): physical contact.
* per-step counts: ``collision_steps``, ``contact_steps`` and ``discomfort_steps`` count the recorded
  states (rows 0..T) at which the condition holds; ``aggregate`` turns them into frequencies per evaluated
  state (over T + 1 states, each distance at the state). Not CrowdNav's per-step count, which tests the
  closest approach within each of the T steps (higher where agents pass close between states); the
  between-steps rates below make that within-step test, per episode.
* discomfort: at some step a robot's projected path intersects a human's projected path; a projected path is
  the closed segment from the agent's position to ``position + velocity * 1.2 s`` (length speed x 1.2 s). An
  agent standing still projects a point; touching segments count as intersecting.
* min distance: robot-human (the collision metric's number); robot-robot and human-human minima are kept too.
* replayed crowds (``Trajectory.human_present``, crowdsim.replay): a human counts only at the rows where it
  is tracked, and between steps only over a step it is tracked at both ends.
* between steps: ``min_distance_between_steps`` is the robot-human closest approach over the whole episode
  with linear motion within each step, ``min over k, s in [0, 1] of |d_k + s (d_(k+1) - d_k)|`` for the
  relative position ``d`` of every robot-human pair (the recorded states included, so it is never above
  ``min_distance``); ``collision_between_steps`` and ``contact_between_steps`` are it below 0.8 m and below
  the sum of the radii (CrowdNav's collision, what ``crowdsim.gym_env``'s reward and ``end_on_collision``
  use).
* path length: per robot, the length of the polyline through its positions over the whole episode.
* robot-robot contact (not a metric of the paper, whose metrics are all robot-human): ``robot_contact``, the
  minimum robot-robot centre distance over the recorded states (``min_distance_robots``) is below the sum of
  the radii, two robots touching; ``robot_contact_steps`` counts the recorded states at which some pair of
  robots is that close. Sampled at the steps as ``contact``; False and 0 with one robot. Between steps as
  for robot-human: ``min_distance_robots_between_steps`` is the robot-robot closest approach with linear
  motion within each step (inf with one robot), ``robot_contact_between_steps`` it below the sum of the radii:
  two robots that cross within a step touch there while no recorded state shows it.

The distances these are computed from, at the recorded states and between them, are crowdsim.distances.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any, Final, cast

import numpy as np

from crowdsim.conventions import SUCCESS_RULES, SuccessRule
from crowdsim.distances import (
    min_distance_between_steps,
    min_robot_distance_between_steps,
    row_min_distance,
    row_min_within,
)
from crowdsim.errors import SimulationError
from crowdsim.world import D_MIN

# m, d_min of Table I: personal-space violation (Section VI). The metric's, fixed: a run that plans with
# another d_min (MPCConfig.d_min) is still scored against Table I's, so its rates compare with the paper's.
COLLISION_DISTANCE: Final[float] = D_MIN
DISCOMFORT_HORIZON: Final[float] = 1.2  # s, "the proportional factor is chosen as 1.2 s" (Section VI)
# Fields added after records were first written: EpisodeMetrics.from_dict leaves them None when absent.
ADDED_COUNTS: Final[tuple[str, ...]] = ("collision_steps", "contact_steps")
BETWEEN_STEPS: Final[tuple[str, ...]] = (
    "min_distance_between_steps",
    "collision_between_steps",
    "contact_between_steps",
)
ROBOT_CONTACT: Final[tuple[str, ...]] = (
    "robot_contact",
    "robot_contact_steps",
    "min_distance_robots_between_steps",
    "robot_contact_between_steps",
)
ADDED_FIELDS: Final[tuple[str, ...]] = (*ADDED_COUNTS, *BETWEEN_STEPS, *ROBOT_CONTACT)
# The episode flags among the added fields: aggregate's rate of each is NaN when some episode lacks it.
ADDED_FLAGS: Final[tuple[str, ...]] = (*BETWEEN_STEPS[1:], ROBOT_CONTACT[0], ROBOT_CONTACT[3])
# as_dict writes inf as null; for these fields inf is the value without any pair of agents.
_INF_WHEN_NULL: Final[tuple[str, ...]] = (
    "min_distance",
    "min_distance_robots",
    "min_distance_humans",
    "min_distance_between_steps",
    "min_distance_robots_between_steps",
)


@dataclass(frozen=True)
class Trajectory:
    """Everything recorded in one episode; row ``k`` is time ``k * dt``."""

    robot_positions: np.ndarray  # (T+1, M, 2) m
    robot_velocities: np.ndarray  # (T+1, M, 2) m/s
    human_positions: np.ndarray  # (T+1, N, 2) m
    human_velocities: np.ndarray  # (T+1, N, 2) m/s, the ORCA velocity each human moved with
    robot_goals: np.ndarray  # (M, 2) m
    human_goals: np.ndarray  # (N, 2) m
    robot_accelerations: np.ndarray  # (T, M, 2) m/s^2, the applied (clipped) accelerations
    dt: float  # s
    radius: float  # m, every agent
    success_rule: SuccessRule = "simultaneous"  # how success is decided (module docstring), EnvConfig's
    # (T+1, N) bool, the humans tracked at each row of a replayed crowd (crowdsim.replay); None: all, always
    human_present: np.ndarray | None = None

    def __post_init__(self):
        if self.success_rule not in SUCCESS_RULES:
            raise SimulationError(
                f"Trajectory.success_rule must be one of {list(SUCCESS_RULES)}, got {self.success_rule!r}"
            )

    @property
    def n_steps(self) -> int:
        return len(self.robot_positions) - 1


@dataclass(frozen=True)
class EpisodeMetrics:
    """One episode's metrics (module docstring); ``as_dict`` / ``from_dict`` round-trip through JSON."""

    success: bool  # the robots reached their goals before the time limit, under the success rule
    travel_time: float  # s until the success rule held; NaN unless success
    collision: bool  # min robot-human distance < 0.8 m
    contact: bool  # min robot-human distance < sum of radii
    discomfort: bool  # projected paths of a robot and a human intersected at some step
    timeout: bool  # not success: under "simultaneous" every robot may have reached its goal, but not at once
    min_distance: float  # m, robot-human centre distance (inf without humans)
    min_distance_robots: float  # m, robot-robot (inf with one robot)
    min_distance_humans: float  # m, human-human (inf with fewer than two humans)
    path_length: tuple[float, ...]  # m, per robot
    reach_times: tuple[float, ...]  # s, first time each robot was within its radius of its goal (NaN: never)
    discomfort_steps: int  # states (rows 0..T) with at least one intersecting robot/human pair
    # States (rows 0..T) whose minimum robot-human distance is below 0.8 m, resp. below the sum of the radii.
    # None only when rebuilt by from_dict from a record written before the counts existed.
    collision_steps: int | None
    contact_steps: int | None
    n_steps: int  # simulation steps in the episode; the trajectory has n_steps + 1 states
    # Robot-human closest approach with linear motion within each step (m, inf without humans), and it below
    # 0.8 m, resp. below the sum of the radii (module docstring). None only when rebuilt by from_dict from a
    # record written before them.
    min_distance_between_steps: float | None
    collision_between_steps: bool | None
    contact_between_steps: bool | None
    # Two robots touched: min robot-robot distance < sum of radii, at the recorded states (not in the paper);
    # and the states (rows 0..T) at which some pair did. None only when rebuilt by from_dict from a record
    # written before them.
    robot_contact: bool | None
    robot_contact_steps: int | None
    # Robot-robot closest approach with linear motion within each step (m, inf with one robot) and it below
    # the sum of the radii; None only when rebuilt from a record written before them.
    min_distance_robots_between_steps: float | None
    robot_contact_between_steps: bool | None

    def as_dict(self) -> dict[str, Any]:
        """JSON-friendly (NaN and inf become None)."""

        def clean(x):
            if isinstance(x, tuple):
                return [clean(v) for v in x]
            if isinstance(x, float) and not math.isfinite(x):
                return None
            return x

        return {k: clean(v) for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> EpisodeMetrics:
        """Rebuild from ``as_dict``'s output (e.g. read back from JSON).

        null becomes inf for the minimum distances (no pair of agents) and NaN elsewhere (travel time, reach
        times), but a null flag or count (``_NEVER_NULL``) raises SimulationError; lists become tuples. The
        fields in ``ADDED_FIELDS`` may be absent (records written before them) and are then None; any other
        missing key raises SimulationError naming it.
        """
        names = [f.name for f in fields(cls)]
        missing = [n for n in names if n not in record and n not in ADDED_FIELDS]
        if missing:
            raise SimulationError(f"episode metrics record lacks {missing}")
        values: dict[str, Any] = {}
        for name in names:
            value = record.get(name)
            if name not in record:  # an added field, absent from an older record
                value = None
            elif name in _INF_WHEN_NULL:
                value = math.inf if value is None else float(value)
            elif isinstance(value, list | tuple):
                value = tuple(math.nan if v is None else v for v in value)
            elif value is None and name in _NEVER_NULL:  # NaN reads as true: a failure counted a success
                raise SimulationError(f"episode metrics record's {name} is null, not {_NEVER_NULL[name]}")
            elif value is None and name not in ADDED_FIELDS:
                value = math.nan
            values[name] = value
        return cls(**values)


# The flags and counts every record holds (not those added later, which may be null): a null one is no value
_NEVER_NULL: Final[dict[str, str]] = {
    f.name: {"bool": "true or false", "int": "a whole number"}[str(f.type)]
    for f in fields(EpisodeMetrics)
    if f.type in ("bool", "int") and f.name not in ADDED_FIELDS
}


def first_reach_steps(robot_positions: np.ndarray, robot_goals: np.ndarray, radius: float) -> np.ndarray:
    """Index of the first row where each robot is strictly within ``radius`` of its goal, -1 if never. (M,)"""
    inside = np.linalg.norm(robot_positions - robot_goals[None], axis=-1) < radius  # (T+1, M)
    return np.where(inside.any(axis=0), inside.argmax(axis=0), -1)


def _success_step(traj: Trajectory, reach: np.ndarray, rule: str) -> int:
    """First row at which ``rule`` holds, -1 if never (module docstring). Never row 0: the simulator judges
    success after a step, so robots that start on their goals succeed at the first step, or not at all."""
    if rule == "first_reach":
        return max(int(reach.max()), 1) if (reach >= 0).all() else -1
    inside = np.linalg.norm(traj.robot_positions - traj.robot_goals[None], axis=-1) < traj.radius
    together = inside.all(axis=1)
    together[0] = False
    return int(together.argmax()) if together.any() else -1


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def segments_intersect(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Whether closed segments ``p1q1`` and ``p2q2`` share a point; arrays ``(..., 2)`` broadcast.

    The classic orientation test with the collinear cases, so touching endpoints, a point lying on a segment
    and overlapping collinear segments all count; degenerate (zero-length) segments are points.
    """
    d1 = q1 - p1
    d2 = q2 - p2
    o1 = _cross(d1[..., 0], d1[..., 1], p2[..., 0] - p1[..., 0], p2[..., 1] - p1[..., 1])
    o2 = _cross(d1[..., 0], d1[..., 1], q2[..., 0] - p1[..., 0], q2[..., 1] - p1[..., 1])
    o3 = _cross(d2[..., 0], d2[..., 1], p1[..., 0] - p2[..., 0], p1[..., 1] - p2[..., 1])
    o4 = _cross(d2[..., 0], d2[..., 1], q1[..., 0] - p2[..., 0], q1[..., 1] - p2[..., 1])
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)

    def on_segment(p, q, r):  # r collinear with pq: is it inside pq's bounding box?
        lo = np.minimum(p, q)
        hi = np.maximum(p, q)
        return np.all((r >= lo) & (r <= hi), axis=-1)

    touch = (
        ((o1 == 0) & on_segment(p1, q1, p2))
        | ((o2 == 0) & on_segment(p1, q1, q2))
        | ((o3 == 0) & on_segment(p2, q2, p1))
        | ((o4 == 0) & on_segment(p2, q2, q1))
    )
    return proper | touch


def discomfort_steps(traj: Trajectory, horizon: float = DISCOMFORT_HORIZON) -> np.ndarray:
    """(T+1,) bool: at that step some robot's projected path intersects some human's projected path."""
    rp, hp = traj.robot_positions, traj.human_positions
    if rp.shape[1] == 0 or hp.shape[1] == 0:
        return np.zeros(len(rp), dtype=bool)
    r_end = rp + horizon * traj.robot_velocities
    h_end = hp + horizon * traj.human_velocities
    hit = segments_intersect(rp[:, :, None], r_end[:, :, None], hp[:, None], h_end[:, None])  # (T+1, M, N)
    if traj.human_present is not None:
        hit &= traj.human_present[:, None, :]
    # any() over axes of a 3-D array is an array; numpy types it as "bool | ndarray" for any input.
    return cast(np.ndarray, hit.any(axis=(1, 2)))


def episode_metrics(
    traj: Trajectory,
    *,
    collision_distance: float = COLLISION_DISTANCE,
    discomfort_horizon: float = DISCOMFORT_HORIZON,
    success_rule: str | None = None,
) -> EpisodeMetrics:
    """The metrics of one episode (module docstring); ``success_rule`` overrides the trajectory's."""
    rp, hp = traj.robot_positions, traj.human_positions
    if rp.shape[1] == 0:
        raise SimulationError("episode metrics need at least one robot; the trajectory has n_robots=0")
    rule = traj.success_rule if success_rule is None else success_rule
    if rule not in SUCCESS_RULES:
        raise SimulationError(f"success_rule must be one of {list(SUCCESS_RULES)}, got {rule!r}")
    reach = first_reach_steps(rp, traj.robot_goals, traj.radius)
    done_step = _success_step(traj, reach, rule)
    success = done_step >= 0

    def seconds(k: int) -> float:  # rounded so that 29 steps read 11.6 s, not 11.600000000000001 s
        return round(float(k * traj.dt), 9)

    reach_times = tuple(seconds(k) if k >= 0 else math.nan for k in reach)
    present = traj.human_present
    row_min = row_min_distance(rp, hp, present)
    min_rh = float(row_min.min())
    swept = min_distance_between_steps(rp, hp, present)
    disc = discomfort_steps(traj, discomfort_horizon)
    row_rr = row_min_within(rp)
    min_rr = float(row_rr.min())
    swept_rr = min_robot_distance_between_steps(rp)
    return EpisodeMetrics(
        success=success,
        travel_time=seconds(done_step) if success else math.nan,
        collision=min_rh < collision_distance,
        contact=min_rh < 2.0 * traj.radius,
        discomfort=bool(disc.any()),
        timeout=not success,
        min_distance=min_rh,
        min_distance_robots=min_rr,
        min_distance_humans=float(row_min_within(hp, present).min()),
        path_length=tuple(float(x) for x in np.linalg.norm(np.diff(rp, axis=0), axis=-1).sum(axis=0)),
        reach_times=reach_times,
        discomfort_steps=int(disc.sum()),
        collision_steps=int((row_min < collision_distance).sum()),
        contact_steps=int((row_min < 2.0 * traj.radius).sum()),
        n_steps=traj.n_steps,
        min_distance_between_steps=swept,
        collision_between_steps=swept < collision_distance,
        contact_between_steps=swept < 2.0 * traj.radius,
        robot_contact=min_rr < 2.0 * traj.radius,
        robot_contact_steps=int((row_rr < 2.0 * traj.radius).sum()),
        min_distance_robots_between_steps=swept_rr,
        robot_contact_between_steps=swept_rr < 2.0 * traj.radius,
    )


def _rate(flags: list[bool]) -> float:
    return 100.0 * sum(flags) / len(flags)


def aggregate(metrics: list[EpisodeMetrics]) -> dict[str, float | int]:
    """Rates in % with their counts, travel time over successful episodes (NaN if none), distances over the
    episodes that have a robot-human pair (inf if none: no pair, as an episode's own).

    Per-step frequencies in % (``collision_step_freq``, ``contact_step_freq``, ``discomfort_step_freq``):
    the states at which the condition holds over all states evaluated, ``100 sum(x_steps) / sum(n_steps +
    1)``; NaN when some episode lacks the count (rebuilt from an older record). The between-step rates
    (``collision_between_steps_rate`` / ``_count``, the same for contact) are NaN, with a NaN count, when
    some episode lacks the field; so are ``robot_contact_rate`` / ``_count`` (two robots touched, not a
    metric of the paper), ``robot_contact_between_steps_rate`` / ``_count`` and ``robot_contact_step_freq``
    (its states, as the per-step frequencies above).
    """
    if not metrics:
        raise SimulationError("aggregate needs at least one episode, got an empty list")
    travel = [m.travel_time for m in metrics if m.success]
    # over the episodes with a robot-human pair, as a sweep's cells.csv and table.md take them: a replayed
    # crowd's episode may have none (inf), which made the mean inf and moved the median where a sweep's
    # report of the same episodes dropped it (4.11 against 1.05 m)
    min_d = [m.min_distance for m in metrics if math.isfinite(m.min_distance)]
    out: dict[str, float | int] = {"episodes": len(metrics)}
    for name in ("success", "collision", "contact", "discomfort", "timeout"):
        flags = [bool(getattr(m, name)) for m in metrics]
        out[f"{name}_rate"] = _rate(flags)
        out[f"{name}_count"] = sum(flags)
    for name in ADDED_FLAGS:
        values = [getattr(m, name) for m in metrics]
        known = all(v is not None for v in values)
        out[f"{name}_rate"] = _rate([bool(v) for v in values]) if known else math.nan
        out[f"{name}_count"] = sum(bool(v) for v in values) if known else math.nan
    out["travel_time_mean"] = float(np.mean(travel)) if travel else math.nan
    out["travel_time_std"] = float(np.std(travel)) if travel else math.nan
    out["min_distance_mean"] = float(np.mean(min_d)) if min_d else math.inf
    out["min_distance_min"] = float(np.min(min_d)) if min_d else math.inf
    out["min_distance_median"] = float(np.median(min_d)) if min_d else math.inf
    states = sum(m.n_steps + 1 for m in metrics)
    for name in ("collision", "contact", "discomfort", "robot_contact"):
        counts = [getattr(m, f"{name}_steps") for m in metrics]
        missing = any(c is None for c in counts)
        out[f"{name}_step_freq"] = math.nan if missing else 100.0 * sum(counts) / states
    out["path_length_mean"] = float(np.mean([np.mean(m.path_length) for m in metrics]))
    return out
