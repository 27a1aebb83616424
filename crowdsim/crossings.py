"""How the humans' starts and goals are sampled, per crossing convention (``EnvConfig.crossing``).

Humans are placed one after the other; ``min_dist`` (the two radii plus the profile's spawn separation) is
the closest a new start or goal may lie to the points it is checked against. Every random number comes
from the ``numpy.random.Generator`` passed in, in the order written below, so a seed fixes the layout.

v1 (this project's first simulator)
    A candidate (start, goal) is redrawn while its start *or* its goal lies closer than ``min_dist`` to any
    start or goal of the agents placed before it (robots first).

    * circle: a uniform angle on the circle plus uniform noise in ``[-v_pref/2, v_pref/2)`` on each
      coordinate (CrowdNav's ``generate_circle_crossing_human``); the goal is the opposite point ``-start``.
    * perpendicular: a fair coin picks the side; ``y`` is uniform in ``[-5, 5)`` m; the start is
      ``(±(5 + e), y)`` with ``e`` uniform in ``[-1, 1)`` m, the goal ``(∓(5 + e'), y + n)``, ``e'`` uniform
      in ``[-1, 1)`` m and ``n`` uniform in ``[-v_pref/2, v_pref/2)`` (drawn in that order: side, y, e, e',
      n).

paper (the authors' CrowdNav fork, ``crowd_sim/envs/crowd_sim.py``)
    * circle (``generate_circle_crossing_human``): the same candidate as v1, but the start is checked only
      against every placed agent's *start* and the goal only against every placed agent's *goal*. The fork
      never gives up; ``max_tries`` is kept as a safety net against an endless loop.
    * perpendicular (``generate_square_crossing_human``): the side's sign is drawn once (``random() > 0.5``
      gives -1); then up to 100 draws of ``px = U(1.0, 1.2) * 5 * sign``, ``py = (random() - 0.5) * 10``,
      checked against the placed starts; after 100 draws the last one is kept even if too close (the fork's
      ``idx >= 100``). Then the goal likewise: ``gx = -px + (random() - 0.5)``, ``gy = py + (random() -
      0.5)``, checked against the placed goals, same give-up.

``scale`` (``crowdsim.scenarios.geometry_scale``) enlarges the circle radius, respectively the square's
vertical extent, for crowds beyond 16 humans; it is 1 for the paper's crowd sizes.

Each convention names the scenarios it samples (``_V1_CANDIDATES``, ``_PAPER_HUMANS``); any other name raises
``SimulationError``, so a scenario added to ``crowdsim.scenarios.SCENARIOS`` without a sampler fails at reset
instead of silently running another one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

import numpy as np

from crowdsim.errors import SimulationError, too_crowded
from crowdsim.world import CIRCLE_RADIUS, SQUARE_WIDTH

PAPER_MAX_DRAWS: Final[int] = 100  # crowd_sim.py generate_square_crossing_human: `idx >= 100` gives up
PAPER_SIDE_OFFSET: Final[tuple[float, float]] = (1.0, 1.2)  # fork: np.random.uniform(1.0, 1.2) * width / 2

Points = list[np.ndarray]
Candidate = Callable[[np.random.Generator, float, float], tuple[np.ndarray, np.ndarray]]
Placer = Callable[..., tuple[Points, Points]]


def circle_candidate(rng: np.random.Generator, v_pref: float, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Start on the circle with noise (angle, then x noise, then y noise) and its mirrored goal."""
    angle = rng.random() * 2.0 * np.pi
    noise = (rng.random(2) - 0.5) * v_pref
    start = scale * CIRCLE_RADIUS * np.array([np.cos(angle), np.sin(angle)]) + noise
    return start, -start


def _v1_perpendicular_candidate(
    rng: np.random.Generator, v_pref: float, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    side = -1.0 if rng.random() > 0.5 else 1.0
    half = SQUARE_WIDTH / 2.0
    y = (rng.random() - 0.5) * scale * SQUARE_WIDTH
    u = rng.random(3)
    start = np.array([side * (half + 2.0 * u[0] - 1.0), y])
    goal = np.array([-side * (half + 2.0 * u[1] - 1.0), y + (u[2] - 0.5) * v_pref])
    return start, goal


_V1_CANDIDATES: Final[dict[str, Candidate]] = {
    "circle": circle_candidate,
    "perpendicular": _v1_perpendicular_candidate,
}


def _clear(point: np.ndarray, placed: Points, min_dist: float) -> bool:
    return not placed or bool(np.linalg.norm(np.asarray(placed) - point, axis=1).min() >= min_dist)


def _no_placer(crossing: str, scenario: str, known: dict[str, Any]) -> SimulationError:
    return SimulationError(
        f"crossing {crossing!r} has no sampler for scenario {scenario!r}; choose from {sorted(known)}"
    )


def place_humans_v1(
    scenario: str,
    n_humans: int,
    robot_starts: np.ndarray,
    robot_goals: np.ndarray,
    rng: np.random.Generator,
    *,
    min_dist: float,
    v_pref: float,
    scale: float,
    max_tries: int,
) -> tuple[Points, Points]:
    """Humans' starts and goals by the v1 rules (module docstring)."""
    candidate = _V1_CANDIDATES.get(scenario)
    if candidate is None:
        raise _no_placer("v1", scenario, _V1_CANDIDATES)
    taken = list(robot_starts) + list(robot_goals)
    starts: Points = []
    goals: Points = []
    for h in range(n_humans):
        for _ in range(max_tries):
            start, goal = candidate(rng, v_pref, scale)
            if _clear(start, taken, min_dist) and _clear(goal, taken, min_dist):
                break
        else:
            raise too_crowded(h, n_humans, scenario, len(robot_starts), max_tries, min_dist)
        starts.append(start)
        goals.append(goal)
        taken += [start, goal]
    return starts, goals


def _paper_side_point(rng: np.random.Generator, sign: float, scale: float) -> np.ndarray:
    px = rng.uniform(*PAPER_SIDE_OFFSET) * SQUARE_WIDTH * 0.5 * sign
    py = (rng.random() - 0.5) * SQUARE_WIDTH * scale
    return np.array([px, py])


def _paper_goal_point(rng: np.random.Generator, start: np.ndarray) -> np.ndarray:
    gx = -start[0] + (rng.random() - 0.5)
    gy = start[1] + (rng.random() - 0.5)
    return np.array([gx, gy])


def _paper_circle_human(
    rng: np.random.Generator,
    starts: Points,
    goals: Points,
    min_dist: float,
    v_pref: float,
    scale: float,
    max_tries: int,
) -> tuple[np.ndarray, np.ndarray] | None:
    """The fork's circle crossing: redraw until the start clears the placed starts and the goal the placed
    goals; None after ``max_tries`` draws (the fork never gives up)."""
    for _ in range(max_tries):
        start, goal = circle_candidate(rng, v_pref, scale)
        if _clear(start, starts, min_dist) and _clear(goal, goals, min_dist):
            return start, goal
    return None


def _paper_perpendicular_human(
    rng: np.random.Generator,
    starts: Points,
    goals: Points,
    min_dist: float,
    v_pref: float,
    scale: float,
    max_tries: int,
) -> tuple[np.ndarray, np.ndarray]:
    """The fork's square crossing: the side, then the start, then the goal, each of the two kept after
    ``PAPER_MAX_DRAWS`` draws even if too close (``v_pref`` and ``max_tries`` do not act)."""
    sign = -1.0 if rng.random() > 0.5 else 1.0
    for _ in range(PAPER_MAX_DRAWS):  # the last draw stands even if it is too close
        start = _paper_side_point(rng, sign, scale)
        if _clear(start, starts, min_dist):
            break
    for _ in range(PAPER_MAX_DRAWS):
        goal = _paper_goal_point(rng, start)
        if _clear(goal, goals, min_dist):
            break
    return start, goal


PaperHuman = Callable[
    [np.random.Generator, Points, Points, float, float, float, int], tuple[np.ndarray, np.ndarray] | None
]
_PAPER_HUMANS: Final[dict[str, PaperHuman]] = {
    "circle": _paper_circle_human,
    "perpendicular": _paper_perpendicular_human,
}


def place_humans_paper(
    scenario: str,
    n_humans: int,
    robot_starts: np.ndarray,
    robot_goals: np.ndarray,
    rng: np.random.Generator,
    *,
    min_dist: float,
    v_pref: float,
    scale: float,
    max_tries: int,
) -> tuple[Points, Points]:
    """Humans' starts and goals by the fork's rules (module docstring)."""
    place = _PAPER_HUMANS.get(scenario)
    if place is None:
        raise _no_placer("paper", scenario, _PAPER_HUMANS)
    starts: Points = list(robot_starts)  # every placed agent's start, robots first
    goals: Points = list(robot_goals)
    n_robots = len(robot_starts)
    for h in range(n_humans):
        placed = place(rng, starts, goals, min_dist, v_pref, scale, max_tries)
        if placed is None:
            raise too_crowded(h, n_humans, scenario, n_robots, max_tries, min_dist)
        starts.append(placed[0])
        goals.append(placed[1])
    return starts[n_robots:], goals[n_robots:]


PLACERS: Final[dict[str, Placer]] = {"v1": place_humans_v1, "paper": place_humans_paper}
