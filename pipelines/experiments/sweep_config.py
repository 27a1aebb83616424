"""What a sweep is asked to run (``SweepConfig``): the experiment, where its directory is, how many episodes a
cell, crowd sizes, seed, robots, workers, backend and recording, each checked against its bounds when the
config is made, before any directory or worker exists.

Apart from the driver that runs it (pipelines.experiments.sweep, ``run_sweep``): the command line's config
files check their values against the same bounds (pipelines.config.settings) without importing the driver.
``SweepConfig`` is importable from pipelines.experiments.sweep too, beside ``run_sweep``
(docs/examples/own_experiment.py).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np

from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS
from crowdsim.world import PAPER_ROBOTS
from pipelines.errors import PipelineError
from pipelines.experiments.backends import BACKENDS
from pipelines.experiments.cells import Experiment
from pipelines.experiments.deadline import check_timeout
from pipelines.experiments.tasks import EpisodeTask
from pipelines.experiments.worker import RECORD_POLICIES
from predictors.errors import short_repr

# Upper bounds checked before any worker starts (a typo must not become thousands of failing episodes): the
# paper runs 1000 episodes per cell (cells.PAPER_EPISODES_PER_CELL); workers are Ray actors at most (a local
# pool is held to its CPUs by the command line, pipelines/commands/sweep.py).
MAX_EPISODES_PER_CELL: Final[int] = 100_000
MAX_WORKERS: Final[int] = 4096


@dataclass(frozen=True)
class SweepConfig:
    experiment: Experiment
    out: Path
    episodes_per_cell: int
    humans: tuple[int, ...] | None = None  # None: the experiment's own
    seed: int = 0
    n_robots: int = PAPER_ROBOTS
    workers: int = 2
    backend: str = "auto"  # "auto": Ray when installed, else a process pool
    ray_address: str | None = None
    record: str = "none"  # RECORD_POLICIES
    progress: bool | None = None  # a bar of the episodes; None: on a terminal only, as the commands draw it
    jit: bool = False  # compile the MPC controllers' NLPs in every worker (make_controller's jit)
    # s of wall-clock time after which a worker stops an episode (pipelines.experiments.deadline); None: none
    episode_timeout_s: float | None = None
    # another sweep's folder, whose episodes of this plan the sweep takes first (pipelines.experiments.reuse)
    reuse: Path | None = None
    # The run's effective config (pipelines/config: every section, and the file it came from), for sweep.json.
    run_config: Mapping[str, Any] | None = field(default=None, compare=False)

    def __post_init__(self):
        if not isinstance(self.experiment, Experiment):
            raise PipelineError(
                f"SweepConfig's experiment must be an Experiment, got {short_repr(self.experiment)}"
            )
        if not isinstance(self.out, str | os.PathLike):  # None failed in run_sweep's Path(out)
            raise PipelineError(f"SweepConfig's out must be a folder's path, got {short_repr(self.out)}")
        for name in ("episodes_per_cell", "seed", "n_robots", "workers"):  # a float failed deep in range()
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer):
                raise PipelineError(f"SweepConfig's {name} must be an int, got {short_repr(value)}")
            object.__setattr__(self, name, int(value))
        if self.seed < 0:
            raise PipelineError(f"--seed must be at least 0, got {self.seed}")
        if self.episodes_per_cell < 1:
            raise PipelineError(f"--episodes-per-cell must be at least 1, got {self.episodes_per_cell}")
        if self.episodes_per_cell > MAX_EPISODES_PER_CELL:
            raise PipelineError(
                f"--episodes-per-cell must be at most {MAX_EPISODES_PER_CELL}, got {self.episodes_per_cell}"
            )
        if not 1 <= self.workers <= MAX_WORKERS:
            raise PipelineError(f"--workers must be at least 1 and at most {MAX_WORKERS}, got {self.workers}")
        if not 1 <= self.n_robots <= MAX_ROBOTS:
            raise PipelineError(f"--robots must be in 1..{MAX_ROBOTS}, got {self.n_robots}")
        if self.record not in RECORD_POLICIES:
            raise PipelineError(f"unknown --record {self.record!r}; choose from {list(RECORD_POLICIES)}")
        if self.backend not in BACKENDS:
            raise PipelineError(f"unknown backend {self.backend!r}; choose from {list(BACKENDS)}")
        if self.humans is not None:  # (5.5,) failed deep inside, 5 in a bare TypeError
            if (
                isinstance(self.humans, str | bytes)
                or not isinstance(self.humans, Iterable)
                or not all(isinstance(n, int | np.integer) and not isinstance(n, bool) for n in self.humans)
            ):
                raise PipelineError(f"--humans must list numbers of humans, got {short_repr(self.humans)}")
            object.__setattr__(self, "humans", tuple(int(n) for n in self.humans))
        if self.humans is not None and (not self.humans or min(self.humans) < 1):
            raise PipelineError(f"--humans must list positive numbers, got {self.humans}")
        if self.humans is not None and max(self.humans) > MAX_HUMANS:
            raise PipelineError(f"--humans must be in 1..{MAX_HUMANS}, got {max(self.humans)}")
        check_timeout(self.episode_timeout_s, "--episode-timeout")
        if self.reuse is not None and not isinstance(self.reuse, str | os.PathLike):
            raise PipelineError(
                f"SweepConfig's reuse must be a sweep folder's path, got {short_repr(self.reuse)}"
            )
        if self.reuse is not None:
            object.__setattr__(self, "reuse", Path(self.reuse))

    def tasks(self) -> list[EpisodeTask]:
        return self.experiment.tasks(
            self.episodes_per_cell, humans=self.humans, seed=self.seed, n_robots=self.n_robots
        )
