"""Seeded start/goal layouts: circle crossing and perpendicular crossing, with the robots in a formation.

Robots (every scenario, every profile)
--------------------------------------
The robots start in a formation centred on ``(0, -5)`` m and travel north: every goal is its start moved
10 m along +y, so the formation arrives, centred on ``(0, +5)``, in the shape it left in. The layout is
deterministic; only the humans are random. Where the paper's robots start and end is not public (its figure
shows 3 robots side by side heading the same way), so both profiles use these formations: they isolate the
published conventions (the humans' sampling, timing and success rule) from a choice of ours. Robots are
numbered left (-x) to right, front to back.

Formations (``FORMATIONS``; ``formation="auto"`` picks by the number of robots M, ``choose_formation``):

* ``"row"``: side by side on ``y = -5`` at ``x_k = (k - (M - 1) / 2) * 1.0`` m. This project's first
  layout, which ``auto`` keeps for M <= 3 (three robots: starts (-1, -5), (0, -5), (1, -5), goals on
  ``y = +5``): stored test digests and published tables depend on it. 1 m is above the robot-robot
  ``d_min`` (``crowdsim.world.D_MIN``) but below the flocking distance ``d_ij`` (``D_FLOCK``): the flock
  closes up or opens a little in its first steps. Any M can ask for it (comparisons).
* ``"wedge"``: ranks of 1, 2, 3, ... robots from the front, the last rank taking what remains (M = 4:
  1 + 2 + 1; 6: 1 + 2 + 3; 12: 1 + 2 + 3 + 4 + 2). ``auto`` for M >= 4.
* ``"two_rows"``: ceil(M / 2) robots in front, floor(M / 2) behind.
* ``"antipodal"``: not a team but robots trading places, the classic multi-robot test: on a circle of
  ``ANTIPODAL_RADIUS`` from ``(0, -3.5)`` anticlockwise, each bound for the opposite point, so every path
  crosses the centre. Eq. 15 then holds the robots together unless the MPC flocks only near goals
  (``flock_range``, docs/extending.md, "Robots bound for separate places"); ``robot_spacing`` does not
  apply, and goals as slots are refused (they would be dealt anew, an even team its own starts).

``EnvConfig.robot_spacing`` (``[env] robot_spacing``) puts neighbours that far apart in any of them, for an
MPC whose ``d_min`` leaves its robots no room on goals 1 m apart (docs/extending.md).

The wedge and the two rows are cut from a hexagonal lattice of spacing ``d_ij``: ranks ``d_ij sqrt(3) / 2``
apart, each shifted half a spacing from the one ahead, each on the lattice slots nearest the middle (ties to
the right). Every robot then stands at least ``d_ij`` from every other and exactly ``d_ij`` from its
neighbours: the flock starts and ends as the compact cluster the flocking term (Eq. 15, every pair towards
``d_ij``) keeps it in on the way.

Why compact, and why the same shape at the goal. Eq. 15 pulls every pair of robots towards ``d_ij``, so the
robots travel as a tight cluster whatever their layout, and a robot can leave it only near its goal, where
Eq. 7's weight grows as ``1 / distance``. Goals spread wider than the cluster keep the last robots pulled
towards each other short of their goals: with goals in lanes at least ``d_min`` apart (the most a formation
can spread if no robot's straight path may come within ``d_min`` of another's goal: 8.8 m wide for 12
robots) CMPC reached no goal formation of 6 robots in 4 episodes, against 8 of 8 for the wedge and the two
rows here and 6 of 8 for the row (constant-velocity predictor, 7 humans, circle and perpendicular). Goals
that are the starts moved forward mean that no robot has to pass a goal where a teammate already stands:
a robot's path crosses only the goals of robots that start behind it and, travelling the same distance,
get there after it has gone by; the robots ahead arrive ahead of it. (Goals mirrored instead of moved would
make the back robots pass between the front robots parked on their goals.) ``auto`` takes the wedge, the
more compact of the two: in the same runs it reached its goals as often or more (5 robots 7 of 8 vs 6 of 8;
7 and 8 robots 3 of 6 each vs 1 and 0 of 6); at 12 robots no layout succeeded (CMPC's all-pairs flocking
compresses the flock below ``d_ij``: ``benchmarks/robot_scaling.py``; the controller's per-robot flocking
weight, ``flocking_weight`` in mpc/config.py, is what took 12 robots to 88-94 %, and 94-100 % with
guidance's penalty-wide discs, docs/examples/many_robots.toml). Its humans' sampling also never ran dry (20
seeds, 14-22 humans, 4-12 robots), where two rows of 12 did once in 20 seeds at 17 humans (v1).

Arrived robots stay in the world (``crowdsim.env``): the success rule needs every robot on its goal at
once, and the humans keep seeing them, as in the authors' fork. The layout keeps them out of the way only
while the flock keeps its shape: a crowd that turns or sweeps the flock lets the robots arrive in another
order, and goals 1.2 m apart are then walled off by the teammates parked around them (passing needs about
2 x 1.03 m). Spreading the goals to 2.2 m was tried and is worse (CMPC at 12 robots reached all goals in 1
of 15 episodes: the flocking keeps the last robots short of spread goals); the controller's
``on_goal="yield"`` (mpc/parked.py) lets parked robots make way instead. Where the robots are interchangeable,
``EnvConfig.goal_assignment="slots"`` (crowdsim/slots.py) makes the goals a formation to fill, so that a late
robot takes a free slot rather than pass a parked teammate: a different task from the paper's, measured beside
it (benchmarks/robot_scaling.py ``--goals``).

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
from typing import Any, Final, Literal, get_args

import numpy as np

from crowdsim.conventions import CROSSINGS, SPAWN_SEPARATION
from crowdsim.crossings import PLACERS
from crowdsim.errors import SimulationError, real_number
from crowdsim.world import D_FLOCK, D_MIN, MOST_COORDINATE, RADIUS, V_PREF, finite_positive

SCENARIOS: Final[tuple[str, ...]] = ("circle", "perpendicular")
Formation = Literal["auto", "row", "wedge", "two_rows", "antipodal"]  # module docstring
FORMATIONS: Final[tuple[Formation, ...]] = get_args(Formation)
ROBOT_SPACING: Final[float] = 1.0  # m between neighbouring robots of the "row" (the first simulator's)
# m: the widest robot spacing taken; 12 robots in a row at 2.5 m span 27.5 m, past the humans' 10 m circle and
# within the gymnasium observation's bounds (crowdsim.gym_observation.scene_bound, 20 m from the origin)
MAX_ROBOT_SPACING: Final[float] = 2.5
ROBOT_START_Y: Final[float] = -5.0  # m, centre of the start formation (module docstring)
# m, the antipodal circle's: inside the circle crossing's 5 m start circle and the perpendicular crossing's
# start strips (|x| from 5 m) by 1.5 m, more than the 1.1 m the samplers keep, so no person is drawn near a
# robot (on a 5 m circle the perpendicular sampler, which keeps its last draw after 100, started people on
# robots in 13 of 100 crowds of 16, and 12 robots left 16 people of the circle no room)
ANTIPODAL_RADIUS: Final[float] = 3.5
ROBOT_TRAVEL: Final[float] = -2.0 * ROBOT_START_Y  # m, every goal is its start moved this far along +y
ROW_MAX_ROBOTS: Final[int] = 3  # "auto" keeps the row up to this many robots (the paper's 3, unchanged)
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
                f"layout.{starts} has {len(arrays[starts])} rows but layout.{goals} {len(arrays[goals])}: "
                "one goal per agent"
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


def choose_formation(n_robots: int) -> Formation:
    """What ``formation="auto"`` gives M robots: the row up to 3, then the wedge (module docstring)."""
    return "row" if n_robots <= ROW_MAX_ROBOTS else "wedge"


def rank_sizes(formation: Formation, n_robots: int) -> list[int]:
    """Robots per rank, front to back, of the wedge or the two rows."""
    if formation == "two_rows":
        return [n for n in ((n_robots + 1) // 2, n_robots // 2) if n]
    if formation == "wedge":
        sizes: list[int] = []
        while sum(sizes) < n_robots:
            sizes.append(min(len(sizes) + 1, n_robots - sum(sizes)))
        return sizes
    raise SimulationError(f"formation {formation!r} has no ranks; choose from ['two_rows', 'wedge']")


def _hexagonal(sizes: list[int], spacing: float) -> np.ndarray:
    """``sizes[k]`` robots on rank ``k`` of a hexagonal lattice of ``spacing`` (module docstring): ``(M, 2)``,
    left to right and front to back, centred on ``(0, 0)``."""
    points = []
    for k, n in enumerate(sizes):
        phase = ((sizes[0] - 1) / 2.0 + k / 2.0) % 1.0  # rank k's slots: x = (j + phase) spacing, j integer
        slots = np.arange(-n - 1, n + 2) + phase
        nearest = np.sort(slots[np.lexsort((-slots, np.abs(slots)))][:n])  # nearest the middle, ties right
        points += [(x * spacing, -k * spacing * math.sqrt(3.0) / 2.0) for x in nearest]
    xy = np.array(points, dtype=float).reshape(-1, 2)
    xy = xy[np.lexsort((-xy[:, 1], xy[:, 0]))]
    return xy - (xy.max(axis=0) + xy.min(axis=0)) / 2.0 if len(xy) else xy


def robot_layout(
    n_robots: int, formation: Formation = "auto", *, spacing: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Starts ``(M, 2)`` and goals ``(M, 2)`` of M robots in ``formation`` (see the module docstring).

    ``spacing`` (m): between neighbouring robots, and so between their goals (``EnvConfig.robot_spacing``);
    None, the formation's own: 1 m in the row (``ROBOT_SPACING``), the MPC's flocking distance ``d_ij``
    (``crowdsim.world.D_FLOCK``) in the wedge and the two rows. It may not be below ``d_min`` (``D_MIN``).
    The antipodal circle ignores it (its neighbours are 7 sin(pi / M) m apart).
    """
    if isinstance(n_robots, bool) or not isinstance(n_robots, int | np.integer) or n_robots < 0:
        raise SimulationError(f"n_robots must be an int >= 0, got {n_robots!r}")
    if formation not in FORMATIONS:
        raise SimulationError(f"unknown formation {formation!r}; choose from {list(FORMATIONS)}")
    check_spacing(spacing, "spacing")
    chosen = choose_formation(int(n_robots)) if formation == "auto" else formation
    if chosen == "antipodal":
        return antipodal_circle(int(n_robots))
    if chosen == "row":
        x = (np.arange(n_robots) - (n_robots - 1) / 2.0) * (ROBOT_SPACING if spacing is None else spacing)
        offsets = np.stack([x, np.zeros(n_robots)], axis=1)
    else:
        offsets = _hexagonal(rank_sizes(chosen, int(n_robots)), D_FLOCK if spacing is None else spacing)
    starts = offsets + [0.0, ROBOT_START_Y]
    return starts, starts + [0.0, ROBOT_TRAVEL]


def antipodal_circle(n_robots: int, radius: float = ANTIPODAL_RADIUS) -> tuple[np.ndarray, np.ndarray]:
    """Starts and goals of the antipodal formation on a circle of ``radius`` m: robot i at angle
    ``-pi/2 + 2 pi i / M``, bound for the opposite point (benchmarks/robot_swaps.py takes other radii)."""
    angles = -math.pi / 2 + 2 * math.pi * np.arange(n_robots) / max(n_robots, 1)
    starts = radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    starts[np.abs(starts) < 1e-12] = 0.0  # cos(pi / 2) is 6e-17: opposite robots exactly head-on
    return starts, 0.0 - starts  # 0.0 - x: no -0.0 among the goals


def check_spacing(spacing: Any, name: str) -> None:
    """Refuse a robot spacing (m) that is not None or a number in [d_min, ``MAX_ROBOT_SPACING``]."""
    if spacing is None:
        return
    number = isinstance(spacing, int | float | np.floating) and not isinstance(spacing, bool)
    if not (number and math.isfinite(spacing) and D_MIN <= spacing <= MAX_ROBOT_SPACING):
        raise SimulationError(
            f"{name} must be a number of metres in [d_min = {D_MIN:g}, {MAX_ROBOT_SPACING:g}], or unset "
            f"for the formation's own; got {spacing!r}"
        )


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


def check_robot_spacing(starts: np.ndarray, radius: float, formation: Formation, n_robots: int) -> None:
    """Refuse a radius at which the formation's neighbours overlap: its spacing (1 m in the row, d_ij in the
    others) does not follow [world] radius, the simulator has no robot-robot contact, and the metrics count
    robot-human contact only, so robots 1 m apart at radius 0.55 m drove the whole episode inside each other
    and the run reported success without a contact. Goals are the starts moved, so the starts tell."""
    if len(starts) < 2:
        return
    gaps = np.linalg.norm(starts[:, None] - starts[None], axis=-1)
    closest = float(gaps[np.triu_indices(len(starts), k=1)].min())
    if closest < 2.0 * radius - 1e-9:  # the lattice's sqrt(3) / 2 puts "1.2 m" neighbours 1e-16 closer
        chosen = choose_formation(n_robots) if formation == "auto" else formation
        spaced = (
            "" if chosen == "antipodal" else "space them out ([env] robot_spacing, m between neighbours) or "
        )
        raise SimulationError(
            f"radius {radius:g} m: the {chosen} formation of {n_robots} robots puts neighbours {closest:g} m "
            f"apart, in contact from the start (2 x radius = {2.0 * radius:g} m); {spaced}use [world] radius "
            f"<= {closest / 2.0:g} m"
        )
