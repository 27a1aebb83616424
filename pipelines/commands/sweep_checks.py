"""The checks a sweep's plan passes before any worker starts (``check_plan``), each refusing in one line, with
the method named, what would otherwise fail once per episode in errors.jsonl: predictors, couplings, margins,
the MPC's d_min."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Final

from pipelines.commands.calibration_notes import (
    CROWD_SETTINGS,
    calibration_controller_note,
    calibration_physics_note,
    calibration_team_note,
    calibration_world_note,
    sensor_margins_note,
)
from pipelines.commands.simulate_checks import flock_note, goal_room_note, horizon_note, plugin_code_note
from pipelines.errors import PipelineError

# The first episodes of a replayed crowd, size and team drawn before a sweep runs (check_replays)
REPLAY_TRIES: Final[int] = 8

if TYPE_CHECKING:
    from collections.abc import Iterable

    from pipelines.experiments.cells import Experiment
    from pipelines.experiments.tasks import Cell, EpisodeTask
    from predictors.base import Predictor


def check_predictors(experiment: Experiment) -> None:
    """Fail before starting workers, not once per episode in errors.jsonl: every predictor is registered or
    in a zoo, a zoo model's kind is registered (a plugin's, with --plugin, which the workers inherit), and it
    loads as simulate loads it (its files' sha256 as its manifest records them, its net's contract), each
    refusal simulate's one line."""
    from predictors import zoo
    from predictors.errors import PredictorError
    from predictors.models import model_kind
    from predictors.registry import PREDICTORS, available

    # only the predictors some method plans with: an orca or straight column loads none, and registered ones
    # need no zoo (a damaged user manifest stopped a sweep of constant velocity and ORCA)
    wanted = {name for _, spec in experiment.methods if (name := spec.predictor_name) is not None}
    if wanted <= set(PREDICTORS):
        return
    known = set(available())
    missing = sorted(wanted - known)
    if missing:
        hint = "--predictors" if experiment.predictor_list else "--predictor"
        raise PipelineError(
            f"experiment {experiment.name!r} needs predictors {missing} that are not available; "
            f"available: {sorted(known)} (check the names {hint} gives, or train or fetch the zoo models)"
        )
    for name in sorted(wanted):
        located = zoo.locate(name)
        if located is not None:
            try:
                model_kind(located.entry.model)
            except PredictorError as exc:
                raise PipelineError(f"predictor {name!r} of the {located.source} zoo: {exc}") from None
            zoo.load_located(located)  # what every worker would do first, and fail at


def check_plan(experiment: Experiment) -> None:
    """The checks a plan passes before any worker starts, in the dry run as in the run: the installed
    controllers (an entry point that would shadow a shipped one is refused here, as ``simulate`` refuses it,
    not in every episode's worker), its predictors (``check_predictors``), the couplings their methods build
    with them (``check_couplings``), the margins they plan with (``check_margins``) and the MPC's d_min
    against the agents' contact distance (``check_contact_distances``)."""
    from pipelines.loop.spec import controller_names

    controller_names()
    check_predictors(experiment)
    check_couplings(experiment)
    check_margins(experiment)
    check_contact_distances(experiment)


def check_couplings(experiment: Experiment) -> None:
    """Every CMPC and DMPC method's coupling is one its controller builds (mpc_setup.check_coupling, the rule
    the controller applies as it is built), refused with the method named: the coupled NLP given to DMPC
    (--set controller.coupling=nlp) or with the ORCA oracle (the coupling experiment with --predictor
    orca_oracle) failed once per episode in errors.jsonl."""
    from pipelines.loop.mpc_setup import check_coupling
    from predictors.registry import load_predictor

    loaded: dict[str, Predictor] = {}  # the coupling experiment's two NLP methods share their predictor
    for label, spec in experiment.methods:
        if spec.controller not in ("cmpc", "dmpc") or spec.coupling == "ibr":
            continue
        distributed = spec.controller == "dmpc"
        if not distributed and spec.predictor not in loaded:
            loaded[spec.predictor] = load_predictor(spec.predictor)
        try:
            check_coupling(spec, distributed, loaded.get(spec.predictor))
        except PipelineError as exc:
            raise PipelineError(f"method {label!r} of experiment {experiment.name!r}: {exc}") from None


def check_contact_distances(experiment: Experiment) -> None:
    """Every CMPC and DMPC method's d_min keeps agents out of contact in the sweep's world (the default one:
    a sweep refuses [world] values), as the controller checks it as it is built
    (``mpc_setup.check_contact_distance``); refused here with the method named, not once per episode in
    errors.jsonl."""
    from crowdsim.world import WORLD
    from pipelines.loop.mpc_setup import check_contact_distance, mpc_config

    for label, spec in experiment.methods:
        if spec.controller not in ("cmpc", "dmpc"):
            continue
        try:
            check_contact_distance(WORLD, mpc_config(spec), radius_settable=False)  # check_world: no [world]
        except PipelineError as exc:
            raise PipelineError(f"method {label!r} of experiment {experiment.name!r}: {exc}") from None


def check_margins(experiment: Experiment) -> None:
    """Every method's margins resolve (a calibration that matches the weights, with per-class margins for the
    per-human modes) before workers start; refused with the method named, as the other checks are: --vary
    mpc.horizon=4,6 with conformal margins was told to 'plan with a horizon of at most 4 (mpc.horizon)',
    a setting it never gave, without the column that asked for 6."""
    from pipelines.loop.mpc_setup import mpc_config
    from predictors.registry import checkpoint_sha256

    for label, spec in experiment.methods:
        name = spec.predictor_name
        horizon, sha256 = mpc_config(spec).horizon, checkpoint_sha256(name)
        world = experiment.method_worlds.get(label, experiment.world)
        margins = spec.margins.behind(world.sensor_range, world.sensor_tracks)
        try:
            margins.resolve(name, horizon, sha256)
            margins.resolve_classes(name, horizon, sha256)
        except PipelineError as exc:
            raise PipelineError(f"method {label!r} of experiment {experiment.name!r}: {exc}") from None


def method_notes(cells: Iterable[Cell]) -> list[str]:
    """simulate's ``goal_room_note`` lines (a d_min that leaves two robots no room at their goals),
    ``horizon_note`` lines (a plan longer than the learned predictor's training), ``flock_note`` lines
    (a team larger than the paper's under its per-pair flocking weight), ``calibration_world_note`` lines
    (margins calibrated under other conventions), ``sensor_margins_note`` lines (calibrated margins
    behind a sensor), ``calibration_controller_note`` lines (with another controller),
    ``calibration_team_note`` lines (another team or crowd size than calibrated) and
    ``calibration_physics_note`` lines (in another crowd's motion, [env] / [env.orca]), each once, naming
    the methods it applies to: a grid of --vary columns printed the same line for each of eight methods."""
    methods: dict[str, list[str]] = {}  # a note's text -> the methods it applies to, in table order
    seen: set[str] = set()
    cells = list(cells)
    sizes: dict[str, list[int]] = {}  # a method's crowd sizes, which the team note reads
    for cell in cells:
        sizes.setdefault(cell.method, []).append(cell.n_humans)
    for cell in cells:
        # a method's cells differ only in their crowd size, which no note reads: each looked at once (the
        # calibration note reads the calibrations file)
        if cell.method in seen:
            continue
        seen.add(cell.method)
        env = cell.world.env_config()
        for note in (
            goal_room_note(cell.spec, cell.n_robots, env.formation, env.robot_spacing),
            horizon_note(cell.spec),
            plugin_code_note(cell.spec.predictor_name),
            flock_note(cell.spec, cell.n_robots),
            calibration_world_note(
                cell.spec,
                cell.world.profile,
                cell.world.visibility,
                cell.world.crowd,
                cell.world.sensor_range,
                cell.world.sensor_tracks,
            ),
            sensor_margins_note(cell.spec, cell.world.sensor_range, cell.world.sensor_tracks),
            calibration_controller_note(cell.spec, cell.world.sensor_range, cell.world.sensor_tracks),
            calibration_team_note(
                cell.spec,
                sizes[cell.method],
                cell.n_robots,
                cell.world.sensor_range,
                cell.world.sensor_tracks,
            ),
            calibration_physics_note(
                cell.spec,
                [f"{k} {v}" for k, v in cell.world.env_settings if k in CROWD_SETTINGS],
                cell.world.sensor_range,
                cell.world.sensor_tracks,
            ),
        ):
            if note is not None:
                methods.setdefault(note, []).append(cell.method)
    return [
        note.replace(
            "note: ", f"note: method{'s' if len(named) > 1 else ''} {', '.join(map(repr, named))}: ", 1
        )
        for note, named in methods.items()
    ]


def check_replays(tasks: Iterable[EpisodeTask]) -> None:
    """PipelineError naming the cell when a replayed crowd cannot give any of its first ``REPLAY_TRIES``
    episodes (too many humans for the recording, say): every episode of it raised in the workers, each after
    its NLPs were built (42 s for the four cells of Table II at 50 humans), with a traceback in errors.jsonl
    for the reason. Each crowd, size and team's first episodes draw their windows here, as they would; one
    that some of them can draw is left to run (the draw depends on the seed: at 46 of ETH's people about
    half the seeds find a window), its failures recorded as before."""
    from crowdsim.env import CrowdEnv
    from crowdsim.errors import SimulationError
    from pipelines.loop.episode import replayed_recording

    # (crowd's config, humans, robots) -> its first cell's label and its episodes' (seed, scenario), in order
    firsts: dict[tuple[Any, ...], tuple[str, dict[tuple[int, str], None]]] = {}
    keys: dict[Cell, tuple[Any, ...]] = {}  # each cell's, its config built once, not once a task
    for task in tasks:
        cell = task.cell
        if cell.world.crowd == "orca":
            continue
        if cell not in keys:
            keys[cell] = (cell.world.env_config(), cell.n_humans, cell.n_robots)
        firsts.setdefault(keys[cell], (cell.method, {}))[1][task.seed, task.scenario] = None
    for (config, n_humans, n_robots), (method, episodes) in firsts.items():
        env = CrowdEnv(config, replayed_recording(config))
        failed: SimulationError | None = None
        for seed, scenario in list(episodes)[:REPLAY_TRIES]:
            try:
                env.reset(seed, scenario, n_humans, n_robots)
                break
            except SimulationError as exc:
                failed = exc
        else:
            tried = min(len(episodes), REPLAY_TRIES)
            which = "its first episode" if tried == 1 else f"any of its first {tried} episodes"
            where = f"cell {method!r} at {n_humans} humans, crowd {config.crowd}"
            raise PipelineError(f"{where}: the recording gives no window for {which}: {failed}")
