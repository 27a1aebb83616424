"""The team's layout as the MPC meets it: robots bound for separate places, which Eq. 15's flocking can hold
together (``separate_goals``, a ``FlockWarning``), and goals closer than the MPC's d_min lets robots stand
(``goal_room``, a ``GoalRoomWarning``). The controller warns at its reset (``warn_team_layout``); the command
line says the same before a run (pipelines.commands.team_notes)."""

from __future__ import annotations

import warnings
from typing import Final, NamedTuple

import numpy as np

from mpc.config import MPCConfig
from pipelines.errors import FlockWarning, GoalRoomWarning


class Parting(NamedTuple):
    """Two robots bound for goals ``apart`` m apart by separate ways (``separate_goals``), and the
    ``flock_range`` that would flock the rest of the team but not them (None where none does: the team's own
    goals lie ``team`` m apart, as far as theirs)."""

    i: int
    j: int
    apart: float
    team: float
    fit: float | None


def separate_goals(cfg: MPCConfig, positions: np.ndarray, goals: np.ndarray) -> Parting | None:
    """The first pair of robots that every pair flocking (``flock_range`` 0, ``w_floc`` > 0) would hold
    together: bound for goals more than ``2 d_flock`` apart whose offset differs from the starts' by as much,
    robots trading places or parting ways, not a team keeping its shape. Eq. 15 then pulls them together all
    the way (two robots swapping places stood 1.42 m apart until the time limit; docs/extending.md)."""
    if cfg.flock_range > 0 or cfg.w_floc == 0 or len(goals) < 2:
        return None
    positions, goals = np.asarray(positions, dtype=float), np.asarray(goals, dtype=float)
    i, j = np.triu_indices(len(goals), k=1)
    apart = np.linalg.norm(goals[i] - goals[j], axis=1)
    reshaped = np.linalg.norm((goals[i] - goals[j]) - (positions[i] - positions[j]), axis=1)
    parting = (apart > 2 * cfg.d_flock) & (reshaped > 2 * cfg.d_flock)
    if not parting.any():
        return None
    k = int(np.flatnonzero(parting)[0])
    team, low = float(apart[~parting].max(initial=cfg.d_flock)), float(apart[parting].min())
    # a range between the team's own goal distances and the parting pairs' keeps the team
    fit = min(team + 0.5, (team + low) / 2) if team < low else None
    return Parting(int(i[k]), int(j[k]), float(apart[k]), team, fit)


def parting_message(cfg: MPCConfig, parting: Parting, setting: str) -> str:
    """Why ``parting``'s episodes may time out and what to set; ``setting`` formats the range as its reader
    sets it (``{:.2f}`` for the number): ``mpc_overrides=(("flock_range", {:.2f}),)`` in the API,
    ``--set mpc.flock_range={:.2f}`` on the command line."""
    if parting.fit is not None:
        way = f"{setting.format(parting.fit)} ([mpc] flock_range) flocks only the pairs "
        way += f"whose goals lie within {parting.fit:.2f} m"
    else:
        way = f"no flock_range parts them from pairs whose goals lie {parting.team:.1f} m apart; w_floc = 0 "
        way += "flocks none"
    return (
        f"robots {parting.i} and {parting.j} are bound for goals {parting.apart:.1f} m apart by separate "
        f"ways, and Eq. 15 pulls every pair of robots towards d_flock {cfg.d_flock:g} m, which can hold them "
        f'together until the time limit: {way} (docs/extending.md, "Robots bound for separate places")'
    )


def warn_team_layout(cfg: MPCConfig, positions: np.ndarray, goals: np.ndarray) -> None:
    """The controller's reset: ``warn_separate_goals`` and ``warn_goal_room``."""
    warn_separate_goals(cfg, positions, goals, stacklevel=4)
    warn_goal_room(cfg, goals, stacklevel=4)


def warn_separate_goals(
    cfg: MPCConfig, positions: np.ndarray, goals: np.ndarray, stacklevel: int = 3
) -> None:
    """A ``FlockWarning`` where ``separate_goals`` finds a pair."""
    parting = separate_goals(cfg, positions, goals)
    if parting is not None:
        message = parting_message(cfg, parting, 'mpc_overrides=(("flock_range", {:.2f}),)')
        warnings.warn(message, FlockWarning, stacklevel=stacklevel)


# How close to the closest two robots' goals d_min may come before the warning (and the command line's note,
# pipelines.commands.team_notes.goal_room_note): no measured rule holds for every formation
# (docs/extending.md, robot_reached), and the row of 4 failed already at 0.98 of 1.0 m.
GOAL_ROOM_MARGIN: Final[float] = 0.05  # m
# m above d_min at which goals gave the robots room (the way out both name): CMPC, row of 3, 7 humans, d_min
# 1.0 m: 0 of 10 episodes reached their goals 1.0 m apart, 9 of 10 at 1.2 m, 10 of 10 at 1.3 m
ROOM_SPACING: Final[float] = 0.3


def short_of_room(d_min: float, gap: float) -> bool:
    """Whether ``d_min`` is within ``GOAL_ROOM_MARGIN`` of two goals ``gap`` m apart, or above: the rule of
    ``warn_goal_room`` and of the command line's note (pipelines.commands.team_notes.goal_room_note)."""
    return d_min >= gap - GOAL_ROOM_MARGIN - 1e-9


def goal_room(cfg: MPCConfig, goals: np.ndarray) -> tuple[int, int, float] | None:
    """The closest two robots' goals, ``(i, j, distance)``, when ``d_min`` is within ``GOAL_ROOM_MARGIN``
    of their distance or above; None otherwise."""
    goals = np.asarray(goals, dtype=float)
    if len(goals) < 2:
        return None
    i, j = np.triu_indices(len(goals), k=1)
    gaps = np.linalg.norm(goals[i] - goals[j], axis=1)
    k = int(np.argmin(gaps))
    if not short_of_room(cfg.d_min, float(gaps[k])):
        return None
    return int(i[k]), int(j[k]), float(gaps[k])


def warn_goal_room(cfg: MPCConfig, goals: np.ndarray, stacklevel: int = 3) -> None:
    """A ``GoalRoomWarning`` where ``goal_room`` finds a pair: Eq. 12 keeps every
    pair of robots d_min apart, which can keep them from standing on their goals at once, and the episode
    then times out with nobody in the way (a row of 3 goals 0.8 m apart, no humans: DMPC timed out; at 0.6 m
    both MPCs did, standing 1.0 m apart)."""
    room = goal_room(cfg, goals)
    if room is None:
        return
    i, j, gap = room
    warnings.warn(
        f"robots {i} and {j}'s goals lie {gap:.2f} m apart, and the MPC keeps every pair of robots d_min "
        f"{cfg.d_min:g} m apart (Eq. 12), which can keep them from standing on their goals at once: the "
        f"episode then times out; goals {cfg.d_min + ROOM_SPACING:g} m apart or more gave room "
        "(docs/extending.md, robot_reached)",
        GoalRoomWarning,
        stacklevel=stacklevel,
    )
