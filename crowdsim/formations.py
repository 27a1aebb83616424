"""The robots' formations: where each of M robots starts and where its goal is, in every scenario and
every profile (``crowdsim.scenarios.make_layout`` samples the humans around them).

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
"""

from __future__ import annotations

import math
from typing import Any, Final, Literal, get_args

import numpy as np

from crowdsim.errors import SimulationError, counted
from crowdsim.world import D_FLOCK, D_MIN

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
            f"radius {radius:g} m: the {chosen} formation of {counted(n_robots, 'robot')} puts neighbours "
            f"{closest:g} m apart, in contact from the start (2 x radius = {2.0 * radius:g} m); {spaced}use "
            f"[world] radius <= {closest / 2.0:g} m"
        )
