"""``crowdmpc simulate``'s refusal of choices its controller would ignore: a value accepted must change the
run, so the ones that could not are one-line errors before any episode. And its notes (``sweep``'s too, once
per method) on choices that run but may not do what was meant: a horizon past the predictor's training, an
NLP that takes seconds to build, a plugin's changed code (the notes on the robots' layout are
``pipelines.commands.team_notes``, on calibrated margins ``pipelines.commands.calibration_notes``)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from crowdsim.orca import neighbor_dist_beyond
from crowdsim.world import sensor_range_refused
from pipelines.commands.idle_choices import (
    SAMPLING_KEYS,
    shown_choice,
    team_keys,
    teamless_refusal,
    typed,
    unsampled_because,
    unseen_because,
    untracked_because,
    visibility_shown,
)
from pipelines.commands.output_paths import names_a_folder
from pipelines.errors import PipelineError
from pipelines.loop.spec import MPC_CONTROLLERS, is_shipped
from predictors.text_table import counted

if TYPE_CHECKING:
    from pipelines.commands.simulate_reads import PredictorRead
    from pipelines.config import RunConfig
    from pipelines.loop.controllers import ControllerSpec
    from predictors.manifest import ZooEntry


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
            shown = shown_choice(config, "mpc", key, value)
            raise PipelineError(f"{shown} changes nothing here, where the runs {why}; leave it out")


def check_choices_apply(config: RunConfig, spec: ControllerSpec) -> PredictorRead | None:
    """Refuse what ``spec``'s controller would ignore: a predictor, margins or coupling for one that plans
    with no predictor, and flocking, record_iterations, an [mpc] value or --no-sensor-tracks for ORCA and
    the straight line, which plan with no MPC and read no pasts. Only values the user chose count
    (``RunConfig.chosen``: a config file shared with cmpc may state the defaults); a plugin reads the spec as
    it sees fit, so only its predictor facts are checked. Then ``record_iterations`` without ``record``:
    nothing would write it. Returns the predictor it loaded (``_check_where_chosen``), None if none, for the
    run to plan with."""
    check_mpc_solvable(config)
    if spec.predictor_name is None:  # ORCA, the straight line, a plugin that predicts nothing
        chosen = config.controller
        _refuse(
            [
                shown_choice(config, "controller", key, value)
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
                shown_choice(config, section, key, config.values[section][key])
                for section, key in mpc
                if config.chosen(section, key)
            ],
            spec.controller,
            "MPC",
            "flocking, record_iterations and [mpc]",
        )
    if is_shipped(spec.controller) and spec.controller in MPC_CONTROLLERS:
        _refuse_unread(config, spec)
    _refuse_teamless(config, is_shipped(spec.controller) and spec.controller in MPC_CONTROLLERS)
    if not config.simulate.sensor_tracks and config.simulate.sensor_range is None:
        raise PipelineError(
            f"{shown_choice(config, 'simulate', 'sensor_tracks', False)}: track lengths are a sensor's; give "
            "--sensor-range M too (or [simulate] sensor_range)"
        )
    sensed = config.simulate.sensor_range
    refused = None if sensed is None else sensor_range_refused(sensed)  # sweep's and calibrate's words
    if refused is not None:  # here, not by SimulateSettings: a sweep folder that ran one reads back
        raise config.error("simulate", "sensor_range", refused)
    beyond = neighbor_dist_beyond(config.env.orca)
    if beyond is not None:  # and not by OrcaParams
        raise config.error("env.orca", "neighbor_dist", beyond)
    _refuse_untracked(config, spec.controller)
    _refuse_unseen_visibility(config)
    _refuse_unsampled(config)
    check_recording(config)
    read = _check_where_chosen(config, spec)
    if spec.record_iterations and config.simulate.record is None:
        raise PipelineError(
            f"{config.label('controller', 'record_iterations')}: the iterations are written to the MCAP "
            "recordings; give --record DIR too (or [simulate] record)"
        )
    return read


def check_mpc_solvable(config: RunConfig, folders: Sequence[Path | None] = ()) -> None:
    """The bounds and least values the MPC's NLP is built with (``mpc.nlp.check_solvable``), refused as a
    run starts and named where they were chosen; a config read back from a sweep folder is not held to
    them. ``folders``: the sweep folders the run would add to or take from (--out, --reuse), named in the
    refusal when one ran with the value before its bound (``recorded.ran_beyond_bound_in``)."""
    from mpc.errors import MPCConfigError
    from mpc.nlp import check_solvable as check_nlp
    from pipelines.config.entries import reason
    from pipelines.config.recorded import ran_beyond_bound_in

    try:
        check_nlp(config.mpc)
    except MPCConfigError as exc:
        key = str(exc.field)  # check_solvable names the field it refuses
        ran = ran_beyond_bound_in(folders, "mpc", key, getattr(config.mpc, key))
        raise config.error("mpc", key, reason(str(exc), key) + ran) from None


def check_predictors_known(config: RunConfig, *keys: tuple[str, str]) -> None:
    """The predictors' names a file or ``--set`` gave the ``keys`` ((section, key): [controller] predictor,
    [sweep] predictors), refused in ``UnknownPredictor``'s words naming where, when neither the registry (a
    plugin's too) nor a zoo knows one; a name an option gives is refused as its predictor loads."""
    from predictors.errors import UnknownPredictor
    from predictors.registry import PREDICTORS, available

    for section, key in keys:
        source, value = config.source(section, key), config.values[section][key]
        names = [value] if isinstance(value, str) else list(value or ())
        if source is None or source.kind == "cli" or set(names) <= set(PREDICTORS):
            continue
        known = available()
        for name in names:
            if name not in known:
                raise config.error(section, key, str(UnknownPredictor(name, known)))


def _refuse_teamless(config: RunConfig, mpc: bool) -> None:
    """A lone robot flocks with nobody, has no teammate to re-plan with and no formation to keep: a value
    given on the command line for a team (``team_keys``: its layout, any formation but antipodal, and for a
    shipped ``mpc`` Eq. 15's and DMPC's pairs) ran the episodes of its default. A value in a file passes, as
    a file may serve every team size."""
    if config.scenario.robots != 1:
        return
    for section, key in team_keys(config, mpc):
        if typed(config, section, key):
            raise teamless_refusal(config, shown_choice(config, section, key, config.values[section][key]))


def _refuse_untracked(config: RunConfig, controller: str) -> None:
    """--no-sensor-tracks for a controller that reads no pasts (``untracked_because``: ORCA, the straight
    line): the switch changed only the record's ``sensing``."""
    why = untracked_because([controller])
    if config.chosen("simulate", "sensor_tracks") and not config.simulate.sensor_tracks and why is not None:
        raise PipelineError(
            f"{shown_choice(config, 'simulate', 'sensor_tracks', False)}: {why}; leave it out"
        )


def _check_where_chosen(config: RunConfig, spec: ControllerSpec) -> PredictorRead | None:
    """The run's own checks of its predictor's name, fixed margins' length and d_min, made now for a value a
    file or ``--set`` chose, so that the refusal names where it came from ("run.toml: controller.predictor:
    unknown predictor 'nope'"); those checks, as the controller is built, named the key at most. Margins
    given by ``--margins`` too: their refusal there named nothing. Returns the predictor loaded for the
    world's check, None if none was."""
    from pipelines.loop.mpc_setup import check_contact_distance, mpc_config

    def chosen(section: str, key: str) -> bool:
        source = config.source(section, key)
        return source is not None and source.kind != "cli"

    name = spec.predictor_name
    if name is not None:
        check_predictors_known(config, ("controller", "predictor"))
    if spec.controller not in MPC_CONTROLLERS:
        return None
    mpc = mpc_config(spec, world=config.world)
    values = spec.margins.values
    if spec.margins.mode == "fixed" and len(values) != mpc.horizon:
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
    if name is None or not (chosen("world", "dt") or chosen("world", "obs_len")):
        return None
    from pipelines.commands.simulate_reads import PredictorRead, load_checked
    from pipelines.loop.mpc_setup import check_world
    from predictors.base import DT as PREDICTOR_DT

    located, predictor = load_checked(name)  # its history and sampling time, which the world must give
    try:
        check_world(config.world, mpc, predictor)
    except PipelineError as exc:
        # check_world's order: the predictor's sampling time, then its history
        key = "dt" if predictor.obs_len > 1 and abs(config.world.dt - PREDICTOR_DT) > 1e-12 else "obs_len"
        raise config.error("world", key, str(exc)) from None
    return PredictorRead(located, predictor)


def check_file_outputs(config: RunConfig) -> None:
    """[simulate] json and plot are files: one named as a folder (``--json runs/``) wrote a file called runs.
    Checked here, not in the settings: a sweep records a config file's, which it never writes."""
    for name in ("json", "plot"):
        value = getattr(config.simulate, name)
        if value is not None and names_a_folder(value):
            label = config.label("simulate", name)
            raise PipelineError(f"{label} {value}: a folder, but this output is a file; name a file in it")


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


def _refuse_unseen_visibility(config: RunConfig) -> None:
    """A plain replayed crowd walks its recorded tracks, seeing no robot whether the robots are visible or
    not: the visibility chosen was run as if not given, while the record stated it."""
    why = unseen_because(config.env.crowd)
    if why is not None and config.chosen("env", "robots_visible"):
        raise PipelineError(f"{visibility_shown(config)}: {why}; leave it out")


def _refuse_unsampled(config: RunConfig) -> None:
    """A replayed crowd's people stand where their tracks put them: the rules by which ORCA's humans are
    sampled (``crowdsim.crossings``) place nobody, and a value chosen for them was run as if not given."""
    why = unsampled_because(config.env.crowd)
    for key in SAMPLING_KEYS:
        if why is not None and config.chosen("env", key):
            raise PipelineError(
                f"{shown_choice(config, 'env', key, config.values['env'][key])}: {why}; leave it out"
            )


def horizon_note(spec: ControllerSpec, entry: ZooEntry | None) -> str | None:
    """A line for an MPC that plans further ahead than its learned predictor was trained to predict, None
    otherwise: the net rolls out past its training length, which nothing else would say (TrajNet++ trains
    12 steps; Table I's horizon H is 4). ``entry``: the zoo entry its predictor loads (``zoo_entry``)."""
    from pipelines.loop.mpc_setup import mpc_config
    from predictors.base import DT
    from predictors.registry import entry_prediction_length

    if spec.controller not in MPC_CONTROLLERS:
        return None
    trained = None if entry is None else entry_prediction_length(entry)
    horizon = mpc_config(spec).horizon
    if trained is None or horizon <= trained:
        return None
    return (
        f"note: the MPC plans {horizon} steps ahead and {spec.predictor_name!r} was trained to predict "
        f"{trained} ({trained * DT:g} s): its {extrapolated_steps(trained, horizon)}"
    )


def extrapolated_steps(trained: int, horizon: int) -> str:
    """ "steps 13..14 are extrapolated", or "step 13 is extrapolated" for one step past ``trained`` (not
    "steps 13..13"): the steps of a ``horizon``-step rollout past the net's training length (``export``'s
    note says it too)."""
    if horizon == trained + 1:
        return f"step {horizon} is extrapolated"
    return f"steps {trained + 1}..{horizon} are extrapolated"


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
        f"note: an NLP of {counted(n_robots, 'robot')} among {counted(n_humans, 'human')} over {horizon} "
        "steps is large (here 11 s to build and 0.6 s a first step for 12 robots, 50 humans, 8 steps; 2.5 s "
        "and 0.9 s for 3, 7 and 30): steps may pass mpc.time_limit_s, and an interrupt waits for CasADi to "
        "return"
    )


def tolerance_note(spec: ControllerSpec) -> str | None:
    """A line for an MPC whose cost_scale lies below its solver_tol, None otherwise: the solvers stop at an
    error of solver_tol in cost_scale * F, so with the default tolerance cost_scale = 1e-9 reported every
    step "ok" while the robots stood still (1e-8 barely moved them). A note, not a refusal: a rule between
    two settings refuses configs recorded in sweep folders, and solver_tol = 1 with cost_scale = 0.01 ran
    well."""
    from pipelines.loop.mpc_setup import mpc_config

    if spec.controller not in MPC_CONTROLLERS:
        return None
    cfg = mpc_config(spec)
    if cfg.cost_scale >= cfg.solver_tol:
        return None
    return (
        f"note: mpc.cost_scale {cfg.cost_scale:g} is below mpc.solver_tol {cfg.solver_tol:g}: the solvers "
        "stop at an error of solver_tol in cost_scale * F, and may return plans that hardly move"
    )


def zoo_entry(predictor: str | None) -> ZooEntry | None:
    """The zoo entry ``predictor`` loads; None for a registered predictor (no zoo's: its manifest is not
    read) or a name no zoo holds. Located once for a command's notes (``horizon_note``, ``zoo_notes``): each
    located apart, the manifest was read once a note, and a `zoo add --replace` between the reads had the
    notes describe two models."""
    from predictors.registry import PREDICTORS
    from predictors.zoo import locate

    if not predictor or predictor in PREDICTORS:
        return None
    located = locate(predictor)
    return None if located is None else located.entry


def zoo_notes(predictor: str | None, entry: ZooEntry | None) -> list[str]:
    """The lines on the zoo model ``predictor`` loads (none for a registered predictor), of its ``entry``
    (``zoo_entry``), printed before the load, whose refusal they may explain: a plugin net whose module file
    changed since training (``plugin_entry_note``: its outputs may differ from the figures `zoo list`
    shows). A quick check's note waits until the inputs are accepted (``quick_check_notes``)."""
    if predictor is None or entry is None:
        return []
    note = plugin_entry_note(predictor, entry)
    return [] if note is None else [note]


def plugin_entry_note(predictor: str, entry: ZooEntry | None) -> str | None:
    """The line on a plugin net's changed module file (``zoo_notes``) of the zoo entry ``predictor`` loads,
    already located (None: none)."""
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
