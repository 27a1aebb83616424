"""The observation of ``crowdmpc/CrowdNav-v0`` (crowdsim.gym_env, whose docstring documents it, and which
exports these names): the array's columns, the bounds of its ``Box``, a native ``Observation`` written into
the array, and the native observation its info carries (``ComparableObservation``).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Final

import numpy as np

from crowdsim.env import Observation
from crowdsim.env_config import EnvConfig
from crowdsim.observation import array_copies
from crowdsim.reaction import CATCH_UP, MIN_SPEED, reacts
from crowdsim.replay import Recording
from crowdsim.scenarios import geometry_scale
from crowdsim.world import CIRCLE_RADIUS, SQUARE_WIDTH

COLUMNS: Final[tuple[str, ...]] = ("x", "y", "vx", "vy", "goal_x", "goal_y", "present")
POSITION: Final[slice] = slice(0, 2)  # m
VELOCITY: Final[slice] = slice(2, 4)  # m/s
GOAL: Final[slice] = slice(4, 6)  # m; 0 for humans
PRESENT: Final[int] = 6  # 1.0 for an agent of this episode (tracked now, in a replay), 0.0 for padding


@dataclass(frozen=True, eq=False)
class ComparableObservation(Observation):
    """An ``Observation`` that compares equal field by field, arrays exactly (``Observation``'s own ``==``
    raises on its arrays), so that an info dict holding one can be compared, as gymnasium's checker does."""

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Observation):
            return NotImplemented
        return all(np.array_equal(getattr(self, f.name), getattr(other, f.name)) for f in fields(Observation))

    __hash__ = None  # type: ignore[assignment]

    @classmethod
    def of(cls, obs: Observation) -> ComparableObservation:
        """``obs`` with copies of its arrays: the environment computes the next step's reward and distances
        from its own ``obs``, which a policy taking the humans relative to a robot in place
        (``human_positions -= robot``) on the info's shared arrays had moved."""
        return cls(**{**{f.name: getattr(obs, f.name) for f in fields(Observation)}, **array_copies(obs)})


def observation_bounds(
    config: EnvConfig, max_robots: int, max_humans: int, recording: Recording | None = None
) -> tuple[float, float, np.ndarray, np.ndarray]:
    """``(scene_limit, position_limit, low, high)``: the limits (m) and the box's bounds, one row per agent
    (``max_robots + max_humans`` rows, ``COLUMNS``); a replayed crowd's ``recording`` bounds its humans'
    positions and velocities instead (``human_limits``), the other limits stay the ones returned."""
    # Bounds (gym_env's docstring): the scene, plus the farthest anyone travels per axis. An episode's
    # max_steps steps end by time_limit, to within the rounding max_steps allows for.
    speed = max(config.v_max, config.v_pref)
    scene_limit = scene_bound(config.v_pref, max_humans)
    duration = max(config.time_limit, config.max_steps * config.dt)
    position_limit = scene_limit + speed * duration
    limit = np.array([position_limit] * 2 + [speed] * 2 + [position_limit] * 2 + [1.0])
    high = np.broadcast_to(limit, (max_robots + max_humans, len(COLUMNS))).copy()
    if recording is not None:  # the robots' rows stay ORCA's: they start and end as there
        human_position, human_speed = human_limits(recording, reacts(config.crowd), duration)
        high[max_robots:, POSITION], high[max_robots:, VELOCITY] = human_position, human_speed
    low = -high
    low[:, PRESENT] = 0.0
    return scene_limit, position_limit, low, high


def human_limits(recording: Recording, reactive: bool, duration: float) -> tuple[float, float]:
    """``(position, speed)``: the largest |coordinate| (m) and |velocity component| (m/s) of a replayed
    person over an episode of at most ``duration`` s. Played back, a person is where the recording has them
    (within ``Recording.extent``'s distance of the centre the episode moves to the origin) at its recorded
    speeds. Reacting (crowdsim.reaction), a person walks at most ``CATCH_UP`` faster than the fastest
    recorded step (ORCA's speed bound: the preferred speed, the recorded one plus the pull back, or
    ``MIN_SPEED``), from a recorded position, for at most ``duration``."""
    distance, fastest = recording.extent()
    if not reactive:
        return distance, fastest
    speed = max(fastest + CATCH_UP, MIN_SPEED)
    return distance + speed * duration, speed


def scene_bound(v_pref: float, max_humans: int) -> float:
    """The largest |coordinate| (m) of any start or goal ``make_layout`` draws for up to ``max_humans``
    humans at human speed ``v_pref`` (m/s): ``max(2 L, L + v_pref / 2)``, ``L = max(circle radius, square
    width) x geometry_scale(max_humans)``. ``2 L`` holds the robots' formations and the perpendicular sides'
    fixed offsets; ``L + v_pref / 2`` the noise of up to ``v_pref / 2`` per coordinate that the circle's
    starts and goals and the v1 perpendicular goals carry (crowdsim.crossings), which the crowd's scale
    does not scale, so that only a fast crowd (v_pref > L) needs more than ``2 L``."""
    scene = max(CIRCLE_RADIUS, SQUARE_WIDTH) * geometry_scale(max_humans)
    return max(2.0 * scene, scene + 0.5 * v_pref)


def observation_array(
    obs: Observation, max_robots: int, max_humans: int, low: np.ndarray, high: np.ndarray
) -> np.ndarray:
    """``obs`` as the environment's array: robots in the first ``max_robots`` rows, then humans, padding rows
    zero, clipped into ``[low, high]`` (``observation_bounds``). A replayed crowd's humans not tracked now
    (``Observation.human_present`` False) are rows of zeros, as padding: nobody would see them."""
    out = np.zeros((max_robots + max_humans, len(COLUMNS)))
    m, n = obs.n_robots, obs.n_humans
    robots, humans = out[:m], out[max_robots : max_robots + n]
    robots[:, POSITION], robots[:, VELOCITY] = obs.robot_positions, obs.robot_velocities
    robots[:, GOAL] = obs.robot_goals
    humans[:, POSITION], humans[:, VELOCITY] = obs.human_positions, obs.human_velocities
    robots[:, PRESENT] = humans[:, PRESENT] = 1.0
    if obs.human_present is not None:
        humans[~np.asarray(obs.human_present, dtype=bool)] = 0.0
    return np.clip(out, low, high)
