"""Seeded start/goal layouts: circle crossing and perpendicular crossing, with a row of robots.

Robots (every scenario)
-----------------------
``n_robots`` robots start on the line ``y = -5`` m at ``x_k = (k - (M - 1) / 2) * 1.0`` m (1 m apart,
centred on ``x = 0``) and have their goals mirrored on ``y = +5`` m at the same ``x``, so they all travel
the same way (north, 10 m) side by side and can flock. Three robots: starts (-1, -5), (0, -5), (1, -5).
The layout is deterministic; only the humans are random.

Humans
------
Sampled one after the other with CrowdNav's rejection rule: a candidate is redrawn while its start or its
goal lies closer than ``r_i + r_j + 0.2`` m (CrowdNav's ``discomfort_dist``) to any start or goal of the
agents placed before it (robots first). CrowdNav checks only the candidate's start; checking the goal too
makes no difference for circle crossing (goals are the mirrored starts) and keeps goals apart in the
perpendicular scenario.

* circle: a uniform angle on the radius-5 m circle plus uniform noise in ``[-v_pref/2, v_pref/2)`` on each
  coordinate (CrowdNav's ``generate_circle_crossing_human``); the goal is the opposite point ``-start``.
* perpendicular: humans cross the 10 m square horizontally, through the robots' north-bound column. A fair
  coin picks the side; the start is ``(±(5 + e), y)`` with ``e`` uniform in ``[-1, 1)`` m (within a metre of
  the square's side) and ``y`` uniform in ``[-5, 5)`` m; the goal is ``(∓(5 + e'), y + n)`` on the opposite
  side, ``e'`` uniform in ``[-1, 1)`` m and ``n`` uniform in ``[-v_pref/2, v_pref/2)``, so the crossing is
  nearly horizontal.

Up to 16 humans (``DENSE_HUMANS``; the paper uses 5-9) the geometry is exactly the above. Larger crowds, up
to 50 for scaling benchmarks, do not fit it (the rejection sampling runs dry around 20 humans), so for
``n_humans > 16`` the circle radius, respectively the square's vertical extent, is multiplied by
``n_humans / 16``: the humans' starts keep the density of 16 humans. The robot row never changes.

Every random number comes from the ``numpy.random.Generator`` passed in, in a fixed order, so a seed fixes
the layout.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

import numpy as np

from crowdsim.errors import SimulationError

CIRCLE_RADIUS: Final[float] = 5.0  # m, circle crossing (the brief; CrowdNav's default is 4 m)
SQUARE_WIDTH: Final[float] = 10.0  # m, side of the perpendicular-crossing square
ROBOT_SPACING: Final[float] = 1.0  # m between neighbouring robots on the start line
ROBOT_START_Y: Final[float] = -5.0  # m; goals at +5
DISCOMFORT_DIST: Final[float] = 0.2  # m, CrowdNav's extra separation between sampled starts/goals
MAX_HUMANS: Final[int] = 50
MAX_ROBOTS: Final[int] = 12
MAX_TRIES: Final[int] = 10_000  # rejection-sampling draws per human before the layout is declared too crowded
# The most humans whose layouts the 10 m geometry holds reliably (every one of 30 seeds placed 18 humans in
# both scenarios with 3 robots; 22-24 failed often). More humans enlarge the geometry, see geometry_scale.
DENSE_HUMANS: Final[int] = 16


@dataclass(frozen=True)
class Layout:
    """Starts and goals of one episode."""

    robot_starts: np.ndarray  # (M, 2) m
    robot_goals: np.ndarray  # (M, 2) m
    human_starts: np.ndarray  # (N, 2) m
    human_goals: np.ndarray  # (N, 2) m


def robot_layout(n_robots: int) -> tuple[np.ndarray, np.ndarray]:
    """Starts ``(M, 2)`` and goals ``(M, 2)`` of the robot row (see the module docstring)."""
    x = (np.arange(n_robots) - (n_robots - 1) / 2.0) * ROBOT_SPACING
    starts = np.stack([x, np.full(n_robots, ROBOT_START_Y)], axis=1)
    goals = np.stack([x, np.full(n_robots, -ROBOT_START_Y)], axis=1)
    return starts, goals


def _circle_candidate(rng: np.random.Generator, v_pref: float, scale: float) -> tuple[np.ndarray, np.ndarray]:
    angle = rng.random() * 2.0 * np.pi
    noise = (rng.random(2) - 0.5) * v_pref
    start = scale * CIRCLE_RADIUS * np.array([np.cos(angle), np.sin(angle)]) + noise
    return start, -start


def _perpendicular_candidate(
    rng: np.random.Generator, v_pref: float, scale: float
) -> tuple[np.ndarray, np.ndarray]:
    side = -1.0 if rng.random() > 0.5 else 1.0
    half = SQUARE_WIDTH / 2.0
    y = (rng.random() - 0.5) * scale * SQUARE_WIDTH
    u = rng.random(3)
    start = np.array([side * (half + 2.0 * u[0] - 1.0), y])
    goal = np.array([-side * (half + 2.0 * u[1] - 1.0), y + (u[2] - 0.5) * v_pref])
    return start, goal


SCENARIOS: dict[str, Callable[[np.random.Generator, float, float], tuple[np.ndarray, np.ndarray]]] = {
    "circle": _circle_candidate,
    "perpendicular": _perpendicular_candidate,
}


def geometry_scale(n_humans: int) -> float:
    """1 up to ``DENSE_HUMANS`` humans; beyond, the crowd's extent grows in proportion to their number."""
    return max(1.0, n_humans / DENSE_HUMANS)


def check_sizes(scenario: str, n_humans: int, n_robots: int) -> None:
    """Raise SimulationError naming the first bad value."""
    if scenario not in SCENARIOS:
        raise SimulationError(f"unknown scenario {scenario!r}; choose from {sorted(SCENARIOS)}")
    if isinstance(n_humans, bool) or not isinstance(n_humans, int | np.integer):
        raise SimulationError(f"n_humans must be an int, got {n_humans!r}")
    if not 0 <= n_humans <= MAX_HUMANS:
        raise SimulationError(f"n_humans must be in [0, {MAX_HUMANS}], got {n_humans}")
    if isinstance(n_robots, bool) or not isinstance(n_robots, int | np.integer):
        raise SimulationError(f"n_robots must be an int, got {n_robots!r}")
    if not 0 <= n_robots <= MAX_ROBOTS:
        raise SimulationError(f"n_robots must be in [0, {MAX_ROBOTS}], got {n_robots}")


def make_layout(
    scenario: str,
    n_humans: int,
    n_robots: int,
    rng: np.random.Generator,
    *,
    radius: float = 0.3,
    v_pref: float = 1.0,
) -> Layout:
    """Robot row plus ``n_humans`` humans rejection-sampled from ``rng`` (module docstring)."""
    check_sizes(scenario, n_humans, n_robots)
    candidate = SCENARIOS[scenario]
    scale = geometry_scale(n_humans)
    robot_starts, robot_goals = robot_layout(n_robots)
    # Every placed agent has the same radius, so the separation is one number.
    min_dist = 2.0 * radius + DISCOMFORT_DIST
    taken = list(robot_starts) + list(robot_goals)
    starts, goals = [], []
    for h in range(n_humans):
        for _ in range(MAX_TRIES):
            start, goal = candidate(rng, v_pref, scale)
            if not taken:
                break
            points = np.asarray(taken)
            if (
                np.linalg.norm(points - start, axis=1).min() >= min_dist
                and np.linalg.norm(points - goal, axis=1).min() >= min_dist
            ):
                break
        else:
            raise SimulationError(
                f"could not place human {h + 1} of n_humans={n_humans} in scenario {scenario!r} with "
                f"{n_robots} robots after {MAX_TRIES} draws; use fewer agents"
            )
        starts.append(start)
        goals.append(goal)
        taken += [start, goal]
    return Layout(
        robot_starts=robot_starts,
        robot_goals=robot_goals,
        human_starts=np.asarray(starts, dtype=float).reshape(n_humans, 2),
        human_goals=np.asarray(goals, dtype=float).reshape(n_humans, 2),
    )
