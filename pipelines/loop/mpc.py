"""CMPC and DMPC as closed-loop controllers: crowdsim observations in, accelerations and solver facts out.

One controller per run: the predictor is loaded once, and the NLPs are built once per problem size (robots,
humans) and reused across episodes. Per step: the observation becomes the solvers' ``StepData``; the humans'
predictions come from the predictor on the last ``predictor.obs_len`` rows of ``obs.history`` (robots first,
then humans) with the robots' planned positions as ``robots_future``: its CasADi twin evaluated numerically
on ``predictor.encode`` of that history (``rollout`` for a predictor without a twin, the ORCA oracle), or,
for ``coupling="nlp"``, the same twin inside the NLP. ``coupling="none"`` shows the predictor the humans'
rows alone: predictions that do not answer the robots' plans (predict, then plan: CMPC's IBR loop ends at its
second iteration without a second solve; DMPC's robots still answer each other's plans, up to j_max).

A robot that has reached its goal (``obs.robot_reached``) holds position and stops flocking: by default
(``on_goal="track"``) it stays in the optimisation anchored by its goal term, so it keeps still unless a
human or a teammate needs the room; ``on_goal="brake"`` pins it to braking instead (mpc/config.py).
A step that cannot solve falls back (mpc/fallback.py) and says so in ``ControlOutput.fallback``; so does a
step whose solve raised CasADi's error (a failure inside a solver call is a ``RuntimeError``), with status
``"exception: <type>"`` and the message in ``extra["exception"]``. Only that is guarded: any other exception
of the solve (a ``TypeError`` is a bug, not a solver failure), an exception from the predictor it calls, or
from anything else in the step propagates; so does Ctrl-C, which CasADi hands back inside a ``SystemError``.

What the controller is built from and checked against (its ``MPCConfig``, the world the MPC, the predictor
and the simulator must agree on, the history the predictor reads) is pipelines.loop.mpc_setup.
"""

from __future__ import annotations

import time
import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from crowdsim.control import ControlOutput
from mpc.cmpc import CMPC, IBRResult
from mpc.coupled import CoupledCMPC
from mpc.dmpc import DMPC
from mpc.dynamics import braking, rollout_numpy
from mpc.fallback import PlanMemory, Start
from mpc.fastcall import BufferedFunction
from mpc.nlp import StepData
from mpc.parked import yield_slack
from mpc.stall import StallWatch
from pipelines.errors import NoTwinWarning, PipelineError, act_before_reset, interrupt_behind
from pipelines.loop.margins_read import Refused, as_planned
from pipelines.loop.mpc_setup import (
    SolversHeld,
    check_coupling,
    check_dt,
    check_history,
    check_margins_world,
    check_world,
    mpc_config,
    predictor_history,
    prepare_sizes,
    standing_history,
)
from pipelines.loop.mpc_step import crowd_allowances, raised_output, solve_output
from pipelines.loop.spec import ControllerSpec
from pipelines.loop.team_layout import warn_team_layout
from predictors.base import ObservingPredictor, Predictor
from predictors.conformal_classes import CLASS_WINDOW
from predictors.errors import NoCasadiTwin, PredictorError
from predictors.registry import load_predictor, loaded_sha256

if TYPE_CHECKING:
    from collections.abc import Iterable
    from types import EllipsisType

    from crowdsim.env import Observation
    from crowdsim.env_config import EnvConfig
    from pipelines.loop.margins import Located


class MPCController(SolversHeld):
    """Algorithm 1 (``distributed=False``), Algorithm 2 (``True``) or the coupled NLP (``coupling="nlp"``)."""

    def __init__(
        self,
        spec: ControllerSpec,
        distributed: bool,
        *,
        env_config: EnvConfig | None = None,
        jit: bool = False,
        predictor: Predictor | Refused | None = None,
        calibration: Located | None | Refused | EllipsisType = ...,
    ):
        """``env_config``: the simulator's settings, for a predictor that observes it (the ORCA oracle);
        ``predictor``, ``calibration``: spec's predictor and block (``look_up``'s), read already; a
        ``Refused`` predictor: the refusal of the command's load of it, raised here where it loads it."""
        from crowdsim.env_config import EnvConfig

        if distributed and spec.coupling == "nlp":  # refused before a predictor is loaded for it
            check_coupling(spec, distributed)
        self.spec = spec
        self.name = "dmpc" if distributed else "cmpc"
        self.distributed = distributed
        self.env_config = env_config if env_config is not None else EnvConfig()
        if isinstance(predictor, Refused):  # loaded once by the command: its refusal at this load's turn
            raise predictor.error
        self.model: Predictor = predictor if predictor is not None else load_predictor(spec.predictor)
        self.predictor: str | None = self.model.name
        self._observer = self.model if isinstance(self.model, ObservingPredictor) else None
        check_coupling(spec, distributed, self.model)
        world = self.env_config.world()
        check_margins_world(spec, world)  # before the calibration is looked up: the cause, not a symptom
        cfg = mpc_config(spec, jit, world)
        self.predictor_sha256 = sha256 = loaded_sha256(self.model)  # of the weights loaded, read with them
        at = as_planned(spec.margins, calibration, self.model.name, cfg.horizon, sha256)  # read once, or here
        self.cfg = cfg.replace(human_margins=spec.margins.resolve(self.model.name, cfg.horizon, sha256, at))
        # conformal-motion and -shortfall: a margin per human and step from its motion class, every step
        self.class_margins = spec.margins.resolve_classes(self.model.name, cfg.horizon, sha256, at)
        self.calibration = spec.margins.calibration(self.model.name, sha256, at)
        if self.class_margins is not None and world.obs_len < CLASS_WINDOW:
            raise PipelineError(
                f"{spec.margins.mode} margins are calibrated for motion classes read from a human's last "
                f"{CLASS_WINDOW} positions, but the simulator keeps {world.obs_len} ([world] obs_len): set "
                f"[world] obs_len >= {CLASS_WINDOW} (e.g. --set world.obs_len={CLASS_WINDOW})"
            )
        check_world(world, self.cfg, self.model)
        self.memory = PlanMemory(self.cfg)
        self.stall = StallWatch(self.cfg.stall_release_s, self.cfg.dt) if self.cfg.stall_release_s else None
        self._solvers: dict[tuple[int, int], CMPC | DMPC | CoupledCMPC] = {}
        self._twins: dict[tuple[int, int], BufferedFunction | None] = {}
        self.solve_exceptions = 0  # control steps whose solve raised (each fell back), in this episode
        self._predictor_error: BaseException | None = None  # raised by the predictor in this step's solve
        self._never_reset = True  # until the first reset, or act's one warning that there was none

    def close(self) -> None:
        """Release what the solvers hold (DMPC's thread pool); the controller can still be used after."""
        for solver in self._solvers.values():
            if isinstance(solver, DMPC):
                solver.close()

    def describe(self) -> dict[str, Any]:
        """What the episode metadata records about this controller (the closed loop merges it)."""
        return {
            "predictor_sha256": self.predictor_sha256,  # the weights loaded, whatever the zoo holds now
            "config": {
                "mpc": self.cfg.to_dict(),
                "coupling": self.spec.coupling,
                "flocking": self.spec.flocking,
                "distributed": self.distributed,
                "margins": self.spec.margins.describe(self.cfg.human_margins)
                | ({} if self.class_margins is None else {"classes": self.class_margins.to_json()})
                | ({} if self.calibration is None else {"calibration": self.calibration}),
            },
        }

    def solver(self, n_robots: int, n_humans: int) -> CMPC | DMPC | CoupledCMPC:
        """The solver for this problem size, built on first use and kept."""
        key = (n_robots, n_humans)
        if key not in self._solvers:
            if self.spec.coupling == "nlp":
                function = self.model.to_casadi(n_humans, n_robots, self.cfg.horizon)
                size = self.model.context_size(n_humans, n_robots)
                self._solvers[key] = CoupledCMPC(self.cfg, n_robots, n_humans, function, size)
            else:
                self._solvers[key] = (DMPC if self.distributed else CMPC)(self.cfg, n_robots, n_humans)
        return self._solvers[key]

    def prepare(self, n_robots: int, n_humans: Iterable[int]) -> dict[tuple[int, int], float]:
        """Build now, before a control loop, what the first step meeting each size would build inside
        itself: the NLP (compiled with ``jit``) and every solver instance a solve may call, the predictor's
        CasADi twin and its exported encoder. On a real robot the number of humans changes as people come
        and go; a step meeting a size not prepared builds it (seconds with ``jit`` and a cold cache).
        Returns the seconds each size took, ``(n_robots, n_humans) -> s``; a size built already costs ~0."""
        sizes = prepare_sizes(n_robots, n_humans)
        seconds: dict[tuple[int, int], float] = {}
        for m, n in sizes:
            t0 = time.perf_counter()
            self._build(m, n, standing_history(m + n, self.model.obs_len)).build_all()
            seconds[(m, n)] = time.perf_counter() - t0
        return seconds

    def _build(self, n_robots: int, n_humans: int, history: np.ndarray) -> CMPC | DMPC | CoupledCMPC:
        """The solver of this size, the predictor's twin and its exported encoder, which its first call
        builds (80 ms for social_lstm_eth), by encoding ``history``: the context is memoised for a step that
        encodes the same past."""
        solver = self.solver(n_robots, n_humans)
        mask = np.ones(history.shape[:2], dtype=bool)
        history, mask, humans, seen = self._seen(history, mask, np.arange(n_robots, n_robots + n_humans))
        if self.spec.coupling == "nlp" or self._twin(n_humans, seen) is not None:
            self.model.encode(history, mask, humans)
        return solver

    def _seen(
        self, history: np.ndarray, mask: np.ndarray, humans: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """The predictor's history, mask, humans and robots: all, or the humans' alone for coupling "none"."""
        m = history.shape[1] - len(humans)  # the robots come first
        if self.spec.coupling != "none":
            return history, mask, humans, m
        return history[:, m:], mask[:, m:], humans - m, 0

    def _twin(self, n_humans: int, n_robots: int) -> BufferedFunction | None:
        """The predictor's CasADi twin for this size, or None for a predictor without one (the oracle)."""
        key = (n_humans, n_robots)
        if key not in self._twins and n_humans + n_robots == 0:  # coupling "none", nobody in sight
            self._twins[key] = None
        if key not in self._twins:
            try:
                function = self.model.to_casadi(n_humans, n_robots, self.cfg.horizon)
            except NoCasadiTwin:
                self._twins[key] = None
            except PredictorError as exc:
                # a plugin net with an operation the exporter lacks still runs, in torch; but say so: a
                # step several times slower, or a twin that disagrees with torch, must not pass unseen
                warnings.warn(
                    f"predictor {self.model.name!r}: no CasADi twin ({exc}); the iterative best response "
                    "predicts with torch instead (slower)",
                    NoTwinWarning,
                    stacklevel=2,
                )
                self._twins[key] = None
            else:
                self._twins[key] = BufferedFunction(function)
        return self._twins[key]

    def _predict_fn(self, history: np.ndarray, mask: np.ndarray, humans: np.ndarray):
        """The IBR loop's ``predict``: robots' planned positions ``(H, M, 2)`` -> humans' ``(H, N_h, 2)``.

        Through the predictor's CasADi twin on ``encode`` of the past when it has one: the contract test
        holds it to ``rollout`` within 1e-6, and for the networks it is ~4x cheaper than the torch rollout
        (0.42 vs 1.78 ms, social_lstm_eth, 7 humans + 3 robots), which the loop calls several times a step.
        What it raises is remembered, so that ``act`` lets it through instead of taking it for the solver's.
        """
        n_humans = len(humans)
        history, mask, humans, n_robots = self._seen(history, mask, humans)
        shape = (self.cfg.horizon, n_humans, 2)
        if n_humans + n_robots == 0:  # coupling "none" with nobody in sight: no one to predict
            return lambda robots_future: np.zeros(shape)
        twin = self._twin(n_humans, n_robots)
        context = None if twin is None else self.model.encode(history, mask, humans)

        def predict(robots_future: np.ndarray) -> np.ndarray:
            robots_future = robots_future[:, :n_robots]  # none of them with coupling "none"
            try:
                if twin is None:
                    return self.model.rollout(history, mask, robots_future, humans)
                return twin(context, robots_future)[0].reshape(shape)
            except BaseException as exc:
                self._predictor_error = exc
                raise

        return predict

    def _observe(self, obs: Observation) -> None:
        if self._observer is not None:
            self._observer.observe(obs, self.env_config)

    def reset(self, obs: Observation) -> None:
        check_dt(obs, self.cfg.dt)
        check_history(obs)
        history, _ = predictor_history(obs, self.model.obs_len)
        self._observe(obs)
        # Build now, not inside the first timed step (which encodes the same past); no robots: act brakes none
        if obs.n_robots:  # without a solver, and DMPC's NLP has no size 0 (CasADi's assertion)
            self._build(obs.n_robots, obs.n_humans, history)
        warn_team_layout(self.cfg, np.asarray(obs.robot_positions), np.asarray(obs.robot_goals))
        self._never_reset = False
        self.solve_exceptions = 0  # the steps' count is of their episode, which its recording holds
        self.memory.reset()
        if self.stall is not None:
            self.stall.reset()

    def act(self, obs: Observation) -> ControlOutput:
        t0 = time.perf_counter()
        if self._never_reset:  # said, not refused: a benchmark may time act alone
            self._never_reset = False
            warnings.warn(act_before_reset(type(self).__name__), stacklevel=2)
        check_dt(obs, self.cfg.dt)  # at every step, not at reset alone: an observation built by hand
        check_history(obs)
        self._observe(obs)
        cfg = self.cfg
        n_robots, n_humans = obs.n_robots, obs.n_humans
        states = np.concatenate([obs.robot_positions, obs.robot_velocities], axis=1).astype(float)
        reached = np.asarray(obs.robot_reached, dtype=bool)
        # Guidance and the stall watch go by where a robot is now: one that arrived and was pushed off its
        # goal (a pair of people herded one 4.8 m back) must be led back, not left as "has arrived"
        on_goal = np.linalg.norm(states[:, :2] - obs.robot_goals, axis=1) < obs.radius
        data = StepData(
            states=states,
            last_actions=np.asarray(obs.robot_last_actions, dtype=float),
            goals=np.asarray(obs.robot_goals, dtype=float),
            active=~reached if cfg.on_goal == "brake" else np.ones(n_robots, dtype=bool),
            arrived=reached,
            flocking=self._flocking(states, obs.robot_goals, on_goal),
            goal_slack=yield_slack(states[:, :2], obs.robot_goals, reached, obs.radius)
            if cfg.on_goal == "yield"
            else None,
            **self._crowd_allowances(obs, states, on_goal),
        )
        # Nothing to optimise when every robot is pinned (on_goal "brake": all have arrived) or stands on
        # its goal now. "Has arrived once" is not enough: under the simultaneous success rule a robot pushed
        # off its goal after the last one arrived must get back; braking everyone froze it there.
        if (reached if cfg.on_goal == "brake" else on_goal).all():
            plan = braking(states, cfg.horizon, cfg.dt, cfg.a_max)
            self.memory.commit(plan, solved=False, kind="brake")
            return ControlOutput(
                accelerations=plan[:, 0],
                solve_time_s=time.perf_counter() - t0,
                plan=rollout_numpy(states, plan, cfg.dt)[0],
            )
        solver = self.solver(n_robots, n_humans)
        history, mask = predictor_history(obs, self.model.obs_len)
        humans = np.arange(n_robots, n_robots + n_humans)
        start = self.memory.start(data)
        if isinstance(solver, CoupledCMPC):
            context = self.model.encode(history, mask, humans)
        else:
            predict = self._predict_fn(history, mask, humans)
        self._predictor_error = None
        try:  # the solve alone
            if isinstance(solver, CoupledCMPC):
                result = solver.solve(data, context, start)
            else:
                result = solver.solve(data, predict, start)
        except (RuntimeError, SystemError) as exc:  # CasADi's errors: a failed call; a wrapped Ctrl-C
            if exc is self._predictor_error:
                raise
            interrupt = interrupt_behind(exc)
            if interrupt is not None:  # Ctrl-C during the solve: stop, never record it as a solver failure
                raise interrupt from None
            return self._exception_output(exc, start, data, t0)
        return self._output(result, start.kind, data, t0)

    def _flocking(self, states: np.ndarray, goals: np.ndarray, on_goal: np.ndarray) -> np.ndarray | None:
        """StepData's ``flocking``: every robot but the stalled ones (mpc/stall.py); None without release."""
        return None if self.stall is None else ~self.stall.update(states[:, :2], goals, on_goal)

    def _crowd_allowances(self, obs: Observation, states: np.ndarray, on_goal: np.ndarray) -> dict[str, Any]:
        """StepData's per-class ``human_margins`` and guidance ``targets`` (pipelines.loop.mpc_step)."""
        return crowd_allowances(self.cfg, self.class_margins, obs, states, on_goal)

    def _exception_output(self, exc: Exception, start: Start, data: StepData, t0: float) -> ControlOutput:
        """A solve that raised falls back to its start, as any failed solve, and says what was raised."""
        self.solve_exceptions += 1
        self.memory.commit(start.accels, solved=False, kind=start.kind)
        return raised_output(exc, start.accels, start.kind, data, t0, self.cfg.dt, self.solve_exceptions)

    def _output(self, result: IBRResult, start_kind: str, data: StepData, t0: float) -> ControlOutput:
        if result.solved:
            self.memory.commit(result.accels, solved=True, lam_x=result.lam_x, lam_g=result.lam_g)
        else:  # unsolved: the plan is the start (Start.accels)
            self.memory.commit(result.accels, solved=False, kind=start_kind)
        fallback = None if result.solved else start_kind
        return solve_output(result, fallback, data, t0, self.cfg.dt, self.spec.record_iterations)
