"""The run settings that have no dataclass of their own elsewhere: the scenario, the controller choice, and
the ``simulate`` and ``sweep`` commands' options. Each validates itself, like ``MPCConfig`` and ``EnvConfig``:
messages start with the field's name ("episodes must be >= 1, got 0"), which the config loader turns into
"run.toml: simulate.episodes: must be >= 1, got 0" or "--episodes must be >= 1, got 0".
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Final

from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS, SCENARIOS, check_sizes
from crowdsim.world import is_sensor_range
from pipelines.errors import PipelineError
from pipelines.experiments.backends import BACKENDS
from pipelines.experiments.cells import EXPERIMENTS, PAPER_EPISODES_PER_CELL
from pipelines.experiments.deadline import check_timeout
from pipelines.experiments.sweep_config import MAX_EPISODES_PER_CELL, MAX_WORKERS
from pipelines.experiments.worker import RECORD_POLICIES
from pipelines.loop.spec import COUPLINGS, ControllerSpec
from predictors.home import expand_home

MAX_SIMULATE_EPISODES: Final[int] = (
    100_000  # a sweep's cell holds at most as many; beyond, use `crowdmpc sweep`
)
# A local pool (processes, or a local Ray) gets at most this many workers per CPU: more only queue for the
# same cores, each holding its own solvers and predictor in memory. A Ray cluster (ray_address) takes more.
LOCAL_WORKERS_PER_CPU: Final[int] = 4
# A swap table of more predictors than this is no table anyone reads; each is a column of every row.
MAX_SWAP_PREDICTORS: Final[int] = 64
JIT_CHOICES: Final[tuple[str, ...]] = ("auto", "on", "off")
MAX_SEED: Final[int] = 2**63 - 1  # TOML's largest integer


def available_cpus() -> int:
    """CPUs this process may use (a container or taskset may allow fewer than the machine has)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def local_workers_limit() -> int:
    """The most workers a local pool takes on this machine: ``LOCAL_WORKERS_PER_CPU`` per CPU, at least 8."""
    return max(LOCAL_WORKERS_PER_CPU * available_cpus(), 8)


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _check_int(name: str, value: object) -> None:
    """Refuse a value that is no integer before its range is checked: "episodes must be >= 1, got 2.0" told
    of a bound that 2.0 keeps."""
    if not _is_int(value):
        raise PipelineError(f"{name} must be an integer, got {value!r}")


def _check_seed(seed: object) -> None:
    """A seed is written into the run's TOML config, whose integers are 64-bit signed: a larger one would make
    a file that TOML readers other than Python's refuse."""
    if not _is_int(seed):
        raise PipelineError(f"seed must be an integer, got {seed!r}")
    assert isinstance(seed, int)
    if seed < 0:
        raise PipelineError(f"seed must be >= 0, got {seed!r}")
    if seed > MAX_SEED:
        raise PipelineError(f"seed must be at most 2**63 - 1 (TOML's largest integer), got {seed!r}")


def check_last_seed(seed: int, offset: int, episodes: str, name: str = "seed") -> None:
    """The last episode's seed, ``seed + offset``, in range too: one past 2**63 - 1 ran and was recorded under
    a seed no command takes back (`--seed` refuses it), so the episode could not be rerun alone."""
    if seed + offset > MAX_SEED:
        raise PipelineError(
            f"{name} must be at most {MAX_SEED - offset} with {episodes} (its last episode's seed, seed + "
            f"{offset}, must stay within 2**63 - 1, TOML's largest integer), got {seed!r}"
        )


def _check_once(name: str, what: str, names: tuple[str, ...]) -> None:
    """Refuse a list that names one twice, as ``humans`` is: each name is a column (the experiment refused it
    later, as "--predictors names [...] more than once" under ``--set sweep.predictors``)."""
    repeated = next((n for i, n in enumerate(names) if n in names[:i]), None)
    if repeated is not None:
        raise PipelineError(f"{name} must name each {what} once, got {repeated[:64]!r} more than once")


def _home(settings: object, name: str) -> None:
    """A path setting with a leading ``~`` made the home directory's, as a shell does: ``record = "~/runs"``
    (no shell reads a config file, nor a quoted --set) wrote a folder named ``~`` here. Set in place: the
    dataclass is frozen, and this is its own validation. Not ``expanduser``: it made an empty ``$HOME``'s
    ``~/runs`` /runs."""
    value = getattr(settings, name)
    if isinstance(value, str) and value.startswith("~"):
        object.__setattr__(settings, name, str(expand_home(value, name)))


def _check_optional_path(name: str, value: object) -> None:
    """A [simulate] path or None; the error says how to switch one off. "none" (or "null") is refused, not
    taken for a file name: it was meant as off, as [sweep] record reads it, and a config file's plot could
    not be switched off (TOML has no null), so `--set simulate.plot=none` was a figure of no type."""
    if value is None:
        return
    word = isinstance(value, str) and value.lower() in ("none", "null")
    if isinstance(value, str) and value and not word:
        return
    named = f"; ./{value} is the path of that name" if word else ""
    raise PipelineError(
        f"{name} must be a path, got {value!r}; to switch it off, leave it out or unset it "
        f"(--set simulate.{name}=null){named}"
    )


@dataclass(frozen=True)
class ScenarioSettings:
    """What ``simulate`` runs: one scenario, a crowd size, a robot count (a sweep reads ``robots`` only)."""

    name: str = "circle"  # crowdsim.scenarios.SCENARIOS
    humans: int = 7
    robots: int = 3

    def __post_init__(self) -> None:
        _check_int("robots", self.robots)
        if not 1 <= self.robots <= MAX_ROBOTS:
            raise PipelineError(f"robots must be in 1..{MAX_ROBOTS}, got {self.robots!r}")
        if self.name not in SCENARIOS:
            raise PipelineError(f"name must be one of {list(SCENARIOS)}, got {self.name!r}")
        check_sizes(self.name, self.humans, self.robots)  # n_humans in [0, MAX_HUMANS]


@dataclass(frozen=True)
class ControllerSettings:
    """The ``ControllerSpec`` choices of a config file. ``None``: not chosen (``simulate`` requires a
    controller and defaults the predictor to constant_velocity and the margins to none; a sweep keeps its
    experiment's own)."""

    controller: str | None = None
    predictor: str | None = None
    coupling: str = "ibr"
    flocking: bool = True
    margins: str | None = None  # pipelines.loop.margins.parse_margins syntax
    record_iterations: bool = False

    def __post_init__(self) -> None:
        if self.controller is not None:
            ControllerSpec(
                self.controller
            )  # a shipped or registered plugin controller, else UnknownController
        if self.coupling not in COUPLINGS:
            raise PipelineError(f"coupling must be one of {list(COUPLINGS)}, got {self.coupling!r}")
        if self.predictor is not None and not (isinstance(self.predictor, str) and self.predictor.strip()):
            raise PipelineError(f"predictor must be a predictor's name, got {self.predictor!r}")
        if self.margins is not None:
            from pipelines.loop.margins import parse_margins

            parse_margins(self.margins)


@dataclass(frozen=True)
class SimulateSettings:
    """``crowdmpc simulate``'s run: how many episodes from which seed, and where the outputs go."""

    episodes: int = 1
    seed: int = 0  # episode i uses seed + i
    json: str | None = None  # the summary and per-episode records
    plot: str | None = None  # the first episode's figure
    record: str | None = None  # a folder of one MCAP file per episode
    progress: bool = True
    sensor_range: float | None = None  # m; None: the controller sees every human (pipelines/loop/sensing.py)
    sensor_tracks: bool = True  # with sensor_range: the tracker reports its track lengths

    def __post_init__(self) -> None:
        _check_int("episodes", self.episodes)
        if self.episodes < 1:
            raise PipelineError(f"episodes must be >= 1, got {self.episodes!r}")
        if self.episodes > MAX_SIMULATE_EPISODES:
            raise PipelineError(
                f"episodes must be at most {MAX_SIMULATE_EPISODES} (use crowdmpc sweep), got {self.episodes}"
            )
        _check_seed(self.seed)
        check_last_seed(self.seed, self.episodes - 1, f"{self.episodes} episodes")
        for name in ("json", "plot", "record"):
            _check_optional_path(name, getattr(self, name))
            _home(self, name)
        sensed = self.sensor_range
        if sensed is not None and not is_sensor_range(sensed):
            raise PipelineError(f"sensor_range must be a finite number of metres > 0, got {sensed!r}")
        if not isinstance(self.sensor_tracks, bool):
            raise PipelineError(f"sensor_tracks must be true or false, got {self.sensor_tracks!r}")


@dataclass(frozen=True)
class SweepSettings:
    """``crowdmpc sweep``'s run: the experiment, its size, where it goes and how it runs."""

    experiment: str | None = None  # pipelines.experiments.cells.EXPERIMENTS; required by sweep
    out: str | None = None  # the sweep directory; required by sweep
    episodes_per_cell: int = PAPER_EPISODES_PER_CELL
    humans: tuple[int, ...] | None = None  # None: the experiment's own
    seed: int = 0
    workers: int | None = None  # None: the CPUs this process may use
    backend: str = "auto"
    ray_address: str | None = None
    record: str = "none"
    jit: str = "auto"
    episode_timeout_s: float | None = None  # s of wall clock an episode may take (experiments/deadline.py)
    predictors: tuple[str, ...] | None = None  # the predictors experiment's list; None: the shipped one
    controllers: tuple[str, ...] | None = None  # the controllers experiment's list; None: the shipped one
    # "mpc.KEY=V1,V2,..": a column per value, ";" between settings: a grid (pipelines/commands/sweep_vary.py)
    vary: str | None = None

    def __post_init__(self) -> None:
        if self.vary is not None and not (isinstance(self.vary, str) and "=" in self.vary):
            raise PipelineError(f"vary must read mpc.KEY=V1,V2,..., got {self.vary!r}")
        if self.experiment is not None and self.experiment not in EXPERIMENTS:
            raise PipelineError(f"experiment must be one of {sorted(EXPERIMENTS)}, got {self.experiment!r}")
        if self.out is not None and not (isinstance(self.out, str) and self.out):
            raise PipelineError(f"out must be a path, got {self.out!r}")
        _home(self, "out")
        n = self.episodes_per_cell
        _check_int("episodes_per_cell", n)
        if n < 1:
            raise PipelineError(f"episodes_per_cell must be at least 1, got {n!r}")
        if n > MAX_EPISODES_PER_CELL:
            raise PipelineError(f"episodes_per_cell must be at most {MAX_EPISODES_PER_CELL}, got {n}")
        self._check_humans()
        _check_seed(self.seed)  # a cell's episode i runs seed + i // 2 (experiments/tasks.py)
        check_last_seed(self.seed, (n - 1) // 2, f"{n} episodes a cell")
        if self.backend not in BACKENDS:
            raise PipelineError(f"backend must be one of {list(BACKENDS)}, got {self.backend!r}")
        if self.ray_address is not None and not (isinstance(self.ray_address, str) and self.ray_address):
            raise PipelineError(f"ray_address must be an address, got {self.ray_address!r}")
        if self.record not in RECORD_POLICIES:
            raise PipelineError(f"record must be one of {list(RECORD_POLICIES)}, got {self.record!r}")
        if self.jit not in JIT_CHOICES:
            raise PipelineError(f"jit must be one of {list(JIT_CHOICES)}, got {self.jit!r}")
        check_timeout(self.episode_timeout_s)
        self._check_workers()
        self._check_predictors()
        self._check_controllers()

    def _check_humans(self) -> None:
        humans = self.humans
        if humans is None:
            return
        if not humans or not all(_is_int(h) for h in humans):
            text = str(list(humans))
            shown = text if len(text) <= 80 else text[:77] + "..."
            raise PipelineError(f"humans must list positive integers, got {shown}")
        # Up to the crowd sizes 1..MAX_HUMANS, each once: more is repeats, each a whole column of cells.
        if len(humans) > MAX_HUMANS:
            raise PipelineError(f"humans must list at most {MAX_HUMANS} crowd sizes, got {len(humans)}")
        if not 1 <= min(humans) or max(humans) > MAX_HUMANS:
            bad = min(humans) if min(humans) < 1 else max(humans)
            raise PipelineError(f"humans must be in 1..{MAX_HUMANS}, got {bad}")
        repeated = next((h for i, h in enumerate(humans) if h in humans[:i]), None)
        if repeated is not None:
            raise PipelineError(f"humans must name each crowd size once, got {repeated} more than once")

    def _check_workers(self) -> None:
        workers = self.workers
        if workers is None:
            return
        if not _is_int(workers):
            raise PipelineError(f"workers must be an integer, got {workers!r}")
        if not 1 <= workers <= MAX_WORKERS:
            raise PipelineError(f"workers must be at least 1 and at most {MAX_WORKERS}, got {workers}")

    def beyond_this_machine(self) -> str | None:
        """Why ``workers`` is more than a local pool takes on this machine (None: it is not). Not part of the
        validation, which holds on every machine: a sweep recorded on a bigger one reads back anywhere
        (``config show --from-sweep``), and the sweep command applies this before it starts workers."""
        workers = self.workers
        local = self.ray_address is None and self.backend != "inline" and not self._joins_ray_address()
        most = local_workers_limit()
        if workers is None or not local or workers <= most:
            return None
        return (
            f"workers {workers}: at most {most} here ({LOCAL_WORKERS_PER_CPU} per CPU this process may use, "
            f"{available_cpus()}); more only queue for the same cores (a Ray cluster takes more)"
        )

    def _joins_ray_address(self) -> bool:
        """Whether the sweep joins the cluster ``$RAY_ADDRESS`` names, as ray.init does (Ray's backend without
        --ray-address: pipelines.experiments.ray_join)."""
        from pipelines.experiments.backends import ray_available
        from pipelines.experiments.ray_join import address_from_environment

        ray = self.backend == "ray" or (self.backend == "auto" and ray_available())
        return ray and address_from_environment() is not None

    def _check_predictors(self) -> None:
        names = self.predictors
        if names is None:
            return
        from predictors.checkpoint import NAME_PATTERN

        if not names:
            raise PipelineError("predictors must name at least one predictor, got []")
        if len(names) > MAX_SWAP_PREDICTORS:
            raise PipelineError(f"predictors must name at most {MAX_SWAP_PREDICTORS}, got {len(names)}")
        bad = [name for name in names if not isinstance(name, str) or NAME_PATTERN.fullmatch(name) is None]
        if bad:
            raise PipelineError(f"predictors must be predictor names, got {str(bad[0])[:64]!r}")
        _check_once("predictors", "predictor", names)

    def _check_controllers(self) -> None:
        names = self.controllers
        if names is None:
            return
        if not names:
            raise PipelineError("controllers must name at least one controller, got []")
        if len(names) > MAX_SWAP_PREDICTORS:
            raise PipelineError(f"controllers must name at most {MAX_SWAP_PREDICTORS}, got {len(names)}")
        bad = [name for name in names if not isinstance(name, str) or not 0 < len(name) <= 200]
        if bad:
            raise PipelineError(f"controllers must be controller names, got {str(bad[0])[:64]!r}")
        _check_once("controllers", "controller", names)

    @property
    def n_workers(self) -> int:
        return available_cpus() if self.workers is None else self.workers
