"""``crowdmpc simulate``'s refusal of choices its controller would ignore: a value accepted must change the
run, so the ones that could not are one-line errors before any episode. And its notes (``sweep``'s too, once
per method) on choices that run but may not do what was meant: a flock larger than the paper's under its
per-pair weight, a d_min that leaves robots no room at their goals, a horizon past the predictor's
training (the notes on calibrated margins are ``pipelines.commands.calibration_notes``)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Final

from crowdsim.world import PAPER_ROBOTS
from pipelines.errors import PipelineError
from pipelines.loop.spec import MPC_CONTROLLERS, is_shipped

if TYPE_CHECKING:
    from pipelines.config import RunConfig
    from pipelines.loop.controllers import ControllerSpec
    from predictors.manifest import ZooEntry


def _shown(config: RunConfig, section: str, key: str, value: Any) -> str:
    """A chosen value as an error names it: "--no-flocking", "--set mpc.horizon 10", "run.toml: mpc.horizon
    10" (a switch given as an option says its value by its name)."""
    label = config.label(section, key)
    source = config.source(section, key)
    if isinstance(value, bool):
        return label if source is not None and source.kind == "cli" else f"{label} {str(value).lower()}"
    text = str(value)  # a 900 kB string in a file is no 900 kB error line
    return f"{label} {text if len(text) <= 80 else text[:77] + '...'}"


def _refuse(shown: list[str], controller: str, plans_with: str, keys: str) -> None:
    if shown:
        listed = shown[0] if len(shown) == 1 else f"{', '.join(shown[:-1])} and {shown[-1]}"
        raise PipelineError(
            f"{listed}: controller {controller!r} plans with no {plans_with}; {keys} apply to "
            f"the controllers that do ({', '.join(MPC_CONTROLLERS)})"
        )


def _refuse_unread(config: RunConfig, spec: ControllerSpec) -> None:
    """Refuse an [mpc] value given on the command line (``--set``) that ``spec``'s MPC does not read (DMPC's
    update rule for CMPC, the coupled NLP's mode under IBR, a flocking weight with --no-flocking): a value in
    a file passes, as a file may serve both controllers (docs/examples/many_robots.toml)."""
    from pipelines.loop.unread import unread_because

    for key, value in config.values["mpc"].items():
        source = config.source("mpc", key)
        why = unread_because(spec, key)
        if source is not None and source.kind != "file" and why is not None:
            shown = _shown(config, "mpc", key, value)
            raise PipelineError(f"{shown} changes nothing here, where the runs {why}; leave it out")


def check_choices_apply(config: RunConfig, spec: ControllerSpec) -> None:
    """Refuse what ``spec``'s controller would ignore: a predictor, margins or coupling for one that plans
    with no predictor, and flocking, record_iterations or an [mpc] value for ORCA and the straight line,
    which plan with no MPC. Only values the user chose count (``RunConfig.chosen``: a config file shared
    with cmpc may state the defaults); a plugin reads the spec as it sees fit, so only its predictor facts
    are checked. Then ``record_iterations`` without ``record``: nothing would write it."""
    if spec.predictor_name is None:  # ORCA, the straight line, a plugin that predicts nothing
        chosen = config.controller
        _refuse(
            [
                _shown(config, "controller", key, value)
                for key, value, given in (
                    ("predictor", chosen.predictor, config.chosen("controller", "predictor")),
                    ("margins", chosen.margins, spec.margins.mode != "none"),
                    ("coupling", spec.coupling, spec.coupling != "ibr"),
                )
                if given
            ],
            spec.controller,
            "predictor",
            "predictor, margins and coupling",
        )
    if is_shipped(spec.controller) and spec.controller not in MPC_CONTROLLERS:
        mpc = [("controller", key) for key in ("flocking", "record_iterations")]
        mpc += [("mpc", key) for key in config.values["mpc"]]
        _refuse(
            [
                _shown(config, section, key, config.values[section][key])
                for section, key in mpc
                if config.chosen(section, key)
            ],
            spec.controller,
            "MPC",
            "flocking, record_iterations and [mpc]",
        )
    if is_shipped(spec.controller) and spec.controller in MPC_CONTROLLERS:
        _refuse_unread(config, spec)
    if not config.simulate.sensor_tracks and config.simulate.sensor_range is None:
        raise PipelineError(
            f"{_shown(config, 'simulate', 'sensor_tracks', False)}: track lengths are a sensor's; give "
            "--sensor-range M too (or [simulate] sensor_range)"
        )
    check_recording(config)
    _check_where_chosen(config, spec)
    if spec.record_iterations and config.simulate.record is None:
        raise PipelineError(
            f"{config.label('controller', 'record_iterations')}: the iterations are written to the MCAP "
            "recordings; give --record DIR too (or [simulate] record)"
        )


def _check_where_chosen(config: RunConfig, spec: ControllerSpec) -> None:
    """The run's own checks of its predictor's name, fixed margins' length and d_min, made now for a value a
    file or ``--set`` chose, so that the refusal names where it came from ("run.toml: controller.predictor:
    unknown predictor 'nope'"); those checks, as the controller is built, named the key at most."""
    from pipelines.loop.mpc_setup import check_contact_distance, mpc_config
    from predictors.errors import UnknownPredictor
    from predictors.registry import PREDICTORS, available

    def chosen(section: str, key: str) -> bool:
        source = config.source(section, key)
        return source is not None and source.kind != "cli"

    name = spec.predictor_name
    if chosen("controller", "predictor") and name is not None and name not in PREDICTORS:
        known = available()
        if name not in known:
            raise config.error("controller", "predictor", str(UnknownPredictor(name, known)))
    if spec.controller not in MPC_CONTROLLERS:
        return
    mpc = mpc_config(spec, world=config.world)
    values = spec.margins.values
    if chosen("controller", "margins") and spec.margins.mode == "fixed" and len(values) != mpc.horizon:
        message = f"fixed margins need one value per horizon step ({mpc.horizon}), got {len(values)}"
        raise config.error("controller", "margins", message)
    if chosen("mpc", "d_min") or chosen("world", "radius"):
        # the d_min a file states at Table I's (`config show` writes every default) is not the one changed
        d_min = config.chosen("mpc", "d_min") or not chosen("world", "radius")
        section, key = ("mpc", "d_min") if d_min else ("world", "radius")
        try:
            check_contact_distance(config.world, mpc)
        except PipelineError as exc:
            raise config.error(section, key, str(exc)) from None
    if name is not None and (chosen("world", "dt") or chosen("world", "obs_len")):
        from pipelines.loop.mpc_setup import check_world
        from predictors.base import DT as PREDICTOR_DT
        from predictors.registry import load_predictor

        predictor = load_predictor(name)  # its history and sampling time, which the world must give
        try:
            check_world(config.world, mpc, predictor)
        except PipelineError as exc:
            # check_world's order: the predictor's sampling time, then its history
            key = "dt" if predictor.obs_len > 1 and abs(config.world.dt - PREDICTOR_DT) > 1e-12 else "obs_len"
            raise config.error("world", key, str(exc)) from None


def check_recording(config: RunConfig) -> None:
    """Read a replayed crowd's recording before any work (pipelines.loop.replay_data: once per process),
    its refusal named by the option that chose the crowd: a missing data folder stopped simulate at its
    first episode, after the controller's build, in words naming an option simulate does not have."""
    if config.env.crowd == "orca":
        return
    from pipelines.loop.replay_data import recording
    from predictors.errors import PredictorError

    try:
        recording(config.env.crowd)
    except (PipelineError, PredictorError) as exc:
        raise PipelineError(f"{config.label('env', 'crowd')} {config.env.crowd}: {exc}") from None


# How close to the closest two robots' goals d_min may come before the note: no measured rule holds for
# every formation (docs/extending.md, robot_reached), and the row of 4 failed already at 0.98 of 1.0 m.
GOAL_ROOM_MARGIN: Final[float] = 0.05  # m
# m above d_min at which goal_room_note's suggested robot spacing gave the robots room: CMPC, row of 3, 7
# humans, d_min 1.0 m: 0 of 10 episodes reached their goals 1.0 m apart, 9 of 10 at 1.2 m, 10 of 10 at 1.3 m
ROOM_SPACING: Final[float] = 0.3
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
    from crowdsim.scenarios import MAX_ROBOT_SPACING
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS or n_robots < 2:
        return None
    shape, gap = _closest_goals(n_robots, formation, spacing)
    if shape == "antipodal":  # robots trading places: the controller's FlockWarning names flock_range
        return None
    cfg = mpc_config(spec)
    d_min = cfg.d_min
    # off with --no-flocking (Table III's "NF"); under flock_distance "goals" the goals' shape costs nothing;
    # a flock_range short of the closest goals' distance leaves that pair out of Eq. 15
    flocking = cfg.w_floc > 0 and cfg.flock_distance == "uniform" and not 0 < cfg.flock_range < gap
    if d_min < gap - GOAL_ROOM_MARGIN - 1e-9:
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
        if wider <= MAX_ROBOT_SPACING
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
    import numpy as np

    from crowdsim.scenarios import choose_formation, robot_layout

    shape = choose_formation(n_robots) if formation == "auto" else formation
    goals = robot_layout(n_robots, shape, spacing=spacing)[1]  # type: ignore[arg-type]  # EnvConfig checked it
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
    if shape == "antipodal":  # goals metres apart: the tail never holds them; flocking is FlockWarning's
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


def horizon_note(spec: ControllerSpec) -> str | None:
    """A line for an MPC that plans further ahead than its learned predictor was trained to predict, None
    otherwise: the net rolls out past its training length, which nothing else would say (TrajNet++ trains
    12 steps; Table I's horizon H is 4)."""
    from pipelines.loop.mpc_setup import mpc_config
    from predictors.base import DT
    from predictors.registry import trained_prediction_length

    if spec.controller not in MPC_CONTROLLERS:
        return None
    trained = trained_prediction_length(spec.predictor_name)
    horizon = mpc_config(spec).horizon
    if trained is None or horizon <= trained:
        return None
    return (
        f"note: the MPC plans {horizon} steps ahead and {spec.predictor_name!r} was trained to predict "
        f"{trained} ({trained * DT:g} s): its steps {trained + 1}..{horizon} are extrapolated"
    )


def size_note(spec: ControllerSpec, n_humans: int, n_robots: int) -> str | None:
    """A line for an MPC whose NLPs take seconds to build and a step past the 0.4 s control period to solve
    (a long horizon, or many robots among many humans), None otherwise: one CasADi call builds each, and an
    interrupt waits for it to return (measured on a 2-core machine with constant velocity)."""
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS:
        return None
    horizon = mpc_config(spec).horizon
    if horizon <= 12 and horizon * n_humans * n_robots < 4000:
        return None
    return (
        f"note: an NLP of {n_robots} robots among {n_humans} humans over {horizon} steps is large (here 11 s "
        "to build and 0.6 s a first step for 12 robots, 50 humans, 8 steps; 2.5 s and 0.9 s for 3, 7 and "
        "30): steps may pass mpc.time_limit_s, and an interrupt waits for CasADi to return"
    )


def plugin_code_note(predictor: str | None) -> str | None:
    """A line for a zoo model of a plugin's net whose module file is not the one it was trained with (the
    sha256 its training recorded, ``code.plugins``): the net's code, and so its outputs, may differ from
    the figures `zoo list` shows, where the model loaded without a word. None otherwise (no record, no
    plugin, the same file)."""
    from predictors.registry import PREDICTORS
    from predictors.zoo import locate

    if not predictor or predictor in PREDICTORS:  # a registered one is no zoo's: its manifest is not read
        return None
    located = locate(predictor)
    return None if located is None else plugin_entry_note(predictor, located.entry)


def plugin_entry_note(predictor: str, entry: ZooEntry | None) -> str | None:
    """``plugin_code_note`` of the zoo entry ``predictor`` loads, already located (None: none)."""
    from pipelines.plugins import plugin_code

    code = None if entry is None else entry.training.get("code")
    trained = code.get("plugins") if isinstance(code, dict) else None
    if entry is None or not isinstance(trained, dict) or entry.model not in trained:
        return None
    model = entry.model
    now = plugin_code().get(model)
    if now is None or now == trained[model]:
        return None
    return (
        f"note: {predictor!r} was trained with plugin {model} of sha256 {str(trained[model])[:12]}, its file "
        f"is now {now[:12]}: if the net's code changed, so may its predictions (zoo list's figures are the "
        "trained code's)"
    )


def flock_note(spec: ControllerSpec, n_robots: int) -> str | None:
    """A line for a flock larger than the paper's 3 under Table I's per-pair flocking weight, which was set
    for 3 robots and pulls a 12-robot flock 5.5x harder against its goals (mpc/config.py, flocking_weight;
    docs/results.md, "More robots, more humans"); None otherwise. Only for this project's MPC controllers."""
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS or n_robots <= PAPER_ROBOTS:
        return None
    cfg = mpc_config(spec)
    if cfg.flocking_weight != "per_pair" or cfg.w_floc == 0:
        return None
    return (
        f"note: {n_robots} robots under the paper's per-pair flocking weight, set for {PAPER_ROBOTS}; "
        "--set mpc.flocking_weight=per_robot (in docs/examples/many_robots.toml) weighs it per robot"
    )
