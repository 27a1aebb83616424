"""Running an experiment's episodes in parallel, durably, resumably.

Durability. Only the driver writes the sweep directory. Each finished episode becomes one JSON line of
``<out>/episodes.jsonl``, written with one ``write`` and made durable (flush + fsync) before the next
is taken, keyed by ``cell/scenario/seed``. A rerun reads the file, skips every key already there and runs
the rest, so no episode is repeated or lost however often the sweep is killed. A kill can tear at most the
last line (a partial write); loading drops it (truncating the file back to its last complete line) and its
episode runs again. A lock file refuses a second sweep writing the same directory at the same time.

Execution. Ray when it is installed (``pip install -e .[cluster]``): ``ray.init`` starts a local Ray with K
CPUs, or joins a cluster with ``--ray-address``; K actors each run episodes. Without Ray, K processes of a
``concurrent.futures`` pool (spawn start method: no state forked from the driver). Both backends run the same
``EpisodeWorker``: it builds a cell's controller once and reuses it for every episode of that cell it gets
(tasks come interleaved across the cells, episode index by episode index), and returns a JSON-ready record
(plus the MCAP bytes of a kept log) to the driver. A failing episode (an exception in the controller) does
not stop the sweep: it goes to ``<out>/errors.jsonl`` and not to the records, so a rerun tries it again.

Recording (``--record failures|all``) happens *during* the run: the worker records every episode to a scratch
file and keeps it only when the policy asks. Re-running a failure afterwards would be cheaper, but an episode
is only reproducible if everything in the loop is (solver timeouts and thread timing are not), and a log of a
different run than the recorded metrics would mislead; recording costs about 5% of a CMPC episode.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import shutil
import socket
import sys
import tempfile
import threading
import time
import traceback
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, Protocol

from pipelines.errors import PipelineError
from pipelines.experiments.cells import EpisodeTask, Experiment, predictor_of
from pipelines.loop.controllers import Controller, ControllerSpec, make_controller
from pipelines.plain_json import plain

if TYPE_CHECKING:
    from crowdsim.env import EnvConfig

EPISODES_FILE: Final[str] = "episodes.jsonl"
ERRORS_FILE: Final[str] = "errors.jsonl"
SWEEP_FILE: Final[str] = "sweep.json"
LOCK_FILE: Final[str] = ".sweep.lock"
MCAP_DIR: Final[str] = "mcap"
# A sweep whose first episodes all raise is misconfigured (a missing model, a broken build): stop it rather
# than fill errors.jsonl with thousands of copies of one traceback.
FAIL_FAST_ERRORS: Final[int] = 4
RECORD_POLICIES: Final[tuple[str, ...]] = ("none", "failures", "all")
BACKENDS: Final[tuple[str, ...]] = ("auto", "ray", "process", "inline")
# Controllers a worker keeps built at once (least recently used dropped first). Tasks come interleaved across
# the cells, so this holds every cell of the largest experiment (Tables II/III: 10) with room to spare; each
# MPC controller holds a few CasADi solver instances (megabytes), worth keeping but not without bound.
CONTROLLER_CACHE: Final[int] = 16
# Controllers whose NLPs jit compiles (build_controller); the baselines solve none.
JIT_CONTROLLERS: Final[frozenset[str]] = frozenset({"cmpc", "dmpc"})
# Library thread pools inside each worker: the workers are the parallelism.
SINGLE_THREAD_ENV: Final[dict[str, str]] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


# ----------------------------------------------------------------------------------------------------------
# The durable record log
# ----------------------------------------------------------------------------------------------------------


class EpisodeLog:
    """Append-only JSON-lines file of episode records, one per key."""

    def __init__(self, path: Path):
        self.path = Path(path)

    def load(self, repair: bool = True) -> dict[str, dict[str, Any]]:
        """Every complete record by key. A torn tail (bytes after the last newline, or a last line that is not
        JSON) is ignored and, with ``repair`` (only the sweep holding the lock may), cut off the file so that
        its episode runs again; a bad line elsewhere or a repeated key means the file was damaged or edited,
        and is refused."""
        if not self.path.exists():
            return {}
        data = self.path.read_bytes()
        lines = data.split(b"\n")[:-1]  # only what a newline ends was fully written
        records: dict[str, dict[str, Any]] = {}
        good_end = 0
        for number, line in enumerate(lines, start=1):
            try:
                record = json.loads(line) if line.strip() else None
            except (json.JSONDecodeError, UnicodeDecodeError) as exc:
                if number == len(lines):
                    break
                raise PipelineError(
                    f"{self.path}:{number}: not a JSON record ({exc}); the file is damaged"
                ) from None
            if record is not None:
                key = record.get("key") if isinstance(record, dict) else None
                if not isinstance(key, str):
                    raise PipelineError(f"{self.path}:{number}: record has no 'key'; the file is damaged")
                if key in records:
                    raise PipelineError(
                        f"{self.path}:{number}: a second record for {key!r}; the file is damaged"
                    )
                records[key] = record
            good_end += len(line) + 1
        if repair and good_end < len(data):
            with open(self.path, "r+b") as f:
                f.truncate(good_end)
                f.flush()
                os.fsync(f.fileno())
        return records

    def append(self, record: dict[str, Any]) -> None:
        line = json.dumps(plain(record), allow_nan=False, separators=(",", ":")) + "\n"
        with open(self.path, "ab") as f:
            f.write(line.encode())
            f.flush()
            os.fsync(f.fileno())


@contextlib.contextmanager
def sweep_lock(out: Path) -> Iterator[None]:
    """Refuse a second sweep writing the same directory (its records would interleave)."""
    import fcntl

    with open(out / LOCK_FILE, "w") as f:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise PipelineError(
                f"another sweep is writing to {out}; wait for it or choose another --out"
            ) from None
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


# ----------------------------------------------------------------------------------------------------------
# Episodes -> records (runs in the workers)
# ----------------------------------------------------------------------------------------------------------


def build_controller(
    spec: ControllerSpec, jit: bool = False, env_config: EnvConfig | None = None
) -> Controller:
    """A cell's controller (the registry routes the ORCA oracle predictor to pipelines.loop.oracle).

    ``jit``: the MPC controllers compile their NLPs (MPCConfig.jit). It is a worker setting, not part of the
    cell: compiled and interpreted functions compute the same costs (to rounding), so the cell key, and the
    records a rerun resumes from, do not depend on it. The coupled NLP is not compiled: its graph (the
    network, or a first-order model's 56 x 24 Jacobian of parameters) kept gcc busy for over two minutes per
    worker (measured: 148 s for the first first-order episode of `--experiment coupling`).
    """
    if jit and spec.controller in JIT_CONTROLLERS and spec.coupling == "ibr":
        spec = replace(spec, mpc_overrides=(*spec.mpc_overrides, ("jit", True)))
    return make_controller(spec, env_config)


def jit_available() -> bool:
    """Whether CasADi's jit can compile here: its "shell" compiler calls gcc."""
    return shutil.which("gcc") is not None


def _jit_scratch_directory() -> None:
    """Move a worker process into a scratch directory of its own: CasADi's jit writes its C sources into the
    current directory (it has no option for another), and a killed worker must not leave them in the
    user's."""
    import atexit

    scratch = tempfile.mkdtemp(prefix="crowdmpc-worker-")
    os.chdir(scratch)
    atexit.register(shutil.rmtree, scratch, ignore_errors=True)


def predictor_sha256(name: str | None) -> str | None:
    from predictors.registry import checkpoint_sha256

    return checkpoint_sha256(name)


def is_failure(metrics: dict[str, Any]) -> bool:
    """What ``--record failures`` keeps: not every robot arrived, or personal space was violated."""
    return (not metrics.get("success")) or bool(metrics.get("collision"))


def episode_record(task: EpisodeTask, result: Any, wall_s: float, cpu_s: float) -> dict[str, Any]:
    """One JSON-ready line of episodes.jsonl from a closed-loop EpisodeResult; ``cpu_s`` is the worker's CPU
    time for the episode, which unlike ``wall_s`` does not depend on how busy the machine was."""
    import numpy as np

    from pipelines.loop.episode import step_time_stats

    spec = task.cell.spec
    solve_ms = np.asarray(result.solve_times_s, dtype=float) * 1e3
    iterations = np.asarray(result.iterations, dtype=float)
    statuses = [str(s) for s in result.statuses]
    status_counts: dict[str, int] = {}
    for status in statuses:
        status_counts[status] = status_counts.get(status, 0) + 1
    return plain(
        {
            "key": task.key,
            "experiment": task.experiment,
            "cell": task.cell.key,
            "method": task.cell.method,
            "controller": spec.controller,
            "predictor": predictor_of(spec),
            "predictor_sha256": predictor_sha256(predictor_of(spec)),
            "flocking": spec.flocking,
            "coupling": spec.coupling,
            "margins": spec.margins.label,
            "profile": task.cell.world.profile,
            "visibility": task.cell.world.visibility,
            "n_humans": task.cell.n_humans,
            "n_robots": task.cell.n_robots,
            "index": task.index,
            "scenario": task.scenario,
            "seed": task.seed,
            "metrics": result.metrics.as_dict(),
            "solver": {
                "steps": int(solve_ms.size),
                "total_ms": float(solve_ms.sum()),
                **step_time_stats(result.solve_times_s),
                "mean_iterations": float(iterations.mean()) if iterations.size else None,
                "max_iterations": int(iterations.max()) if iterations.size else None,
                "fallback_steps": sum(f is not None for f in result.fallbacks),
                "statuses": status_counts,
            },
            "wall_s": wall_s,
            "cpu_s": cpu_s,
            "worker": f"{socket.gethostname()}:{os.getpid()}",
        }
    )


@dataclass
class EpisodeOutcome:
    """What a worker hands back: a record, or the error that stopped the episode; a kept MCAP log."""

    key: str
    record: dict[str, Any] | None = None
    error: str | None = None
    mcap: bytes | None = None


class EpisodeWorker:
    """Runs episode tasks; builds each cell's controller once and reuses it across that cell's episodes."""

    def __init__(self, record: str = "none", jit: bool = False):
        if record not in RECORD_POLICIES:
            raise PipelineError(f"unknown --record {record!r}; choose from {list(RECORD_POLICIES)}")
        self.record = record
        self.jit = jit
        self._controllers: OrderedDict[str, Controller] = OrderedDict()
        self.builds = 0  # controllers built so far (a test checks the reuse)

    def controller(self, task: EpisodeTask) -> Controller:
        key = task.cell.key
        if key in self._controllers:
            self._controllers.move_to_end(key)
            return self._controllers[key]
        controller = build_controller(task.cell.spec, self.jit, task.cell.world.env_config())
        self.builds += 1
        self._controllers[key] = controller
        while len(self._controllers) > CONTROLLER_CACHE:
            self._controllers.popitem(last=False)
        return controller

    def run(self, task: EpisodeTask) -> EpisodeOutcome:
        try:
            return self._run(task)
        except Exception:  # a bug or a solver crash in one episode must not end a sweep of thousands
            return EpisodeOutcome(task.key, error=traceback.format_exc())

    def _run(self, task: EpisodeTask) -> EpisodeOutcome:
        from pipelines.loop.episode import run_episode

        controller = self.controller(task)
        recorder = None
        if self.record != "none":
            from pipelines.logs.recording import McapEpisodeRecorder

            # A scratch folder per episode; a kept log goes to the driver as bytes (it may run elsewhere).
            run_meta = {"experiment": task.experiment, "cell": task.cell.key}
            recorder = McapEpisodeRecorder(tempfile.mkdtemp(prefix="crowdmpc-episode-"), run_meta=run_meta)
        meta = {
            "experiment": task.experiment,
            "cell": task.cell.key,
            "method": task.cell.method,
            "predictor": predictor_of(task.cell.spec),
            "predictor_sha256": predictor_sha256(predictor_of(task.cell.spec)),
        }
        start, cpu_start = time.perf_counter(), time.process_time()
        try:
            result = run_episode(
                controller,
                seed=task.seed,
                scenario=task.scenario,
                n_humans=task.cell.n_humans,
                n_robots=task.cell.n_robots,
                env_config=task.cell.world.env_config(),
                observers=() if recorder is None else (recorder,),
                meta=meta,
            )
            record = episode_record(
                task, result, time.perf_counter() - start, time.process_time() - cpu_start
            )
            mcap = None
            if recorder is not None and (self.record == "all" or is_failure(record["metrics"])):
                mcap = recorder.paths[-1].read_bytes()
            return EpisodeOutcome(task.key, record=record, mcap=mcap)
        finally:
            if recorder is not None:
                recorder.close()  # already closed by on_end unless the episode raised
                shutil.rmtree(recorder.out_dir, ignore_errors=True)


# ----------------------------------------------------------------------------------------------------------
# Backends: the same worker, in a process pool or in Ray actors
# ----------------------------------------------------------------------------------------------------------


class Backend(Protocol):
    name: str

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        """Outcomes in completion order."""
        ...

    def close(self) -> None: ...


_WORKER: EpisodeWorker | None = None  # one per pool process


def _exit_with_parent() -> None:
    """A pool worker whose driver was killed (SIGKILL leaves no time to shut the pool down) exits at once
    instead of finishing its episode and waiting for work forever."""
    import multiprocessing
    from multiprocessing.connection import wait

    parent = multiprocessing.parent_process()
    if parent is None:
        return

    def watch() -> None:
        wait([parent.sentinel])
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="exit-with-parent").start()


def _init_pool_worker(record: str, jit: bool) -> None:
    import signal

    global _WORKER
    # Ctrl-C goes to the whole process group; the driver alone handles it (and ends the workers).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_with_parent()
    if jit:
        _jit_scratch_directory()
    _WORKER = EpisodeWorker(record, jit)


def _run_in_pool(task: EpisodeTask) -> EpisodeOutcome:
    assert _WORKER is not None, "pool worker used before its initializer ran"
    return _WORKER.run(task)


@contextlib.contextmanager
def _child_environment(values: dict[str, str]) -> Iterator[None]:
    """Environment for processes started inside the block (spawned workers copy it at start)."""
    saved = {k: os.environ.get(k) for k in values}
    os.environ.update({k: os.environ.get(k, v) for k, v in values.items()})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class InlineBackend:
    """One episode at a time in the driver's own process: for debugging and profiling (pdb, cProfile)."""

    name = "inline"

    def __init__(self, record: str, jit: bool = False):
        # jit's C sources land in the current directory while the driver runs (removed when it exits).
        self.worker = EpisodeWorker(record, jit)

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        for task in tasks:
            yield self.worker.run(task)

    def close(self) -> None:
        pass


class ProcessBackend:
    """K spawned processes of a concurrent.futures pool."""

    name = "process"

    def __init__(self, workers: int, record: str, jit: bool = False):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        with _child_environment(SINGLE_THREAD_ENV):
            self._pool = ProcessPoolExecutor(
                max_workers=workers,
                mp_context=multiprocessing.get_context("spawn"),
                initializer=_init_pool_worker,
                initargs=(record, jit),
            )
            # Start every worker now, while the environment above is in force.
            for future in [self._pool.submit(os.getpid) for _ in range(workers)]:
                future.result()

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        from concurrent.futures import FIRST_COMPLETED, wait

        pending = iter(tasks)
        in_flight: set = set()
        # Two tasks in flight per worker keep them busy without queueing the whole sweep (a cancel is quick).
        for task in _take(pending, 2 * self.workers):
            in_flight.add(self._pool.submit(_run_in_pool, task))
        while in_flight:
            done, in_flight = wait(in_flight, return_when=FIRST_COMPLETED)
            for future in done:
                for task in _take(pending, 1):
                    in_flight.add(self._pool.submit(_run_in_pool, task))
                yield future.result()

    def close(self) -> None:
        # Cancel what has not started and end the running episodes now: their records were never written, so a
        # rerun runs them again. (ProcessPoolExecutor has no public way to stop a running call.)
        processes = list((getattr(self._pool, "_processes", None) or {}).values())
        self._pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.terminate()
        for process in processes:
            process.join(timeout=5)


class _RayEpisodeWorker(EpisodeWorker):
    """An EpisodeWorker in a Ray actor: its own process, so it may move to a scratch directory for jit."""

    def __init__(self, record: str = "none", jit: bool = False):
        if jit:
            _jit_scratch_directory()
        super().__init__(record, jit)


class RayBackend:
    """K Ray actors, on a local Ray (K CPUs) or on a cluster (--ray-address); the cluster's nodes need
    crowdmpc installed like the driver. The driver alone writes the sweep directory, so any node can run
    episodes."""

    name = "ray"

    def __init__(self, workers: int, record: str, address: str | None, jit: bool = False):
        try:
            import ray
        except ImportError:
            raise PipelineError(
                "the Ray backend needs the cluster extra: pip install -e '.[cluster]'"
            ) from None
        self._ray = ray
        self._owns_ray = not ray.is_initialized()
        if self._owns_ray:
            env = {"env_vars": dict(SINGLE_THREAD_ENV)}
            if address is None:
                ray.init(num_cpus=workers, include_dashboard=False, runtime_env=env, log_to_driver=False)
            else:
                ray.init(address=address, runtime_env=env, log_to_driver=False)
        actor = ray.remote(num_cpus=1)(_RayEpisodeWorker)
        self._actors = [actor.remote(record, jit) for _ in range(workers)]

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        ray = self._ray
        pending = iter(tasks)
        owner: dict[Any, Any] = {}  # object ref -> actor
        for actor in self._actors:
            for task in _take(pending, 2):
                owner[actor.run.remote(task)] = actor
        while owner:
            (ref,), _ = ray.wait(list(owner), num_returns=1)
            actor = owner.pop(ref)
            for task in _take(pending, 1):
                owner[actor.run.remote(task)] = actor
            yield ray.get(ref)

    def close(self) -> None:
        for actor in self._actors:
            self._ray.kill(actor)
        if self._owns_ray:
            self._ray.shutdown()


def _take(it: Iterator[EpisodeTask], n: int) -> list[EpisodeTask]:
    return list(itertools.islice(it, n))


def ray_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("ray") is not None


def make_backend(kind: str, workers: int, record: str, ray_address: str | None, jit: bool = False) -> Backend:
    if kind not in BACKENDS:
        raise PipelineError(f"unknown backend {kind!r}; choose from {list(BACKENDS)}")
    if workers < 1:
        raise PipelineError(f"--workers must be at least 1, got {workers}")
    if ray_address is not None and kind in ("process", "inline"):
        raise PipelineError(f"--ray-address needs the Ray backend, not --backend {kind}")
    if kind == "inline":
        return InlineBackend(record, jit)
    if kind == "ray" or (kind == "auto" and (ray_available() or ray_address is not None)):
        return RayBackend(workers, record, ray_address, jit)
    return ProcessBackend(workers, record, jit)


# ----------------------------------------------------------------------------------------------------------
# The driver
# ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SweepConfig:
    experiment: Experiment
    out: Path
    episodes_per_cell: int
    humans: tuple[int, ...] | None = None  # None: the experiment's own
    seed: int = 0
    n_robots: int = 3
    workers: int = 2
    backend: str = "auto"  # "auto": Ray when installed, else a process pool
    ray_address: str | None = None
    record: str = "none"  # RECORD_POLICIES
    progress: bool = True
    jit: bool = False  # compile the MPC controllers' NLPs in every worker (build_controller)

    def __post_init__(self):
        if self.episodes_per_cell < 1:
            raise PipelineError(f"--episodes-per-cell must be at least 1, got {self.episodes_per_cell}")
        if self.workers < 1:
            raise PipelineError(f"--workers must be at least 1, got {self.workers}")
        if self.record not in RECORD_POLICIES:
            raise PipelineError(f"unknown --record {self.record!r}; choose from {list(RECORD_POLICIES)}")
        if self.backend not in BACKENDS:
            raise PipelineError(f"unknown backend {self.backend!r}; choose from {list(BACKENDS)}")
        if self.humans is not None and (not self.humans or min(self.humans) < 1):
            raise PipelineError(f"--humans must list positive numbers, got {self.humans}")

    def tasks(self) -> list[EpisodeTask]:
        return self.experiment.tasks(
            self.episodes_per_cell, humans=self.humans, seed=self.seed, n_robots=self.n_robots
        )


@dataclass
class SweepOutcome:
    planned: int  # episodes the sweep asks for
    already_done: int  # of those, recorded before this run
    ran: int = 0  # recorded by this run
    errors: list[str] = field(default_factory=list)  # keys whose episode raised (see errors.jsonl)
    wall_s: float = 0.0  # this run, from starting the workers to the last record
    startup_s: float = 0.0  # of which starting the workers (processes, or Ray and its actors)
    backend: str = ""
    interrupted: bool = False

    @property
    def complete(self) -> bool:
        return self.already_done + self.ran == self.planned

    @property
    def episodes_per_minute(self) -> float:
        """Over the whole run, worker start-up included."""
        return 60.0 * self.ran / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def steady_episodes_per_minute(self) -> float:
        """Once the workers are up: the rate a long sweep approaches."""
        running = self.wall_s - self.startup_s
        return 60.0 * self.ran / running if running > 0 else 0.0


def mcap_path(out: Path, task: EpisodeTask) -> Path:
    return out / MCAP_DIR / task.cell.key / f"{task.scenario}_seed{task.seed:06d}.mcap"


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".part")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _update_sweep_file(out: Path, config: SweepConfig, planned: int) -> None:
    """sweep.json: what the directory holds, and a line per run (a directory belongs to one experiment)."""
    from pipelines.version import crowdmpc_version

    path = out / SWEEP_FILE
    meta: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    if meta and meta.get("experiment") != config.experiment.name:
        raise PipelineError(
            f"{out} holds a sweep of experiment {meta.get('experiment')!r}, not {config.experiment.name!r}; "
            "choose another --out"
        )
    meta["experiment"] = config.experiment.name
    meta["title"] = config.experiment.title
    meta.setdefault("runs", []).append(
        {
            "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
            "version": crowdmpc_version(),
            "episodes_per_cell": config.episodes_per_cell,
            "humans": list(config.humans or config.experiment.humans),
            "seed": config.seed,
            "n_robots": config.n_robots,
            "jit": config.jit,
            "planned": planned,
            "cells": [
                {
                    "key": c.key,
                    "method": c.method,
                    "n_humans": c.n_humans,
                    **asdict(c.spec),
                    **asdict(c.world),
                }
                for c in config.experiment.cells(config.humans, config.n_robots)
            ],
        }
    )
    tmp = path.with_suffix(".json.part")
    tmp.write_text(json.dumps(plain(meta), indent=1) + "\n")
    os.replace(tmp, path)


def run_sweep(
    config: SweepConfig,
    *,
    backend_factory: Callable[[SweepConfig], Backend] | None = None,
) -> SweepOutcome:
    """Run every planned episode that ``<out>/episodes.jsonl`` does not hold yet."""
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = config.tasks()
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        raise PipelineError("the sweep plans the same episode twice (repeated --humans?)")
    with sweep_lock(out):
        _update_sweep_file(out, config, len(tasks))
        log = EpisodeLog(out / EPISODES_FILE)
        done = log.load()
        _check_same_predictors(out, tasks, done)
        todo = [t for t in tasks if t.key not in done]
        outcome = SweepOutcome(planned=len(tasks), already_done=len(tasks) - len(todo))
        if not todo:
            return outcome
        by_key = {t.key: t for t in todo}
        start = time.perf_counter()
        backend = (backend_factory or _default_backend)(config)
        outcome.backend = backend.name
        outcome.startup_s = time.perf_counter() - start
        bar = _progress_bar(config, outcome)
        try:
            for result in backend.run(todo):
                task = by_key[result.key]
                if result.error is not None:
                    outcome.errors.append(result.key)
                    _append_error(out, task, result.error)
                    bar.set_postfix(errors=len(outcome.errors), refresh=False)
                    if outcome.ran == 0 and len(outcome.errors) >= FAIL_FAST_ERRORS:
                        last = result.error.strip().splitlines()[-1]
                        raise PipelineError(
                            f"the first {len(outcome.errors)} episodes all raised ({last}); "
                            f"tracebacks in {out / ERRORS_FILE}"
                        )
                    continue
                if result.mcap is not None:
                    _write_atomic(mcap_path(out, task), result.mcap)  # before the record that vouches for it
                log.append(result.record)
                outcome.ran += 1
                bar.update(1)
        except KeyboardInterrupt:
            outcome.interrupted = True
        finally:
            outcome.wall_s = time.perf_counter() - start
            bar.close()
            backend.close()
    return outcome


def _check_same_predictors(out: Path, tasks: list[EpisodeTask], done: dict[str, dict[str, Any]]) -> None:
    """Refuse to extend a cell whose records came from other weights than the zoo holds now (a retrained
    model): its table would silently mix two predictors."""
    current: dict[str, str | None] = {}
    for task in tasks:
        record = done.get(task.key)
        if record is None:
            continue
        name = record.get("predictor")
        if name not in current:
            current[name] = predictor_sha256(name)
        if record.get("predictor_sha256") != current[name]:
            raise PipelineError(
                f"{out / EPISODES_FILE} holds episodes of {task.cell.key} run with predictor {name!r} of "
                f"sha256 {record.get('predictor_sha256')}, but the zoo's {name!r} is now {current[name]}; "
                "use another --out for the new weights"
            )


def _default_backend(config: SweepConfig) -> Backend:
    return make_backend(config.backend, config.workers, config.record, config.ray_address, config.jit)


def _append_error(out: Path, task: EpisodeTask, error: str) -> None:
    EpisodeLog(out / ERRORS_FILE).append(
        {"key": task.key, "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "error": error}
    )


def _progress_bar(config: SweepConfig, outcome: SweepOutcome) -> Any:
    from tqdm import tqdm

    return tqdm(
        total=outcome.planned,
        initial=outcome.already_done,
        unit="ep",
        desc=config.experiment.name,
        disable=not config.progress,
        file=sys.stderr,
        dynamic_ncols=True,
        smoothing=0.05,  # episodes vary in length: average the rate over many for a steady ETA
    )
