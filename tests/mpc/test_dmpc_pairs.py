"""A stalled robot and the teammate in its way re-planning jointly (``MPCConfig.dmpc_pairs``): the equilibrium
that no single best response leaves, left by the pair; the other robots' plans untouched; nothing changes
without a stalled robot."""

import dataclasses

import numpy as np
import pytest

from mpc.config import MPCConfig
from mpc.dmpc_pairs import blocker, stalled
from mpc.errors import MPCConfigError
from tests.mpc.test_dmpc_start import at_rest, solve

CFG = MPCConfig(dmpc_update="gauss_seidel", dmpc_stop="no_improvement", j_max=3, stall_release_s=4.0)


def held(data, *robots):
    """``data`` with ``robots`` marked stalled by the stall watch (out of flocking)."""
    flocking = np.ones(data.n_robots, dtype=bool)
    flocking[list(robots)] = False
    return dataclasses.replace(data, flocking=flocking)


def test_the_option_is_off_by_default_and_needs_the_stall_watch():
    assert MPCConfig().dmpc_pairs is False
    with pytest.raises(MPCConfigError, match="stall_release_s"):
        MPCConfig(dmpc_pairs=True)
    with pytest.raises(MPCConfigError, match="dmpc_pairs"):
        MPCConfig(dmpc_pairs="yes", stall_release_s=4.0)


def test_who_is_stalled_and_who_is_in_the_way():
    """Robot 0 at the origin heads for (4, 0). Robot 3 is nearest to it but 1 m off its way; robot 2 stands
    on the way 2 m ahead (0.1 m off); robot 1 is past the target, 0.5 m from its end of the segment."""
    positions = [[0.0, 0.0], [4.5, 0.0], [2.0, 0.1], [0.0, 1.0]]
    data = at_rest(positions, [[4.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    assert stalled(data).size == 0  # no stall watch: nobody
    data = dataclasses.replace(held(data, 0, 1), arrived=np.array([False, True, False, False]))
    np.testing.assert_array_equal(stalled(data), [0])  # an arrived robot is never stalled
    assert blocker(data, 0) == 2
    pinned = dataclasses.replace(data, active=np.array([True, True, False, True]))
    assert blocker(pinned, 0) == 1  # a pinned robot cannot move aside; 0.5 m beats robot 3's 1 m
    alone = dataclasses.replace(data, active=np.array([True, False, False, False]))
    assert blocker(alone, 0) is None


def test_two_robots_swapping_places_sidestep_together():
    """Robots 1 m apart, each heading for the other's place (a 0.1 m offset breaks the symmetry). Their
    Gauss-Seidel best responses back away from each other (F = 60.6: each steps away from its own goal,
    since passing alone would run into the other's plan); solving the two together, they swerve to opposite
    sides at a_max while heading for their goals, F = 33.5."""
    data = held(at_rest([[0.0, 0.0], [1.0, 0.1]], [[1.0, 0.1], [0.0, 0.0]]), 0)
    alone = solve(CFG, data)
    paired = solve(CFG.replace(dmpc_pairs=True), data)
    assert alone.accels[0, 0, 0] < 0 < alone.accels[1, 0, 0]  # backing off
    assert paired.potential < alone.potential - 20.0
    assert paired.potentials[-1] == paired.potential and paired.solves == alone.solves + 1
    first = paired.accels[:, 0]
    assert first[0, 0] > 0.3 and first[1, 0] < -0.3  # each towards its goal
    assert first[0, 1] * first[1, 1] < 0 and np.all(np.abs(first[:, 1]) > 1.9)  # to opposite sides


def test_the_other_robots_plans_are_kept_and_no_stall_changes_nothing():
    """Three robots in a row, the outer ones swapping ends: robot 0 is stalled and moves with robot 2, which
    stands on its target (robot 1 is 0.1 m off the way); robot 1's plan is the loop's, bit for bit. Without a
    stalled robot the option is inert."""
    data = at_rest([[0.0, 0.0], [1.2, 0.1], [2.4, 0.0]], [[2.4, 0.0], [1.2, 0.1], [0.0, 0.0]])
    assert blocker(held(data, 0), 0) == 2
    alone = solve(CFG, held(data, 0))
    paired = solve(CFG.replace(dmpc_pairs=True), held(data, 0))
    assert paired.potential <= alone.potential - CFG.epsilon
    assert np.array_equal(paired.accels[1], alone.accels[1])
    assert not np.array_equal(paired.accels[0], alone.accels[0])
    assert not np.array_equal(paired.accels[2], alone.accels[2])
    free = solve(CFG.replace(dmpc_pairs=True), held(data))
    assert np.array_equal(free.accels, solve(CFG, held(data)).accels)
