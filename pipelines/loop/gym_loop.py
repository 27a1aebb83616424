"""The closed loop through gymnasium's API: ``crowdmpc/CrowdNav-v0`` (``crowdsim.gym_env``) driven by a
``Controller`` or by any policy, with the closed loop's observers and records.

* ``make_env(config, **kwargs)`` is ``gym.make("crowdmpc/CrowdNav-v0", ...)`` with the recording a replayed
  crowd plays (``EnvConfig(crowd="eth_test")``) read from the data.
* ``run_gym_episode(controller, env, seed=...)`` is ``run_episode`` through ``env.reset`` / ``env.step``:
  the controller acts on ``info["observation"]`` and its accelerations are the action. The episode, its
  ``EpisodeResult`` and what the observers see are those of ``run_episode`` with the same seed, scenario and
  sizes (the environment's ``EpisodeMetrics`` are the ones ``crowdmpc simulate`` reports).
* ``ObserveEpisodes(env, observers)`` wraps the environment for a policy that is not a ``Controller`` (a
  CrowdNav-style velocity policy under ``crowdsim.gym_wrappers.VelocityControl``): every episode goes to the
  observers (``pipelines.logs.recording.McapEpisodeRecorder`` records it to MCAP, each episode to its own
  file, one of a seed reset to again too) and ends in an ``EpisodeResult`` in ``results`` (the last
  ``buffer_length``, 100 by default, as gymnasium's ``RecordEpisodeStatistics`` keeps its queues). The
  action it sees is the acceleration command; its "solve time" is the wall time from the environment
  handing out an observation to the next action arriving (the policy's).
"""

from __future__ import annotations

import numbers
import time
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from crowdsim import ENV_ID
from crowdsim.control import ControlOutput
from crowdsim.env import Observation
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.gym_env import CrowdNavEnv
from crowdsim.gym_wrappers import VelocityControl
from crowdsim.profiles import as_env_config
from pipelines.errors import PipelineError
from pipelines.loop.contract import (
    called,
    checked_description,
    checked_meta,
    checked_output,
    episode_meta,
    handed_out,
)
from pipelines.loop.controllers import Controller, check_built_for, check_controller
from pipelines.loop.episode import (
    EpisodeObserver,
    EpisodeResult,
    EpisodeSteps,
    behind_tracks,
    replayed_recording,
)
from pipelines.loop.interrupt import interrupts_between_steps
from pipelines.loop.run_arguments import checked_observers
from predictors.errors import short_repr


def _action_changer(env: gym.Env[Any, Any], base: CrowdNavEnv) -> str | None:
    """None when an action given to ``env`` reaches ``base`` as it is: no VelocityControl in between (with
    a_max equal to v_max its action space is the base's, so comparing spaces let it through) and the base's
    action space. Otherwise the name of the outermost wrapper that changes the actions, for the message
    (ClipAction, RescaleAction: the message named VelocityControl whatever the wrapper)."""
    layers = []
    layer = env
    while isinstance(layer, gym.Wrapper):
        layers.append(layer)
        layer = layer.env
    if env.action_space == base.action_space and not any(isinstance(w, VelocityControl) for w in layers):
        return None
    for wrapper in layers:
        if isinstance(wrapper, VelocityControl) or wrapper.action_space != wrapper.env.action_space:
            return type(wrapper).__name__
    return type(env).__name__


def make_env(
    config: EnvConfig | Mapping[str, Any] | None = None, **kwargs: Any
) -> gym.Env[np.ndarray, np.ndarray]:
    """``gym.make(crowdsim.ENV_ID, config=config, **kwargs)`` with, for a replayed ``config.crowd``, the
    ``Recording`` it plays, read from the BIWI data (``$CROWDMPC_DATA``; pipelines.loop.replay_data): the
    environment among real people in one call, ``make_env(EnvConfig(crowd="eth_test"), n_humans=10)``."""
    try:  # before reading anything: the environment says it too
        config = as_env_config(config)  # or plain data (crowdsim.profiles.as_env_config)
    except SimulationError as exc:
        raise PipelineError(f"make_env: {exc}") from None
    if "recording" in kwargs:
        raise PipelineError("make_env reads the recording of config.crowd itself; give no recording=")
    return gym.make(ENV_ID, config=config, recording=replayed_recording(config), **kwargs)


def crowdnav_env(env: gym.Env[Any, Any]) -> CrowdNavEnv:
    """The ``CrowdNavEnv`` under ``env``'s wrappers; PipelineError for another environment."""
    base = env.unwrapped
    if not isinstance(base, CrowdNavEnv):
        raise PipelineError(f"expected a crowdmpc/CrowdNav-v0 environment, got {type(base).__name__}")
    return base


def _result(
    steps: EpisodeSteps, base: CrowdNavEnv, meta: Mapping[str, Any], info: Mapping[str, Any]
) -> EpisodeResult:
    """The ``EpisodeResult`` of the episode ``base`` holds, whose last step's info is ``info``."""
    # An outer wrapper (gymnasium's TimeLimit from max_episode_steps) may end the episode before the
    # environment does, on a step whose info has no metrics: the episode's so far are then the ones.
    metrics = info.get("episode_metrics")
    metrics = base.episode_metrics() if metrics is None else metrics
    return steps.result(base.episode, meta, base.simulator.trajectory(), metrics)


def _padded(accelerations: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The action of ``checked_output``'s ``(n_robots, 2)`` accelerations: rows past them are ignored."""
    action = np.zeros(shape)
    action[: len(accelerations)] = accelerations
    return action


def run_gym_episode(
    controller: Controller,
    env: gym.Env[np.ndarray, np.ndarray],
    *,
    seed: int,
    options: dict[str, Any] | None = None,
    observers: Sequence[EpisodeObserver] = (),
    meta: Mapping[str, Any] | None = None,
) -> EpisodeResult:
    """One episode of ``controller`` in the gymnasium environment ``env`` (acceleration actions), from
    ``env.reset(seed=seed, options=options)`` to ``terminated`` or ``truncated`` (module docstring)."""
    check_controller(controller, "run_gym_episode")  # a spec given in its place, as run_episode refuses it
    base = crowdnav_env(env)
    changer = _action_changer(env, base)
    if changer is not None:
        raise PipelineError(
            f"run_gym_episode gives the environment accelerations; pass it without {changer}, which changes "
            "the actions"
        )
    check_built_for(controller, base.config, "run_gym_episode")
    observers = checked_observers(observers, base.config, "run_gym_episode")
    checked_meta(meta, "run_gym_episode")  # before the reset: a recorder inside env opened its file there
    controller = behind_tracks(controller, base.config)  # among a replayed crowd, the people tracked now
    shape = (base.max_robots, 2)
    _, info = env.reset(seed=seed, options=options)
    obs: Observation = info["observation"]
    called(controller, "reset", handed_out(obs))
    described = checked_description(controller)
    full_meta = episode_meta(
        base.episode,
        base.config,
        controller.name,
        controller.predictor,
        described,
        meta,
        "run_gym_episode",
        end_on_collision=base.end_on_collision,
    )
    steps = EpisodeSteps()
    done = False
    with interrupts_between_steps() as interrupt:  # as run_episode's loop, the observers' starts too
        for observer in observers:
            observer.on_reset(obs, full_meta)
        while not done:
            out = checked_output(controller, called(controller, "act", handed_out(obs)), obs)
            _, _, terminated, truncated, info = env.step(_padded(out.accelerations, shape))
            steps.add(out)
            for observer in observers:
                observer.on_step(obs, out, info["observation"])
            obs = info["observation"]
            done = terminated or truncated
            interrupt.check()
        result = _result(steps, base, full_meta, info)
        for observer in observers:  # their ends too, as run_episode's
            observer.on_end(result)
    return result


class ObserveEpisodes(
    gym.Wrapper[np.ndarray, np.ndarray, np.ndarray, np.ndarray], gym.utils.RecordConstructorArgs
):
    """Every episode of the wrapped ``crowdmpc/CrowdNav-v0`` (acceleration actions) to ``observers``
    (module docstring).

    :param env: the environment, possibly wrapped; wrap it in ``VelocityControl`` after this wrapper.
    :param observers: ``EpisodeObserver``\\ s, e.g. an ``McapEpisodeRecorder``, which names an episode's file
        by its seed, and one of a seed it already recorded with a count (``circle_seed000005_1.mcap``): every
        episode keeps its own file.
    :param controller: the name the records give the policy.
    :param meta: added to each episode's meta (``contract.episode_meta``); it may not set the episode's own
        fields (seed, scenario, ...: ``contract.OWN_FIELDS``).
    :param buffer_length: how many of the latest episodes ``results`` keeps (None: every one).
        Each holds its episode's trajectories, so keeping every one made a training loop's memory grow
        without end: 12 KB an episode at 7 humans, over a gigabyte per 10^5 episodes.
    """

    def __init__(
        self,
        env: gym.Env[np.ndarray, np.ndarray],
        observers: Sequence[EpisodeObserver],
        *,
        controller: str = "gym_policy",
        meta: Mapping[str, Any] | None = None,
        buffer_length: int | None = 100,
    ):
        buffer_length = _checked_length(buffer_length)
        if not isinstance(controller, str) or not controller.strip():  # a policy was recorded by its repr
            raise PipelineError(
                f"ObserveEpisodes: controller is the name the records give the policy, a non-empty str; got "
                f"{short_repr(controller)}"
            )
        # env.spec can then rebuild the wrapper (gym.make(env.spec)), and check_env accepts it
        gym.utils.RecordConstructorArgs.__init__(
            self, observers=observers, controller=controller, meta=meta, buffer_length=buffer_length
        )
        gym.Wrapper.__init__(self, env)
        self._base = crowdnav_env(env)
        changer = _action_changer(env, self._base)
        if changer is not None:  # it would record what the wrapper takes (velocities) as accelerations
            raise PipelineError(
                f"ObserveEpisodes records the environment's accelerations: wrap {changer} around it, "
                f"{changer}(ObserveEpisodes(env, ...)), not inside it"
            )
        self.observers = checked_observers(observers, self._base.config, "ObserveEpisodes")
        self.controller = controller
        self.meta = checked_meta(meta, "ObserveEpisodes")
        # a list, trimmed, not a deque(maxlen=...): users slice it (results[-10:]) and compare it with lists
        self.results: list[EpisodeResult] = []  # the latest finished, in order
        self.buffer_length = buffer_length
        self._obs: Observation | None = None
        self._meta: dict[str, Any] = {}
        self._steps = EpisodeSteps()
        self._open = False  # an episode reset and not yet ended
        self._handed_out = 0.0

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        self._end_cut_episode()
        obs, info = self.env.reset(seed=seed, options=options)
        # the observers' own copy: the policy may change info["observation"] in place (handed_out)
        self._obs = handed_out(info["observation"])
        base = self._base
        self._meta = episode_meta(
            base.episode,
            base.config,
            self.controller,
            None,
            None,
            self.meta,
            "ObserveEpisodes",
            end_on_collision=base.end_on_collision,
        )
        self._steps = EpisodeSteps()
        for observer in self.observers:
            observer.on_reset(self._obs, self._meta)
        self._open = True
        self._handed_out = time.perf_counter()
        return obs, info

    def close(self) -> None:
        try:
            self._end_cut_episode()
        finally:  # an observer that cannot take it (a recorder closed before the env) leaves the env's close
            super().close()

    def _end_cut_episode(self) -> None:
        """End, as its last step would have, an episode a wrapper outside this one cut short (gymnasium's
        ``TimeLimit`` put around it: its truncation never reaches this wrapper): before the next reset or
        the close, while the environment still holds it. Its recording had no metrics and the episode no
        result. One reset again before any step stays without either."""
        if self._open and self._steps.solve_times:
            self._end({})
        self._open = False

    def _end(self, info: Mapping[str, Any]) -> None:
        self._open = False  # first: an observer raising in on_end must not have the episode ended twice
        result = _result(self._steps, self._base, self._meta, info)
        self.results.append(result)
        if self.buffer_length is not None and len(self.results) > self.buffer_length:
            del self.results[: len(self.results) - self.buffer_length]
        for observer in self.observers:
            observer.on_end(result)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, Any, bool, bool, dict[str, Any]]:
        elapsed = time.perf_counter() - self._handed_out
        if self._obs is None:
            raise PipelineError("step() called before reset()")
        before = self._obs
        # the environment checks the action first: numpy's "could not convert string to float" named nothing
        obs, reward, terminated, truncated, info = self.env.step(action)
        out = ControlOutput(
            accelerations=np.array(action, dtype=float)[: before.n_robots], solve_time_s=elapsed
        )
        self._obs = handed_out(info["observation"])
        self._steps.add(out)
        for observer in self.observers:
            observer.on_step(before, out, self._obs)
        if terminated or truncated:
            self._end(info)
        self._handed_out = time.perf_counter()
        return obs, reward, terminated, truncated, info


def _checked_length(value: object) -> int | None:
    """``buffer_length`` as an int, or None. Any integral type counts: a count computed with numpy
    (``np.int64``) is no ``int`` and was refused."""
    if value is None:
        return None
    if isinstance(value, numbers.Integral) and not isinstance(value, bool) and int(value) >= 1:
        return int(value)
    raise PipelineError(f"buffer_length must be an int >= 1 or None, got {value!r:.60}")
