"""``dmpc_conflicts``: after DMPC's loop, two robots whose plans come within d_min of each other re-plan
together (mpc/dmpc_pairs.py). Under the paper's Jacobi update the loop can end on plans that collide, each a
best response to plans replaced meanwhile; a joint move of the pair lowers F out of it."""

import numpy as np
import pytest

from mpc.config import MPCConfig
from mpc.dmpc_pairs import conflict_groups, conflicts
from mpc.errors import MPCConfigError
from mpc.nlp import StepData
from tests.mpc.test_dmpc_convergence import row_crossing, solve


def _data(active: list[bool]) -> StepData:
    return StepData(np.zeros((3, 4)), np.zeros((3, 2)), np.zeros((3, 2)), np.array(active))


def test_conflicting_pairs_by_hand():
    """Robot 1 is 0.5 m from robot 0 at the first step, robot 2 0.7 m; robots 1 and 2 are
    sqrt(0.5^2 + 0.7^2) = 0.86 m apart at the first step and sqrt(5) m at the second, beyond d_min = 0.8."""
    planned = np.array(
        [
            [[0.0, 0.0], [0.0, 0.0]],
            [[0.5, 0.0], [1.0, 0.0]],
            [[0.0, 0.7], [0.0, 2.0]],
        ]
    )
    assert conflicts(_data([True, True, True]), planned, 0.8) == [(0, 1), (0, 2)]  # closest first
    assert conflicts(_data([True, False, True]), planned, 0.8) == [(0, 2)]  # a pinned robot cannot move
    assert conflicts(_data([True, True, True]), planned, 0.5) == []  # 0.5 is not closer than 0.5
    assert conflicts(_data([True, True, True]), planned, 0.9) == [(0, 1), (0, 2), (1, 2)]


def test_the_paper_has_no_conflict_moves_and_the_option_is_a_bool():
    assert MPCConfig().dmpc_conflicts is False
    with pytest.raises(MPCConfigError, match="dmpc_conflicts"):
        MPCConfig(dmpc_conflicts="yes")


def test_a_jacobi_cycle_ending_on_colliding_plans_is_moved_apart():
    """The standing row of 3 cycles between colliding and safe plans (tests/mpc/test_dmpc_convergence.py);
    stopped after 9 iterations its last plans put robots 0.42 m apart (F 6.5e6). The pair moves leave every
    pair more than d_min apart at a far lower F; stopped after 10, on safe plans, nothing changes."""
    data = row_crossing(3)
    plain = solve(MPCConfig(j_max=9), data)
    moved = solve(MPCConfig(j_max=9, dmpc_conflicts=True), data)
    i, j = np.triu_indices(3, k=1)
    gaps = [np.linalg.norm(r.positions[i] - r.positions[j], axis=-1).min() for r in (plain, moved)]
    assert gaps[0] < 0.5 and gaps[1] > 0.8
    assert plain.potential > 1e6 > 1e2 > moved.potential
    assert moved.potentials[:-1] == plain.potentials and moved.potentials[-1] == moved.potential
    assert moved.solves > plain.solves
    safe = solve(MPCConfig(j_max=10), data)
    again = solve(MPCConfig(j_max=10, dmpc_conflicts=True), data)
    np.testing.assert_array_equal(again.accels, safe.accels)
    assert again.solves == safe.solves


def test_no_conflict_move_starts_past_the_steps_time_limit():
    """The IBR loop stops at time_limit_s; the moves after it ran two joint solves a pair whatever the time
    (132 at most at 12 robots)."""
    data = row_crossing(3)
    late = solve(MPCConfig(j_max=9, dmpc_conflicts=True, time_limit_s=1e-6), data)
    plain = solve(MPCConfig(j_max=9, time_limit_s=1e-6), data)
    assert late.status == plain.status == "timeout" and late.solves == plain.solves
    np.testing.assert_array_equal(late.accels, plain.accels)


def test_robots_sharing_a_conflict_move_as_one_group_by_hand():
    """Robots 0, 1 and 2 in a line 0.5 and 0.6 m apart (0 and 2 1.1 m), 3 and 4 0.7 m apart, 5 m off: two
    groups, the one of the closest pair first. Four robots trading places met in the middle of their circle,
    and pair by pair each move ran into a third robot (two robots 0.33 m apart in 1 of 100 episodes)."""
    planned = np.array([[[0.0, 0.0]], [[0.5, 0.0]], [[1.1, 0.0]], [[5.0, 0.0]], [[5.7, 0.0]]])
    data = StepData(np.zeros((5, 4)), np.zeros((5, 2)), np.zeros((5, 2)), np.ones(5, dtype=bool))
    assert conflicts(data, planned, 0.8) == [(0, 1), (1, 2), (3, 4)]
    assert conflict_groups(data, planned, 0.8) == [(0, 1, 2), (3, 4)]
    assert conflict_groups(data, planned, 0.55) == [(0, 1)]
