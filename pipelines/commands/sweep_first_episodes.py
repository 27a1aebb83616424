"""The first episodes a sweep's crowds draw, tried before any worker starts (``check_first_episodes``): an
episode no crowd can draw raised in every worker, after its NLPs were built."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Final

from pipelines.errors import PipelineError
from predictors.text_table import counted

if TYPE_CHECKING:
    from collections.abc import Iterable

    from pipelines.experiments.tasks import Cell, EpisodeTask

# The first episodes of a crowd, size, team and scenario drawn before a sweep runs (check_first_episodes)
FIRST_TRIES: Final[int] = 8


def check_first_episodes(tasks: Iterable[EpisodeTask]) -> None:
    """PipelineError naming the cell when a crowd cannot give any of the first ``FIRST_TRIES`` episodes of a
    scenario: a replayed crowd's recording no window (too many humans for it, say), ORCA's humans no
    placement (a spawn separation too wide for the arena). Every such episode raised in the workers, each
    after its NLPs were built (42 s for the four cells of Table II at 50 humans), with a traceback in
    errors.jsonl for the reason; ``--vary env.spawn_separation=0.1,30`` recorded the circle's episodes at 30
    m that way and tabled its perpendicular ones alone. Each crowd, size, team and scenario's first episodes
    are drawn here, as they would be; one that some of them can draw is left to run (the draw depends on the
    seed: at 46 of ETH's people about half the seeds find a window), its failures recorded as before."""
    from crowdsim.env import CrowdEnv
    from crowdsim.errors import SimulationError
    from pipelines.loop.episode import replayed_recording

    # (crowd's config, humans, robots, scenario) -> its first cell's label and its episodes' seeds, in order
    firsts: dict[tuple[Any, ...], tuple[str, dict[int, None]]] = {}
    configs: dict[Cell, Any] = {}  # each cell's, built once, not once a task
    for task in tasks:
        cell = task.cell
        if cell not in configs:
            configs[cell] = cell.world.env_config()
        key = (configs[cell], cell.n_humans, cell.n_robots, task.scenario)
        firsts.setdefault(key, (cell.method, {}))[1][task.seed] = None
    envs: dict[Any, CrowdEnv] = {}
    for (config, n_humans, n_robots, scenario), (method, seeds) in firsts.items():
        if config not in envs:
            envs[config] = CrowdEnv(config, replayed_recording(config))
        failed: SimulationError | None = None
        for seed in list(seeds)[:FIRST_TRIES]:
            try:
                envs[config].reset(seed, scenario, n_humans, n_robots)
                break
            except SimulationError as exc:
                failed = exc
        else:
            tried = min(len(seeds), FIRST_TRIES)
            which = (
                f"its first {scenario} episode"
                if tried == 1
                else f"any of its first {tried} {scenario} episodes"
            )
            where = f"cell {method!r} at {counted(n_humans, 'human')}, crowd {config.crowd}"
            gives = (
                "the recording gives no window" if config.crowd != "orca" else "the humans cannot be placed"
            )
            raise PipelineError(f"{where}: {gives} for {which}: {failed}")
