"""The notes of ``crowdmpc simulate`` (and ``sweep``, once per method) on an MPC team's layout that runs but
may not do what was meant: robots trading places whom every pair flocking holds together
(``separate_goals_note``), a flock larger than the paper's under its per-pair weight (``flock_note``), a
d_min that leaves robots no room at their goals (``goal_room_note``), robots smaller than the MPC's parking
(``radius_note``). Each reads the formation's own layout (``crowdsim.formations.robot_layout``), which every
episode of a run moves rigidly (slots keep it: their matching of least squared distance is the identity)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Final

import numpy as np

from crowdsim.world import PAPER_ROBOTS
from pipelines.loop.spec import MPC_CONTROLLERS
from pipelines.loop.team_layout import ROOM_SPACING, short_of_room

if TYPE_CHECKING:
    from pipelines.loop.controllers import ControllerSpec


# m by which the closest goals may lie beyond d_flock before the note: Eq. 15's all-pairs pull held the outer
# robots of a row of 3 off their goals with no humans about at 1.5 m spacing (0.39 m short), not at 1.25,
# 1.3 or 1.4 m (CMPC, d_flock 1.2, 2 episodes each; DMPC arrived at 1.3, not at 2.0); d_flock = 1.5 let them
# arrive, and so did flock_distance "goals" at 1.5 and 2.0 m, and at d_min 1.5 / 2.0 with 1.8 / 2.3 m
# spacing (CMPC and DMPC, 2 of 2 each), where d_flock 2.3 with d_min 2.0 did not.
FLOCK_SLACK: Final[float] = 0.25


def goal_room_note(
    spec: ControllerSpec, n_robots: int, formation: str, spacing: float | None = None
) -> str | None:
    """A line for an MPC whose d_min is within ``GOAL_ROOM_MARGIN`` of, or above, the distance between two
    robots' goals (``formation`` of ``n_robots`` at ``spacing``, ``EnvConfig.robot_spacing``), None
    otherwise: the MPC keeps every pair of robots d_min apart (Eq. 12), which can keep them from standing on
    their goals at once, and the episodes then time out for a reason no metric names. Where it starts
    depends on the formation, the number of robots and the controller (measured, no humans, 2 episodes each:
    CMPC in the row of 3, goals 1.0 m apart, arrived at 0.98 and never from 1.0; in the row of 4 never from
    0.98; the wedge of 3, goals 1.2 m apart, arrived up to 1.5, the wedge of 6 failed at 1.3), so the line
    says "can", and docs/extending.md has the table. It names the spacing that gave room: ``ROOM_SPACING``
    above d_min, with flock_distance "goals" where that spacing passes d_flock. Goals with room but further
    apart than d_flock by more than ``FLOCK_SLACK`` get the flocking line instead (Eq. 15 pulls the pair
    together)."""
    from crowdsim.formations import MAX_ROBOT_SPACING
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS or n_robots < 2:
        return None
    shape, gap = _closest_goals(n_robots, formation, spacing)
    cfg = mpc_config(spec)
    d_min = cfg.d_min
    # off with --no-flocking (Table III's "NF"); under flock_distance "goals" the goals' shape costs nothing;
    # a flock_range short of the closest goals' distance leaves that pair out of Eq. 15; robots trading
    # places have separate_goals_note's, which names flock_range
    trading = shape == "antipodal"
    flocking = not trading and cfg.w_floc > 0 and cfg.flock_distance == "uniform"
    flocking = flocking and not 0 < cfg.flock_range < gap
    if not short_of_room(d_min, gap):
        if flocking and gap > cfg.d_flock + FLOCK_SLACK + 1e-9:
            return (
                f"note: the robots' closest goals are {gap:g} m apart ({shape} of {n_robots}), beyond the "
                f"MPC's flocking distance d_flock {cfg.d_flock:g} m: Eq. 15 pulls every pair towards it, "
                "which can hold robots off their goals while nobody is in the way (row of 3, no humans: 0 "
                "of 2 arrived 1.5 m apart, 2 of 2 with --set mpc.flock_distance=goals, which gives each pair "
                "its goals' distance)"
            )
        return None
    wider = math.ceil((d_min + ROOM_SPACING) * 20 - 1e-9) / 20  # to 5 cm, up
    flock = flocking and wider > cfg.d_flock + FLOCK_SLACK  # then the flocking line's way out too
    toml, option = (
        ('with [mpc] flock_distance = "goals" ', " --set mpc.flock_distance=goals") if flock else ("", "")
    )
    hint = (
        f"; [env] robot_spacing = {wider:g} {toml}(--set env.robot_spacing={wider:g}{option}) spaces them "
        f"{wider:g} m apart"
        if wider <= MAX_ROBOT_SPACING and not trading  # the antipodal circle takes no robot_spacing
        else ""
    )
    return (
        f"note: the MPC's d_min {d_min:g} m is not well below the {gap:g} m between two robots' goals "
        f"({shape} of {n_robots}), and it keeps them d_min apart, which can keep them from standing on their "
        f"goals at once: the episodes then time out (measured thresholds: docs/extending.md){hint}"
    )


def _closest_goals(n_robots: int, formation: str, spacing: float | None) -> tuple[str, float]:
    """The formation ``formation`` stands for (``auto``: by the team's size) and the distance, m, between
    its two closest goals at ``spacing`` (None: the formation's own)."""
    from crowdsim.formations import choose_formation

    shape = choose_formation(n_robots) if formation == "auto" else formation
    goals = _layout(n_robots, shape, spacing)[1]
    gaps = np.linalg.norm(goals[:, None] - goals[None], axis=-1)[np.triu_indices(n_robots, k=1)]
    return shape, float(gaps.min())


# m of robot radius below which robots may not count as arrived (the arrival test is the radius): 3 robots
# in a row, no humans, radius 0.01 m, CMPC parked the outer ones 4, 1, 9 and 19 cm off their goals at 1.0,
# 1.1, 1.2 and 1.3 m spacing (Eq. 12's tail at 1.0 m, Eq. 15's pull of the outer pair beyond) and timed out
# at all but 1.1 m; with flock_distance "goals" 0.1 mm off from 1.2 m on (`crowdmpc simulate --controller
# cmpc --humans 0 --set world.radius=0.01 --set env.robot_spacing=S [--set mpc.flock_distance=goals]`).
SMALL_RADIUS: Final[float] = 0.2
# m between goals from which Eq. 12's tail no longer holds robots off them (the 1.2 m above)
TAIL_FREE: Final[float] = 1.2
# Robots up to which the formations with goals TAIL_FREE apart arrived at 0.01 m under the one d_flock: the
# wedge and two rows of 3 and 4 did, of 5, 6 and 12 did not (and did with flock_distance "goals" at 6)
SMALL_TEAM: Final[int] = 4


def radius_note(
    spec: ControllerSpec, n_robots: int, radius: float, formation: str, spacing: float | None
) -> str | None:
    """A line for an MPC team whose robots are smaller than ``SMALL_RADIUS`` (``[world] radius``): a robot
    has arrived once within its radius of its goal, and the MPC's own terms (Eq. 12's tail, Eq. 15's one
    d_flock) can hold it centimetres off, so the episodes time out with nobody in the way. None when the
    goals lie ``TAIL_FREE`` apart or more and flocking leaves their shape alone (flock_distance "goals", no
    flocking) or the team is small (``SMALL_TEAM``)."""
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS or n_robots < 2 or radius >= SMALL_RADIUS:
        return None
    cfg = mpc_config(spec)
    shape, gap = _closest_goals(n_robots, formation, spacing)
    if shape == "antipodal":  # goals metres apart: the tail never holds them; separate_goals_note's flocking
        return None
    harmless = cfg.w_floc == 0 or cfg.flock_distance == "goals" or n_robots <= SMALL_TEAM
    if harmless and gap >= TAIL_FREE - 1e-9:
        return None
    return (
        f"note: robots arrive within [world] radius {radius:g} m of their goals, and the MPC can hold them a "
        f"few centimetres off ({shape} of {n_robots}, goals {gap:g} m apart; a row of 3 with no humans at "
        "radius 0.01 m parked 1-19 cm off at 1.0-1.3 m spacing): the episodes can time out; --set "
        f"env.robot_spacing={max(gap, TAIL_FREE):g} --set mpc.flock_distance=goals arrived within 0.1 mm"
    )


def flock_note(
    spec: ControllerSpec, n_robots: int, formation: str = "auto", spacing: float | None = None
) -> str | None:
    """A line for a flock larger than the paper's 3 under Table I's per-pair flocking weight, which was set
    for 3 robots and pulls a 12-robot flock 5.5x harder against its goals (mpc/config.py, flocking_weight;
    docs/results.md, "More robots, more humans"); None otherwise. With ``flock_range`` a robot flocks only
    with the teammates whose goals lie within it (in ``formation`` at ``spacing``), so the line is for a
    robot with more of them than a robot of the paper's team has. Only for this project's MPC controllers."""
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS or n_robots <= PAPER_ROBOTS:
        return None
    cfg = mpc_config(spec)
    if cfg.flocking_weight != "per_pair" or cfg.w_floc == 0:
        return None
    if cfg.flock_range > 0:
        goals = _layout(n_robots, formation, spacing)[1]
        within = np.linalg.norm(goals[:, None] - goals[None], axis=-1) <= cfg.flock_range
        if int(within.sum(axis=1).max()) - 1 <= PAPER_ROBOTS - 1:  # less oneself
            return None
    return (
        f"note: {n_robots} robots under the paper's per-pair flocking weight, set for {PAPER_ROBOTS}; "
        "--set mpc.flocking_weight=per_robot (in docs/examples/many_robots.toml) weighs it per robot"
    )


def separate_goals_note(
    spec: ControllerSpec, n_robots: int, formation: str = "auto", spacing: float | None = None
) -> str | None:
    """The controller's ``FlockWarning`` (pipelines.loop.team_layout.separate_goals) as a note, for the
    formation's layout: robots trading places (the antipodal formation) whom every pair flocking holds
    together, and the ``--set mpc.flock_range`` that parts them. Said here once for the run: a sweep's
    workers each said it (they leave the warning out now)."""
    from pipelines.loop.mpc_setup import mpc_config
    from pipelines.loop.team_layout import parting_message, separate_goals

    if spec.controller not in MPC_CONTROLLERS or n_robots < 2:
        return None
    cfg = mpc_config(spec)
    parting = separate_goals(cfg, *_layout(n_robots, formation, spacing))
    if parting is None:
        return None
    return "note: " + parting_message(cfg, parting, "--set mpc.flock_range={:.2f}")


def _layout(n_robots: int, formation: str, spacing: float | None) -> tuple[np.ndarray, np.ndarray]:
    """``robot_layout``'s starts and goals of ``formation`` (``auto``: by the team's size) at ``spacing``
    (None: the formation's own), which the run's EnvConfig has checked."""
    from crowdsim.formations import robot_layout

    return robot_layout(n_robots, formation, spacing=spacing)  # type: ignore[arg-type]  # checked
