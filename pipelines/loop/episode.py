"""The closed loop: scenario -> (controller -> simulator step) until the episode ends -> metrics.

Controllers handle their own failures (a solver that fails falls back inside the controller and says so in
``ControlOutput.fallback``); anything that escapes a shipped controller or an observer is a bug and
propagates with its traceback. A plugin whose method raises, or a controller that breaks the plugin contract
(``act`` returning no ``ControlOutput``, or one of the wrong shapes; ``describe`` no dict), is a
PipelineError naming it (``pipelines.loop.contract``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Protocol

import numpy as np

from crowdsim.control import ControlOutput
from crowdsim.env import CrowdEnv, Observation
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.metrics import EpisodeMetrics, Trajectory, episode_metrics
from crowdsim.replay import Recording
from crowdsim.scenarios import MAX_ROBOTS, check_sizes
from crowdsim.world import PAPER_ROBOTS
from pipelines.errors import CloseFailed, EpisodeFailed, PipelineError
from pipelines.loop.contract import (
    called,
    checked_description,
    checked_meta,
    checked_output,
    episode_meta,
    handed_out,
)
from pipelines.loop.controllers import (
    Controller,
    ControllerReads,
    ControllerSpec,
    check_built_for,
    check_controller,
    make_controller,
)
from pipelines.loop.interrupt import interrupts_between_steps
from pipelines.loop.progress import StepShown
from pipelines.loop.record import EpisodeRecord, SolverStats
from pipelines.loop.record import summarize as summarize  # its callers import it from here
from pipelines.loop.run_arguments import check_run, checked_observers
from predictors.errors import PredictorError
from predictors.progress import progress_bar


class EpisodeObserver(Protocol):
    """Hooks the closed loop calls; the MCAP recorder is one."""

    def on_reset(self, obs: Observation, meta: Mapping[str, Any]) -> None: ...

    def on_step(self, obs: Observation, out: ControlOutput, next_obs: Observation) -> None: ...

    def on_end(self, result: EpisodeResult) -> None: ...


DEFAULT_ENV: Final[EnvConfig] = EnvConfig()


@dataclass(frozen=True)
class EpisodeResult:
    """One finished episode: who drove, what happened, what it cost, and the trajectories."""

    seed: int | None  # None: no seed drew the episode (a gym episode started from a layout)
    scenario: str
    n_humans: int
    n_robots: int
    controller: str
    predictor: str | None
    predictor_sha256: str | None
    metrics: EpisodeMetrics
    # Not in the repr: a notebook showing a result printed every one of them (30 kB for one episode).
    robot_positions: np.ndarray = field(repr=False)  # (T+1, M, 2) m
    human_positions: np.ndarray = field(repr=False)  # (T+1, N, 2) m
    robot_goals: np.ndarray = field(repr=False)  # (M, 2) m
    human_goals: np.ndarray = field(repr=False)  # (N, 2) m
    solve_times_s: np.ndarray = field(repr=False, compare=False)  # (T,) s, wall time of each control step
    statuses: tuple[str, ...] = field(repr=False)  # (T,) solver status per control step
    fallbacks: tuple[str | None, ...] = field(repr=False)  # (T,) None or the fallback used
    iterations: np.ndarray = field(repr=False)  # (T,) int, IBR iterations per control step
    # (T+1, N) bool, a replayed crowd's tracked humans at each row (crowdsim.replay); None: all, always
    human_present: np.ndarray | None = field(default=None, repr=False)

    def __eq__(self, other: object) -> bool:
        """Field by field, arrays by their values and NaN equal to NaN (the generated ``==`` asked numpy for
        one truth value of an array: a ValueError); the wall times of the steps (``solve_times_s``) are not
        compared, so two runs of one seed are equal."""
        if not isinstance(other, EpisodeResult):
            return NotImplemented
        compared = (f.name for f in dataclasses.fields(self) if f.compare)
        return all(_same(getattr(self, name), getattr(other, name)) for name in compared)

    def record(self) -> EpisodeRecord:
        """The episode without its trajectories: what every report and log serialises."""
        return EpisodeRecord(
            seed=self.seed,
            scenario=self.scenario,
            n_humans=self.n_humans,
            n_robots=self.n_robots,
            controller=self.controller,
            predictor=self.predictor,
            predictor_sha256=self.predictor_sha256,
            metrics=self.metrics,
            solver=SolverStats.of_steps(self.solve_times_s, self.iterations, self.statuses, self.fallbacks),
        )


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and bool(np.all((a == b) | (_nan(a) & _nan(b))))
    if dataclasses.is_dataclass(a) and type(a) is type(b):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, tuple | list) and type(a) is type(b):  # reach_times: NaN for a robot that never arrived
        return len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


def _nan(values: np.ndarray) -> np.ndarray:  # NaN where the values are floats (ints have none)
    return np.isnan(values) if values.dtype.kind in "fc" else np.zeros(values.shape, dtype=bool)


class EpisodeSteps:
    """One episode's control steps as each closed loop takes them (``run_episode``, the gym loops), and the
    ``EpisodeResult`` they end in."""

    def __init__(self) -> None:
        self.solve_times: list[float] = []
        self.statuses: list[str] = []
        self.fallbacks: list[str | None] = []
        self.iterations: list[int] = []

    def add(self, out: ControlOutput) -> None:
        self.solve_times.append(float(out.solve_time_s))
        self.statuses.append(str(out.status))
        self.fallbacks.append(out.fallback)
        self.iterations.append(int(out.iterations))

    def result(
        self, episode: Mapping[str, Any], meta: Mapping[str, Any], traj: Trajectory, metrics: EpisodeMetrics
    ) -> EpisodeResult:
        """The result of the episode ``episode`` (seed, scenario, n_humans, n_robots) whose meta (who drove:
        controller, predictor, predictor_sha256) is ``meta``, its states ``traj``."""
        return EpisodeResult(
            seed=episode["seed"],
            scenario=episode["scenario"],
            n_humans=episode["n_humans"],
            n_robots=episode["n_robots"],
            controller=meta["controller"],
            predictor=meta["predictor"],
            predictor_sha256=meta["predictor_sha256"],
            metrics=metrics,
            robot_positions=traj.robot_positions,
            human_positions=traj.human_positions,
            robot_goals=traj.robot_goals,
            human_goals=traj.human_goals,
            solve_times_s=np.asarray(self.solve_times, dtype=float),
            statuses=tuple(self.statuses),
            fallbacks=tuple(self.fallbacks),
            iterations=np.asarray(self.iterations, dtype=int),
            human_present=traj.human_present,
        )


def run_episode(
    controller: Controller,
    *,
    seed: int,
    scenario: str,
    n_humans: int,
    n_robots: int = PAPER_ROBOTS,
    env_config: EnvConfig = DEFAULT_ENV,
    observers: Sequence[EpisodeObserver] = (),
    meta: Mapping[str, Any] | None = None,
) -> EpisodeResult:
    """Run one episode to its end (every robot at its goal, or the time limit). SimulationError, before
    anything runs, for a scenario or size the simulator refuses, or no robot (``n_robots`` >= 1).

    The meta given to ``on_reset`` holds seed, scenario, n_humans, n_robots, controller, predictor (the
    controller's), predictor_sha256 and config (the environment's settings, plus what the controller's
    ``describe()`` adds: the MPC's config, the checkpoint's sha256); entries of ``meta`` are added and take
    precedence; an entry that would replace one of the episode's own fields (``contract.OWN_FIELDS``) is a
    PipelineError.
    """
    check_controller(controller)
    observers = checked_observers(observers, env_config, "run_episode")
    checked_meta(meta, "run_episode")  # before the controller's reset, which may build its NLPs
    check_built_for(controller, env_config, "run_episode")
    _check_team(scenario, n_humans, n_robots, "run_episode")
    env = CrowdEnv(env_config, replayed_recording(env_config))
    controller = behind_tracks(controller, env_config)
    obs = env.reset(seed, scenario, n_humans, n_robots)
    called(controller, "reset", handed_out(obs))
    episode = {"seed": seed, "scenario": scenario, "n_humans": n_humans, "n_robots": n_robots}
    described = checked_description(controller)
    full_meta = episode_meta(
        episode, env_config, controller.name, controller.predictor, described, meta, "run_episode"
    )
    steps = EpisodeSteps()
    done = False
    with interrupts_between_steps() as interrupt:  # CasADi's own Ctrl-C lines: see pipelines.loop.interrupt
        # the observers' starts too: a recorder opening its .part, interrupted there, left it behind
        for observer in observers:
            observer.on_reset(obs, full_meta)
        while not done:
            out = checked_output(controller, called(controller, "act", handed_out(obs)), obs)
            next_obs, done, _ = env.step(out.accelerations)
            steps.add(out)
            for observer in observers:
                observer.on_step(obs, out, next_obs)
            obs = next_obs
            interrupt.check()
        # and their ends: a recorder interrupted while it finished its file (the footer written and synced,
        # not yet renamed) left it as a .part, which a `kill` of simulate under load met
        traj = env.trajectory()
        result = steps.result(episode, full_meta, traj, episode_metrics(traj))
        for observer in observers:
            observer.on_end(result)
    return result


def run_episodes(
    spec: ControllerSpec,
    *,
    episodes: int,
    seed: int,
    scenario: str,
    n_humans: int,
    n_robots: int = PAPER_ROBOTS,
    observers_factory: Callable[[], Iterable[EpisodeObserver]] | None = None,
    progress: bool | None = None,
    env_config: EnvConfig = DEFAULT_ENV,
    meta: Mapping[str, Any] | None = None,
    into: list[EpisodeResult] | None = None,
    sensor_range: float | None = None,
    sensor_tracks: bool = True,
    read: ControllerReads | None = None,
) -> list[EpisodeResult]:
    """``episodes`` episodes with one controller built once from ``spec``; episode ``i`` uses ``seed + i``;
    ``read``: what the command read of the zoo for it already (``make_controller``'s).

    ``sensor_range``: the controller sees only the humans within that many metres of some robot, as a tracker
    gives them, reporting its track lengths with ``sensor_tracks`` (pipelines.loop.sensing.RangeLimited); an
    MPC's NLPs for every number of humans in view are built before the first episode.

    ``observers_factory()`` is called once per episode (fresh observers for each, e.g. a recorder per file);
    when that episode raises (Ctrl-C, a plugin's error), its observers that have a ``close`` are closed
    before the exception goes on (a recorder finishes its file as it is); a ``PipelineError`` (a controller
    plugin's) or a ``PredictorError`` (a net plugin's) goes on as an ``EpisodeFailed`` naming the episode's
    seed.
    ``into``: the list each finished episode is appended to (and returned), so that a caller interrupted
    half-way (Ctrl-C) still holds the episodes that finished.
    """
    seed = check_run(spec, episodes, seed, env_config, sensor_range, sensor_tracks, into, observers_factory)
    _check_team(scenario, n_humans, n_robots, "run_episodes")
    run_meta = checked_meta(meta, "run_episodes")  # before the controller is built: an MPC's NLPs take long
    if env_config.crowd != "orca" and episodes:  # its first window drawn before the NLPs are built: 12
        # robots' took 2.5 minutes before "no window has 50 pedestrians" (SimulationError)
        CrowdEnv(env_config, replayed_recording(env_config)).reset(seed, scenario, n_humans, n_robots)
    controller = make_controller(spec.behind(sensor_range, sensor_tracks), env_config, read=read)
    controller = behind_sensor(controller, sensor_range, sensor_tracks, n_robots, n_humans, env_config.crowd)
    results: list[EpisodeResult] = [] if into is None else into
    bar = progress_bar(range(episodes), desc=f"{spec.controller} {scenario}", unit="ep", show=progress)
    successes = sum(r.metrics.success for r in results)  # counted as they come: a sum per episode was O(N^2)
    stepper = StepShown(bar)
    try:
        for i in bar:
            observers = tuple(observers_factory()) if observers_factory is not None else ()
            if not bar.disable:
                observers = (*observers, stepper)
            result = _observed_episode(
                controller, observers, seed + i, scenario, n_humans, n_robots, env_config, run_meta
            )
            results.append(result)
            successes += result.metrics.success
            stepper.success = f"success={100.0 * successes / len(results):.0f}%"
            bar.set_postfix_str(stepper.success, refresh=False)
    except BaseException:
        with contextlib.suppress(PipelineError):  # a plugin's close() failing too: the run's error is told
            called(controller, "close")
        raise
    try:
        called(controller, "close")  # e.g. DMPC's solver threads
    except PipelineError as exc:
        raise CloseFailed(exc, len(results)) from exc
    return results


def _observed_episode(
    controller: Controller,
    observers: tuple[EpisodeObserver, ...],
    seed: int,
    scenario: str,
    n_humans: int,
    n_robots: int,
    env_config: EnvConfig,
    meta: Mapping[str, Any],
) -> EpisodeResult:
    """One episode of ``run_episodes``: when it raises, its ``observers`` are closed before the exception goes
    on, a plugin's error as an ``EpisodeFailed`` naming the episode's seed."""
    try:
        return run_episode(
            controller,
            seed=seed,
            scenario=scenario,
            n_humans=n_humans,
            n_robots=n_robots,
            env_config=env_config,
            observers=observers,
            meta=meta,
        )
    except (PipelineError, PredictorError) as exc:  # a plugin's: the episode, to rerun it alone
        _close_quietly(observers)
        raise EpisodeFailed(seed, scenario, exc) from exc
    except BaseException:
        _close_quietly(observers)
        raise


def behind_sensor(
    controller: Controller,
    radius: float | None,
    tracks: bool,
    n_robots: int,
    n_humans: int,
    crowd: str = "orca",
) -> Controller:
    """``controller`` behind a sensor of range ``radius`` (RangeLimited), and among a replayed ``crowd``
    shown only the people tracked now (at every distance when ``radius`` is None), an MPC's every crowd size
    up to ``n_humans`` built, for ``n_robots`` robots; ``controller`` itself with neither."""
    from pipelines.loop.mpc import MPCController
    from pipelines.loop.sensing import RangeLimited

    if radius is None and crowd == "orca":
        return controller
    radius = math.inf if radius is None else radius
    sensed = RangeLimited(controller, radius, report_tracks=tracks)  # refuses a radius that is no distance
    if isinstance(controller, MPCController):
        controller.prepare(n_robots, range(n_humans + 1))  # inside the steps, builds would count as solves
    return sensed


def replayed_recording(env_config: EnvConfig) -> Recording | None:
    """The recording a replayed crowd plays back (pipelines.loop.replay_data), None for ORCA's crowd."""
    if env_config.crowd == "orca":
        return None
    from pipelines.loop.replay_data import recording

    return recording(env_config.crowd)


def behind_tracks(controller: Controller, env_config: EnvConfig) -> Controller:
    """``controller`` shown only the humans a replayed crowd tracks now (RangeLimited at every distance),
    unless a sensor already does that; ``controller`` itself for ORCA's crowd, where every human is there."""
    from pipelines.loop.sensing import RangeLimited

    if env_config.crowd == "orca" or isinstance(controller, RangeLimited):
        return controller
    return RangeLimited(controller, math.inf)


def _check_team(scenario: str, n_humans: int, n_robots: int, where: str) -> None:
    """``check_sizes`` with at least one robot: the simulator runs crowds alone, an episode's metrics are
    its robots' (13 robots were refused as out of [0, 12] and 0 as out of [1, 12])."""
    whole = isinstance(n_robots, int | np.integer) and not isinstance(n_robots, bool)
    if whole and not 1 <= n_robots <= MAX_ROBOTS:
        raise SimulationError(f"{where}: n_robots must be in [1, {MAX_ROBOTS}], got {n_robots}")
    check_sizes(scenario, n_humans, n_robots)


def _close_quietly(observers: Iterable[EpisodeObserver]) -> None:
    """Close the observers of an episode that raised. Nobody else can: the factory made them inside
    ``run_episodes``, and the traceback a notebook keeps (``sys.last_traceback``) kept a recorder's
    ``.part`` open and locked, so that running the cell again was refused as "another run is recording
    that episode". What a ``close`` raises is dropped: the episode's own exception is the one to see."""
    for observer in observers:
        close = getattr(observer, "close", None)
        if callable(close):
            with contextlib.suppress(Exception):
                close()
