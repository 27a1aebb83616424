"""crowdmpc/CrowdNav-v0 under gymnasium.vector: environments whose episodes have different n_robots (the same
max_robots) stack, their per-robot info padded to max_robots rows."""

import math

import gymnasium as gym
import numpy as np

from crowdsim.gym_env import PRESENT, CrowdNavEnv

PER_ROBOT = ("accelerations", "clipped", "surface_distance", "robot_rewards", "reached")


def _make(n_robots: int):
    return lambda: CrowdNavEnv(n_robots=n_robots, max_robots=3, n_humans=2)


def test_sync_vector_env_over_two_and_three_robots():
    envs = gym.vector.SyncVectorEnv([_make(2), _make(3)])
    obs, info = envs.reset(seed=[4, 5])
    assert obs.shape == (2, 5, 7) and info["n_robots"].tolist() == [2, 3]
    assert obs[0, :3, PRESENT].tolist() == [1, 1, 0] and obs[1, :3, PRESENT].tolist() == [1, 1, 1]
    for _ in range(3):
        obs, reward, terminated, truncated, info = envs.step(np.full((2, 3, 2), 0.5))
    assert info["n_robots"].tolist() == [2, 3] and reward.shape == (2,)
    assert info["accelerations"].shape == (2, 3, 2)
    for name in PER_ROBOT[1:]:
        assert info[name].shape == (2, 3), name
    # env 0's third row is padding: 0 acceleration and reward, not clipped nor reached, no human near
    assert info["accelerations"][0, 2].tolist() == [0.0, 0.0] and info["robot_rewards"][0, 2] == 0.0
    assert not info["clipped"][0, 2] and not info["reached"][0, 2]
    assert info["surface_distance"][0, 2] == math.inf
    # the robots of the episode: the asked 0.5 m/s^2 applied (under the bounds), finite distances
    assert info["accelerations"][0, :2].tolist() == [[0.5, 0.5]] * 2
    assert (
        np.isfinite(info["surface_distance"][0, :2]).all() and np.isfinite(info["surface_distance"][1]).all()
    )
    envs.close()


def test_one_environment_pads_its_info_rows_the_same_way():
    env = CrowdNavEnv(n_robots=1, max_robots=3, n_humans=1)
    env.reset(seed=0)
    *_, info = env.step(np.zeros((3, 2)))
    assert info["n_robots"] == 1
    assert info["surface_distance"][1:].tolist() == [math.inf, math.inf]
    assert info["reached"].dtype == bool and info["clipped"].dtype == bool
    assert info["robot_rewards"].tolist()[1:] == [0.0, 0.0]
