"""Seeded start/goal layouts: circle crossing and perpendicular crossing, with the robots in a formation.

Robots
------
They stand in a formation that the scenario and the crowd do not change: ``crowdsim.formations`` says
where, why, and which one ``formation="auto"`` picks; this module samples the humans around them.
``Formation``, ``FORMATIONS``, ``choose_formation`` and ``robot_layout`` are importable from here too.

Humans
------
Sampled by ``crowdsim.crossings`` under the profile's convention (``crossing``: "paper" follows the
authors' CrowdNav fork, "v1" this project's first simulator), with ``r_i + r_j + spawn_separation`` as the
minimum separation (1.1 m for "paper", 0.8 m for "v1"). What each new human is checked against:

* v1: its start and its goal against every start and goal placed before, the robots' included.
* paper, circle (the fork): its start only against the placed *starts*, its goal only against the placed
  *goals*. Humans are clear of the robots' starts, not of their goals: of seeds 0-299 with 3 robots, 125,
  181 and 228 layouts (5, 7, 9 humans) have a human starting within 2 r = 0.6 m of a robot's goal.
* paper, perpendicular (the fork): the same checks, but after 100 draws the last start (goal) is kept even
  if too close (``idx >= 100``). Layouts of seeds 0-99 (3 robots) with two humans starting closer than
  0.6 m, in contact from the first step: none at 5 and 7 humans, 3 at 9, 14 at 12, 64 at 16, 71 at 20, 99
  at 50; none in the circle at any size (it redraws up to ``MAX_TRIES``, then raises). Measured with
  ``.venv/bin/python -c "import numpy as np; from crowdsim.scenarios import make_layout, start_overlaps as o;
  print([sum(bool(o(make_layout('perpendicular', n, 3, np.random.default_rng(s)))) for s in range(100))
  for n in (5, 7, 9, 12, 16, 20, 50)])"`` (``make_layout``'s defaults are ``CrowdEnv.reset``'s).

Up to 16 humans (``DENSE_HUMANS``; the paper uses 5-9) the geometry is exactly that of the crossing rules.
Larger crowds, up to 50 for scaling benchmarks, do not fit it (the rejection sampling runs dry around 20
humans, except the paper's perpendicular one, which keeps the overlaps instead), so for ``n_humans > 16``
the circle radius, respectively the square's vertical extent, is multiplied by ``n_humans / 16``: the
humans' starts keep the density of 16 humans. In the circle that keeps every start 1.1 m clear; the
perpendicular crowd keeps the density of its 16 humans *with* their overlaps (above). The robots' formation
never changes with the crowd.

One seed, one crowd? Across crowd sizes, yes: with the same robots, the first ``n`` humans of a layout of
``N > n`` humans are the layout of ``n`` humans (while ``N <= DENSE_HUMANS``: beyond, the geometry grows).
Across numbers of robots, not in the circle: a human drawn near a robot is redrawn, and every later draw
shifts. Seed 5 with 7 humans: with 3 or 6 robots only humans 4-6 start where they do with 1 robot (the
1-robot crowd's first human, next to where the 3-robot row stands, is redrawn, humans 1-3 move up one place
and a new draw takes place 3); of seeds 0-99 only 53 (3 robots), 55 (6) and 26 (12) give the 1-robot crowd
(v1: 20, 25, 5). The perpendicular crowds start over 1.5 m from the auto, wedge and two-row formations
(over 3 m from the teams; a long row's ends come nearer) and are the same for every number of robots. A
robot-scaling comparison "on the same seeds" thus faces other circle crowds at each number of robots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

import numpy as np

from crowdsim.conventions import CROSSINGS, SPAWN_SEPARATION
from crowdsim.crossings import PLACERS
from crowdsim.errors import SimulationError, counted, real_number, texts_or_bools
from crowdsim.formations import FORMATIONS as FORMATIONS
from crowdsim.formations import Formation as Formation
from crowdsim.formations import check_robot_spacing
from crowdsim.formations import choose_formation as choose_formation
from crowdsim.formations import robot_layout as robot_layout
from crowdsim.world import MOST_COORDINATE, RADIUS, V_PREF, finite_positive

SCENARIOS: Final[tuple[str, ...]] = ("circle", "perpendicular")
MAX_HUMANS: Final[int] = 50
MAX_ROBOTS: Final[int] = 12
MAX_TRIES: Final[int] = 10_000  # rejection-sampling draws per human before the layout is declared too crowded
# The most humans the 10 m geometry holds (every one of 30 seeds placed 18 humans in both scenarios with 3
# robots; 22-24 failed often). "Placed": the perpendicular sampler of the paper profile gives up after 100
# draws and keeps overlapping starts (module docstring). More humans enlarge the geometry, see geometry_scale.
DENSE_HUMANS: Final[int] = 16


@dataclass(frozen=True)
class Layout:
    """Starts and goals of one episode."""

    robot_starts: np.ndarray  # (M, 2) m
    robot_goals: np.ndarray  # (M, 2) m
    human_starts: np.ndarray  # (N, 2) m
    human_goals: np.ndarray  # (N, 2) m


def checked_layout(layout: Layout) -> Layout:
    """``layout``'s arrays as float copies, or SimulationError naming the field and row that are wrong:
    shapes ``(M, 2), (M, 2), (N, 2), (N, 2)`` (an empty list or array is ``(0, 2)``: no robots, no humans),
    real coordinates within ``crowdsim.world.MOST_COORDINATE``, at most ``MAX_ROBOTS`` robots and
    ``MAX_HUMANS`` humans (``check_sizes``'s limits, which ``CrowdEnv.reset`` and the gym wrapper apply
    too)."""
    if not isinstance(layout, Layout):
        raise SimulationError(f"layout must be a crowdsim.scenarios.Layout, got {type(layout).__name__}")
    arrays = {}
    for name in ("robot_starts", "robot_goals", "human_starts", "human_goals"):
        rows = "M" if name.startswith("robot") else "N"
        try:
            raw = np.asarray(getattr(layout, name))
        except (TypeError, ValueError) as exc:  # ragged rows: numpy's long text names no row
            why = str(exc) if isinstance(exc, TypeError) else "its rows are of unequal lengths, or one nests"
            raise SimulationError(f"layout.{name} must be a ({rows}, 2) array of numbers: {why}") from None
        if raw.dtype.kind == "c" or (
            raw.dtype == object and any(isinstance(x, complex | np.complexfloating) for x in raw.flat)
        ):  # numpy's float conversion would only warn (ComplexWarning) and drop the imaginary parts
            raise SimulationError(f"layout.{name} must hold real numbers, got {raw.dtype} values")
        try:
            points = np.array(raw, dtype=float)
        except (TypeError, ValueError) as exc:
            raise SimulationError(f"layout.{name} must be a ({rows}, 2) array of numbers: {exc}") from None
        held = texts_or_bools(raw)
        if held is not None:  # converted, "3" was a start at 3 m and True one at 1 m
            raise SimulationError(f"layout.{name} must hold real numbers, got {held} values")
        if points.shape == (0,):  # [] or np.array([]): no agents
            points = points.reshape(0, 2)
        if points.ndim != 2 or points.shape[1] != 2:
            raise SimulationError(f"layout.{name} must be a ({rows}, 2) array, got shape {points.shape}")
        # a start beyond MOST_COORDINATE failed at the first step inside ORCA, which names no field of the
        # layout; a goal beyond it lies past any agent's reach (MOST_SPEED x MOST_TIME = 8.6e6 m)
        bad = np.flatnonzero(~(np.abs(points) <= MOST_COORDINATE).all(axis=1))
        if len(bad):
            raise SimulationError(
                f"layout.{name}[{bad[0]}] is {points[bad[0]].tolist()}: every coordinate must be finite "
                f"and within ±{MOST_COORDINATE:g} m ({len(bad)} bad row(s))"
            )
        arrays[name] = points
    for starts, goals in (("robot_starts", "robot_goals"), ("human_starts", "human_goals")):
        if len(arrays[starts]) != len(arrays[goals]):
            raise SimulationError(
                f"layout.{starts} has {counted(len(arrays[starts]), 'row')} but layout.{goals} "
                f"{len(arrays[goals])}: one goal per agent"
            )
    limits = (
        ("robot_starts", "robots", "MAX_ROBOTS", MAX_ROBOTS),
        ("human_starts", "humans", "MAX_HUMANS", MAX_HUMANS),
    )
    for starts, agents, limit, most in limits:
        if len(arrays[starts]) > most:
            raise SimulationError(
                f"layout.{starts} has {len(arrays[starts])} rows: at most {limit} = {most} {agents} "
                "(crowdsim.scenarios)"
            )
    return Layout(**arrays)


def start_overlaps(layout: Layout, radius: float = RADIUS) -> list[tuple[str, str, float]]:
    """Pairs of agents whose starts are closer than ``2 radius`` (centre to centre, m): in contact from the
    first step. Each is ``(agent, agent, distance)``, agent named by its row: ``"human_starts[3]"``."""
    robots, humans = (np.asarray(p, float).reshape(-1, 2) for p in (layout.robot_starts, layout.human_starts))
    names = [f"robot_starts[{i}]" for i in range(len(robots))] + [
        f"human_starts[{j}]" for j in range(len(humans))
    ]
    return _closer_than(np.concatenate([robots, humans]), names, 2.0 * radius)


def robot_goal_overlaps(layout: Layout, radius: float = RADIUS) -> list[tuple[str, str, float]]:
    """Pairs of robot goals closer than ``2 radius`` (m), as ``start_overlaps`` names them: robots standing
    on both would overlap. Humans' goals may be shared: a human stops within its radius of its goal, and ORCA
    keeps the others off it."""
    goals = np.asarray(layout.robot_goals, float).reshape(-1, 2)
    return _closer_than(goals, [f"robot_goals[{i}]" for i in range(len(goals))], 2.0 * radius)


def _closer_than(points: np.ndarray, names: list[str], distance: float) -> list[tuple[str, str, float]]:
    gaps = np.linalg.norm(points[:, None] - points[None], axis=-1)
    first, second = np.nonzero(np.triu(gaps < distance, k=1))
    return [(names[i], names[j], float(gaps[i, j])) for i, j in zip(first, second, strict=True)]


def geometry_scale(n_humans: int) -> float:
    """1 up to ``DENSE_HUMANS`` humans; beyond, the crowd's extent grows in proportion to their number (the
    density of 16 humans, overlaps of the perpendicular sampler included: module docstring)."""
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
    formation: Formation = "auto",
    spacing: float | None = None,
) -> Layout:
    """Robots in ``formation`` plus ``n_humans`` humans sampled from ``rng`` under the ``crossing`` rules.

    ``spawn_separation`` (m, added to the two radii) defaults to the crossing convention's own: 0.5 for
    "paper", 0.2 for "v1". The defaults are the paper profile's, like ``EnvConfig()``'s.
    """
    check_sizes(scenario, n_humans, n_robots)
    if crossing not in CROSSINGS:
        raise SimulationError(f"unknown crossing {crossing!r}; choose from {list(CROSSINGS)}")
    # Checked here, not left to the samplers: a nan radius or speed made every draw fail ("could not place
    # human ... use fewer agents"), and a negative radius was taken.
    radius = real_number("radius", radius, "a finite number > 0 m", finite_positive)
    v_pref = real_number("v_pref", v_pref, "a finite number > 0 m/s", finite_positive)
    separation = real_number(
        "spawn_separation",
        SPAWN_SEPARATION[crossing] if spawn_separation is None else spawn_separation,
        "a finite number >= 0 m",
        lambda s: math.isfinite(s) and s >= 0,
    )
    robot_starts, robot_goals = robot_layout(n_robots, formation, spacing=spacing)
    check_robot_spacing(robot_starts, radius, formation, n_robots)
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
