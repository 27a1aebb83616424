"""Where a sweep's episodes run: the same EpisodeWorker inline, in a process pool, or in Ray actors.

Execution. Ray when it is installed (``pip install -e .[cluster]``): ``ray.init`` starts a local Ray with K
CPUs, or joins a cluster with ``--ray-address`` or, without it, ``$RAY_ADDRESS`` as ``ray.init`` reads it
(pipelines.experiments.ray_join); K actors each run episodes.
Without Ray, K processes of a ``concurrent.futures`` pool (spawn start method: no state forked from the
driver). Both backends run the same
``EpisodeWorker`` (pipelines.experiments.worker) and hand its outcomes back to the driver in completion order;
library thread pools inside each worker are held to one thread, since the workers are the parallelism. The
inline backend runs one episode at a time in the driver's own process, for debugging and profiling.

This module holds the backends' protocol, the inline and Ray backends and ``make_backend``, which picks one;
the process pool's backend, with its handling of a worker process that dies, is
pipelines.experiments.process_backend.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import signal
import threading
import time
import warnings
from collections.abc import Iterable, Iterator
from typing import Any, Final, Protocol

from pipelines.errors import PipelineError, SweepStopped, print_note, quiet_team_warnings
from pipelines.experiments.process_backend import CLOSE_GRACE_S, MAX_BREAKS_IN_A_ROW, ProcessBackend
from pipelines.experiments.ray_join import (
    RAY_ADDRESS_ENV,
    address_from_environment,
    answers,
    gcs_endpoint,
    join_cluster,
    joining_from_environment,
    left_to_the_job,
    stopped_answering,
    workers_that_fit,
)
from pipelines.experiments.ray_stop import StopFlag, finished_on_actors, say_stop, stopped
from pipelines.experiments.tasks import EpisodeTask
from pipelines.experiments.worker import SINGLE_THREAD_ENV, EpisodeOutcome, EpisodeWorker, worker_scratch
from predictors.plugin_import import search_listed_folders

BACKENDS: Final[tuple[str, ...]] = ("auto", "ray", "process", "inline")
RAY_MISSING: Final[str] = "the Ray backend needs the cluster extra: pip install -e '.[cluster]'"
# Ray's driver ends its own process (exit 1, one C++ log line, no report) when its cluster's GCS has not
# answered for 60 s (Ray 2.60's gcs_rpc_server_reconnect_timeout_s): `ray stop` on the head, the head lost.
# While no episode comes back, the GCS's port is tried every GCS_PROBE_S; unanswered for GCS_GONE_S, the
# sweep stops itself first, with its report.
GCS_PROBE_S: Final[float] = 5.0
GCS_GONE_S: Final[float] = 20.0


class Backend(Protocol):
    name: str
    # (and, where it says, ``workers``: how many episodes it runs at once, Ray's those the cluster fits; where
    # it has one, ``finished(wait_s)``: at a stop, the outcomes of its episodes in flight that come back
    # within wait_s, and how many others it cut, which pipelines.experiments.sweep_stop writes and counts)

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        """Outcomes in completion order."""
        ...

    def close(self) -> None: ...


def worker_environment() -> dict[str, str]:
    """What a Ray worker's environment must hold: one library thread, and every ``CROWDMPC_*`` variable of the
    driver (plugins, controllers, zoo, checkpoints, data, compile cache), its plugin variables listing every
    plugin registered in the driver (pipelines.plugins.plugin_environment). A local process pool inherits
    them; actors on a cluster's other nodes start from their own environment and would not find the plugins
    the driver registered, nor its user zoo."""
    from pipelines.plugins import plugin_environment

    forwarded = {k: v for k, v in os.environ.items() if k.startswith("CROWDMPC_")}
    return {**SINGLE_THREAD_ENV, **forwarded, **plugin_environment()}


class InlineBackend:
    """One episode at a time in the driver's own process: for debugging and profiling (pdb, cProfile)."""

    name = "inline"
    workers = 1

    def __init__(
        self, record: str, jit: bool = False, scratch_root: str | None = None, timeout_s: float | None = None
    ):
        # The driver stays where it is: the compile cache writes jit's C sources into its own folder.
        self.worker = EpisodeWorker(record, jit, worker_scratch(scratch_root), timeout_s)

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        with warnings.catch_warnings():  # once for the run: a filter set per episode repeated other warnings
            quiet_team_warnings()  # the sweep says them once (sweep_checks.method_notes)
            for task in tasks:
                yield self.worker.run(task)

    def close(self) -> None:
        self.worker.close()


class _RayEpisodeWorker(EpisodeWorker):
    """An EpisodeWorker in a Ray actor: its own process, so it may move to a scratch directory for jit (the
    driver's scratch root when the actor runs on the driver's machine, else one of its own)."""

    def __init__(
        self,
        record: str = "none",
        jit: bool = False,
        scratch_root: str | None = None,
        timeout_s: float | None = None,
        stop_flag: Any = None,
    ):
        search_listed_folders()  # the driver's plugin folders, before the move below
        quiet_team_warnings()  # for the actor's life: the sweep says them once (sweep_checks.method_notes)
        scratch = worker_scratch(scratch_root)
        if jit:
            os.chdir(scratch)
        super().__init__(record, jit, scratch, timeout_s)
        self._stop_flag = stop_flag  # a StopFlag actor's handle (pipelines.experiments.ray_stop)

    def run_unless_stopped(self, task: EpisodeTask) -> EpisodeOutcome | None:
        """``run(task)``; None, never started, once the driver has said the sweep stops."""
        import ray

        if self._stop_flag is not None and stopped(ray, self._stop_flag):
            return None
        return self.run(task)

    def code(self) -> tuple[str, dict[str, Any] | str]:
        """(this node's name, the code it runs as the driver records its own: ``code_with_plugins``), the
        plugins the driver named loaded first; in place of the code, why one of them does not load here."""
        import platform

        from pipelines.plugins import code_with_plugins, load_environment_plugins

        try:
            load_environment_plugins()
        except PipelineError as exc:
            return platform.node(), str(exc)
        return platform.node(), code_with_plugins()


class RayBackend:
    """K Ray actors, on a local Ray (K CPUs) or on a cluster (--ray-address, $RAY_ADDRESS); the cluster's
    nodes need crowdmpc installed like the driver. The driver alone writes the sweep directory, so any node
    can run episodes."""

    name = "ray"

    def __init__(
        self,
        workers: int,
        record: str,
        address: str | None,
        jit: bool = False,
        scratch_root: str | None = None,
        timeout_s: float | None = None,
    ):
        try:
            import ray
        except ImportError:
            raise PipelineError(RAY_MISSING) from None
        # Any: Ray's own annotations (checked when the extra is installed) do not follow ray.remote's wrapping
        self._ray: Any = ray
        self._owns_ray = not ray.is_initialized()
        if self._owns_ray:
            env = {"env_vars": left_to_the_job(worker_environment())}
            # Ray's driver installs its own SIGTERM handler, which aborted a sweep (exit 134, no report)
            # where the other backends stop as at Ctrl-C (pipelines.loop.interrupt): put ours back after
            terminate = signal.getsignal(signal.SIGTERM)
            given = "--ray-address"
            if address is None and (address := address_from_environment()) is not None:
                given = RAY_ADDRESS_ENV  # as ray.init joins it: a `ray job submit` entrypoint's cluster
                joining_from_environment(address)
            try:
                if address is None:  # "local": its own Ray, as without a cluster, even beside a `ray start`
                    # one, where ray.init refused num_cpus in a traceback
                    init = {"num_cpus": workers, "include_dashboard": False, "log_to_driver": False}
                    ray.init(address="local", runtime_env=env, **init)
                else:
                    join_cluster(ray, address, env, given)
                    try:
                        workers = workers_that_fit(ray, address, workers)
                    except BaseException:  # joined: leave the cluster as a refused join leaves it
                        ray.shutdown()
                        raise
            finally:
                if terminate is not None and threading.current_thread() is threading.main_thread():
                    signal.signal(signal.SIGTERM, terminate)
        self.workers = workers  # on a cluster, those that fit its free CPUs
        self._local = self._owns_ray and address is None  # a Ray of its own: no cluster to wait for
        self._gcs = gcs_endpoint(ray, address)
        self._actor_class: Any = ray.remote(num_cpus=1)(_RayEpisodeWorker)
        self._flag: Any = ray.remote(num_cpus=0)(StopFlag).remote()  # the stop's word to the actors
        self._actor_args = (record, jit, scratch_root, timeout_s, self._flag)
        self._actors: list[Any] = [self._actor_class.remote(*self._actor_args) for _ in range(workers)]
        self._uncommitted_nodes: set[str] = set()  # compared without a commit: said once a node
        self._gcs_gone = False
        self._drained = False
        self._owner: dict[Any, tuple[int, Any, EpisodeTask]] = {}  # run's: object ref -> (slot, actor, task)
        try:
            self._check_code(self._actors)
        except BaseException:
            self.close()
            raise

    def _check_code(self, actors: list[Any]) -> None:
        """PipelineError unless every actor runs the driver's code (commit and uncommitted diff, libraries,
        plugins: ``code_changes``): a cluster node with another checkout or other libraries mixed two
        codebases' episodes in one table, which sweep.json names by the driver's code alone. An actor
        that died before answering is no refusal: its episodes fail as a dead actor's do."""
        from pipelines.plugins import code_with_plugins
        from pipelines.version import code_changes

        driver = code_with_plugins()
        for ref in [actor.code.remote() for actor in actors]:
            try:
                # a replacement's start waits on the GCS: tried as episodes' waits are (_next_done)
                node, code = self._ray.get(ref if self._gcs is None else self._next_done([ref]))
            except self._ray.exceptions.RayActorError:
                continue
            if isinstance(code, str):  # a plugin that does not load there
                differ = code
            else:
                earlier, now, commits = _comparable(driver, code)
                if not commits and node not in self._uncommitted_nodes:
                    self._uncommitted_nodes.add(node)
                    print_note(
                        f"note: the Ray worker on {node} or the driver names no commit (an installed "
                        "package): their code is compared by version, Python, libraries and plugins only"
                    )
                differ = code_changes(earlier, now)
            if differ:
                raise PipelineError(
                    f"a Ray worker on {node} does not run this driver's code ({differ}; the driver's -> "
                    "the worker's): its episodes would be counted beside the driver's as one codebase's; "
                    "install the same crowdmpc commit, libraries and plugins on every node"
                )

    def run(self, tasks: Iterable[EpisodeTask]) -> Iterator[EpisodeOutcome]:
        """Each actor holds two episodes. An actor that dies (a segfault, the OOM killer, a node lost)
        fails every episode it held: each becomes an episode error (retried by a rerun), a new actor takes
        its place, and the sweep stops when actors keep dying with no episode finishing in between, as the
        process backend does."""
        ray = self._ray
        self._drained = False  # until this run's episodes have all come back
        pending = iter(tasks)
        owner = self._owner = {}  # the episodes the actors hold, for ``finished`` at a stop too

        def submit(slot: int, count: int) -> None:
            for task in _take(pending, count):
                ref = self._actors[slot].run_unless_stopped.remote(task)  # None only after ``finished``
                owner[ref] = (slot, self._actors[slot], task)

        for slot in range(len(self._actors)):
            submit(slot, 2)
        deaths = 0  # actor deaths since an episode last came back
        while owner:
            ref = self._next_done(list(owner))
            slot, actor, task = owner.pop(ref)
            try:
                outcome = ray.get(ref)
                deaths = 0
            except ray.exceptions.RayActorError as exc:
                if self._actors[slot] is actor:  # the first of its episodes to fail: replace it once
                    deaths += 1
                    self._actors[slot] = self._actor_class.remote(*self._actor_args)
                    self._check_code([self._actors[slot]])  # it may start on another node
                reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                error = f"Ray actor died while this episode was on it ({reason}); a rerun tries it again"
                outcome = EpisodeOutcome(task.key, error=error)
            if deaths >= MAX_BREAKS_IN_A_ROW:
                yield outcome
                raise SweepStopped(
                    f"the Ray actors died {deaths} times in a row with no episode finishing in between; "
                    "the episodes lost are in errors.jsonl"
                )
            submit(slot, 2 - sum(1 for s, _, _ in owner.values() if s == slot))
            yield outcome
        self._drained = True  # every episode came back: close may let the actors close their controllers

    def _next_done(self, refs: list[Any]) -> Any:
        """The first of ``refs`` to come back; SweepStopped once the cluster's GCS has not answered for
        ``GCS_GONE_S`` while none did (Ray would end the driver's process at 60 s: see GCS_PROBE_S)."""
        if self._gcs is None:  # nothing to try: wait as Ray does
            return self._ray.wait(refs, num_returns=1)[0][0]
        silent_since: float | None = None
        while True:
            done, _ = self._ray.wait(refs, num_returns=1, timeout=GCS_PROBE_S)
            if done:
                return done[0]
            if answers(self._gcs, GCS_PROBE_S):
                silent_since = None
                continue
            now = time.monotonic()
            silent_since = now if silent_since is None else silent_since
            if now - silent_since >= GCS_GONE_S:
                self._gcs_gone = True  # close() then leaves Ray alone: its calls wait on the GCS
                raise SweepStopped(stopped_answering(self._local, *self._gcs, GCS_GONE_S))

    def finished(self, wait_s: float) -> tuple[list[EpisodeOutcome], int]:
        """At a stop (pipelines.experiments.sweep_stop): the outcomes of the episodes the actors hold that
        come back within ``wait_s`` (once the cluster's GCS is gone, only those back already: nothing came
        for GCS_GONE_S, and Ray's waits without a timeout wait on it), and how many of the others the actors
        were running (cut); from the stop on, an actor starts no episode it takes
        (pipelines.experiments.ray_stop)."""
        held = dict(self._owner)
        self._owner.clear()
        if held and not self._gcs_gone:
            say_stop(self._ray, self._flag)
        return finished_on_actors(self._ray, held, wait_s, self._gcs_gone)

    def close(self) -> None:
        if self._gcs_gone:  # Ray's kill and shutdown wait on the lost GCS until Ray ends the process
            return
        try:
            if self._drained:
                with contextlib.suppress(Exception):  # a hung or dead actor: killed below all the same
                    self._ray.get([actor.close.remote() for actor in self._actors], timeout=CLOSE_GRACE_S)
        finally:  # a Ctrl-C in the wait above still ends the actors
            for actor in [*self._actors, self._flag]:
                self._ray.kill(actor)
        if self._owns_ray:
            self._ray.shutdown()


def _comparable(
    driver: dict[str, Any], code: dict[str, Any]
) -> tuple[list[dict[str, Any]], dict[str, Any], bool]:
    """``code_changes``' arguments for an actor's ``code`` beside the ``driver``'s, and whether both name a
    commit: the actor's plugins those the driver ran (``_plugins_of``), and, where either side names no
    commit (an installed package has no git checkout), the commit and its diff left out: a node installed
    from the wheel was refused beside a driver in a clone, with nothing known to differ."""
    code = _plugins_of(code, driver)
    commits = driver.get("commit") is not None and code.get("commit") is not None
    if not commits:
        unnamed = ("commit", "dirty", "diff_sha256")
        driver, code = ({k: v for k, v in c.items() if k not in unnamed} for c in (driver, code))
    return [driver], code, commits


def _plugins_of(code: dict[str, Any], driver: dict[str, Any]) -> dict[str, Any]:
    """An actor's ``code`` with only the plugins ``driver``'s code names: an actor loads every plugin its
    variables list, a Python driver only those it registered or ran (one listed and never run is no code of
    the run)."""
    wanted = driver.get("plugins") or {}
    plugins = {spec: sha for spec, sha in (code.get("plugins") or {}).items() if spec in wanted}
    return {key: value for key, value in code.items() if key != "plugins"} | (
        {"plugins": plugins} if plugins else {}
    )


def check_backend(kind: str, workers: int, ray_address: str | None) -> None:
    """Refuse a backend choice that cannot start, before the sweep writes anything (``make_backend`` checks
    it again): an unknown kind, no workers, --ray-address without Ray's backend, Ray when not installed."""
    if kind not in BACKENDS:
        raise PipelineError(f"unknown backend {kind!r}; choose from {list(BACKENDS)}")
    if workers < 1:
        raise PipelineError(f"--workers must be at least 1, got {workers}")
    if ray_address is not None and kind in ("process", "inline"):
        raise PipelineError(f"--ray-address needs the Ray backend, not --backend {kind}")
    if (kind == "ray" or ray_address is not None) and not ray_available():
        raise PipelineError(RAY_MISSING)


def _take(it: Iterator[EpisodeTask], n: int) -> list[EpisodeTask]:
    return list(itertools.islice(it, n))


def ray_available() -> bool:
    import importlib.util

    return importlib.util.find_spec("ray") is not None


def make_backend(
    kind: str,
    workers: int,
    record: str,
    ray_address: str | None,
    jit: bool = False,
    scratch_root: str | None = None,
    timeout_s: float | None = None,
) -> Backend:
    """``scratch_root``: the driver's folder for the workers' scratch (pipelines.experiments.worker), which
    the driver removes; None: each worker makes its own in the temp directory. ``timeout_s``: each
    episode's wall-clock limit (pipelines.experiments.deadline)."""
    check_backend(kind, workers, ray_address)
    if kind == "inline":
        return InlineBackend(record, jit, scratch_root, timeout_s)
    if kind == "ray" or (kind == "auto" and (ray_available() or ray_address is not None)):
        return RayBackend(workers, record, ray_address, jit, scratch_root, timeout_s)
    return ProcessBackend(workers, record, jit, scratch_root, timeout_s)
