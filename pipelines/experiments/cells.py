"""The experiments a sweep runs, as data, and the registry of those the project ships (``EXPERIMENTS``).

An experiment is a table: its columns are *methods* (a label and the ControllerSpec behind it) repeated for
each number of humans, its rows are the paper's metrics. A *cell* is one method at one crowd size; an
*episode task* is one seeded scenario run in one cell. The cell, the episode task and the seeding schedule
are pipelines.experiments.tasks; the paper's figures are pipelines.experiments.paper; the methods the shipped
experiments compare (the paper's predictor, the swap table's list, the ablations' columns) are
pipelines.experiments.methods.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from types import MappingProxyType
from typing import Any, Final

from crowdsim.world import PAPER_ROBOTS
from pipelines.errors import PipelineError

# the module, not the name: CONTROLLER_CACHE read when tasks are planned (a test shrinks it)
from pipelines.experiments import worker as episode_worker
from pipelines.experiments.methods import (
    CONVENTION_METHODS,
    CONVENTION_WORLDS,
    COUPLING_PREDICTOR,
    PAPER_PREDICTOR,
    SENSING_METHODS,
    SENSING_WORLDS,
    SHIPPED_CONTROLLERS,
    coupled_method,
    safety_methods,
    swap_predictors,
)
from pipelines.experiments.paper import (
    PAPER_HUMANS,
    PAPER_REFERENCE,
    PAPER_TABLE_II,
    PAPER_TABLE_III,
    PaperFigures,
)
from pipelines.experiments.tasks import Cell, EpisodeTask, World, checked_experiment, scenario_schedule
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.margins import MarginSpec
from predictors.oracle import ORACLE_PREDICTOR

PAPER_EPISODES_PER_CELL: Final[int] = 1000  # Section VI: 500 circle + 500 perpendicular crossing per cell
# Experiment's mappings, read-only (MappingProxyType), which pickling sends as dicts
READ_ONLY_FIELDS: Final[tuple[str, ...]] = ("paper", "method_worlds", "method_robots")


def _as_controller(template: ControllerSpec, controller: str) -> ControllerSpec:
    """``template`` for ``controller``; margins only where it plans with a predictor (``with_margins``' rule:
    after ``with_margins``, ORCA's and the straight line's columns took the first method's)."""
    spec = replace(template, controller=controller)
    return spec if spec.kind.uses_predictor else replace(spec, margins=MarginSpec())


@dataclass(frozen=True)
class Experiment:
    """A table to reproduce: methods (columns, in table order) x numbers of humans."""

    name: str
    title: str
    methods: tuple[tuple[str, ControllerSpec], ...]  # (column label, controller spec)
    humans: tuple[int, ...]
    paper: Mapping[tuple[str, int], PaperFigures] = field(default_factory=lambda: MappingProxyType({}))
    paper_source: str | None = None  # where `paper` was transcribed from; None: no such table
    # False when the methods' predictors are part of the comparison (or they use none): no `--predictor`.
    predictor_swappable: bool = True
    world: World = World()  # the conventions of every cell, unless `method_worlds` names the method's own
    method_worlds: Mapping[str, World] = field(default_factory=lambda: MappingProxyType({}))
    # a method's own number of robots (``--vary scenario.robots``), else the sweep's (--robots)
    method_robots: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    # False when the methods' margins are part of the comparison (safety, conventions): no `--margins`.
    margins_swappable: bool = True
    # True when the methods are one per predictor, labelled by its name (the swap table): `--predictors`
    # replaces the list.
    predictor_list: bool = False
    # True when the methods are one per controller, labelled by its name: `--controllers` replaces the list
    # (plugins included, `crowdmpc --plugin module:Class`).
    controller_list: bool = False

    def __post_init__(self):
        humans = checked_experiment(self.name, self.methods, self.humans, self.method_robots)
        object.__setattr__(self, "humans", humans)  # np.arange's counts too, as ints

    def __reduce__(self) -> tuple[Any, ...]:
        # A read-only mapping cannot be pickled nor deep-copied: a SweepConfig sent to a background process
        # (multiprocessing's spawn) failed with "cannot pickle 'mappingproxy' object". Sent as plain dicts,
        # made read-only again.
        values = {f.name: getattr(self, f.name) for f in fields(self)}
        for name in READ_ONLY_FIELDS:
            values[name] = dict(values[name])
        return _rebuilt_experiment, (values,)

    @property
    def method_labels(self) -> tuple[str, ...]:
        return tuple(label for label, _ in self.methods)

    def with_predictor(self, predictor: str) -> Experiment:
        """The experiment with every method's predictor replaced (e.g. Table II with constant velocity)."""
        if not self.predictor_swappable:
            raise PipelineError(
                f"experiment {self.name!r} fixes each method's predictor; --predictor applies only to "
                f"{sorted(n for n, e in EXPERIMENTS.items() if e.predictor_swappable)}"
            )
        methods = tuple((label, replace(spec, predictor=predictor)) for label, spec in self.methods)
        # a title naming the paper's predictor would describe the table wrongly
        title = self.title.replace(PAPER_PREDICTOR_WORDS, predictor).replace("paper's predictor", predictor)
        return replace(self, methods=methods, title=title)

    def with_predictors(self, predictors: Sequence[str]) -> Experiment:
        """The swap table over ``predictors`` (one method each, labelled by its name, in this order), every
        method as the experiment's first (controller, margins ...) but for its predictor."""
        hint = " (use --predictor to replace every method's predictor)" if self.predictor_swappable else ""
        self._check_list("--predictors", "predictor", predictors, lambda e: e.predictor_list, hint)
        template = self.methods[0][1]
        methods = tuple((name, replace(template, predictor=name)) for name in predictors)
        title = self.title if ORACLE_PREDICTOR in predictors else self.title.replace(ORACLE_WORDS, "")
        return replace(self, methods=methods, title=title)

    def with_controllers(self, controllers: Sequence[str]) -> Experiment:
        """One method per controller (labelled by its name, in this order), each as the experiment's first
        method (predictor, margins ...) but for its controller; one that predicts nothing keeps no margins, as
        ``with_margins`` leaves it. An unregistered name is refused here."""
        from pipelines.loop.spec import controller_kind

        self._check_list("--controllers", "controller", controllers, lambda e: e.controller_list)
        for name in controllers:
            controller_kind(name)  # UnknownController: one line saying how to register a plugin
        template = self.methods[0][1]
        methods = tuple((name, _as_controller(template, name)) for name in controllers)
        predicting = any(spec.kind.uses_predictor for _, spec in methods)
        # the clause on the predictor would describe columns that do not exist
        title = self.title if predicting else self.title.split(PREDICTING_WORDS)[0]
        return replace(self, methods=methods, title=title)

    def _check_list(
        self,
        option: str,
        what: str,
        names: Sequence[str],
        lists: Callable[[Experiment], bool],
        hint: str = "",
    ) -> None:
        """``option`` (``--predictors``, ``--controllers``) naming one method each: refused on an experiment
        whose methods it does not list (``lists``), and when ``names`` is empty or repeats a name."""
        if not lists(self):
            allowed = sorted(n for n, e in EXPERIMENTS.items() if lists(e))
            raise PipelineError(
                f"{option} applies only to the experiments {allowed}, not {self.name!r}{hint}"
            )
        if not names:
            raise PipelineError(f"experiment {self.name!r} needs at least one {what}")
        repeated = sorted({name for name in names if list(names).count(name) > 1})
        if repeated:
            raise PipelineError(f"{option} names {repeated} more than once")

    def with_margins(self, margins: MarginSpec) -> Experiment:
        """Every method that plans with a predictor planning with ``margins`` (e.g. Table II with conformal
        margins). Margins widen Eq. 11's distance by an allowance for prediction error: a method that
        predicts nothing (ORCA, the straight line of the controllers experiment) keeps its own, as it keeps no
        predictor (``ControllerSpec.predictor_name``), and its cell key says so."""
        if not self.margins_swappable:
            raise PipelineError(
                f"experiment {self.name!r} fixes each method's margins; --margins does not apply"
            )
        methods = tuple(
            (label, replace(spec, margins=margins) if spec.kind.uses_predictor else spec)
            for label, spec in self.methods
        )
        return replace(self, methods=methods)

    def with_world(self, world: World) -> Experiment:
        """Every cell simulated under ``world``'s profile and visibility, each keeping what it senses."""
        if any(
            self._conventions(own) != self._conventions(self.world) for own in self.method_worlds.values()
        ):
            raise PipelineError(
                f"experiment {self.name!r} fixes each method's profile and visibility; --profile and "
                "--visibility do not apply"
            )

        def conventions(own: World) -> World:
            return replace(own, profile=world.profile, visibility=world.visibility)

        worlds = {label: conventions(own) for label, own in self.method_worlds.items()}
        return replace(self, world=conventions(self.world), method_worlds=MappingProxyType(worlds))

    def with_sensing(self, sensor_range: float, sensor_tracks: bool = True) -> Experiment:
        """Every method's controller behind a sensor of ``sensor_range`` m, track lengths given or not
        (``World.sensing``): e.g. Table II for robots that see 3 m around them."""
        if any(own.sensor_range != self.world.sensor_range for own in self.method_worlds.values()):
            raise PipelineError(
                f"experiment {self.name!r} compares sensor ranges across its methods; --sensor-range and "
                "--no-sensor-tracks do not apply"
            )
        world = self.world.sensing(sensor_range, sensor_tracks)  # refuses a range that is no distance
        worlds = {
            label: own.sensing(sensor_range, sensor_tracks) for label, own in self.method_worlds.items()
        }
        title = f"{self.title}; controllers behind a {world.sensing_label} sensor"
        return replace(self, title=title, world=world, method_worlds=MappingProxyType(worlds))

    def with_env(self, settings: dict[str, Any]) -> Experiment:
        """Every cell simulated with the simulator ``settings`` over its profile's (``World.with_env``: a
        sweep's [env] and [env.orca]), e.g. the humans' ORCA time horizon, or a longer time limit."""
        worlds = {label: own.with_env(settings) for label, own in self.method_worlds.items()}
        shown = ", ".join(f"{key} = {value}" for key, value in sorted(settings.items()))
        title = f"{self.title}; simulator {shown}"
        return replace(
            self, title=title, world=self.world.with_env(settings), method_worlds=MappingProxyType(worlds)
        )

    @staticmethod
    def _conventions(world: World) -> tuple[str, str]:
        return world.profile, world.visibility

    def cells(self, humans: Sequence[int] | None = None, n_robots: int = PAPER_ROBOTS) -> tuple[Cell, ...]:
        """Cells in table order: for each number of humans, smallest first, every method, each with
        ``n_robots`` robots unless ``method_robots`` gives its own. Sorted: ``--humans 6,5`` listed the
        6-human rows of cells.csv, episodes.csv and episodes.jsonl first, where table.md and the plots go by
        crowd size and 5,6 gives the same episodes."""
        return tuple(
            Cell(
                label,
                spec,
                n,
                self.method_robots.get(label, n_robots),
                self.method_worlds.get(label, self.world),
            )
            for n in sorted(humans or self.humans)
            for label, spec in self.methods
        )

    def tasks(
        self,
        episodes_per_cell: int,
        *,
        humans: Sequence[int] | None = None,
        seed: int = 0,
        n_robots: int = PAPER_ROBOTS,
    ) -> list[EpisodeTask]:
        """Every episode of the sweep, episode index by episode index across the cells: at any moment of a
        sweep every cell has run (about) the same crowds, so a sweep stopped early still gives a whole table
        compared on the same crowds, and the progress bar's rate (a stationary mix of cells) gives an honest
        ETA. A sweep of more cells than a worker keeps controllers built (worker.CONTROLLER_CACHE) runs them
        in groups of consecutive cells (``cell_groups``), each group's episodes interleaved and the groups
        one after the other: interleaved across all of them, every worker cycled through every cell and
        rebuilt most controllers for every episode (a replayed crowd's, ~300 MB at 20 people, takes seconds);
        within a group it builds each once."""
        schedule = scenario_schedule(episodes_per_cell, seed)
        return [
            EpisodeTask(self.name, cell, i, scenario, s)
            for group in cell_groups(self.cells(humans, n_robots), episode_worker.CONTROLLER_CACHE)
            for i, (scenario, s) in enumerate(schedule)
            for cell in group
        ]


def cell_groups(cells: Sequence[Cell], most: int) -> list[Sequence[Cell]]:
    """``cells`` in consecutive groups of at most ``most`` (one group when they fit), as even as can be: 21
    cells by 16 in 11 + 10, not 16 + 5, so that a sweep stopped in its second group has more of it."""
    if len(cells) <= most:
        return [cells]
    count = -(-len(cells) // most)
    size, longer = divmod(len(cells), count)  # the first ``longer`` groups take one cell more
    starts = [g * size + min(g, longer) for g in range(count + 1)]
    return [cells[a:b] for a, b in zip(starts, starts[1:], strict=False)]


# Words of titles that hold only for the default methods (Experiment.with_predictor, with_predictors).
PAPER_PREDICTOR_WORDS: Final[str] = "the paper's predictor"
ORACLE_WORDS: Final[str] = " (ORCA ground truth as an oracle)"
PREDICTING_WORDS: Final[str] = ", those that predict the humans with "  # and with_controllers


def _rebuilt_experiment(values: dict[str, Any]) -> Experiment:
    """An ``Experiment`` from ``Experiment.__reduce__``'s values."""
    read_only = {k: MappingProxyType(values[k]) for k in READ_ONLY_FIELDS}
    return Experiment(**{**values, **read_only})


ABLATION_HUMANS: Final[tuple[int, ...]] = (7,)  # the middle of the paper's range

EXPERIMENTS: dict[str, Experiment] = {
    "table2": Experiment(
        name="table2",
        title="Table II: centralized (CMPC) vs distributed (DMPC) MPC",
        methods=(
            ("CMPC", ControllerSpec("cmpc", PAPER_PREDICTOR)),
            ("DMPC", ControllerSpec("dmpc", PAPER_PREDICTOR)),
        ),
        humans=PAPER_HUMANS,
        paper=PAPER_TABLE_II,
        paper_source=f"{PAPER_REFERENCE}, Table II",
    ),
    "table3": Experiment(
        name="table3",
        title="Table III: CMPC with (F) and without (NF) the flocking objective",
        methods=(
            ("F", ControllerSpec("cmpc", PAPER_PREDICTOR, flocking=True)),
            ("NF", ControllerSpec("cmpc", PAPER_PREDICTOR, flocking=False)),
        ),
        humans=PAPER_HUMANS,
        paper=PAPER_TABLE_III,
        paper_source=f"{PAPER_REFERENCE}, Table III",
    ),
    "predictors": Experiment(
        name="predictors",
        title=f"Predictor swap: CMPC with each predictor{ORACLE_WORDS}",
        methods=tuple((name, ControllerSpec("cmpc", name)) for name in swap_predictors()),
        humans=ABLATION_HUMANS,
        predictor_swappable=False,
        predictor_list=True,
    ),
    "controllers": Experiment(
        name="controllers",
        # the table names its humans; ORCA and the straight line plan with no predictor
        title=f"Controllers: each controller{PREDICTING_WORDS}{PAPER_PREDICTOR_WORDS}",
        methods=tuple((name, ControllerSpec(name, PAPER_PREDICTOR)) for name in SHIPPED_CONTROLLERS),
        humans=ABLATION_HUMANS,
        controller_list=True,
    ),
    "coupling": Experiment(
        name="coupling",
        title="Coupling: CMPC by iterated best response (Alg. 1) vs the predictor inside the joint NLP",
        methods=(
            ("IBR", ControllerSpec("cmpc", COUPLING_PREDICTOR, coupling="ibr")),
            # mpc/coupled.py's two models of the humans, named explicitly (its default "auto" picks one by the
            # network's size): the network itself inside the NLP, and its linearisation at the current plan,
            # re-linearised until F settles (nearly the cost of fixed predictions, with the exact gradient).
            ("NLP exact", coupled_method("exact")),
            ("NLP first-order", coupled_method("first_order")),
        ),
        humans=ABLATION_HUMANS,
    ),
    "safety": Experiment(
        name="safety",
        title="Safety: CMPC without margins (the paper), with conformal margins at decreasing alpha: pooled, "
        "per motion class, per motion class of the distance shortfall",
        methods=safety_methods(),
        humans=ABLATION_HUMANS,
        margins_swappable=False,
    ),
    "conventions": Experiment(
        name="conventions",
        title="Conventions: simulation profile x robot visibility x margins (CMPC, paper's predictor)",
        methods=CONVENTION_METHODS,
        humans=ABLATION_HUMANS,
        method_worlds=CONVENTION_WORLDS,
        margins_swappable=False,
    ),
    "sensing": Experiment(
        name="sensing",
        title="Sensing: CMPC given every human vs behind a sensor of each range (a tracker's humans, with "
        "their track lengths, and without them at the middle range), the paper's predictor",
        methods=SENSING_METHODS,
        humans=ABLATION_HUMANS,
        method_worlds=SENSING_WORLDS,
    ),
    "baselines": Experiment(
        name="baselines",
        title="Baselines: robots driving straight to their goals vs robots moving by ORCA",
        methods=(("straight", ControllerSpec("straight")), ("ORCA", ControllerSpec("orca"))),
        humans=PAPER_HUMANS,
        predictor_swappable=False,
        margins_swappable=False,
    ),
}


def get_experiment(name: str) -> Experiment:
    if name not in EXPERIMENTS:
        raise PipelineError(f"unknown experiment {name!r}; choose from {sorted(EXPERIMENTS)}")
    return EXPERIMENTS[name]


def experiment_option(name: str) -> str:
    """What a line refusing a sweep of experiment ``name`` tells to type: ``give --experiment NAME``, or, for
    an ``Experiment`` swept from Python (docs/examples/own_experiment.py), whose name no --experiment takes
    (the advice was refused in turn), how its report is written."""
    if name in EXPERIMENTS:
        return f"give --experiment {name}"
    return (
        f"{name!r} is no --experiment but an Experiment swept from Python: "
        "pipelines.experiments.report.write_report writes its report (docs/examples/own_experiment.py)"
    )
