"""A replayed crowd that yields to the robots: real tracks, bent by ORCA where a robot is in the way.

A plain replay (crowdsim.replay) is exact and blind: nobody in BIWI's recordings saw a robot, so a robot
that cuts in front of a person is walked into, and every contact is the robot's to avoid. ORCA's crowd
reacts, but walks straight at one speed. A reactive replay ("eth_test_reactive", ...) keeps the people's
real paths, speeds, groups and stops, and lets each of them avoid the robots as one of ORCA's humans does
(``robots_visible``, the paper's setting: the robots are reciprocal agents with their current velocities),
while ignoring the other people (their recorded paths already avoid each other, and groups walking closer
than ORCA's 0.62 m would be pushed apart).

Each step a person tracked now and at the next row prefers their recorded velocity plus a pull back onto
their track, ``v_rec - e / RETURN_TIME`` for a deviation ``e`` from where the recording has them now, the
pull at most ``CATCH_UP``; ORCA then picks the velocity closest to that against the robots, up to the
preferred speed or ``MIN_SPEED``, whichever is more (a person standing still can step aside). A person
nobody deflects walks exactly their recorded track (the position is carried as the recording's plus the
deviation, so rounding does not drift it). A person who appears takes their recorded position; one whose
track ends stays where they are (absent, as in the plain replay, and left out of the metrics).

With ``robots_visible`` false the people do not see the robots, and the replay is the plain one.
"""

from __future__ import annotations

from typing import Final

import numpy as np

from crowdsim.orca import OrcaParams, orca_velocities
from crowdsim.replay import REACTIVE, ReplayEpisode

RETURN_TIME: Final[float] = 1.2  # s over which a deflected person closes their gap to their track (3 steps)
CATCH_UP: Final[float] = 0.5  # m/s at most added to the recorded velocity to regain the track
MIN_SPEED: Final[float] = 0.5  # m/s a person may always move at to avoid a robot (a slow walk)


def reacts(crowd: str) -> bool:
    """Whether ``crowd`` (an ``EnvConfig.crowd``) is a replay whose people avoid the robots."""
    return crowd in REACTIVE


def reactive_step(
    episode: ReplayEpisode,
    row: int,
    positions: np.ndarray,
    velocities: np.ndarray,
    robot_positions: np.ndarray,
    robot_velocities: np.ndarray,
    *,
    radius: float,
    params: OrcaParams,
    dt: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The people's positions and velocities at ``row + 1`` of ``episode`` (module docstring) from their
    ``positions`` and ``velocities (N, 2)`` at ``row`` and the robots' current state; ``radius`` is ORCA's
    (the agents' radius plus its margin). Returns ``(positions, velocities, used_lp3)``, the last for the
    people walking (tracked at both rows)."""
    recorded, recorded_next = episode.positions[row], episode.positions[row + 1]
    walking = episode.present[row] & episode.present[row + 1]
    appeared = episode.present[row + 1] & ~episode.present[row]
    seen_before = episode.present[: row + 1].any(axis=0)
    # absent at row + 1: held where the recording holds them until they appear, where they are once gone
    new_positions = np.where((appeared | ~seen_before)[:, None], recorded_next, positions)
    new_velocities = np.zeros_like(positions)
    used_lp3 = np.zeros(0, dtype=bool)
    walkers = np.flatnonzero(walking)
    if len(walkers) == 0:
        return new_positions, new_velocities, used_lp3
    deviation = positions[walkers] - recorded[walkers]
    v_recorded = episode.velocities[row + 1, walkers]
    pull = -deviation / RETURN_TIME
    size = np.linalg.norm(pull, axis=1, keepdims=True)
    pull = np.where(size > CATCH_UP, pull * (CATCH_UP / np.maximum(size, CATCH_UP)), pull)
    preferred = v_recorded + pull
    m = len(robot_positions)
    speeds = np.maximum(np.linalg.norm(preferred, axis=1), MIN_SPEED)
    chosen, used_lp3 = orca_velocities(
        np.concatenate([robot_positions, positions[walkers]]),
        np.concatenate([robot_velocities, velocities[walkers]]),
        preferred,
        radius,
        np.concatenate([np.zeros(m), speeds]),  # the robots' entries are never used: they are no agents
        params,
        dt,
        agents=m + np.arange(len(walkers)),
        seen=np.arange(m),
    )
    # the recording's next position plus the new deviation: exact where nobody was deflected
    new_positions[walkers] = recorded_next[walkers] + (deviation + dt * (chosen - v_recorded))
    new_velocities[walkers] = chosen
    return new_positions, new_velocities, used_lp3
