"""A stalled robot and the teammate in its way re-planning jointly (``MPCConfig.dmpc_pairs``): the equilibrium
that no single best response leaves, left by the pair; the other robots' plans untouched; nothing changes
without a stalled robot."""

import dataclasses

import numpy as np
import pytest

from mpc.cmpc import IBRResult
from mpc.config import MPCConfig
from mpc.dmpc import DMPC
from mpc.dmpc_pairs import blocker, pair_moves, stalled
from mpc.dynamics import rollout_numpy
from mpc.errors import MPCConfigError
from mpc.solvers import Solution
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
    """Robots 1 m apart, each heading for the other's place along one line: an exact tie, which each robot
    leaves by keeping right (mpc/head_on.py). Before that tie-break their Gauss-Seidel best responses backed
    away from each other (F = 60.6: passing alone ran into the other's plan) and only the pair solved
    together swerved (F = 33.5); now the best responses swerve to their right (F = 32.07, against targets
    3 cm to the right) and the pair's joint solve, one more solve, keeps to the same sides at F = 32.03. No
    layout of two robots off such a tie that was tried (five: a parked teammate in the way, swaps 1 mm to
    10 cm off the line) left the best responses backing off; what pair moves are worth is measured at 12
    robots (docs/results.md, "DMPC pair moves")."""
    data = held(at_rest([[0.0, 0.0], [1.0, 0.1]], [[1.0, 0.1], [0.0, 0.0]]), 0)
    alone = solve(CFG, data)
    paired = solve(CFG.replace(dmpc_pairs=True), data)
    for result in (alone, paired):
        first = result.accels[:, 0]
        assert first[0, 0] > 0.2 and first[1, 0] < -0.3  # each towards its goal
        assert first[0, 1] < -1.5 and first[1, 1] > 1.5  # each to its own right: opposite sides
        assert result.potential < 32.1
    assert paired.potential <= alone.potential - CFG.epsilon
    assert paired.potentials[-1] == paired.potential and paired.solves == alone.solves + 1


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


def test_pinned_robots_are_not_stalled_and_the_way_leads_to_the_eq8_target():
    """Robot 0 at the origin, held out of flocking, with its goal at (4, 0) but a guidance target at (0, 4):
    its way is the segment to (0, 4), so robot 2 at (0, 2) is in it, not robot 1 at (2, 0). Two robots
    equally far off the way (robots 3 and 4, 0.5 m off at 1 and 3 m along it): the nearer to robot 0."""
    positions = [[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]]
    data = held(at_rest(positions, [[4.0, 0.0], [0.0, 0.0], [0.0, 0.0]]), 0, 1)
    data = dataclasses.replace(data, targets=np.array([[0.0, 4.0], [0.0, 0.0], [0.0, 0.0]]))
    assert blocker(data, 0) == 2
    pinned = dataclasses.replace(data, active=np.array([True, False, True]))
    np.testing.assert_array_equal(stalled(pinned), [0])  # robot 1 is held but pinned: it cannot move
    ties = at_rest([[0.0, 0.0], [3.0, 0.5], [1.0, 0.5]], [[4.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    assert blocker(ties, 0) == 2


class _ScriptedJoint:
    """A JointNLP stand-in for pair_moves: hands out the given solutions in turn and records each call."""

    def __init__(self, cfg, solutions):
        self.cfg, self.solutions, self.calls = cfg, list(solutions), []

    def solve_group(self, data, prediction, accels, free):
        self.calls.append((accels.copy(), np.flatnonzero(free).tolist()))
        return self.solutions.pop(0)


def _solution(accels, cost, success=True, lam=0.0):
    """A solve's outcome with 7 solver iterations and multipliers ``lam`` (``-lam`` for the constraints)."""
    status = "Solve_Succeeded" if success else "Fatrop_Failed"
    lam_x = np.full(accels.size, lam)
    return Solution(accels, cost, status, success, 7, "fatrop", lam_x, -lam_x)


def _loop_result(data, cfg):
    accels = np.zeros((data.n_robots, cfg.horizon, 2))
    lam = np.ones_like(accels)
    return IBRResult(
        accels, rollout_numpy(data.states, accels, cfg.dt)[0], np.zeros((cfg.horizon, 0, 2)), 50.0, 3, 9,
        True, True, "ok", (), (51.0, 50.0), lam, -lam, 30,
    )  # fmt: skip


def test_pair_moves_keep_a_pair_only_for_an_improvement_of_epsilon_and_chain_the_pairs():
    """Scripted solves, so every number is known. Robots 0 and 2 (swapping the ends of a row) are both held
    and each is the other's blocker: two solves of pair (0, 2). The first lowers F from 50 to 49 and is kept
    (plans, F, planned positions, the pair's multipliers); the second starts from those plans and lowers F by
    1e-4 < epsilon = 1e-3: rejected. Both count as solves."""
    cfg = CFG.replace(dmpc_pairs=True)
    # robot 2 heads 2 cm off robot 0's start: no exact head-on tie, whose tie-break would move its target
    data = held(at_rest([[0.0, 0.0], [1.2, 0.1], [2.4, 0.0]], [[2.4, 0.0], [1.2, 0.1], [0.0, 0.02]]), 0, 2)
    result = _loop_result(data, cfg)
    moved = np.zeros_like(result.accels)
    moved[[0, 2], :, 1] = [[0.5], [-0.5]]
    joint = _ScriptedJoint(cfg, [_solution(moved, 49.0, lam=2.0), _solution(moved * 2, 49.0 - 1e-4)])
    out = pair_moves(joint, data, result)
    assert [c[1] for c in joint.calls] == [[0, 2], [0, 2]]
    np.testing.assert_array_equal(joint.calls[1][0], moved)  # the second pair starts from the first's plans
    np.testing.assert_array_equal(out.accels, moved)
    assert out.potential == 49.0 and out.potentials == (51.0, 50.0, 49.0)
    np.testing.assert_array_equal(out.positions, rollout_numpy(data.states, moved, cfg.dt)[0])
    np.testing.assert_array_equal(out.lam_x[:, 0, 0], [2.0, 1.0, 2.0])  # robot 1 keeps the loop's
    np.testing.assert_array_equal(out.lam_g[:, 0, 0], [-2.0, -1.0, -2.0])
    assert out.solves == 9 + 2 and out.solver_iterations == 30 + 2 * 7


def test_a_failed_pair_solve_is_not_kept_but_counted():
    cfg = CFG.replace(dmpc_pairs=True)
    data = held(at_rest([[0.0, 0.0], [1.0, 0.1]], [[1.0, 0.1], [0.0, 0.0]]), 0)
    result = _loop_result(data, cfg)
    joint = _ScriptedJoint(cfg, [_solution(result.accels + 1.0, 10.0, success=False)])
    out = pair_moves(joint, data, result)
    np.testing.assert_array_equal(out.accels, result.accels)
    assert out.potential == 50.0 and out.potentials == result.potentials
    assert out.solves == 10 and out.solver_iterations == 37


def test_the_joint_solver_is_built_only_for_the_pair_moves():
    """DMPC evaluates F with the joint NLP but solves it only in its pair moves; the solver (most of the
    joint NLP's build, a gcc compile with jit) is built on the first solve, to the same solution."""
    assert DMPC(CFG, 2, 0).joint._built is None
    paired = DMPC(CFG.replace(dmpc_pairs=True), 2, 0).joint
    assert paired._built is not None
    lazy = DMPC(CFG, 2, 0).joint
    data = held(at_rest([[0.0, 0.0], [1.0, 0.1]], [[1.0, 0.1], [0.0, 0.0]]), 0)
    start = np.zeros((2, CFG.horizon, 2))
    eager, built = (nlp.solve(data, np.zeros((CFG.horizon, 0, 2)), start) for nlp in (paired, lazy))
    assert lazy._built is not None
    np.testing.assert_array_equal(built.accels, eager.accels)
