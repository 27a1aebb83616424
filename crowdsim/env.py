"""The crowd world the robots navigate: a gymnasium-style environment, CrowdNav-equivalent for several robots.

One step (``tau = dt = 0.4`` s), everything simultaneous:

1. Every human computes its ORCA velocity (``crowdsim.orca``) from the *current* positions and velocities
   of the other agents. With ``robots_visible`` (the default, as in the paper's fork) the robots are among
   them, treated as ordinary reciprocal agents; otherwise the humans' ORCA does not see the robots at all
   (CrowdNav's own default). This equals one RVO2 ``doStep`` and CrowdNav's per-human ``ORCA.predict``
   (which builds a fresh RVO2 simulator holding every other visible agent with its current velocity).
   Preferred velocity: ``v_pref`` towards the goal, the raw goal offset within 1 m, zero once strictly
   within ``radius`` of the goal (the human stops).
2. Robots are double integrators, Eq. (2): ``s' = s + tau v + tau^2/2 a``, ``v' = v + tau a``, with the
   bounds of Eq. (6) enforced by clipping the acceleration, per component, to
   ``[max(-a_max, (-v_max - v) / tau), min(a_max, (v_max - v) / tau)]``: within the acceleration bound and
   such that the new velocity stays within ``[-v_max, v_max]``. (That interval is never empty because the
   velocity starts at zero and so always lies within the bound.)
3. Humans move with their new velocity: ``p' = p + tau v'`` (RVO2's ``Agent::update``).

RVO2 radius: CrowdNav gives RVO2 every agent's radius plus 0.01 m "for safety"
(``EnvConfig.orca_radius_margin``); this is kept, so ORCA agents aim to stay 0.62 m apart while contact
(the metric) is counted below 0.6 m.

A robot has reached its goal once it is strictly within ``radius`` of it (``Observation.robot_reached``
keeps "has reached it at some point", whatever the success rule). The episode ends in success under
``success_rule``: "simultaneous" (paper) when every robot is within its radius of its goal at the same
step, the fork's ``all(reaching_goal)``; "first_reach" (v1) when every robot has reached its goal at
least once. Otherwise it ends at the time limit, after ``max_steps`` steps (see ``EnvConfig.max_steps``).
With no robots at all (synthetic crowds) it ends when every human is within its radius of its goal, or at
the time limit.

Goals (``goal_assignment``): "fixed" (paper) gives robot ``i`` goal ``i`` for the episode; with "slots" the
goals are a formation to fill, and after every step each robot holds the goal crowdsim.slots' matching gives
it (``Observation.robot_goals``, and the trajectory's goals are those held at the end).

Replayed crowds (``EnvConfig.crowd`` "eth", "hotel", "eth_test" or "hotel_test", crowdsim.replay): the
humans are real tracks, played back row by row instead of steps 1 and 3; ``reset`` draws the window and the
pedestrians from the seed, and the ``Recording`` is given to ``CrowdEnv`` (pipelines.loop.replay_data reads
it from the BIWI data). ``Observation.human_present`` and ``Trajectory.human_present`` say which humans are
tracked at each step; the others stand where their track begins or ends, and the metrics leave them out.
A controller must be handed the tracked ones alone, as the closed loop does (pipelines.loop.sensing). The
reactive replays ("eth_reactive", ..., crowdsim.reaction) bend the tracks where ORCA has a person yield to a
robot (with ``robots_visible``; unseen robots leave the plain replay).

This module holds the simulator (``CrowdEnv``); the humans' steps 1 and 3 are crowdsim.human_motion, what
a controller sees (``Observation``) crowdsim.observation, its settings (``EnvConfig`` and the bounds it
checks) crowdsim.env_config; the last two are importable from here too, as ``CrowdEnv``'s argument and
answer: plugins and pipelines.config take them from here.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from crowdsim.env_config import EnvConfig
from crowdsim.errors import LayoutWarning, SimulationError, got
from crowdsim.human_motion import humans_next
from crowdsim.metrics import Trajectory
from crowdsim.observation import Observation
from crowdsim.replay import REPLAYED, Recording, ReplayEpisode, recorded, replay_episode
from crowdsim.scenarios import (
    Layout,
    check_sizes,
    checked_layout,
    make_layout,
    robot_goal_overlaps,
    start_overlaps,
)
from crowdsim.slots import match_slots
from crowdsim.world import PAPER_ROBOTS


def _warn_pairs(pairs: list[tuple[str, str, float]], what: str, radius: float, meaning: str) -> None:
    """A LayoutWarning, to ``reset_layout``'s caller, naming how many ``pairs`` (``crowdsim.scenarios``'
    ``(name, name, distance)``) of ``what`` are closer than ``2 radius``, what that means, and the first."""
    if pairs:
        first, second, distance = pairs[0]
        warnings.warn(
            f"layout: {len(pairs)} pair(s) of {what} closer than 2 x radius = {2 * radius:g} m{meaning}, "
            f"e.g. {first} and {second} {distance:.3g} m apart",
            LayoutWarning,
            stacklevel=3,
        )


class CrowdEnv:
    """ORCA humans and double-integrator robots (module docstring). Not thread-safe; one episode at a time."""

    def __init__(
        self,
        config: EnvConfig = EnvConfig(),  # noqa: B008 (frozen: one shared default is safe)
        recording: Recording | None = None,
    ):
        if not isinstance(config, EnvConfig):
            raise SimulationError(f"config must be an EnvConfig, got {type(config).__name__}")
        if config.crowd == "orca" and recording is not None:
            raise SimulationError(
                f"a recording replays a crowd: give it with EnvConfig(crowd=...) one of {list(REPLAYED)}, "
                "not 'orca'"
            )
        if config.crowd != "orca":
            name = recorded(config.crowd)
            if not isinstance(recording, Recording) or recording.name != name:
                raise SimulationError(
                    f"crowd {config.crowd!r} needs its Recording (named {name!r}), got "
                    f"{type(recording).__name__}; pipelines.loop.replay_data.recording reads it"
                )
            # a row a step: a 10 Hz recording walked at a quarter of the speed its velocities said
            if not math.isclose(recording.dt, config.dt, rel_tol=1e-9):
                raise SimulationError(
                    f"recording {recording.name!r} has steps of {got(recording.dt)} s, but dt is "
                    f"{got(config.dt)} s: a replay plays one recorded step a simulation step"
                )
        self.config = config
        self.recording = recording
        self._started = False
        self._replay: ReplayEpisode | None = None

    # ---- episode control ---------------------------------------------------------------------------------

    def reset(self, seed: int, scenario: str, n_humans: int, n_robots: int = PAPER_ROBOTS) -> Observation:
        if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
            raise SimulationError(f"seed must be an int >= 0, got {seed!r}")
        cfg = self.config
        if self.recording is not None:
            check_sizes(scenario, n_humans, n_robots)
            episode = replay_episode(
                self.recording,
                scenario,
                int(n_humans),
                int(n_robots),
                cfg.max_steps,
                np.random.default_rng(seed),
                radius=cfg.radius,
                past=cfg.history_len - 1,
                formation=cfg.formation,
                spacing=cfg.robot_spacing,
                crowd=cfg.crowd,
            )
            return self._start_replay(episode)
        layout = make_layout(
            scenario,
            n_humans,
            n_robots,
            np.random.default_rng(seed),
            radius=cfg.radius,
            v_pref=cfg.v_pref,
            crossing=cfg.crossing,
            spawn_separation=cfg.spawn_separation,
            formation=cfg.formation,
            spacing=cfg.robot_spacing,
        )
        return self._start(layout)

    def reset_layout(self, layout: Layout) -> Observation:
        """Start an episode from given starts and goals (everyone at rest), e.g. a hand-built test scene.

        SimulationError names the field and row of a wrong shape or a coordinate not finite or beyond
        ``crowdsim.world.MOST_COORDINATE``. Starts closer
        than ``2 radius`` (agents in contact from the first step) only warn (``LayoutWarning``): tests start
        agents in contact on purpose, and the paper profile's perpendicular sampler keeps overlapping human
        starts, as the authors' fork does (crowdsim.scenarios); ``reset`` runs its layouts without a warning.
        Robot goals closer than ``2 radius`` warn too: robots standing on both would overlap.
        """
        if self.recording is not None:
            raise SimulationError(  # a layout's humans walk by ORCA; a replayed crowd's walk their tracks
                f"reset_layout places ORCA humans; crowd {self.config.crowd!r} is replayed: use "
                "reset(seed, scenario, n_humans, n_robots)"
            )
        layout = checked_layout(layout)
        radius = self.config.radius
        _warn_pairs(
            start_overlaps(layout, radius), "agents start", radius, ", in contact from the first step"
        )
        # The simulator has no robot-robot contact and the metrics count robot-human contact only: robots
        # driven onto one goal "succeeded" inside each other, and an MPC keeping d_min timed out unexplained.
        _warn_pairs(
            robot_goal_overlaps(layout, radius), "robot goals", radius, ": robots on both goals would overlap"
        )
        return self._start(layout)

    def _start(self, layout: Layout) -> Observation:
        self._rp = np.array(layout.robot_starts, dtype=float)
        self._rv = np.zeros_like(self._rp)
        self._ra = np.zeros_like(self._rp)
        self._rg = np.array(layout.robot_goals, dtype=float)
        self._hp = np.array(layout.human_starts, dtype=float)
        self._hv = np.zeros_like(self._hp)
        self._hg = np.array(layout.human_goals, dtype=float)
        self._step = 0
        self._done = False
        self._reach_step = np.full(len(self._rp), -1)
        self._mark_reached()
        self._rp_log, self._rv_log = [self._rp], [self._rv]
        self._hp_log, self._hv_log = [self._hp], [self._hv]
        self._ra_log: list[np.ndarray] = []
        self._started = True
        self._replay = None
        return self._observation()

    def _start_replay(self, episode: ReplayEpisode) -> Observation:
        now = episode.past
        self._start(Layout(episode.robot_starts, episode.robot_goals, episode.positions[now], episode.goals))
        self._replay = episode
        self._hv = episode.velocities[now]
        self._hv_log = [self._hv]
        return self._observation()

    def step(self, robot_accelerations: np.ndarray) -> tuple[Observation, bool, dict[str, Any]]:
        """Advance one ``dt``. Returns ``(observation, done, info)``.

        info: ``accelerations`` (M, 2) applied after clipping, ``clipped`` (M,) bool, ``orca_lp3`` number of
        humans whose 2-D linear program was infeasible this step, ``success`` and ``timeout`` (when done).
        """
        if not self._started:
            raise SimulationError("step() called before reset()")
        if self._done:
            raise SimulationError("step() called after the episode ended; call reset()")
        cfg = self.config
        m = len(self._rp)
        given = np.asarray(robot_accelerations)
        if given.dtype.kind not in "iuf":  # strings were read as numbers, booleans as 0/1, complex cut
            raise SimulationError(
                f"robot_accelerations must be a ({m}, 2) array of real numbers, got one of {given.dtype}"
            )
        a = given.astype(float)
        if a.shape != (m, 2) or not np.isfinite(a).all():
            raise SimulationError(
                f"robot_accelerations must be a finite ({m}, 2) array, got shape {a.shape} "
                f"with {int((~np.isfinite(a)).sum())} non-finite entries"
            )

        robots, humans = (self._rp, self._rv), (self._hp, self._hv, self._hg)
        hp_new, hv_new, lp3 = humans_next(cfg, self._replay, self._step, robots, humans)

        # Robots: clip the acceleration so that |a| <= a_max and |v + dt a| <= v_max, per component.
        lo = np.maximum(-cfg.a_max, (-cfg.v_max - self._rv) / cfg.dt)
        hi = np.minimum(cfg.a_max, (cfg.v_max - self._rv) / cfg.dt)
        a_applied = np.clip(a, lo, hi)
        rv_new = np.clip(self._rv + cfg.dt * a_applied, -cfg.v_max, cfg.v_max)  # clip only absorbs rounding
        self._rp = self._rp + cfg.dt * self._rv + 0.5 * cfg.dt**2 * a_applied
        self._rv = rv_new
        self._ra = a_applied
        self._hp, self._hv = hp_new, hv_new
        self._step += 1
        if cfg.goal_assignment == "slots":
            self._match_slots()
        self._mark_reached()

        self._rp_log.append(self._rp)
        self._rv_log.append(self._rv)
        self._hp_log.append(self._hp)
        self._hv_log.append(self._hv)
        self._ra_log.append(a_applied)

        if m > 0 and cfg.success_rule == "first_reach":
            all_there = bool((self._reach_step >= 0).all())
        elif m > 0:
            all_there = bool((np.linalg.norm(self._rp - self._rg, axis=1) < cfg.radius).all())
        else:
            all_there = bool((np.linalg.norm(self._hp - self._hg, axis=1) < cfg.radius).all())
        timeout = self._step >= cfg.max_steps and not all_there
        self._done = all_there or timeout
        info: dict[str, Any] = {
            "accelerations": a_applied.copy(),  # the trajectory keeps a_applied: the caller's to change
            "clipped": np.any(a_applied != a, axis=1),
            "orca_lp3": int(lp3.sum()),
        }
        if self._done:
            info["success"] = all_there
            info["timeout"] = timeout
        return self._observation(), self._done, info

    def trajectory(self) -> Trajectory:
        """Everything recorded since the last reset."""
        if not self._started:
            raise SimulationError("trajectory() called before reset()")
        m = len(self._rg)
        return Trajectory(
            robot_positions=np.stack(self._rp_log),
            robot_velocities=np.stack(self._rv_log),
            human_positions=np.stack(self._hp_log),
            human_velocities=np.stack(self._hv_log),
            robot_goals=self._rg.copy(),
            human_goals=self._hg.copy(),
            robot_accelerations=np.stack(self._ra_log) if self._ra_log else np.zeros((0, m, 2)),
            dt=self.config.dt,
            radius=self.config.radius,
            success_rule=self.config.success_rule,
            human_present=self._replay_rows(),
        )

    # ---- internals ---------------------------------------------------------------------------------------

    def _match_slots(self) -> None:
        """Robots take crowdsim.slots' matching of goals; a robot whose goal changed has not reached it."""
        order = match_slots(self._rp, self._rg)
        moved = order != np.arange(len(order))
        if moved.any():
            self._rg = self._rg[order]
            self._reach_step[moved] = -1

    def _mark_reached(self) -> None:
        inside = np.linalg.norm(self._rp - self._rg, axis=1) < self.config.radius
        self._reach_step = np.where((self._reach_step < 0) & inside, self._step, self._reach_step)

    def _observation(self) -> Observation:
        rows = self._positions_history()
        return Observation(
            time=self._step * self.config.dt,
            step=self._step,
            robot_positions=self._rp.copy(),
            robot_velocities=self._rv.copy(),
            robot_goals=self._rg.copy(),
            robot_last_actions=self._ra.copy(),
            robot_reached=self._reach_step >= 0,
            human_positions=self._hp.copy(),
            human_velocities=self._hv.copy(),
            human_goals=self._hg.copy(),
            history=rows,
            radius=self.config.radius,
            dt=self.config.dt,
            **self._replay_now(),
        )

    def _replay_rows(self) -> np.ndarray | None:
        """(T+1, N) a replayed crowd's presence at each step so far; None for ORCA's."""
        if self._replay is None:
            return None
        return self._replay.present[self._replay.past : self._replay.past + self._step + 1].copy()

    def _replay_now(self) -> dict[str, np.ndarray]:
        """A replayed crowd's presence and track lengths now, as Observation's fields (none for ORCA's)."""
        if self._replay is None:
            return {}
        row = self._replay.past + self._step
        return {
            "human_present": self._replay.present[row].copy(),
            "human_observed": self._replay.observed[row].copy(),
        }

    def _positions_history(self) -> np.ndarray:
        length = self.config.history_len
        if self._replay is not None:  # the humans' rows before the episode are the recording's
            robots = self._rp_log[-length:]
            robots = [robots[0]] * (length - len(robots)) + robots
            humans = (list(self._replay.positions[self._step : self._replay.past]) + self._hp_log)[-length:]
            return np.stack([np.concatenate([r, h]) for r, h in zip(robots, humans, strict=True)])
        recent = list(zip(self._rp_log[-length:], self._hp_log[-length:], strict=True))
        # At the start of an episode the missing past is the initial position repeated (standing still).
        recent = [recent[0]] * (length - len(recent)) + recent
        return np.stack([np.concatenate([r, h]) for r, h in recent])
