"""``crowdmpc/CrowdNav-v0``: the crowd simulator (``crowdsim.env.CrowdEnv``) as a gymnasium environment.

``import crowdsim`` registers it; then ``gymnasium.make("crowdmpc/CrowdNav-v0", n_humans=7)`` (constructor
keyword arguments below). The dynamics, the humans and the episode end are ``CrowdEnv``'s, unchanged: an
episode of this environment with seed ``s`` is the episode ``crowdmpc simulate`` runs with seed ``s``.

Replayed crowds: ``config=EnvConfig(crowd="eth_test")`` (any of ``crowdsim.replay.CROWDS`` but "orca") with
``recording=`` the ``Recording`` it plays (``pipelines.loop.replay_data.recording("eth_test")`` reads it from
the BIWI data). The humans are then real people (crowdsim.replay; the "_reactive" crowds yield to the robots,
crowdsim.reaction) and ``n_humans`` counts those who come by during an episode: a human's row is present
(1.0) only while that person is tracked, and all zeros otherwise, as padding; the reward and the info's
robot-human figures leave untracked people out, as the episode's metrics do (``info["observation"]`` still
holds everyone, with ``human_present``). The human rows' bounds are the recording's
(``crowdsim.gym_observation.human_limits``); ``options["layout"]`` is refused (a layout's humans are ORCA's).

Observation: ``Box`` of shape ``(max_robots + max_humans, 7)``, float64, one row per agent, robots first
(rows ``0..max_robots-1``), then humans. Columns (``COLUMNS``; named slices ``POSITION``, ``VELOCITY``,
``GOAL`` and the index ``PRESENT``):

    x, y [m]  vx, vy [m/s]  goal_x, goal_y [m]  present (1.0 or 0.0)

A human's goal columns are 0: as in CrowdNav, a human's observable state is its position and velocity.
Rows past the episode's ``n_robots`` robots, respectively ``n_humans`` humans, are all zeros (present 0):
the spaces are fixed at construction for ``max_robots`` and ``max_humans``, and ``reset(options=...)``
may run smaller episodes (``scenario``, ``n_humans``, ``n_robots``) or a hand-built ``Layout``. Bounds:
velocities within ``±max(v_max, v_pref)`` (robots per component, humans' ORCA speed); positions and goals
within ``±position_limit = scene_limit + max(v_max, v_pref) T``, where ``scene_limit = max(2 L, L + v_pref /
2)``, ``L = max(circle radius, square width) x geometry_scale(max_humans)``, bounds every start and goal (the
samplers' noise of up to ``v_pref / 2`` per coordinate is not scaled; 20 m, so 60 m with the paper's
defaults) and ``T = time_limit`` (no step ends after it: ``EnvConfig.max_steps``). Values are clipped into
the box, which absorbs rounding only.

Action: ``Box(-a_max, a_max, (max_robots, 2))``, float64: each robot's acceleration [m/s^2], the native
action. ``CrowdEnv`` clips it per component to the acceleration and velocity bounds of Eq. (6); rows past
``n_robots`` are ignored. For velocity commands (CrowdNav's holonomic ``ActionXY``) wrap the environment in
``crowdsim.gym_wrappers.VelocityControl``.

Reward: one team reward per step, the rule of the paper authors' CrowdNav fork (``crowd_sim.py`` ``step``,
values from ``env_m.config [reward]``, ``RewardConfig``). With ``d_i`` the closest distance between robot
``i``'s boundary and any human's during the step (the relative motion taken as a straight segment, as
CrowdNav's ``point_to_segment_dist``), and ``d = min_i d_i``, the first rule that applies gives it:

1. some robot touches a human (``d < 0``): ``collision = -0.25``. By default the episode goes on, as in the
   fork (``done = False`` after a collision); if the robots also succeed on this step, which ends the
   episode, the step pays ``collision + success = +0.75``: the fork pays the penalty for the contact and
   the success reward on the step that ends an episode in success (the next one, there), so every episode
   ending in success is paid it, here as there. With ``end_on_collision=True`` the contact ends the
   episode, as upstream CrowdNav does, and comes first: ``-0.25`` only, the success not paid (upstream's
   ``Collision``: ``info["success"]`` and the episode metrics' ``success`` are False);
2. the robots succeed (the success rule of ``EnvConfig``; ``terminated``): ``success = +1``;
3. ``d < discomfort_dist = 0.4`` m: ``(d - discomfort_dist) * discomfort_factor * dt``, factor 0.5 /s;
4. otherwise 0.

The step that reaches the time limit (``truncated``) is paid by the same rules: the fork's ``Timeout`` (0,
``done``) comes on a further call, the first to start at ``time_limit - 1`` s or later, whose motion its
episode never records; the calls before it are the ``max_steps`` steps this environment runs.

``info["robot_rewards"]`` gives each robot the same rules applied to its own ``d_i`` (success is the
team's), for multi-agent learners.

Info: ``"observation"`` is the native ``Observation`` (a ``ComparableObservation``): what the MPC
controllers and baselines act on, with the positions history the predictors read. ``reset`` adds ``seed``
(the seed the episode's layout was drawn with; None for ``options["layout"]``, which no seed generated),
``scenario``, ``n_humans`` and ``n_robots``. ``step`` adds ``n_robots``, ``CrowdEnv``'s ``accelerations``
(applied after clipping) ``(max_robots, 2)``, ``clipped`` ``(max_robots,)`` and ``orca_lp3``; the new
state's metrics as ``crowdsim.metrics`` counts them per state: ``min_distance`` (robot-human centre
distance, m), ``collision`` (below 0.8 m), ``contact`` (below the sum of the radii), ``discomfort``
(projected paths intersect); the step's, with the relative motion a straight segment, as the reward
takes it: ``min_distance_between_steps`` (m), ``collision_between_steps`` and ``contact_between_steps``
(``d < 0``: what costs the collision penalty and, with ``end_on_collision``, ends the episode);
two robots touching (not in the paper, nor in the reward): ``min_distance_robots`` (m, inf with one robot)
and ``robot_contact`` at the new state, ``min_distance_robots_between_steps`` and
``robot_contact_between_steps`` over the step; ``surface_distance`` ``(max_robots,)`` (the ``d_i``
above), ``robot_rewards`` ``(max_robots,)``, ``reached`` ``(max_robots,)``, ``success`` and ``timeout``.
The last step adds ``episode_metrics``, the ``EpisodeMetrics`` of the whole episode (what ``crowdmpc
simulate`` reports; an episode that an outer ``TimeLimit`` ended has them from
``env.unwrapped.episode_metrics()``, since the environment cannot know that step is the last); an episode that
a contact ended has ``contact_between_steps`` True there (and the metrics' ``timeout`` True: it did not
succeed; the step's ``info["timeout"]`` is the time limit alone, False there), while its step-sampled
``contact`` may be False.

Per-robot info arrays have ``max_robots`` rows, as the action and the observation, so that
``gymnasium.vector`` can stack environments whose episodes have different ``n_robots``: rows past
``n_robots`` are padding, filled with 0.0 (``accelerations``, ``robot_rewards``), False (``clipped``,
``reached``) and inf (``surface_distance``: no robot, no human near).

``render()`` (``render_mode="rgb_array"``) draws the trajectories so far and the agents now
(``crowdsim.plotting``) into a ``(480, 640, 3)`` uint8 array.

The observation's array and bounds and ``ComparableObservation`` are built in crowdsim.gym_observation, the
reward and the step's distances in crowdsim.gym_reward; this module exports their names. A step's reward, end
and info are put together in crowdsim.gym_step; ``reset``'s options are checked in crowdsim.gym_options.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any, Final

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from crowdsim import ENV_ID
from crowdsim.env import CrowdEnv, Observation
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError, counted
from crowdsim.gym_observation import (
    COLUMNS,
    GOAL,
    POSITION,
    PRESENT,
    VELOCITY,
    ComparableObservation,
    observation_array,
    observation_bounds,
)
from crowdsim.gym_options import count as _count
from crowdsim.gym_options import episode_options, numbers, warn_formation
from crowdsim.gym_reward import (
    RewardConfig,
    as_reward_config,
    step_closest,
    surface_distances,
)
from crowdsim.gym_step import step_outcome
from crowdsim.metrics import EpisodeMetrics, episode_metrics
from crowdsim.outcome import ended_text
from crowdsim.profiles import as_env_config
from crowdsim.replay import Recording
from crowdsim.scenarios import MAX_HUMANS, MAX_ROBOTS, check_sizes
from crowdsim.world import DT, PAPER_ROBOTS

__all__ = [
    "COLUMNS",
    "ENV_ID",
    "GOAL",
    "POSITION",
    "PRESENT",
    "VELOCITY",
    "ComparableObservation",
    "CrowdNavEnv",
    "RewardConfig",
    "step_closest",
    "surface_distances",
]

RENDER_SIZE: Final[tuple[float, float]] = (8.0, 6.0)  # inches at RENDER_DPI: 640 x 480 pixels
RENDER_DPI: Final[int] = 80


class CrowdNavEnv(gym.Env[np.ndarray, np.ndarray]):
    """ORCA's or a replayed crowd, double-integrator robots, CrowdNav's reward (module docstring).

    :param scenario: "circle" or "perpendicular", the default of ``reset``.
    :param n_humans: humans per episode (default of ``reset``).
    :param n_robots: robots per episode (default of ``reset``), at least 1.
    :param max_humans: rows of humans in the observation (default ``n_humans``).
    :param max_robots: rows of robots in the observation and the action (default ``n_robots``).
    :param config: the simulator's settings (default ``EnvConfig()``, the paper's profile;
        ``crowdsim.profiles.make_env_config`` names the others), or plain data: a mapping of its fields with
        ``profile`` and ``visibility`` (``crowdsim.profiles.as_env_config``).
    :param reward: the reward's numbers, a ``RewardConfig`` or a mapping of its fields.
    :param end_on_collision: end the episode (``terminated``) at a robot-human contact during a step
        (``info["contact_between_steps"]``), as upstream CrowdNav; its success is then not paid.
    :param render_mode: None or "rgb_array".
    :param recording: the ``Recording`` a replayed ``config.crowd`` plays (None for ORCA's crowd).
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 1.0 / DT}  # 1 / dt by default

    def __init__(
        self,
        *,
        scenario: str = "circle",
        n_humans: int = 5,
        n_robots: int = PAPER_ROBOTS,
        max_humans: int | None = None,
        max_robots: int | None = None,
        config: EnvConfig | Mapping[str, Any] | None = None,
        reward: RewardConfig | Mapping[str, Any] | None = None,
        end_on_collision: bool = False,
        render_mode: str | None = None,
        recording: Recording | None = None,
    ):
        config = as_env_config(config)  # a mapping too: plain data, as a YAML file of gym.make's keywords
        self._sim = CrowdEnv(config, recording)  # refuses a recording that is not the crowd's
        reward = as_reward_config(reward)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise SimulationError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if not isinstance(end_on_collision, bool | np.bool_):  # numpy's from a sweep's values, as EnvConfig's
            raise SimulationError(f"end_on_collision must be a bool, got {end_on_collision!r}")
        end_on_collision = bool(end_on_collision)
        check_sizes(scenario, n_humans, n_robots)
        self.n_robots = _count(n_robots, "n_robots", 1, MAX_ROBOTS)
        warn_formation(config, self.n_robots)
        self.n_humans = int(n_humans)
        self.max_robots = _count(
            n_robots if max_robots is None else max_robots, "max_robots", n_robots, MAX_ROBOTS
        )
        self.max_humans = _count(
            n_humans if max_humans is None else max_humans, "max_humans", n_humans, MAX_HUMANS
        )
        self.scenario = scenario
        self.config = config
        self.reward_config = reward
        self.end_on_collision = end_on_collision
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": 1.0 / config.dt}

        self.scene_limit, self.position_limit, self._low, self._high = observation_bounds(
            config, self.max_robots, self.max_humans, recording
        )
        self.observation_space = spaces.Box(self._low, self._high, dtype=np.float64)
        self.action_space = spaces.Box(-config.a_max, config.a_max, (self.max_robots, 2), dtype=np.float64)

        self._obs: Observation | None = None
        self._episode: dict[str, Any] = {}
        self._done = self._contact_ended = False
        self._figure: Any = None

    # ---- gymnasium API -----------------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """A new episode: layout seed ``seed``, or the next draw of the environment's generator when None.

        ``options`` may set ``scenario``, ``n_humans`` (at most ``max_humans``) and ``n_robots`` (1 to
        ``max_robots``) for this episode; the constructor's values are the defaults. Or ``layout``, a
        ``crowdsim.scenarios.Layout`` of starts and goals to start from instead (a hand-built scene; its
        scenario reads "layout", its seed None: no seed draws it), alone. Every reset takes one draw from
        the generator when ``seed`` is None, a layout's too, so that the episodes after it are the same
        whichever layouts came between. A reset that raises changes nothing of the generator, and leaves no
        episode to step on (the last one carried on)."""
        generator, seeded = self._np_random, self._np_random_seed
        state = None if generator is None else generator.bit_generator.state
        self._obs = None
        try:
            return self._reset(seed, options)
        except BaseException:
            self._np_random, self._np_random_seed = generator, seeded
            if generator is not None and state is not None:
                generator.bit_generator.state = state
            raise

    def _reset(self, seed: int | None, options: dict[str, Any] | None) -> tuple[np.ndarray, dict[str, Any]]:
        if isinstance(seed, bool):  # gymnasium seeds with it as an int (True ran seed 1); CrowdEnv refuses it
            raise SimulationError(f"seed must be an int >= 0 or None, got {seed!r}")
        super().reset(seed=seed)
        defaults = {"scenario": self.scenario, "n_humans": self.n_humans, "n_robots": self.n_robots}
        chosen = episode_options(options, defaults, self.scene_limit, self.max_humans, self.max_robots)
        if "layout" in chosen and self._sim.recording is not None:  # before the draw: nothing changes
            raise SimulationError(
                f"options['layout'] places ORCA humans; crowd {self.config.crowd!r} is replayed (its "
                "episodes come from the seed, scenario, n_humans and n_robots)"
            )
        drawn = int(self.np_random.integers(0, 2**31 - 1)) if seed is None else int(seed)
        episode_seed: int | None = drawn
        if "layout" in chosen:
            obs = self._sim.reset_layout(chosen.pop("layout"))
            episode_seed = None
        else:
            obs = self._sim.reset(drawn, chosen["scenario"], chosen["n_humans"], chosen["n_robots"])
        self._obs = obs
        self._episode = {"seed": episode_seed, **chosen}
        self._done = self._contact_ended = False
        return self._array(obs), {"observation": ComparableObservation.of(obs), **self._episode}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        if self._obs is None:
            raise SimulationError("step() called before reset() (or after a reset that raised)")
        if self._done:
            raise SimulationError("step() called after the episode ended; call reset()")
        a = numbers(action, "action")
        if a.shape != (self.max_robots, 2):
            raise SimulationError(f"action must be a ({self.max_robots}, 2) array, got shape {a.shape}")
        before = self._obs
        m = before.n_robots
        if not np.isfinite(a[:m]).all():  # the simulator refused it as "robot_accelerations", not the action
            bad = int((~np.isfinite(a[:m])).sum())
            raise SimulationError(
                f"action must be finite for the episode's {counted(m, 'robot')}, got "
                f"{counted(bad, 'non-finite entry', 'non-finite entries')}"
            )
        obs, done, native = self._sim.step(a[:m])
        self._obs = obs

        reward, terminated, truncated, self._contact_ended, info = step_outcome(
            before, obs, native, self.config, self.reward_config, self.end_on_collision, self.max_robots
        )
        self._done = terminated or truncated
        if self._done:
            info["episode_metrics"] = self.episode_metrics()
        return self._array(obs), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        if self.render_mode is None:
            return None
        if self._obs is None:
            raise SimulationError("render() called before reset()")
        from crowdsim.plotting import render_frame

        traj = self._sim.trajectory()
        seed = self._episode["seed"]
        title = f"{self._episode['scenario']}{'' if seed is None else f', seed {seed}'}: "
        # As the legend's snapshot time: all its digits (":.1f" titled a 0.25 s step "t = 0.2 s").
        title += f"t = {round(traj.n_steps * self.config.dt, 6):g} s"
        if self._done:
            title += f"\n{ended_text(self.episode_metrics(), self._contact_ended, self.config)}"
        return render_frame(traj, title, size=RENDER_SIZE, dpi=RENDER_DPI)

    def close(self) -> None:
        """Nothing is held between calls (each frame is drawn on a figure of its own)."""

    # ---- the native simulator and the episode -------------------------------------------------------------

    @property
    def observation(self) -> Observation:
        """The native observation of the current state (what ``info["observation"]`` holds): a copy, as the
        info's, since the next step's reward and distances are computed from the environment's own, which a
        policy shifting the humans relative to a robot in place had moved (a contact it never made)."""
        if self._obs is None:
            raise SimulationError("no observation before reset()")
        return ComparableObservation.of(self._obs)

    @property
    def simulator(self) -> CrowdEnv:
        """The ``CrowdEnv`` underneath: ``simulator.trajectory()`` is the episode so far."""
        return self._sim

    @property
    def episode(self) -> dict[str, Any]:
        """This episode's seed, scenario, n_humans and n_robots (empty before the first reset)."""
        return dict(self._episode)

    def episode_metrics(self) -> EpisodeMetrics:
        """The ``EpisodeMetrics`` of the episode so far, as its last step's ``info["episode_metrics"]``: for
        an episode that an outer wrapper ended (gymnasium's ``TimeLimit``, from ``max_episode_steps``), whose
        last step's info the environment could not know to be the last.

        The ``crowdsim.metrics`` metrics with the outcome this environment gave it: those read success off the
        trajectory alone, which does not show that a contact ended the episode on the step the robots reached
        their goals. Such an episode did not succeed: timeout True, no travel time."""
        if self._obs is None:
            raise SimulationError("no episode before reset()")
        metrics = episode_metrics(self._sim.trajectory())
        if self._contact_ended and metrics.success:
            return replace(metrics, success=False, timeout=True, travel_time=math.nan)
        return metrics

    # ---- internals ---------------------------------------------------------------------------------------

    def _array(self, obs: Observation) -> np.ndarray:
        return observation_array(obs, self.max_robots, self.max_humans, self._low, self._high)
