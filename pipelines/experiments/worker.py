"""Episodes into records: what runs in the workers, whichever backend hosts them.

Every backend (pipelines.experiments.backends) runs the same ``EpisodeWorker``: it builds a cell's controller
once and reuses it for every episode of that cell it gets (tasks come interleaved across the cells, episode
index by episode index, in groups of at most CONTROLLER_CACHE cells: Experiment.tasks), and returns a
JSON-ready record (plus the MCAP bytes of a kept log) to the driver. A failing episode (an exception in the
controller) does not stop the sweep: the worker hands back its traceback,
which the driver writes to ``<out>/errors.jsonl`` and not to the records, so a rerun tries it again. A
controller that loaded other weights than the driver checked (pipelines.experiments.checked_weights) is no
episode's failure: the worker hands back the refusal's line as ``stop``, and the driver stops the sweep.

Recording (``--record failures|all``) happens *during* the run: the worker records every episode to a scratch
file and keeps it only when the policy asks. Re-running a failure afterwards would be cheaper, but an episode
is only reproducible if everything in the loop is (solver timeouts and thread timing are not), and a log of a
different run than the recorded metrics would mislead; recording costs about 5% of a CMPC episode.
"""

from __future__ import annotations

import json
import os
import re
import resource
import shutil
import socket
import tempfile
import time
import traceback
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pipelines.errors import PipelineError, interrupt_behind, print_note
from pipelines.experiments.checked_calibrations import controller_reads
from pipelines.experiments.checked_weights import WeightsReplaced, check_loaded_weights
from pipelines.experiments.deadline import EpisodeTimeout, check_timeout, deadline, timeout_error
from pipelines.experiments.tasks import EpisodeTask
from pipelines.loop.contract import checked_description, episode_config
from pipelines.loop.controllers import Controller, make_controller
from pipelines.plain_json import plain
from predictors.locking import pid_alive

if TYPE_CHECKING:
    from crowdsim.env_config import EnvConfig
    from pipelines.loop.episode import EpisodeResult

RECORD_POLICIES: Final[tuple[str, ...]] = ("none", "failures", "all")
# Controllers a worker keeps built at once (least recently used dropped first). Tasks come interleaved across
# groups of at most this many cells (Experiment.tasks), so a worker builds each cell's once; this holds every
# cell of the largest paper experiment (Tables II/III: 10). An MPC controller holds a few CasADi solver
# instances (megabytes), a replayed crowd's one per crowd size (~300 MB at 20 people): not without bound.
CONTROLLER_CACHE: Final[int] = 16
# Library thread pools inside each worker: the workers are the parallelism.
SINGLE_THREAD_ENV: Final[dict[str, str]] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


def jit_available() -> bool:
    """Whether CasADi's jit can compile here: its "shell" compiler calls gcc."""
    return shutil.which("gcc") is not None


# The scratch of one sweep run: ``<temp>/crowdmpc-sweep-<driver pid>-<random>/``, one subfolder per worker for
# CasADi's jit sources and the MCAP files of episodes being recorded. The driver removes it when the run ends;
# a killed driver (or worker) cannot, so every sweep first removes the roots of drivers that are gone. The
# driver holds ``DRIVER_LOCK`` in its root while it runs: with the temp directory on a file system that
# several machines share, a pid cannot tell another machine's running driver from a dead one (a sweep's
# cleanup removed a running sweep's root on another node: 88 of its 200 recorded episodes failed).
SCRATCH_PREFIX: Final[str] = "crowdmpc-sweep-"
DRIVER_LOCK: Final[str] = ".driver.lock"
_HELD: dict[Path, int] = {}  # this process's scratch roots -> the descriptor holding their lock


def make_scratch_root() -> Path:
    """A new scratch root for this driver's sweep run, after removing those of drivers that are gone; its
    lock held until ``release_scratch_root``."""
    import fcntl

    remove_stale_scratch()
    root = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{os.getpid()}-"))
    fd = os.open(root / DRIVER_LOCK, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX)  # a new file: nobody else holds it
    _HELD[root] = fd
    return root


def release_scratch_root(root: Path) -> None:
    """Remove this driver's scratch ``root`` and release its lock."""
    shutil.rmtree(root, ignore_errors=True)
    fd = _HELD.pop(root, None)
    if fd is not None:
        os.close(fd)


def remove_stale_scratch(
    temp_dir: str | Path | None = None, prefix: str = SCRATCH_PREFIX, older_than_s: float = 0.0
) -> list[Path]:
    """Remove the folders ``<prefix><pid>-...`` (in ``temp_dir``, default the system's: the sweeps' scratch
    roots) whose writer is gone: its process is not running here, the folder was last written
    ``older_than_s`` ago or more (a writer without a lock, on another machine sharing the folder, may still
    be writing it: a report's staging folder), and nobody holds its ``DRIVER_LOCK`` (a root without one, made
    before the lock, is judged by the pid alone)."""
    from predictors.locking import unless_held

    named = re.compile(re.escape(prefix) + r"(\d+)-")
    removed = []
    for root in Path(temp_dir or tempfile.gettempdir()).glob(prefix + "*"):
        match = named.match(root.name)
        if match is None or root.is_symlink() or not root.is_dir() or pid_alive(int(match[1])):
            continue  # this process's own too: its pid is alive
        try:
            if older_than_s and time.time() - root.stat().st_mtime < older_than_s:
                continue
        except OSError:  # another process removed it first
            continue
        with unless_held(root / DRIVER_LOCK, gone=True) as free:
            if not free:  # a driver on another machine sharing the folder
                continue
            shutil.rmtree(root, ignore_errors=True)
        removed.append(root)
    return removed


def worker_scratch(root: str | Path | None) -> str:
    """A scratch folder of this worker process's own: in the driver's ``root`` when it is on this machine,
    else (no root, or a Ray node elsewhere) a new folder in the temp directory, removed when the process exits
    normally (a killed worker's is left behind: only a driver-owned root avoids that)."""
    import atexit

    if root is not None and os.path.isdir(root):
        return tempfile.mkdtemp(prefix=f"worker-{os.getpid()}-", dir=root)
    scratch = tempfile.mkdtemp(prefix="crowdmpc-worker-")
    atexit.register(shutil.rmtree, scratch, ignore_errors=True)
    return scratch


def is_failure(metrics: dict[str, Any]) -> bool:
    """What ``--record failures`` keeps: not every robot arrived, or personal space was violated."""
    return (not metrics.get("success")) or bool(metrics.get("collision"))


def process_cpu_s() -> float:
    """CPU seconds of this process and of its finished children: the gcc that compiles a ``--jit on``
    solver runs as a child process, which ``time.process_time`` does not count (a 5 + 7 humans table2
    sweep: 4.6 s of episode CPU by ``process_time`` against 15.2 s user by ``time``). One episode runs at a
    time per worker process, so the difference over an episode is that episode's."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def episode_record(
    task: EpisodeTask,
    result: EpisodeResult,
    wall_s: float,
    cpu_s: float,
    config: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """One line of episodes.jsonl: the closed loop's ``EpisodeRecord`` and what only the sweep knows (the
    cell, the worker). ``cpu_s`` is the worker's CPU time for the episode (``process_cpu_s``: gcc compiling a
    solver included), which unlike ``wall_s`` does not
    depend on how busy the machine was. ``config``: the effective config the episode ran with
    (``cell_config``: the simulator's and the controller's, as in the MCAP metadata), under "config": a
    resume checks its margins (resume_checks), table.md names their calibration (cell_columns), compare pairs
    crowds by its "env". Records written before it existed have none: no margins to check, no calibration
    to name, their profile's crowd."""
    spec, world = task.cell.spec, task.cell.world
    sweep = {
        "key": task.key,
        "experiment": task.experiment,
        "cell": task.cell.key,
        "method": task.cell.method,
        "index": task.index,
        "flocking": spec.flocking,
        "coupling": spec.coupling,
        "margins": spec.margins.label,
        "profile": world.profile,
        "visibility": world.visibility,
        # what the controller saw: null, every human; else the sensor's range (m) and whether it gave tracks
        "sensor_range": world.sensor_range,
        "sensor_tracks": None if world.sensor_range is None else world.sensor_tracks,
        "wall_s": wall_s,
        "cpu_s": cpu_s,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }
    if world.crowd != "orca":  # the file its people came from: a resume checks it (resume_checks)
        from pipelines.loop.replay_data import recording_sha256

        sweep["crowd_sha256"] = recording_sha256(world.crowd)
    if config is not None:
        sweep["config"] = config
    return {**result.record().to_dict(), **plain(sweep)}


def check_json(record: dict[str, Any], task: EpisodeTask) -> None:
    """Refuse, as this episode's error, a record the driver could not write as JSON (EpisodeLog.append):
    a plugin controller's ``describe()`` holding a set, say, would otherwise stop the driver at the write and
    the rest of the sweep with it."""
    try:
        json.dumps(plain(record), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise PipelineError(
            f"controller {task.cell.spec.controller!r}: its episode record is not JSON ({exc}); describe() "
            "must return JSON values (dicts, lists, strings, numbers, booleans, None)"
        ) from None


def cell_config(controller: Controller, env_config: EnvConfig) -> dict[str, Any]:
    """The effective config of a cell's episodes, as ``run_episode`` puts it in the MCAP "config" metadata:
    the simulator's settings and what the controller's ``describe()`` adds (the MPC's config, coupling,
    flocking, margins)."""
    return plain(episode_config(env_config, checked_description(controller)))


@dataclass
class EpisodeOutcome:
    """What a worker hands back: a record, or the error that stopped the episode, or the refusal that stops
    the sweep (``stop``: its one line); a kept MCAP log."""

    key: str
    record: dict[str, Any] | None = None
    error: str | None = None
    mcap: bytes | None = None
    stop: str | None = None


class EpisodeWorker:
    """Runs episode tasks; builds each cell's controller once and reuses it across that cell's episodes."""

    def __init__(
        self,
        record: str = "none",
        jit: bool = False,
        scratch: str | Path | None = None,
        timeout_s: float | None = None,
    ):
        """``scratch``: the folder of this worker's temporary files (default: the temp directory);
        ``timeout_s``: each episode's wall-clock limit (pipelines.experiments.deadline; None: none)."""
        if record not in RECORD_POLICIES:
            raise PipelineError(f"unknown --record {record!r}; choose from {list(RECORD_POLICIES)}")
        self.record = record
        self.jit = jit
        self.scratch = scratch
        self.timeout_s = check_timeout(timeout_s)
        self._controllers: OrderedDict[str, Controller] = OrderedDict()
        self._configs: dict[str, dict[str, Any]] = {}  # cell key -> cell_config, built with its controller
        self.builds = 0  # controllers built so far (a test checks the reuse)

    def controller(self, task: EpisodeTask) -> Controller:
        key = task.cell.key
        if key in self._controllers:
            self._controllers.move_to_end(key)
            return self._controllers[key]
        from pipelines.loop.episode import behind_sensor
        from pipelines.loop.mpc import MPCController

        cell, world = task.cell, task.cell.world
        env_config = world.env_config()
        spec = cell.spec.behind(world.sensor_range, world.sensor_tracks)
        # with the calibration block the driver checked, where it handed one: the file is not read again here
        controller = make_controller(spec, env_config, jit=self.jit, read=controller_reads(task))
        try:  # loaded again here, after the driver checked them: a `zoo add --replace` may have come between
            check_loaded_weights(task, controller)
        except PipelineError:
            controller.close()
            raise
        controller = behind_sensor(
            controller, world.sensor_range, world.sensor_tracks, cell.n_robots, cell.n_humans, world.crowd
        )
        if self.timeout_s is not None and isinstance(controller, MPCController):
            # its NLP too, not only at the episode's reset, inside the limit (behind_sensor built every size)
            controller.prepare(cell.n_robots, [cell.n_humans])
        self.builds += 1
        self._controllers[key] = controller
        self._configs[key] = cell_config(controller, env_config)
        while len(self._controllers) > CONTROLLER_CACHE:
            self._drop(next(iter(self._controllers)))
        return controller

    def _drop(self, key: str, close: bool = True) -> None:
        """Forget cell ``key``'s controller, closed (``close``): a controller's ``close`` releases its threads
        and solvers (a plugin's, its hardware), and a sweep called it for none of them. Within the episode
        limit, if the sweep has one: a close that hangs must not hold the worker for good."""
        self._configs.pop(key, None)
        controller = self._controllers.pop(key, None)
        if controller is None or not close:
            return
        name = getattr(controller, "name", type(controller).__name__)
        try:
            with deadline(self.timeout_s):
                controller.close()
        except EpisodeTimeout:
            print_note(f"note: controller {name!r}'s close() did not return in {self.timeout_s:g} s")
        except Exception as exc:  # an episode's record is written already: say it, do not end the sweep
            print_note(f"note: controller {name!r}'s close() raised {type(exc).__name__}: {exc}")

    def close(self) -> None:
        """Close every controller built (the sweep's end; the process backend's workers at their exit)."""
        for key in list(self._controllers):
            self._drop(key)

    def run(self, task: EpisodeTask) -> EpisodeOutcome:
        try:
            # built outside the limit: a first episode's gcc compile (2-8 s) or solver build is no hang, and a
            # compile stopped half-way would leave its files to the cache's clean-up
            controller = self.controller(task)
            with deadline(self.timeout_s):
                return self._run(task, controller)
        except EpisodeTimeout:
            # stopped anywhere, mid-step too: its state is not to be trusted with another episode, nor its
            # close() (a plugin's may wait on the device its act hung on), so it is dropped unclosed
            self._drop(task.cell.key, close=False)
            assert self.timeout_s is not None  # only a limit raises it
            return EpisodeOutcome(task.key, error=timeout_error(self.timeout_s, traceback.format_exc()))
        except WeightsReplaced as exc:  # every later episode of the predictor would refuse: the sweep's
            return EpisodeOutcome(task.key, stop=str(exc))
        except Exception as exc:  # a bug or a solver crash in one episode must not end a sweep of thousands
            interrupt = interrupt_behind(exc)
            if interrupt is not None:  # Ctrl-C in CasADi (inline sweeps): the sweep's, not the episode's
                raise interrupt from None
            return EpisodeOutcome(task.key, error=traceback.format_exc())

    def _run(self, task: EpisodeTask, controller: Controller) -> EpisodeOutcome:
        from pipelines.loop.episode import run_episode

        recorder = None
        if self.record != "none":
            from pipelines.logs.recording import McapEpisodeRecorder

            # A scratch folder per episode; a kept log goes to the driver as bytes (it may run elsewhere).
            # "record": which episodes the sweep kept, so that a review of the files alone (no sweep.json
            # beside them) can say that --record failures' rates are over the failures only.
            run_meta = {"experiment": task.experiment, "cell": task.cell.key, "record": self.record}
            crowd = task.cell.world.crowd
            if crowd != "orca":  # the file its people came from, as the episode's record names it
                from pipelines.loop.replay_data import recording_sha256

                run_meta["crowd_sha256"] = recording_sha256(crowd)
            scratch = tempfile.mkdtemp(prefix="crowdmpc-episode-", dir=self.scratch)
            # unsynced: the driver keeps a copy of its bytes, synced then (log.write_whole), and a power
            # loss takes the scratch folder with the episode unrecorded in episodes.jsonl, to run again
            recorder = McapEpisodeRecorder(scratch, run_meta=run_meta, durable=False)
        meta = {
            "experiment": task.experiment,
            "cell": task.cell.key,
            "method": task.cell.method,
        }
        start, cpu_start = time.perf_counter(), process_cpu_s()
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
                task,
                result,
                time.perf_counter() - start,
                process_cpu_s() - cpu_start,
                config=self._configs.get(task.cell.key),
            )
            check_json(record, task)
            mcap = None
            if recorder is not None and (self.record == "all" or is_failure(record["metrics"])):
                mcap = recorder.paths[-1].read_bytes()
            return EpisodeOutcome(task.key, record=record, mcap=mcap)
        finally:
            if recorder is not None:
                recorder.close()  # already closed by on_end unless the episode raised
                shutil.rmtree(recorder.out_dir, ignore_errors=True)
