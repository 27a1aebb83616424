"""What a sweep runs, episode by episode: the cell (one method at one crowd size, under a world's simulation
conventions), the episode task (one seeded scenario run in one cell) and the seeding schedule they share.

Seeding. Episode ``i`` of every cell of an experiment is the same crowd: scenario ``SCENARIOS[i % 2]`` (so
any prefix of a cell is half circle and half perpendicular crossing, as the paper's 500 + 500) with seed
``seed + i // 2``. The circle episodes of a cell are therefore exactly those of
``crowdmpc simulate --scenario circle --seed S --episodes N/2``, and cells differ only in the controller.
Only where the cells share their number of robots, profile and the [env] settings that place the humans,
though: another team, profile or placement draws other humans from the same seed (crowdsim.scenarios), and
table.md pairs successes only within those.

The experiments these make up, and the registry of those the project ships, are pipelines.experiments.cells.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any, Final

from crowdsim.profiles import PROFILES, VISIBILITY, make_env_config
from crowdsim.replay import CROWDS
from crowdsim.scenarios import MAX_HUMANS
from crowdsim.world import PAPER_ROBOTS, is_sensor_range
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec
from predictors.errors import short_repr

if TYPE_CHECKING:
    from types import EllipsisType

    from crowdsim.env_config import EnvConfig
    from pipelines.loop.margins_read import CheckedBlock

SCENARIOS: Final[tuple[str, str]] = ("circle", "perpendicular")
# What a sweep's [env] and [env.orca] may set over a cell's profile: what shapes the humans and the episode,
# not the world facts the controllers and predictors share ([world]) nor what the World names itself
ENV_SETTINGS: Final[tuple[str, ...]] = (
    "crossing",
    "formation",
    "goal_assignment",
    "orca.max_neighbors",
    "orca.neighbor_dist",
    "orca.time_horizon",
    "orca_radius_margin",
    "robot_spacing",
    "spawn_separation",
    "success_rule",
    "time_limit",
    "timeout_margin",
)


@dataclass(frozen=True)
class World:
    """The simulation conventions of a cell: a profile of crowdsim.profiles and the robots' visibility, the
    crowd (ORCA's humans or a replay), simulator values over the profile's (``env_settings``), and what the
    controller sees of it: every human, or (``sensor_range`` in m) those within that range of some robot as
    a tracker gives them, with their track lengths unless ``sensor_tracks`` is False
    (pipelines.loop.sensing.RangeLimited)."""

    profile: str = "paper"
    visibility: str = "visible"
    sensor_range: float | None = None
    sensor_tracks: bool = True
    crowd: str = "orca"  # EnvConfig.crowd: ORCA's humans, or a BIWI sequence replayed (crowdsim.replay)
    # simulator settings over the profile's, sorted: ("time_limit", 60.0), ("orca.time_horizon", 2.0), ... (an
    # EnvConfig field, or "orca." and an OrcaParams field; ENV_SETTINGS), the sweep's [env] and [env.orca]
    env_settings: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self):
        if self.profile not in PROFILES:
            raise PipelineError(f"unknown profile {self.profile!r}; choose from {sorted(PROFILES)}")
        if self.visibility not in VISIBILITY:
            raise PipelineError(f"unknown visibility {self.visibility!r}; choose from {list(VISIBILITY)}")
        sensed = self.sensor_range
        if sensed is not None and not is_sensor_range(sensed):
            raise PipelineError(f"a sensor range must be a finite number of metres > 0, got {sensed!r}")
        if not isinstance(self.sensor_tracks, bool):
            raise PipelineError(f"sensor_tracks must be true or false, got {self.sensor_tracks!r}")
        if not self.sensor_tracks and sensed is None:
            raise PipelineError("sensor_tracks = false needs a sensor range: track lengths are a sensor's")
        if self.crowd not in CROWDS:
            raise PipelineError(f"unknown crowd {self.crowd!r}; choose from {list(CROWDS)}")
        self._check_env_settings()

    def _check_env_settings(self) -> None:
        pairs = self.env_settings
        if not (isinstance(pairs, tuple) and all(isinstance(p, tuple) and len(p) == 2 for p in pairs)):
            raise PipelineError(f"env_settings must be a tuple of (key, value) pairs, got {pairs!r:.80}")
        unknown = sorted(k for k, _ in pairs if k not in ENV_SETTINGS)
        if unknown:
            raise PipelineError(f"unknown simulator settings {unknown}; a sweep sets {list(ENV_SETTINGS)}")
        if [k for k, _ in pairs] != sorted({k for k, _ in pairs}):  # one order: one cell key
            raise PipelineError(f"env_settings must name each key once, sorted, got {[k for k, _ in pairs]}")
        from crowdsim.errors import SimulationError

        try:
            self.env_config()
        except SimulationError as exc:
            raise PipelineError(f"simulator settings {dict(pairs)}: {exc}") from None

    @property
    def label(self) -> str:
        """Part of the cell key; a world that sees every human of ORCA's crowd keeps the label of the sweeps
        before sensing and replays, so that they resume into the same cells."""
        label = f"{self.profile}-{self.visibility}"
        if self.sensor_range is not None:
            label += f"-sensed{self.sensor_range:.12g}m" + ("" if self.sensor_tracks else "-notracks")
        label = label if self.crowd == "orca" else f"{label}-{self.crowd}"
        return "-".join([label, *(f"{key}={value}" for key, value in self.env_settings)])

    @property
    def sensing_label(self) -> str:
        """What the controller sees, as the report names it: "every human", "3 m", "3 m untracked"."""
        if self.sensor_range is None:
            return "every human"
        return f"{self.sensor_range:.12g} m" + ("" if self.sensor_tracks else " untracked")

    def sensing(self, sensor_range: float | None, sensor_tracks: bool = True) -> World:
        """This world seen through a sensor of ``sensor_range`` m (None: every human)."""
        return replace(self, sensor_range=sensor_range, sensor_tracks=sensor_tracks)

    def env_config(self) -> EnvConfig:
        config = make_env_config(self.profile, self.visibility)
        orca = {k.removeprefix("orca."): v for k, v in self.env_settings if k.startswith("orca.")}
        env = {k: v for k, v in self.env_settings if not k.startswith("orca.")}
        return replace(config, crowd=self.crowd, orca=replace(config.orca, **orca), **env)

    def with_env(self, settings: dict[str, Any]) -> World:
        """This world with the simulator ``settings`` (``env_settings``' keys) over its own; a value its
        profile has already adds nothing to the cell (``--set env.orca.time_horizon=5``, the paper's, made
        other cells than Table II's, whose episodes it reran, where ``--vary``'s 5 was Table II's cell)."""
        merged = {**dict(self.env_settings), **settings}
        plain = replace(self, env_settings=()).env_config()
        own = {k: v for k, v in merged.items() if _setting(plain, k) != v}
        return replace(self, env_settings=tuple(sorted(own.items())))


def _setting(config: EnvConfig, key: str) -> Any:
    """The value of ``World.env_settings``' ``key`` ("time_limit", "orca.time_horizon") in ``config``."""
    if key.startswith("orca."):
        return getattr(config.orca, key.removeprefix("orca."))
    return getattr(config, key)


@dataclass(frozen=True)
class Cell:
    """One method at one crowd size: a column of the experiment's table."""

    method: str  # the column label, e.g. "CMPC", "NF", "social_lstm_eth"
    spec: ControllerSpec
    n_humans: int
    n_robots: int = PAPER_ROBOTS
    world: World = World()

    def __post_init__(self):
        if self.n_humans < 1:
            raise PipelineError(f"a cell needs at least one human, got n_humans={self.n_humans}")
        if self.n_robots < 1:
            raise PipelineError(f"a cell needs at least one robot, got n_robots={self.n_robots}")

    @property
    def key(self) -> str:
        """Everything that defines the cell's episodes, so records of a changed definition never mix."""
        s = self.spec
        parts = [s.controller, s.predictor_name or "none", "F" if s.flocking else "NF", s.coupling]
        parts += [f"{name}={value}" for name, value in s.mpc_overrides]
        parts += [f"m={s.margins.label}", self.world.label]
        return "-".join(parts) + f"-h{self.n_humans}-r{self.n_robots}"


@dataclass(frozen=True)
class EpisodeTask:
    """One episode to run: a cell and a seeded scenario."""

    experiment: str
    cell: Cell
    index: int  # episode index within the cell
    scenario: str
    seed: int
    # the sha256 of the cell's predictor's weights as the sweep's driver checked them, which the worker's load
    # must match (pipelines.experiments.checked_weights); None: nothing to check. Not part of the episode
    weights_sha256: str | None = field(default=None, compare=False)
    # the calibration block of the cell's method as the driver checked it, which the worker's controller plans
    # with (pipelines.experiments.checked_calibrations); ...: none handed, the controller looks it up itself
    calibration: CheckedBlock | None | EllipsisType = field(default=..., compare=False, repr=False)

    @cached_property
    def key(self) -> str:
        """The record key in episodes.jsonl: unique within a sweep directory. Kept once computed, and sent
        with the task (pickled with it): a worker process where the cell's plugin controller does not load
        (a class defined in a notebook, which a spawned worker cannot import) could not compute it for the
        episode's error, and the sweep's driver ended in that traceback."""
        return f"{self.cell.key}/{self.scenario}/{self.seed}"


def scenario_schedule(episodes: int, seed: int = 0) -> list[tuple[str, int]]:
    """(scenario, seed) of episodes 0..episodes-1 of every cell: alternate scenarios, seeds count up per
    scenario, so a cell's first 2k episodes are k circle + k perpendicular crossings."""
    if episodes < 1:
        raise PipelineError(f"episodes per cell must be at least 1, got {episodes}")
    if seed < 0:
        raise PipelineError(f"the base seed must be non-negative, got {seed}")
    return [(SCENARIOS[i % 2], seed + i // 2) for i in range(episodes)]


def checked_experiment(name: str, methods: Any, humans: Any, method_robots: Any) -> tuple[int, ...]:
    """An ``Experiment``'s humans as ints, once its methods are (label, ControllerSpec) pairs of distinct
    labels, its humans numbers in 1..MAX_HUMANS (numpy's too) and its ``method_robots`` of its methods;
    PipelineError naming the field otherwise (a str spec, an int for humans failed deep inside; 99 humans ran
    every episode into errors.jsonl)."""
    if not isinstance(methods, tuple | list) or not all(
        isinstance(m, tuple) and len(m) == 2 and isinstance(m[1], ControllerSpec) for m in methods
    ):
        raise PipelineError(
            f"experiment {name!r}: methods must be (label, ControllerSpec) pairs, got {short_repr(methods)}"
        )
    labels = [label for label, _ in methods]
    if not labels or len(set(labels)) != len(labels):
        raise PipelineError(f"experiment {name!r} needs distinct method labels, got {labels}")
    counts = humans if isinstance(humans, tuple | list) else ()
    if not counts or not all(
        isinstance(n, numbers.Integral) and not isinstance(n, bool) and 1 <= int(n) <= MAX_HUMANS
        for n in counts
    ):
        raise PipelineError(
            f"experiment {name!r}: humans must be numbers of humans in 1..{MAX_HUMANS}, got "
            f"{short_repr(humans)}"
        )
    unknown = sorted(set(method_robots) - set(labels))
    if unknown:
        raise PipelineError(f"experiment {name!r}: method_robots names no method: {unknown}")
    return tuple(int(n) for n in counts)
