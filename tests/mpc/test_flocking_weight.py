"""Eq. 15's weight per pair (``MPCConfig.flocking_weight``): the paper's w_floc on every pair, or w_floc
scaled so that each robot's flocking weighs what it weighs in the paper's team of 3. Hand-computed weights,
and the joint and local NLPs reading them."""

import dataclasses

import numpy as np
import pytest

from mpc.config import MPCConfig
from mpc.errors import MPCConfigError
from mpc.local_params import LocalParams
from mpc.nlp import JointNLP
from tests.mpc.test_dmpc_start import at_rest

PER_ROBOT = MPCConfig(flocking_weight="per_robot")


def test_the_paper_weight_is_the_default_and_bad_values_are_named():
    assert MPCConfig().flocking_weight == "per_pair"
    with pytest.raises(MPCConfigError, match="flocking_weight") as info:
        MPCConfig(flocking_weight="per_team")
    assert "'per_team'" in str(info.value)


def test_weights_by_hand():
    """w_floc = 10. Per pair: 10 at any M. Per robot, 10 * 2 / (M - 1): 20 for two robots (one teammate
    carries both of a paper robot's terms), 10 for three (the paper exactly), 5 for five, 20 / 11 for 12."""
    assert [MPCConfig().pair_floc_weight(m) for m in (2, 3, 12)] == [10.0, 10.0, 10.0]
    assert [PER_ROBOT.pair_floc_weight(m) for m in (1, 2, 3, 5)] == [10.0, 20.0, 10.0, 5.0]
    assert PER_ROBOT.pair_floc_weight(12) == pytest.approx(20.0 / 11.0, rel=1e-15)
    assert PER_ROBOT.replace(w_floc=0.0).pair_floc_weight(12) == 0.0  # Table III's "NF" stays NF


def five_robots():
    """Five robots 1.5 m apart in a row (flocking terms away from d_flock = 1.2 m), robot 4 arrived."""
    positions = np.column_stack([1.5 * np.arange(5.0), np.zeros(5)])
    data = at_rest(positions, positions + [0.0, 10.0])
    return dataclasses.replace(data, arrived=np.array([False, False, False, False, True]))


def test_the_joint_nlp_weighs_every_flocking_pair_by_half_at_five_robots():
    """F with per-robot weights at M = 5 is F with w_floc = 10 * 2 / 4 = 5 on every pair, and differs from the
    paper's F (the plan stretches the row, so the flocking terms are not zero)."""
    data = five_robots()
    plan = np.zeros((5, 4, 2))
    plan[:, :, 0] = np.linspace(-1.0, 1.0, 5)[:, None]
    no_humans = np.zeros((4, 0, 2))
    potentials = [
        JointNLP(cfg, 5, 0).potential(plan, data, no_humans)
        for cfg in (PER_ROBOT, MPCConfig(w_floc=5.0), MPCConfig())
    ]
    assert potentials[0] == pytest.approx(potentials[1], rel=1e-12)
    assert potentials[2] - potentials[0] > 1.0


def test_the_local_parameters_carry_the_same_weights():
    """Robot 0's four pairs: 5 with robots 1-3, 0 with robot 4 (arrived: no flocking with it)."""
    head = LocalParams.build(five_robots(), PER_ROBOT, 0).head
    np.testing.assert_array_equal(head[0, -4:], [5.0, 5.0, 5.0, 0.0])
    paper = LocalParams.build(five_robots(), MPCConfig(), 0).head
    np.testing.assert_array_equal(paper[0, -4:], [10.0, 10.0, 10.0, 0.0])
