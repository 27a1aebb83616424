"""DMPC's initial strategy (``MPCConfig.dmpc_start``): the heading plan by hand, and "heading" starting a
flock at rest where the shifted start creeps, while keeping the paper's start wherever it is the lower F."""

import numpy as np
import pytest

from mpc.config import MPCConfig
from mpc.dmpc import DMPC
from mpc.dynamics import rollout_numpy
from mpc.errors import MPCConfigError
from mpc.fallback import PlanMemory, heading_plan
from mpc.nlp import StepData


def at_rest(positions, goals) -> StepData:
    positions = np.asarray(positions, dtype=float)
    m = len(positions)
    states = np.column_stack([positions, np.zeros((m, 2))])
    return StepData(states, np.zeros((m, 2)), np.asarray(goals, dtype=float), np.ones(m, dtype=bool))


def solve(cfg: MPCConfig, data: StepData, memory: PlanMemory | None = None):
    """One DMPC step without humans, from ``memory``'s start (braking for a fresh memory)."""
    solver = DMPC(cfg, data.n_robots, 0)
    try:
        no_humans = np.zeros((cfg.horizon, 0, 2))
        start = (memory or PlanMemory(cfg)).start(data)
        return solver.solve(data, lambda robots_future: no_humans, start)
    finally:
        solver.close()


def test_the_paper_start_is_the_default_and_bad_values_are_named():
    assert MPCConfig().dmpc_start == "shifted"
    with pytest.raises(MPCConfigError, match="dmpc_start") as info:
        MPCConfig(dmpc_start="straight")
    assert "'straight'" in str(info.value)


def test_heading_plan_by_hand():
    """dt 0.4, a_max 2, v_max 1. From rest 10 m from the target: a = min(1 / 0.4, 2) = 2, then v = 0.8 and
    a = (1 - 0.8) / 0.4 = 0.5, then v = 1: a = 0. Moving at 1 m/s 0.2 m before the target: the wanted speed
    is 0.2 / 0.4 = 0.5, so a = (0.5 - 1) / 0.4 = -1.25."""
    cfg = MPCConfig()
    far = heading_plan(at_rest([[0.0, 0.0]], [[10.0, 0.0]]), cfg)
    np.testing.assert_allclose(far[0], [[2.0, 0.0], [0.5, 0.0], [0.0, 0.0], [0.0, 0.0]], atol=1e-12)
    near = StepData(
        np.array([[0.0, 0.0, 0.0, 1.0]]), np.zeros((1, 2)), np.array([[0.0, 0.2]]), np.ones(1, bool)
    )
    np.testing.assert_allclose(heading_plan(near, cfg)[0, 0], [0.0, -1.25], atol=1e-12)


def test_a_flock_at_rest_starts_moving_only_with_the_heading_start():
    """Three robots at rest in a triangle of side d_flock = 1.2 m, goals 10 m ahead. Braking is nearly an
    equilibrium (a robot stepping forward alone stretches both of its flocking terms), so two Gauss-Seidel
    sweeps from it leave F at 9.0 and the first accelerations at 0.5 m/s^2; the heading plan moves the
    whole flock at once with the lower F, and the sweeps from it end at F = 3.4, accelerating at 1.5."""
    triangle = np.array([[0.0, 0.0], [1.2, 0.0], [0.6, 0.6 * np.sqrt(3.0)]])
    data = at_rest(triangle, triangle + [0.0, 10.0])
    base = MPCConfig(dmpc_update="gauss_seidel", dmpc_stop="no_improvement", j_max=2)
    shifted = solve(base, data)
    started = solve(base.replace(dmpc_start="heading"), data)
    assert started.potential < shifted.potential - 5.0
    assert np.all(started.accels[:, 0, 1] > shifted.accels[:, 0, 1] + 0.8)


def test_where_heading_costs_more_the_paper_start_is_kept_bit_for_bit():
    """Two robots 1 m apart, each heading for the other's place: the straight plans meet inside d_min, so
    the heading plan has the higher F and the step is exactly the shifted start's."""
    data = at_rest([[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [0.0, 0.0]])
    cfg = MPCConfig(dmpc_update="gauss_seidel", dmpc_stop="no_improvement", j_max=3)
    shifted = solve(cfg, data)
    started = solve(cfg.replace(dmpc_start="heading"), data)
    assert np.array_equal(started.accels, shifted.accels)
    assert started.potentials == shifted.potentials


def test_a_step_that_does_not_start_from_braking_keeps_the_shifted_plan():
    """The triangle of the test above, one step on with a solved plan standing still: the start is the
    shifted plan, not braking, so both settings solve the very same step."""
    triangle = np.array([[0.0, 0.0], [1.2, 0.0], [0.6, 0.6 * np.sqrt(3.0)]])
    data = at_rest(triangle, triangle + [0.0, 10.0])
    cfg = MPCConfig(dmpc_update="gauss_seidel", dmpc_stop="no_improvement", j_max=2)
    results = []
    for setting in (cfg, cfg.replace(dmpc_start="heading")):
        memory = PlanMemory(setting)
        memory.commit(np.zeros((3, setting.horizon, 2)), solved=True)
        assert memory.start(data).kind == "shifted"
        results.append(solve(setting, data, memory))
    assert np.array_equal(results[0].accels, results[1].accels)
    assert results[0].potentials == results[1].potentials


def test_the_heading_start_leaves_a_pinned_robot_braking():
    """The triangle at rest with robot 1 pinned (on_goal="brake") 10 m short of its goal: the heading start is
    taken for robots 0 and 2, but robot 1 does not play, so its plan stays braking (all zeros from rest)
    rather than heading for its goal."""
    triangle = np.array([[0.0, 0.0], [1.2, 0.0], [0.6, 0.6 * np.sqrt(3.0)]])
    data = at_rest(triangle, triangle + [0.0, 10.0])
    data = StepData(data.states, data.last_actions, data.goals, np.array([True, False, True]))
    cfg = MPCConfig(
        dmpc_update="gauss_seidel", dmpc_stop="no_improvement", j_max=2, on_goal="brake", dmpc_start="heading"
    )
    result = solve(cfg, data)
    np.testing.assert_array_equal(result.accels[1], 0.0)
    assert np.all(result.accels[[0, 2], 0, 1] > 1.0)  # the others left at once


def test_the_first_iteration_predicts_for_the_start_it_takes():
    """The heading start is judged under the humans predicted for braking. Taken, iteration 1 predicts again,
    for the heading plans; not taken, the braking prediction serves iteration 1 and each later iteration
    predicts for the plans of the one before (one prediction per iteration)."""
    calls = []

    def predict(robots_future):  # one human 3 m east of robot 0's plan: depends on the plans
        calls.append(np.array(robots_future))
        return robots_future[:, :1] + [3.0, 0.0]

    def run(cfg, data):
        solver = DMPC(cfg, data.n_robots, 1)
        try:
            return solver.solve(data, predict, PlanMemory(cfg).start(data))
        finally:
            solver.close()

    triangle = np.array([[0.0, 0.0], [1.2, 0.0], [0.6, 0.6 * np.sqrt(3.0)]])
    data = at_rest(triangle, triangle + [0.0, 10.0])
    cfg = MPCConfig(dmpc_update="gauss_seidel", dmpc_stop="no_improvement", j_max=1, dmpc_start="heading")
    run(cfg, data)
    assert len(calls) == 2
    np.testing.assert_array_equal(calls[0], np.repeat(triangle[None], cfg.horizon, axis=0))  # braking at rest
    heading = rollout_numpy(data.states, heading_plan(data, cfg), cfg.dt)[0].transpose(1, 0, 2)
    np.testing.assert_array_equal(calls[1], heading)
    # Two robots swapping places 1 m apart: heading costs more (test above), braking is kept.
    calls.clear()
    swap = at_rest([[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [0.0, 0.0]])
    result = run(cfg.replace(j_max=3), swap)
    assert result.iterations > 1 and len(calls) == result.iterations
    np.testing.assert_array_equal(calls[0], np.repeat(swap.states[None, :, :2], cfg.horizon, axis=0))


@pytest.mark.parametrize("update", ["jacobi", "gauss_seidel"])
def test_a_step_that_cannot_solve_applies_its_fallback_not_the_heading_plan(update):
    """Every solve fails (iteration limit 0): the step applies braking, its fallback (Start.kind "brake",
    what the controller labels it), not the heading plan towards the goals, which ignores the humans."""
    triangle = np.array([[0.0, 0.0], [1.2, 0.0], [0.6, 0.6 * np.sqrt(3.0)]])
    data = at_rest(triangle, triangle + [0.0, 10.0])
    cfg = MPCConfig(dmpc_start="heading", dmpc_update=update, solver_max_iter=0)
    start = PlanMemory(cfg).start(data)
    assert start.kind == "brake" and np.any(heading_plan(data, cfg) != start.accels)  # heading differs
    result = solve(cfg, data)
    assert not result.solved
    np.testing.assert_array_equal(result.accels, start.accels)
    np.testing.assert_array_equal(result.positions, rollout_numpy(data.states, start.accels, cfg.dt)[0])
