"""Two robots swapping places with nobody about, the multi-robot test a newcomer writes first. Measured before
the fixes (docs/extending.md, "Robots bound for separate places" and "Two robots exactly head-on"): typed
as exact coordinates, CMPC held both at a standstill 1.08 m apart and DMPC drove them through each other
(0.39 m between centres); offset by 5 cm they passed, and Eq. 15 then held them 1.42 m apart, each facing
away, until the time limit."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import crowdsim
from crowdsim.env_config import EnvConfig
from crowdsim.scenarios import Layout
from mpc.config import MPCConfig
from pipelines.errors import FlockWarning
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.gym_loop import run_gym_episode
from pipelines.loop.team_layout import warn_separate_goals

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
def test_two_robots_crossing_at_right_angles_from_the_same_distance_cross_apart(controller):
    """Mirror images across y = x: DMPC's Jacobi best responses stayed mirror images (both dodging, both
    waiting) and at 22.4 s went through each other (0.19 m between centres, 0.001 m between steps); broken
    as a tie (mpc/head_on.py), CMPC crosses in 9.2 s and DMPC in 9.6 s, never closer than 0.9 m."""
    cross = Layout([[-4.0, 0.0], [0.0, -4.0]], [[4.0, 0.0], [0.0, 4.0]], [], [])
    m = swap(ControllerSpec(controller, mpc_overrides=(("flock_range", 2.0),)), cross)
    assert m.success and m.travel_time < 10.0
    assert m.min_distance_robots_between_steps > 0.9


@pytest.mark.parametrize("controller", ["cmpc", "dmpc"])
def test_robots_bound_for_separate_places_pass_when_only_near_goals_flock(controller):
    """Eq. 15 with every pair flocking holds the robots 1.42 m apart once they have passed; flock_range 2 m
    (their goals lie 8 m apart) leaves the pair out of it, and they arrive."""
    with pytest.warns(FlockWarning, match="flock_range"):  # the reset says so (the last test)
        held = swap(ControllerSpec(controller), OFFSET)
    assert not held.success and held.timeout
    m = swap(ControllerSpec(controller, mpc_overrides=(("flock_range", 2.0),)), OFFSET)
    assert m.success and m.travel_time < 10.0
    assert m.min_distance_robots > 0.8
    exact = swap(ControllerSpec(controller, mpc_overrides=(("flock_range", 2.0),)), SWAP)
    assert exact.success and exact.min_distance_robots > 0.8


def test_a_warning_names_robots_parting_ways_while_every_pair_flocks():
    """The controller's reset says why such an episode may time out, and what to set: a range 0.5 m above
    the team's own goal distances (d_flock when there is no team: 1.7 m; the pair 2.5 m apart: 3.0 m), or
    halfway to the parting pairs' (8 m) when nearer, else no range parts them. A team keeping its shape (the
    paper's row, and a row of 12 robots 11 m wide) and a controller with flock_range or without flocking
    say nothing."""
    config = EnvConfig()
    alone = r"robots 0 and 1 are bound for goals 8\.0 m apart by separate ways.*\(\"flock_range\", 1\.70\)"
    with pytest.warns(FlockWarning, match=alone):
        warn_separate_goals(MPCConfig(), SWAP.robot_starts, SWAP.robot_goals)
    team = np.array([[-4.0, 0.0], [-4.0, 2.5], [4.0, 0.0]])  # robots 0 and 1 side by side, 2 swapping ends
    with pytest.warns(FlockWarning, match=r"robots 0 and 2 .*\(\"flock_range\", 3\.00\)"):
        warn_separate_goals(MPCConfig(), team, team[[2, 2, 0]] + [[0.0, 0.0], [0.0, 2.5], [0.0, 0.0]])
    wide = np.array([[-4.0, 0.0], [-4.0, 9.0], [4.0, 0.0]])  # the side-by-side pair's goals 9 m apart
    with pytest.warns(FlockWarning, match="no flock_range parts them from pairs whose goals lie 9.0 m apart"):
        warn_separate_goals(MPCConfig(), wide, wide[[2, 2, 0]] + [[0.0, 0.0], [0.0, 9.0], [0.0, 0.0]])
    row = np.array([[x, -5.0] for x in np.arange(12.0)])
    quiet = [
        (MPCConfig(), row, row + [0.0, 10.0]),
        (MPCConfig(flock_range=2.0), SWAP.robot_starts, SWAP.robot_goals),
        (MPCConfig(w_floc=0.0), SWAP.robot_starts, SWAP.robot_goals),
    ]
    with warnings.catch_warnings():
        warnings.simplefilter("error", FlockWarning)
        for cfg, starts, goals in quiet:
            warn_separate_goals(cfg, np.asarray(starts), np.asarray(goals))
        env = gym.make(crowdsim.ENV_ID, n_humans=3, n_robots=3, config=config)
        controller = make_controller(ControllerSpec("cmpc"), config)
        run_gym_episode(controller, env, seed=0)  # the paper's circle crossing
        controller.close()
    with pytest.warns(FlockWarning):
        swap(ControllerSpec("dmpc"), SWAP)
