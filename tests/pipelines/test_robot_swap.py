"""Two robots swapping places with nobody about, the multi-robot test a newcomer writes first. Measured before
the fixes (docs/extending.md, "Robots that swap places"): typed as exact coordinates, CMPC held both at a
standstill 1.08 m apart and DMPC drove them through each other (0.39 m between centres); offset by 5 cm they
passed, and Eq. 15 then held them 1.42 m apart, each facing away, until the time limit."""

from __future__ import annotations

import gymnasium as gym
import pytest

import crowdsim
from crowdsim.env_config import EnvConfig
from crowdsim.scenarios import Layout
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.gym_loop import run_gym_episode

SWAP = Layout([[-4.0, 0.0], [4.0, 0.0]], [[4.0, 0.0], [-4.0, 0.0]], [], [])
OFFSET = Layout([[-4.0, 0.0], [4.0, 0.05]], [[4.0, 0.0], [-4.0, 0.05]], [], [])


def swap(spec: ControllerSpec, layout: Layout):
    config = EnvConfig()
    env = gym.make(crowdsim.ENV_ID, n_humans=0, n_robots=2, config=config)
    controller = make_controller(spec, config)
    try:
        return run_gym_episode(controller, env, seed=0, options={"layout": layout}).metrics
    finally:
        controller.close()
        env.close()


@pytest.mark.parametrize("controller", ["cmpc", "dmpc"])
def test_an_exact_swap_passes_right_shoulder_to_right_shoulder(controller):
    """Without flocking (Eq. 15 alone would hold them, the next test): the tie is broken (mpc/head_on.py), the
    robots keep d_min apart and arrive in under 10 s."""
    m = swap(ControllerSpec(controller, flocking=False), SWAP)
    assert m.success and m.travel_time < 10.0
    assert m.min_distance_robots > 0.8


@pytest.mark.parametrize("controller", ["cmpc", "dmpc"])
def test_robots_bound_for_separate_places_pass_when_only_near_goals_flock(controller):
    """Eq. 15 with every pair flocking holds the robots 1.42 m apart once they have passed; flock_range 2 m
    (their goals lie 8 m apart) leaves the pair out of it, and they arrive."""
    held = swap(ControllerSpec(controller), OFFSET)
    assert not held.success and held.timeout
    m = swap(ControllerSpec(controller, mpc_overrides=(("flock_range", 2.0),)), OFFSET)
    assert m.success and m.travel_time < 10.0
    assert m.min_distance_robots > 0.8
    exact = swap(ControllerSpec(controller, mpc_overrides=(("flock_range", 2.0),)), SWAP)
    assert exact.success and exact.min_distance_robots > 0.8
