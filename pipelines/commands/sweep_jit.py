"""Whether a sweep compiles its MPC NLPs with gcc (``--jit`` on, off, auto) and the compile cache its workers
will use, settled before any worker starts."""

from __future__ import annotations

from typing import TYPE_CHECKING

from pipelines.errors import PipelineError

if TYPE_CHECKING:
    from pipelines.experiments.cells import Experiment


def choose_jit(
    choice: str,
    label: str,
    experiment: Experiment,
    humans: tuple[int, ...] | None,
    n_robots: int,
    episodes: int,
) -> bool:
    """--jit: on, off, or auto: on when gcc is found and the CPU the compiled solvers save over the run's
    episodes covers compiling every NLP the run needs (jit_pays)."""
    from pipelines.experiments.worker import jit_available

    if choice == "on" and not jit_available():
        raise PipelineError(f"{label} on needs gcc on the PATH (CasADi compiles with it); use --jit off")
    if choice != "auto":
        return choice == "on"
    return (
        jit_available()
        and jit_pays(experiment.cells(humans, n_robots), episodes)
        and _room_short_by() is None  # off rather than a run whose every compile fails
    )


def _room_short_by() -> str | None:
    """Why the compile cache's file system has no room for a compile, or None when it has."""
    from mpc.cache_location import cache_dir, free_bytes
    from mpc.compile_cache import COMPILE_ROOM_BYTES

    free = free_bytes()
    if free >= COMPILE_ROOM_BYTES:
        return None
    return (
        f"the compile cache {cache_dir()} has {free / 2**20:.1f} MB free, under the "
        f"{COMPILE_ROOM_BYTES // 2**20} MB a compile may need: free space, set $CROWDMPC_CACHE to a folder "
        "with room"
    )


def check_compile_cache(label: str, choice: str) -> None:
    """The compile cache the workers will compile into, checked (and made) before they start: there an
    unusable one ($CROWDMPC_CACHE a file, read-only, a path gcc cannot take, a full disk) raised in every
    episode."""
    from mpc.cache_location import writable_dir
    from mpc.errors import CacheLocationError

    try:
        writable_dir()
    except CacheLocationError as exc:
        raise PipelineError(f"{label} {choice}: {exc}; or use --jit off") from None
    if (short := _room_short_by()) is not None:  # gcc's "No space left" then failed every episode
        raise PipelineError(f"{label} {choice}: {short}, or use --jit off")


def jit_pays(cells, episodes_per_cell: int) -> bool:
    """Whether compiling repays itself: the saving (episodes x saving per episode, mpc.compile_cache's
    measured SAVING_PER_EPISODE_S) is at least one cold compile (COMPILE_S) per NLP the cells may need. Cells
    are counted apart when anything that may change their NLP differs (shared NLPs compile once per machine,
    so this overestimates); the coupled NLP is not compiled. What the cache already holds is not consulted
    (its key needs the NLP built): below the threshold a warm cache forgoes ~0.1-0.2 s an episode."""
    from mpc.compile_cache import COMPILE_S, SAVING_PER_EPISODE_S

    nlps: dict[str, float] = {}
    saving = 0.0
    for cell in cells:
        spec = cell.spec
        if not spec.kind.compiles or spec.coupling == "nlp":
            continue
        nlp = "local" if spec.controller == "dmpc" else "joint"  # a compiling plugin: counted as CMPC
        per_predictor = spec.predictor if spec.margins.mode != "none" else None  # conformal margins
        # Not the predictor otherwise, nor flocking: predictions and flocking weights are NLP parameters, nor
        # what the controller senses; behind a sensor, or among a replayed crowd's comings and goings, it
        # meets every number of humans up to the cell's.
        world = (cell.world.profile, cell.world.visibility)
        identity = (nlp, spec.mpc_overrides, spec.margins, per_predictor, world)
        sensed = cell.world.sensor_range is not None or cell.world.crowd != "orca"
        for n_humans in range(cell.n_humans + 1) if sensed else (cell.n_humans,):
            nlps[repr((identity, cell.n_robots, n_humans))] = COMPILE_S[nlp]
        saving += episodes_per_cell * SAVING_PER_EPISODE_S[nlp]
    return bool(nlps) and saving >= sum(nlps.values())
