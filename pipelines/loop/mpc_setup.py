"""What an MPC controller (pipelines.loop.mpc) is built from and checked against: its ``MPCConfig`` from a
``ControllerSpec`` and the world's facts (``mpc_config``), the check that the MPC, the predictor and the
simulator agree on the world (``check_world``) and that its d_min keeps agents apart
(``check_contact_distance``), that calibrated margins were measured at its tau
(``check_margins_world``), the coupling the controller can build (``check_coupling``),
that an observation's step is its tau (``check_dt``) and its history the one of its agents
(``check_history``), and the rows of that history the predictor reads (``predictor_history``).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import TYPE_CHECKING, Final, NamedTuple, NoReturn

import numpy as np

from crowdsim.scenarios import MAX_HUMANS
from crowdsim.world import WORLD, WorldFacts
from mpc.config import MPCConfig
from pipelines.errors import FlockWarning, GoalRoomWarning, PipelineError
from pipelines.loop.margins import CALIBRATED_MODES, human_observed
from pipelines.loop.observed import agent, check_fields, check_magnitudes, check_positions
from pipelines.loop.spec import ControllerSpec
from predictors.backfill import backfill
from predictors.base import DT as PREDICTOR_DT
from predictors.base import ObservingPredictor, Predictor
from predictors.errors import PredictorError
from predictors.oracle import ORACLE_PREDICTOR

if TYPE_CHECKING:
    from crowdsim.env import Observation


def mpc_config(spec: ControllerSpec, jit: bool = False, world: WorldFacts = WORLD) -> MPCConfig:
    """Table I in ``world`` (tau, robot bounds), then ``spec.mpc_overrides``, then ``omega_floc = 0`` when
    flocking is off.

    ``jit`` (or ``jit`` in ``spec.mpc_overrides``, a config file's ``[mpc] jit``) compiles the IBR loops'
    NLPs. The coupled NLP (``coupling = "nlp"``) is never compiled, whichever asks: jit is set off for it,
    not refused, so that one config file serves IBR and coupled runs alike (jit changes speed, not results).
    Its graph (the network, or a first-order model's 56 x 24 Jacobian of parameters) kept gcc busy for over
    two minutes per process (measured: 148 s for the first first-order episode of `--experiment coupling`).
    """
    cfg = MPCConfig.from_world(world).replace(**dict(spec.mpc_overrides))
    cfg = cfg.replace(jit=spec.coupling != "nlp" and (jit or cfg.jit))
    return cfg if spec.flocking else cfg.replace(w_floc=0.0)


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


class SolversHeld:
    """A controller holding built CasADi solvers (SWIG objects): ``copy.deepcopy`` and ``pickle`` failed
    with "cannot pickle 'SwigPyObject'"; the refusal says what to do instead."""

    def __reduce__(self) -> NoReturn:
        raise PipelineError(
            f"{type(self).__name__} holds built CasADi solvers, which cannot be copied or pickled: build "
            "another with make_controller(spec, env_config), or pickle its ControllerSpec"
        )


def check_coupling(spec: ControllerSpec, distributed: bool, model: Predictor | None = None) -> None:
    """Refuse a coupled NLP (``coupling = "nlp"``) the controller could not build: in DMPC, whose robots each
    solve their own NLP, or with a predictor that observes the simulator (the ORCA oracle), which has no
    CasADi twin to put inside it; and predictions blind to the robots (``coupling = "none"``) from that
    predictor, whose humans see them. The controller applies it as it is built, and a sweep to its plan before
    any worker starts, so that both refuse alike. ``model``: the predictor ``spec.predictor`` names, loaded
    here when not given (not for "ibr")."""
    from predictors.registry import load_predictor

    if spec.coupling == "ibr":
        return
    if spec.coupling == "nlp" and distributed:
        raise PipelineError(
            "coupling 'nlp' puts the predictor inside the joint NLP, which is centralised: use it with "
            "--controller cmpc (dmpc supports coupling 'ibr')"
        )
    model = model if model is not None else load_predictor(spec.predictor)
    if isinstance(model, ObservingPredictor) and spec.coupling == "none":
        raise PipelineError(
            f"the {model.name} predictor predicts the simulator's humans, who see the robots: coupling "
            "'none' takes a predictor that predicts from the past alone"
        )
    if isinstance(model, ObservingPredictor):
        raise PipelineError(
            f"the {model.name} predictor works with coupling 'ibr' only: it has no CasADi twin "
            "to put inside the joint NLP"
        )
    if spec.coupling == "nlp":  # a plugin net the exporter cannot take failed in the first episode's step
        try:
            model.to_casadi(1, 1, mpc_config(spec).horizon)
        except PredictorError as exc:
            raise PipelineError(
                f"coupling 'nlp' puts the predictor inside the joint NLP, and {model.name!r} has no CasADi "
                f"twin ({exc}): use coupling 'ibr', which runs it in torch"
            ) from None


def predictor_history(obs: Observation, obs_len: int) -> tuple[np.ndarray, np.ndarray]:
    """The last ``obs_len`` rows of ``obs.history`` ``(L, M+N, 2)`` and an all-True mask.

    The predictor gets exactly the rows it reads: a history shorter than ``obs_len`` is refused (the
    simulator's ``EnvConfig.history_len``, which ``[world] obs_len`` sets, must be at least the predictor's
    ``obs_len``), never padded here.
    Before an episode's first step everyone stood still, which is what the simulator's own history says. A
    tracker's human observed for fewer rows (``obs.human_observed``) has the rows before its track, which are
    no observation, filled by ``predictors.backfill``: the track extended back at its mean velocity.
    """
    history = np.asarray(obs.history, dtype=float)
    if len(history) < obs_len:
        # the observation may be a tracker's: say what it needs, then the simulator's key
        raise PipelineError(
            f"the predictor reads {obs_len} observed steps but obs.history holds {len(history)} rows (an "
            f"observation built outside the simulator needs {obs_len}; the simulator keeps "
            f"EnvConfig.history_len, from [world] obs_len): {_keep_more(obs_len)}"
        )
    history = history[-obs_len:]
    if obs.human_present is not None and not np.all(obs.human_present):
        raise PipelineError(
            "the observation holds humans a replayed crowd does not track now (obs.human_present False): "
            "hand the controller the tracked ones, as the closed loop does (pipelines.loop.sensing."
            "RangeLimited(controller, math.inf))"
        )
    observed = human_observed(obs)
    tracks = None if observed is None else np.concatenate([np.full(obs.n_robots, obs_len), observed])
    if tracks is not None:  # a tracker's late arrivals: their padded rows become their tracks extended back
        history = backfill(history, tracks)
    lost = np.argwhere(~np.isfinite(history).all(axis=-1))
    if lost.size and tracks is not None:  # a NaN inside a track made its backfill NaN too: name the cause
        inside = lost[lost[:, 0] >= obs_len - tracks[lost[:, 1]]]
        lost = inside if inside.size else lost
    if lost.size:  # a tracker's NaN rows before a track: the predictor's refusal spoke of a mask never given
        step, i = lost[0]
        who, _ = agent(obs, int(i))
        if i < obs.n_robots:  # no track length covers a robot: it knows where it was
            fix = "a robot's rows must hold its positions"
        elif observed is not None:
            track = int(observed[i - obs.n_robots])
            fix = f"that row is within its track of {track} (obs.human_observed): fill it, or give a "
            fix += "shorter track"
        else:
            fix = "give obs.human_observed, each human's track length (the rows before a track may then hold "
            fix += "anything), or fill those rows with finite positions"
        raise PipelineError(
            f"obs.history[{step - obs_len}] holds a position that is not finite for {who} ({len(lost)} such "
            f"entr{'y' if len(lost) == 1 else 'ies'} in the rows the predictor reads): {fix}"
        )
    return history, np.ones(history.shape[:2], dtype=bool)


def check_dt(obs: Observation, dt: float) -> None:
    """``obs.dt`` is the MPC's tau ``dt``, else a PipelineError: an episode of another simulator than the
    one the controller was built for."""
    if abs(obs.dt - dt) > 1e-12:
        raise PipelineError(
            f"obs.dt is {obs.dt} s (the simulator's step) but the MPC plans with tau = {dt} s"
        )


def check_history(obs: Observation) -> None:
    """``obs.history`` is ``(L, M+N, 2)`` and its row -1 is ``obs.robot_positions`` then
    ``obs.human_positions``, else a PipelineError naming the first agent that differs.

    The predictor reads the history and the MPC the positions: an observation built outside the simulator (a
    tracker's, on a real robot) whose history keeps a human who left, misses one who came, or lags a step
    was otherwise planned with silently, or failed deep in the predictor. The simulator's agree exactly (a
    float32 history, a tracker's, within its rounding). Its robots' and humans' fields are checked first,
    and then how large their numbers are (``check_magnitudes``)."""
    check_fields(obs)
    history = np.asarray(obs.history)
    agents = obs.n_robots + obs.n_humans
    if history.ndim != 3 or history.shape[1:] != (agents, 2):
        raise PipelineError(
            f"obs.history has shape {history.shape}, expected (L, {agents}, 2): the last L positions of the "
            f"{obs.n_robots} robots then the {obs.n_humans} humans, in the order of robot_positions and "
            "human_positions"
        )
    check_positions(obs)  # said as such, not as a history that differs from the positions (NaN differs)
    check_magnitudes(obs)
    now = np.concatenate([obs.robot_positions, obs.human_positions]).astype(float)
    # NaN differs; a float32 history (a tracker's) is its positions rounded: 9e-8 m at 3 m, 6e-5 m at 1 km
    eps = np.finfo(history.dtype).eps if np.issubdtype(history.dtype, np.floating) else 0.0
    differs = ~np.all(np.abs(history[-1] - now) <= 1e-9 + 2 * eps * np.abs(now), axis=1)
    if differs.any():
        i = int(np.flatnonzero(differs)[0])
        who, field = agent(obs, i)
        raise PipelineError(
            f"obs.history[-1] (now) is not the agents' positions: {who} is at {history[-1, i].tolist()} "
            f"there but at {now[i].tolist()} in {field} ({int(differs.sum())} agent(s) differ); row -1 of "
            "the history must be the current positions, robots first"
        )


def check_world(world: WorldFacts, cfg: MPCConfig, predictor: Predictor) -> None:
    """The MPC and the predictor agree with the simulator's world facts (crowdsim/world.py): the control
    period is the simulation step and the predictor's sampling time, the MPC's robot bounds are the
    simulator's, and the history holds what the predictor and guidance "standing" read."""
    for name in ("dt", "v_max", "a_max"):
        ours, theirs = getattr(cfg, name), getattr(world, name)
        if abs(ours - theirs) > 1e-12:
            raise PipelineError(f"the simulator's {name} is {theirs} but the MPC's is {ours} (mpc_overrides)")
    check_contact_distance(world, cfg)
    if predictor.obs_len > 1 and abs(world.dt - PREDICTOR_DT) > 1e-12:
        raise PipelineError(  # a predictor reading no history (the ORCA oracle) plans at any tau
            f"the predictor {predictor.name} reads positions sampled every {PREDICTOR_DT} s, the "
            f"simulator's tau is {world.dt} s ([world] dt): set --set world.dt={PREDICTOR_DT}, or plan "
            f"with {ORACLE_PREDICTOR}"
        )
    # guidance "standing" tells who stands still by how far each human moved over the history: 2 rows at least
    rows = max(predictor.obs_len, 2 if cfg.guidance == "standing" else 1)
    if rows > world.obs_len:
        reader = f"the predictor {predictor.name}" if predictor.obs_len == rows else "guidance 'standing'"
        raise PipelineError(
            f"{reader} reads {rows} observed steps but the simulator keeps {world.obs_len} ([world] "
            f"obs_len): {_keep_more(rows)}"
        )


def check_contact_distance(world: WorldFacts, cfg: MPCConfig, radius_settable: bool = True) -> None:
    """Eqs. 11 and 12 keep ``d_min`` between the centres of a robot and a human or a teammate; below the sum
    of their radii that distance is a contact, which the MPC then accepts in its plans (``--set
    mpc.d_min=0.5``, 9 humans, seeds 0-5: within 0.8 m of a human in 6 of 6 episodes, in contact in 1). A
    d_min equal to ``2 radius`` is allowed: agents that touch without overlapping. ``radius_settable``: the
    run may change [world] radius (a sweep may not), so the message offers it."""
    contact = 2.0 * world.radius
    if cfg.d_min < contact - 1e-12:
        raise PipelineError(
            f"the MPC's d_min {cfg.d_min:g} m is below the contact distance 2 x [world] radius = "
            f"{contact:g} m: its plans would touch humans and teammates (Eqs. 11 and 12 keep d_min between "
            f"centres); set [mpc] d_min >= {contact:g} (--set mpc.d_min={contact:g})"
            + (", or a smaller [world] radius" if radius_settable else "")
        )


def check_margins_world(spec: ControllerSpec, world: WorldFacts) -> None:
    """Calibrated margins are quantiles of the prediction error k steps of the predictors' sampling time
    ahead: real scenes are TrajNet++'s 2.5 Hz, and `crowdmpc calibrate`'s closed loop runs the default world.
    At another tau the MPC's step k is another time ahead (and conformal-motion's classes read another
    window), so such margins are refused there; only the ORCA oracle plans at another tau (check_world)."""
    if spec.margins.mode in CALIBRATED_MODES and abs(world.dt - PREDICTOR_DT) > 1e-12:
        raise PipelineError(
            f"{spec.margins.mode} margins are calibrated per step of {PREDICTOR_DT} s but the simulator's "
            f"tau is {world.dt} s ([world] dt): set --set world.dt={PREDICTOR_DT}, or give fixed margins "
            "(--margins fixed:M1,..,MH)"
        )


def _keep_more(obs_len: int) -> str:
    """What to do about a history shorter than a predictor reads: [world] obs_len is the one key that sets
    it (EnvConfig.history_len follows it; [env] refuses history_len)."""
    return f"set [world] obs_len >= {obs_len} (e.g. --set world.obs_len={obs_len})"


def prepare_sizes(n_robots: int, n_humans: Iterable[int]) -> list[tuple[int, int]]:
    """``MPCController.prepare``'s sizes, ``(n_robots, n)`` for each ``n`` of ``n_humans`` in order, or a
    PipelineError naming the value that is not a count (robots >= 1, humans >= 0)."""
    if isinstance(n_humans, int | np.integer):
        raise PipelineError(
            f"n_humans must be the numbers of humans to prepare for (e.g. range(0, 16) or [7]), got the "
            f"int {n_humans}"
        )
    if not _is_count(n_robots) or n_robots < 1:
        raise PipelineError(f"n_robots must be an int >= 1, got {n_robots!r}")
    if not isinstance(n_humans, Iterable):  # None: iterating it raised a bare TypeError
        raise PipelineError(
            f"n_humans must be the numbers of humans to prepare for (e.g. range(0, 16) or [7]), got "
            f"{n_humans!r:.60}"
        )
    sizes = []
    for n in n_humans:
        if not _is_count(n) or not 0 <= n <= MAX_HUMANS:  # 100000 took gigabytes without a word
            raise PipelineError(
                f"each number of humans must be an int in 0..{MAX_HUMANS}, got {n!r} in n_humans"
            )
        sizes.append((int(n_robots), int(n)))
    return sizes


def _is_count(value: object) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def standing_history(n_agents: int, obs_len: int) -> np.ndarray:
    """A history ``(obs_len, n_agents, 2)`` of agents standing 2 m apart in a row: what ``prepare`` encodes
    to build a predictor's encoder for that many agents (its numbers are not used)."""
    row = np.stack([2.0 * np.arange(n_agents), np.zeros(n_agents)], axis=1)
    return np.broadcast_to(row, (obs_len, n_agents, 2)).copy()
