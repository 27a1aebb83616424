"""What an MPC controller (pipelines.loop.mpc) is built from and checked against: its ``MPCConfig`` from a
``ControllerSpec`` and the world's facts (``mpc_config``), the check that the MPC, the predictor and the
simulator agree on the world (``check_world``) and that its d_min keeps agents apart
(``check_contact_distance``), that calibrated margins were measured at its tau
(``check_margins_world``), the coupling the controller can build (``check_coupling``),
that an observation's step is its tau (``check_dt``) and its history the one of its agents
(``check_history``), and the rows of that history the predictor reads (``predictor_history``).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING, NoReturn

import numpy as np

from crowdsim.scenarios import MAX_HUMANS
from crowdsim.world import LEAST, WORLD, WorldFacts
from mpc.config import MPCConfig
from pipelines.errors import PipelineError
from pipelines.loop.margins import CALIBRATED_MODES
from pipelines.loop.motion_classes import human_observed
from pipelines.loop.observed import agent, check_fields, check_magnitudes, check_positions
from pipelines.loop.spec import ControllerSpec
from predictors.backfill import backfill
from predictors.base import DT as PREDICTOR_DT
from predictors.base import ObservingPredictor, Predictor
from predictors.errors import PredictorError
from predictors.oracle import ORACLE_PREDICTOR
from predictors.text_table import counted

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
            f"{counted(obs.n_robots, 'robot')} then the {counted(obs.n_humans, 'human')}, in the order of "
            "robot_positions and human_positions"
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
    run may change [world] radius (a sweep may not), so the message offers it, unless the radius d_min
    needs (d_min / 2) is below the world's least (crowdsim.world.LEAST), which is refused: the offer stood
    at radius 2e-06 for d_min 1e-07, and at the default 0.3 for d_min 1e-09."""
    contact = 2.0 * world.radius
    # a smaller radius helps only down to d_min / 2, which [world] radius must itself allow (at least LEAST):
    # with a d_min below twice the least, no radius it takes passes the check below
    smaller = radius_settable and cfg.d_min >= 2.0 * LEAST["radius"][0] - 1e-12
    if cfg.d_min < contact - 1e-12:
        raise PipelineError(
            f"the MPC's d_min {cfg.d_min:g} m is below the contact distance 2 x [world] radius = "
            f"{contact:g} m: its plans would touch humans and teammates (Eqs. 11 and 12 keep d_min between "
            f"centres); set [mpc] d_min >= {contact:g} (--set mpc.d_min={contact:g})"
            + (", or a smaller [world] radius" if smaller else "")
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
