"""A step of ``crowdmpc/CrowdNav-v0`` (crowdsim.gym_env) from the simulator's: its reward, whether it ended
and its info, by the rules the environment's docstring gives (the reward's numbers and distances:
crowdsim.gym_reward). Per-robot arrays are padded to ``max_robots`` rows, as the action."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from crowdsim.env import Observation
from crowdsim.env_config import EnvConfig
from crowdsim.gym_observation import ComparableObservation
from crowdsim.gym_reward import RewardConfig, robot_pair_info, state_info, step_closest, surface_distances
from crowdsim.metrics import COLLISION_DISTANCE


def step_outcome(
    before: Observation,
    obs: Observation,
    native: dict[str, Any],
    cfg: EnvConfig,
    reward_config: RewardConfig,
    end_on_collision: bool,
    max_robots: int,
) -> tuple[float, bool, bool, bool, dict[str, Any]]:
    """The step from ``before`` to ``obs`` (``native``: ``CrowdEnv.step``'s info): the team reward,
    ``terminated``, ``truncated``, whether a contact ended the episode (then no success, in the episode's
    metrics too: ``CrowdNavEnv.episode_metrics``) and the step's info (the module docstring of gym_env)."""
    closest = step_closest(before, obs)  # (M, N) m, within the step
    swept = float(closest.min()) if closest.size else math.inf
    gaps = surface_distances(closest, cfg.radius)
    contact_in_step = gaps < 0
    timeout = bool(native.get("timeout", False))
    contact_ends = end_on_collision and bool(contact_in_step.any())
    # A contact that ends the episode comes first (upstream CrowdNav's Collision): a step that also brings
    # the robots to their goals is no success, in the rewards, the info and the episode's metrics alike.
    success = bool(native.get("success", False)) and not contact_ends

    def rule(gap: float) -> float:
        return reward_config.step_reward(gap, success=success, dt=cfg.dt, contact_ends=end_on_collision)

    reward = rule(float(gaps.min()))
    robot_rewards = np.array([rule(float(g)) for g in gaps])

    terminated = success or contact_ends
    truncated = timeout and not terminated
    info: dict[str, Any] = {
        "observation": ComparableObservation.of(obs),
        **native,
        "n_robots": obs.n_robots,
        "accelerations": padded(max_robots, native["accelerations"], 0.0),
        "clipped": padded(max_robots, native["clipped"], False),
        **state_info(obs, cfg.radius),
        "min_distance_between_steps": swept,
        "collision_between_steps": swept < COLLISION_DISTANCE,
        "contact_between_steps": bool(contact_in_step.any()),
        **robot_pair_info(before, obs, cfg.radius),
        "surface_distance": padded(max_robots, gaps, math.inf),
        "robot_rewards": padded(max_robots, robot_rewards, 0.0),
        "reached": padded(max_robots, obs.robot_reached, False),
        "success": success,
        "timeout": timeout,
    }
    return reward, terminated, truncated, contact_ends, info


def padded(max_robots: int, values: np.ndarray, fill: float | bool) -> np.ndarray:
    """``values`` (one row per robot of the episode) padded to ``max_robots`` rows with ``fill``."""
    values = np.asarray(values)
    out = np.full((max_robots, *values.shape[1:]), fill, dtype=values.dtype)
    out[: len(values)] = values
    return out
