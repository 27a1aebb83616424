"""The checks a sweep's plan passes before any worker starts (``check_plan``), each refusing in one line, with
the method named, what would otherwise fail once per episode in errors.jsonl: predictors, couplings, margins,
the MPC's d_min."""

from __future__ import annotations

from functools import partial
from typing import TYPE_CHECKING, Any, Final

from mpc.config import MPC_BOUNDS, MPC_LEAST
from pipelines.commands.calibration_notes import (
    CROWD_SETTINGS,
    calibration_controller_note,
    calibration_physics_note,
    calibration_team_note,
    calibration_world_note,
    sensor_margins_note,
)
from pipelines.commands.simulate_checks import horizon_note, size_note, tolerance_note, zoo_entry, zoo_notes
from pipelines.commands.sweep_predictors import PlanModels, check_predictors, read_predictors
from pipelines.commands.team_notes import flock_note, goal_room_note, separate_goals_note
from pipelines.config.schema import MPC_FROM_WORLD
from pipelines.errors import PipelineError, print_note
from pipelines.loop.margins_read import Refused, block_of, look_up, read_once

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Mapping
    from pathlib import Path

    from mpc.config import MPCConfig
    from pipelines.config import RunConfig
    from pipelines.experiments.cells import Experiment
    from pipelines.experiments.tasks import Cell
    from pipelines.loop.margins_read import Planned
    from predictors.base import Predictor
    from predictors.manifest import ZooEntry


def noted_models(experiment: Experiment, cfg: RunConfig | None, cells: Iterable[Cell]) -> PlanModels:
    """The installed controllers' and ``check_predictors``' checks of the plan, a killed calibrate's blocks
    taken back and ``check_margins``, then the ``method_notes`` of its ``cells`` printed, of the entries and
    blocks those checks located: the manifest and the calibrations read once for both, where read apart
    (the manifest and the calibrations once a calibration note) a `zoo add --replace` or a calibrate run
    between the reads had the notes describe other models or blocks than were checked. A refusal comes
    after the notes, as it did when the whole ``check_plan`` followed them: a model that does not load
    (``read_predictors``' ``refused``) with the notes of the entries and blocks located for it, others with
    notes that look them up themselves; the margins' is ``check_plan``'s, in its turn after the couplings'."""
    from pipelines.commands.calibrate_store import take_back_before_planning
    from pipelines.loop.spec import controller_names
    from predictors.errors import PredictorError

    cells = list(cells)
    try:
        controller_names()
        models = read_predictors(experiment, {} if cfg is None else _predictors_chosen(cfg))
        if models.refused is None:  # a model that does not load: refused after the notes, as before
            take_back_before_planning(cell.spec.margins for cell in cells)  # before any block is read
    except (PipelineError, PredictorError):
        for note in method_notes(cells):
            print_note(note)
        raise
    try:  # a refusal kept for check_plan to raise after the couplings' check
        models = models._replace(blocks=planned_margins(experiment, models.loaded, models.entries))
    except (PipelineError, ValueError, OSError):  # check_plan runs it again, after the couplings' check
        pass
    for note in method_notes(cells, models.entries, models.blocks):
        print_note(note)
    if models.refused is not None:
        raise models.refused
    return models


def check_plan(
    experiment: Experiment,
    cfg: RunConfig | None = None,
    models: PlanModels | None = None,
    folders: Iterable[Path | None] = (),
) -> None:
    """The checks a plan passes before any worker starts, in the dry run as in the run: the installed
    controllers (an entry point that would shadow a shipped one is refused here, as ``simulate`` refuses it,
    not in every episode's worker), its predictors (``check_predictors``), the couplings their methods build
    with them (``check_couplings``), the margins they plan with (``check_margins``), the MPC's d_min against
    the agents' contact distance (``check_contact_distances``), the sensor's range (``check_sensor_ranges``),
    ORCA's neighbour distance (``check_neighbor_distances``) and the MPC's bounds (``check_solvable_values``).
    With the run's ``cfg``, a refusal of a value the run chose names where it chose it first ("run.toml:
    mpc.d_min: method 'CMPC' of ..."), as simulate's do: they named the method alone, and a file's value
    looked like one of the experiment's. ``models``: ``check_predictors``' as ``noted_models`` made them
    (None: made here), with the blocks ``planned_margins`` looked up there, or their refusal (not looked up
    again: its refusal is raised in its turn). ``folders``: the sweep folders the run adds to or takes from
    (--out, --reuse), named in the refusal of a sensor range, neighbor_dist or MPC value (a --vary column's
    too) one of them ran with before its bound (``recorded.ran_beyond_bound_in``), as ``check_mpc_solvable``
    names them for the run's own [mpc] values."""
    from pipelines.loop.spec import controller_names

    controller_names()
    if models is None:
        models = check_predictors(experiment, {} if cfg is None else _predictors_chosen(cfg))
    loaded = models.loaded
    for check, keys in (
        (
            partial(check_couplings, loaded=loaded),
            (("controller", "coupling"), ("controller", "predictor"), ("sweep", "predictors")),
        ),
        (
            # looked up in noted_models, whose notes describe the blocks it located: not read again
            partial(check_margins, loaded=loaded, entries=models.entries, planned=models.blocks),
            (("controller", "margins"), ("mpc", "horizon"), *SENSING_KEYS),
        ),
        (check_contact_distances, (("mpc", "d_min"),)),
        (partial(check_sensor_ranges, folders=folders), SENSING_KEYS[:1]),
        (partial(check_neighbor_distances, folders=folders), (("env.orca", "neighbor_dist"),)),
        (partial(check_solvable_values, folders=folders), SOLVABLE_KEYS),
    ):
        try:
            check(experiment)
        except PipelineError as exc:
            where = None if cfg is None else _chosen_where(cfg, keys)
            if where is None:
                raise
            raise PipelineError(f"{where}: {exc}") from None


# what the margins a method plans with read beside their own setting and its horizon
SENSING_KEYS: Final = (("simulate", "sensor_range"), ("simulate", "sensor_tracks"))
# the [mpc] values its NLP is built within (dt, v_max and a_max are [world]'s, which the simulator bounds)
SOLVABLE_KEYS: Final = tuple(("mpc", key) for key in {**MPC_BOUNDS, **MPC_LEAST} if key not in MPC_FROM_WORLD)


def _predictors_chosen(cfg: RunConfig) -> dict[str, str]:
    """The predictors a file or ``--set`` names -> where (``check_predictors``' ``chosen_by``); the refusal of
    one an option names says "check the names --predictor gives", as simulate's does."""
    chosen: dict[str, str] = {}
    for section, key, names in (
        ("sweep", "predictors", cfg.sweep.predictors or ()),
        ("controller", "predictor", (cfg.controller.predictor,) if cfg.controller.predictor else ()),
    ):
        source = cfg.source(section, key)
        if source is not None and source.kind != "cli" and cfg.chosen(section, key):
            chosen.update(dict.fromkeys(names, source.prefix(section, key)))
    return chosen


def _chosen_where(cfg: RunConfig, keys: tuple[tuple[str, str], ...]) -> str | None:
    """Where the run chose what a check refused: [sweep] vary's label where it varies one of ``keys`` (the
    refused method is one of its columns: --margins conformal:0.1 with --vary mpc.horizon=4,6 is refused
    at 6), else the first of them the run sets; None where it sets none of them."""
    from pipelines.commands.sweep_vary import varied

    varies = {(vary.section, vary.key) for vary in varied(cfg)}
    if varies.intersection(keys):
        return cfg.label("sweep", "vary")
    return next((cfg.label(section, key) for section, key in keys if cfg.chosen(section, key)), None)


def check_couplings(experiment: Experiment, loaded: Mapping[str, Predictor] | None = None) -> None:
    """Every CMPC and DMPC method's coupling is one its controller builds (mpc_setup.check_coupling, the rule
    the controller applies as it is built), refused with the method named: the coupled NLP given to DMPC
    (--set controller.coupling=nlp) or with the ORCA oracle (the coupling experiment with --predictor
    orca_oracle) failed once per episode in errors.jsonl. ``loaded``: predictors ``check_predictors`` loaded,
    by name (others are loaded here)."""
    from pipelines.loop.mpc_setup import check_coupling
    from predictors.registry import load_predictor

    loaded = dict(loaded or {})  # the coupling experiment's two NLP methods share their predictor
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
    from pipelines.loop.mpc_setup import check_contact_distance

    # check_world: no [world]
    _each_mpc(
        experiment, lambda mpc: check_contact_distance(WORLD, mpc, radius_settable=False), PipelineError
    )


def check_sensor_ranges(experiment: Experiment, folders: Iterable[Path | None] = ()) -> None:
    """The range of the sensor the methods see through (a --vary column's too) within
    ``crowdsim.world.SENSOR_RANGE``, as the sensor checks it as it is built (``RangeLimited``), refused here,
    not once per episode in errors.jsonl; a --report-only of a folder that ran beyond them runs no such
    check. The refusal names the one of ``folders`` (``check_plan``'s) that ran the range before its bound."""
    from crowdsim.world import sensor_range_refused
    from pipelines.config.recorded import ran_beyond_bound_in

    for world in (experiment.world, *experiment.method_worlds.values()):
        sensed = world.sensor_range
        refused = None if sensed is None else sensor_range_refused(sensed)
        if refused is not None:
            ran = ran_beyond_bound_in(folders, "simulate", "sensor_range", sensed)
            raise PipelineError(f"{refused}{ran}")


def check_neighbor_distances(experiment: Experiment, folders: Iterable[Path | None] = ()) -> None:
    """ORCA's neighbor_dist in every world the methods run in (a --vary column's too) at least
    ``crowdsim.orca.LEAST_NEIGHBOR_DIST``, as orca_velocities checks it, refused here, not once per episode
    in errors.jsonl; a --report-only of a folder that ran less runs no such check. The refusal names the one
    of ``folders`` (``check_plan``'s) that ran the distance before its bound."""
    from crowdsim.orca import neighbor_dist_beyond
    from pipelines.config.recorded import ran_beyond_bound_in

    for world in (experiment.world, *experiment.method_worlds.values()):
        orca = world.env_config().orca
        beyond = neighbor_dist_beyond(orca)
        if beyond is not None:
            ran = ran_beyond_bound_in(folders, "env.orca", "neighbor_dist", orca.neighbor_dist)
            raise PipelineError(f"ORCA's neighbor_dist {beyond}{ran}")


def check_solvable_values(experiment: Experiment, folders: Iterable[Path | None] = ()) -> None:
    """Every CMPC and DMPC method's MPC takes the bounds and least values its NLP is built with
    (``MPC_BOUNDS``, ``MPC_LEAST``), as the NLP checks them, refused here with the method named (a column of
    --vary mpc.rho too), not once per episode in errors.jsonl; a --report-only of a folder that ran beyond
    them runs no such check. The refusal names the one of ``folders`` (``check_plan``'s) that ran the value
    before its bound, as ``check_mpc_solvable`` does for the run's own [mpc] values."""
    from mpc.errors import MPCConfigError
    from mpc.nlp import check_solvable
    from pipelines.config.recorded import ran_beyond_bound_in

    def check(config: MPCConfig) -> None:
        try:
            check_solvable(config)
        except MPCConfigError as exc:
            key = exc.field or ""  # check_solvable names the field it refuses
            ran = ran_beyond_bound_in(folders, "mpc", key, getattr(config, key, None))
            raise MPCConfigError(f"{exc}{ran}") from None

    _each_mpc(experiment, check, MPCConfigError)


def _each_mpc(experiment: Experiment, check: Callable[[MPCConfig], None], refusal: type[Exception]) -> None:
    """``check`` of every CMPC and DMPC method's MPCConfig, its ``refusal`` naming the method."""
    from pipelines.loop.mpc_setup import mpc_config

    for label, spec in experiment.methods:
        if spec.controller not in ("cmpc", "dmpc"):
            continue
        try:
            check(mpc_config(spec))
        except refusal as exc:
            raise PipelineError(f"method {label!r} of experiment {experiment.name!r}: {exc}") from None


def check_margins(
    experiment: Experiment,
    loaded: Mapping[str, Predictor] | None = None,
    entries: Mapping[str, ZooEntry] | None = None,
    planned: Mapping[str, Planned] | None = None,
) -> None:
    """Every method's margins resolve (a calibration that matches the weights, with per-class margins for the
    per-human modes) before workers start; refused with the method named, as the other checks are: --vary
    mpc.horizon=4,6 with conformal margins was told to 'plan with a horizon of at most 4 (mpc.horizon)',
    a setting it never gave, without the column that asked for 6. ``planned``: ``planned_margins``' (None:
    looked up here, of ``loaded`` and ``entries``), whose first refusal in the experiment's order is
    raised."""
    planned = planned_margins(experiment, loaded, entries) if planned is None else planned
    for at in planned.values():
        if isinstance(at, Refused):
            raise at.error


def planned_margins(
    experiment: Experiment,
    loaded: Mapping[str, Predictor] | None = None,
    entries: Mapping[str, ZooEntry] | None = None,
) -> dict[str, Planned]:
    """The block each method plans with (``MarginSpec.located``'s), by label, for ``check_margins`` and the
    notes, a method's refusal kept as a ``Refused`` of the block it refused: the notes of a refused plan
    looked each block up again (the manifest, then calibrations.json, once a note and method), and the
    check once more. ``loaded``: as ``check_couplings``'; the margins are looked up for the weights those
    hold (the manifest, read again, may name others). ``entries``: ``check_predictors``', whose model kinds
    the calibrate command a refusal quotes registers (None: that command locates it)."""
    from pipelines.loop.mpc_setup import mpc_config
    from predictors.registry import checkpoint_sha256, loaded_sha256

    loaded = loaded or {}
    in_force = read_once()  # every method's block from one read of the calibrations, not one a predictor
    blocks: dict[tuple[Any, ...], Planned] = {}  # Table II's CMPC and DMPC plan with one block: read once
    planned: dict[str, Planned] = {}
    for label, spec in experiment.methods:
        name = spec.predictor_name
        predictor = loaded.get(name) if name is not None else None
        entry = None if entries is None else entries.get(name or "")
        # a model that did not load (read_predictors): its entry's, as the notes read it; a zoo name not in
        # ``entries`` is in no zoo (read_predictors located every one): no manifest read again for it
        located = checkpoint_sha256(name) if entries is None else None
        unloaded = located if entry is None else entry.sha256
        sha256 = loaded_sha256(predictor) if predictor is not None else unloaded
        horizon = mpc_config(spec).horizon
        world = experiment.method_worlds.get(label, experiment.world)
        margins = spec.margins.behind(world.sensor_range, world.sensor_tracks)
        kind = ... if entries is None else None if entry is None else entry.model
        key = (margins, name, horizon, sha256)
        if key not in blocks:  # the calibrations read once, as the controller does
            blocks[key] = look_up(margins, name, horizon, sha256, kind, in_force)
        at = blocks[key]
        if not isinstance(at, Refused):
            try:
                margins.resolve(name, horizon, sha256, at)  # fixed margins: one a step
            except PipelineError as exc:
                at = Refused(exc, at)
        if isinstance(at, Refused) and isinstance(at.error, PipelineError):  # a PredictorError as it is
            named = PipelineError(f"method {label!r} of experiment {experiment.name!r}: {at.error}")
            at = Refused(named, at.found)
        planned[label] = at
    return planned


def method_notes(
    cells: Iterable[Cell],
    entries: Mapping[str, ZooEntry] | None = None,
    blocks: Mapping[str, Planned] | None = None,
) -> list[str]:
    """simulate's ``separate_goals_note`` lines (robots trading places whom every pair flocking holds
    together: each worker's controller said it, and leaves it out now), ``goal_room_note`` lines (a d_min
    that leaves two robots no room at their goals), ``horizon_note`` lines (a plan longer than the learned
    predictor's training), ``size_note`` lines (an NLP of the method's largest crowd that takes seconds to
    build and may pass the time limit a step; a sweep said nothing of it), ``flock_note`` lines
    (a team larger than the paper's under its per-pair flocking weight), ``calibration_world_note`` lines
    (margins calibrated under other conventions), ``sensor_margins_note`` lines (calibrated margins
    behind a sensor), ``calibration_controller_note`` lines (with another controller),
    ``calibration_team_note`` lines (another team or crowd size than calibrated) and
    ``calibration_physics_note`` lines (in another crowd's motion, [env] / [env.orca]), each once, naming
    the methods it applies to: a grid of --vary columns printed the same line for each of eight methods.
    ``entries``: the zoo entry each zoo predictor loads, located already (``check_predictors``'; None:
    located here; the calibrate commands the notes quote take its model kind from it); ``blocks``: the block
    each method plans with, by label (``planned_margins``', the block a refusal is of; None: each
    calibration note looks it up)."""
    methods: dict[str, list[str]] = {}  # a note's text -> the methods it applies to, in table order
    seen: set[str] = set()
    cells = list(cells)
    sizes: dict[str, list[int]] = {}  # a method's crowd sizes, which the team note reads
    for cell in cells:
        sizes.setdefault(cell.method, []).append(cell.n_humans)
    # each predictor's zoo entry located once, for every method that plans with it
    names = {cell.spec.predictor_name for cell in cells}
    located = {n: zoo_entry(n) if entries is None else entries.get(n or "") for n in names}
    for cell in cells:
        # a method's cells differ only in their crowd size, which no note reads: each looked at once (the
        # calibration note reads the calibrations file)
        if cell.method in seen:
            continue
        seen.add(cell.method)
        env = cell.world.env_config()
        view = cell.world.sensor_range, cell.world.sensor_tracks
        block = block_of(... if blocks is None else blocks.get(cell.method, ...))
        entry = located[cell.spec.predictor_name]
        for note in (
            separate_goals_note(cell.spec, cell.n_robots, env.formation, env.robot_spacing),
            goal_room_note(cell.spec, cell.n_robots, env.formation, env.robot_spacing),
            horizon_note(cell.spec, entry),
            size_note(cell.spec, max(sizes[cell.method]), cell.n_robots),  # its largest crowd's NLP
            tolerance_note(cell.spec),
            *zoo_notes(cell.spec.predictor_name, entry),
            flock_note(cell.spec, cell.n_robots, env.formation, env.robot_spacing),
            calibration_world_note(
                cell.spec,
                cell.world.profile,
                cell.world.visibility,
                cell.world.crowd,
                cell.world.sensor_range,
                cell.world.sensor_tracks,
                as_read=block,
                entry=entry,
            ),
            sensor_margins_note(cell.spec, *view, as_read=block, entry=entry),
            calibration_controller_note(cell.spec, *view, as_read=block, entry=entry),
            calibration_team_note(cell.spec, sizes[cell.method], cell.n_robots, *view, as_read=block),
            calibration_physics_note(
                cell.spec,
                [f"{k} {v}" for k, v in cell.world.env_settings if k in CROWD_SETTINGS],
                *view,
                as_read=block,
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
