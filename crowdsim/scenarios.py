"""Seeded start/goal layouts: circle crossing and perpendicular crossing, with a row of robots.

Robots (every scenario, every profile)
--------------------------------------
``n_robots`` robots start on the line ``y = -5`` m at ``x_k = (k - (M - 1) / 2) * 1.0`` m (1 m apart,
centred on ``x = 0``) and have their goals mirrored on ``y = +5`` m at the same ``x``, so they all travel
the same way (north, 10 m) side by side and can flock. Three robots: starts (-1, -5), (0, -5), (1, -5).
The layout is deterministic; only the humans are random. Where the paper's robots start and end is not
public, so both profiles keep this row: it isolates the published conventions (the humans' sampling,
timing and success rule) from a choice of ours.

Humans
------
Sampled by ``crowdsim.crossings`` under the profile's convention (``crossing``: "paper" follows the
authors' CrowdNav fork, "v1" this project's first simulator), with ``r_i + r_j + spawn_separation`` as the
minimum separation (1.1 m for "paper", 0.8 m for "v1").

Up to 16 humans (``DENSE_HUMANS``; the paper uses 5-9) the geometry is exactly that of the crossing rules.
Larger crowds, up to 50 for scaling benchmarks, do not fit it (the rejection sampling runs dry around 20
humans), so for ``n_humans > 16`` the circle radius, respectively the square's vertical extent, is
multiplied by ``n_humans / 16``: the humans' starts keep the density of 16 humans. The robot row never
changes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from crowdsim.conventions import CROSSINGS, SPAWN_SEPARATION
from crowdsim.crossings import PLACERS
from crowdsim.errors import SimulationError
from crowdsim.world import RADIUS, V_PREF

SCENARIOS: Final[tuple[str, ...]] = ("circle", "perpendicular")
ROBOT_SPACING: Final[float] = 1.0  # m between neighbouring robots on the start line
ROBOT_START_Y: Final[float] = -5.0  # m; goals at +5
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
    radius: float = RADIUS,
    v_pref: float = V_PREF,
    crossing: str = "paper",
    spawn_separation: float | None = None,
) -> Layout:
    """Robot row plus ``n_humans`` humans sampled from ``rng`` under the ``crossing`` rules.

    ``spawn_separation`` (m, added to the two radii) defaults to the crossing convention's own: 0.5 for
    "paper", 0.2 for "v1". The defaults are the paper profile's, like ``EnvConfig()``'s.
    """
    check_sizes(scenario, n_humans, n_robots)
    if crossing not in CROSSINGS:
        raise SimulationError(f"unknown crossing {crossing!r}; choose from {list(CROSSINGS)}")
    separation = SPAWN_SEPARATION[crossing] if spawn_separation is None else spawn_separation
    if not (np.isfinite(separation) and separation >= 0):
        raise SimulationError(f"spawn_separation must be a finite number >= 0 m, got {spawn_separation!r}")
    robot_starts, robot_goals = robot_layout(n_robots)
    # Every placed agent has the same radius, so the separation is one number.
    starts, goals = PLACERS[crossing](
        scenario,
        n_humans,
        robot_starts,
        robot_goals,
        rng,
        min_dist=2.0 * radius + separation,
        v_pref=v_pref,
        scale=geometry_scale(n_humans),
        max_tries=MAX_TRIES,
    )
    return Layout(
        robot_starts=robot_starts,
        robot_goals=robot_goals,
        human_starts=np.asarray(starts, dtype=float).reshape(n_humans, 2),
        human_goals=np.asarray(goals, dtype=float).reshape(n_humans, 2),
    )
