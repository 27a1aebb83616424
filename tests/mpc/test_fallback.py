"""A failing step never ends an episode: shifted previous plan, else braking; the status is recorded."""

import re

import numpy as np
import pytest

from mpc.cmpc import CMPC
from mpc.config import MPCConfig
from mpc.dmpc import DMPC
from mpc.dynamics import braking
from mpc.fallback import PlanMemory, Start, heading_plan, shift
from mpc.nlp import StepData


def moving_data():
    states = np.array([[0.0, 0.0, 0.5, 0.5], [2.0, 0.0, -0.5, 0.5]])
    return StepData(states, np.zeros((2, 2)), np.array([[0.0, 5.0], [2.0, 5.0]]), np.ones(2, dtype=bool))


def humans(cfg, value=0.0):
    return lambda robots_future: np.full((cfg.horizon, 1, 2), value) + [5.0, -5.0]


def test_forced_ipopt_failure_returns_the_start_and_its_status():
    cfg = MPCConfig(solver_max_iter=0)
    data = moving_data()
    start = PlanMemory(cfg).start(data)
    assert start.kind == "brake"
    for solver in (CMPC(cfg, 2, 1), DMPC(cfg, 2, 1)):
        result = solver.solve(data, humans(cfg), start)
        assert not result.solved
        assert result.status == "Maximum_Iterations_Exceeded"
        np.testing.assert_array_equal(result.accels, braking(data.states, cfg.horizon, cfg.dt, cfg.a_max))


def test_nan_prediction_is_a_failure_not_a_crash():
    cfg = MPCConfig()
    data = moving_data()
    start = PlanMemory(cfg).start(data)
    for solver in (CMPC(cfg, 2, 1), DMPC(cfg, 2, 1)):
        result = solver.solve(data, humans(cfg, np.nan), start)
        assert not result.solved and result.status == "nan_prediction" and result.solves == 0


def test_a_prediction_of_another_shape_is_named_not_taken_for_nan():
    """A predict function of one's own returning (N_h, H, 2), or too few humans, was reported as
    "nan_prediction" and every step fell back: the shape is a programming error, named."""
    cfg = MPCConfig()
    data = moving_data()
    start = PlanMemory(cfg).start(data)
    for solver in (CMPC(cfg, 2, 1), DMPC(cfg, 2, 1)):
        for wrong in ((1, cfg.horizon, 2), (cfg.horizon, 2, 2)):
            expected = rf"returned shape {re.escape(str(wrong))}, expected \(4, 1, 2\): \(H, N_h, 2\)"
            with pytest.raises(ValueError, match=expected):
                solver.solve(data, lambda robots_future, wrong=wrong: np.zeros(wrong), start)


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        (
            "arrived",
            np.array([True]),
            r"arrived must be booleans of shape \(2,\), one per robot of states, got ",
        ),
        ("active", np.ones(3, dtype=bool), r"active must be booleans of shape \(2,\)"),
        (
            "goals",
            np.full((2, 2), np.nan),
            r"goals must be finite positions of shape \(2, 2\), .*, got shape \(2, 2\) with 4 non-finite",
        ),
        ("last_actions", np.zeros(2), r"last_actions must be finite accelerations of shape \(2, 2\)"),
        ("states", np.zeros((2, 2)), r"states must be finite rows \[s_x, s_y, v_x, v_y\] of shape \(M, 4\)"),
        (
            "states",
            np.full((2, 4), np.inf),
            r"states must be finite rows.*got shape \(2, 4\) with 8 non-finite",
        ),
    ],
)
def test_step_data_of_the_wrong_shape_is_refused_naming_the_field(field, value, message):
    """A one-robot ``arrived`` for two robots was stretched to both by numpy's broadcasting (both taken as
    arrived, the plan changed, status ok); other shapes failed deep in the NLP with numpy's words. Values
    that are not finite are counted: "got shape (2, 4)" alone read as if the shape were wrong."""
    import dataclasses

    with pytest.raises(ValueError, match=message):
        dataclasses.replace(moving_data(), **{field: value})


def test_step_data_takes_lists():
    data = StepData([[0.0, 0.0, 0.5, 0.5]], [[0.0, 0.0]], [[0.0, 5.0]], [True], arrived=[False])
    assert data.states.dtype == float and data.active.dtype == bool and data.arrived.shape == (1,)


def test_timeout_is_a_failure():
    cfg = MPCConfig(time_limit_s=1e-9)
    data = moving_data()
    result = CMPC(cfg, 2, 1).solve(data, humans(cfg), PlanMemory(cfg).start(data))
    assert not result.solved and result.status == "Maximum_WallTime_Exceeded"


def test_shifted_plan_then_braking_after_the_solved_actions_run_out():
    cfg = MPCConfig()
    data = moving_data()
    memory = PlanMemory(cfg)
    plan = np.zeros((2, cfg.horizon, 2))
    plan[:, :, 1] = [[0.1, 0.2, 0.3, 0.4], [-0.1, -0.2, -0.3, -0.4]]  # small: within Eq. 6 from data.states
    memory.commit(plan, solved=True)
    kinds = []
    for k in range(1, cfg.horizon + 1):
        start = memory.start(data)
        kinds.append(start.kind)
        if start.kind == "shifted":
            np.testing.assert_allclose(start.accels[:, 0], plan[:, k])  # the action planned for this step
            np.testing.assert_allclose(start.accels[:, -1], 0.0)  # padding keeps the velocity
        else:
            np.testing.assert_allclose(start.accels, braking(data.states, cfg.horizon, cfg.dt, cfg.a_max))
        memory.commit(start.accels, solved=False)
    # A horizon-4 plan covers 3 further steps; the 4th failing step brakes.
    assert kinds == ["shifted", "shifted", "shifted", "brake"]


def test_shifted_plan_is_clipped_to_the_bounds_from_the_current_state():
    cfg = MPCConfig()
    memory = PlanMemory(cfg)
    memory.commit(np.full((1, cfg.horizon, 2), 2.0), solved=True)  # full acceleration, planned from rest
    data = StepData(np.array([[0.0, 0.0, 0.9, -0.9]]), np.zeros((1, 2)), np.ones((1, 2)), np.ones(1, bool))
    start = memory.start(data)
    # v_x = 0.9 leaves (1 - 0.9) / 0.4 = 0.25 of acceleration; v_y = -0.9 leaves the full 2.0.
    np.testing.assert_allclose(start.accels[0, 0], [0.25, 2.0])


def test_a_parked_robot_brakes_in_the_shifted_start():
    """Robot 1 is pinned (``active`` False): its part of u^(0) is braking, robot 0's the shifted plan."""
    cfg = MPCConfig()
    data = moving_data()
    memory = PlanMemory(cfg)
    plan = np.full((2, cfg.horizon, 2), 0.1)
    memory.commit(plan, solved=True)
    pinned = StepData(data.states, data.last_actions, data.goals, np.array([True, False]))
    start = memory.start(pinned)
    assert start.kind == "shifted"
    np.testing.assert_allclose(start.accels[0], shift(plan)[0])
    np.testing.assert_array_equal(start.accels[1], braking(data.states, cfg.horizon, cfg.dt, cfg.a_max)[1])


def test_the_multipliers_are_shifted_with_the_plan():
    """The warm start's multipliers follow the plan: one step shifted at the next start, and each failed step
    (which applies the shifted plan) shifts them once more."""
    cfg = MPCConfig()
    data = moving_data()
    memory = PlanMemory(cfg)
    lam_x = np.arange(2 * cfg.horizon * 2, dtype=float).reshape(2, cfg.horizon, 2) + 1.0
    lam_g = -lam_x
    memory.commit(np.zeros((2, cfg.horizon, 2)), solved=True, lam_x=lam_x, lam_g=lam_g)
    start = memory.start(data)
    np.testing.assert_array_equal(start.lam_x, shift(lam_x))
    np.testing.assert_array_equal(start.lam_g, shift(lam_g))
    memory.commit(start.accels, solved=False)
    start = memory.start(data)
    np.testing.assert_array_equal(start.lam_x, shift(shift(lam_x)))
    np.testing.assert_array_equal(start.lam_g, shift(shift(lam_g)))
    # shift drops step 0 and pads with zeros: step 0 of the twice-shifted multipliers is step 2's.
    np.testing.assert_array_equal(start.lam_x[:, 0], lam_x[:, 2])
    np.testing.assert_array_equal(start.lam_x[:, -2:], 0.0)


def test_a_plan_for_another_team_size_is_not_shifted():
    cfg = MPCConfig()
    memory = PlanMemory(cfg)
    memory.commit(np.zeros((3, cfg.horizon, 2)), solved=True)
    assert memory.start(moving_data()).kind == "brake"  # 2 robots now


def test_only_the_first_solve_restarts_or_explores():
    """A step from the shifted plan restarts its first solve from braking when stuck; one that starts from
    braking explores with both solvers instead; no later solve does either."""
    accels = np.zeros((1, 4, 2))
    shifted, brake = Start(accels, "shifted", None, None), Start(accels, "brake", None, None)
    assert shifted.first_solve(1) == {"restart": True, "explore": False}
    assert brake.first_solve(1) == {"restart": False, "explore": True}
    for start in (shifted, brake):
        assert start.first_solve(2) == {"restart": False, "explore": False}


def test_heading_plan_follows_its_own_rollout_and_heads_for_the_targets():
    """From rest 0.5 m from the target (dt 0.4, a_max 2, v_max 1), along x:
    k = 0: wanted min(1, 0.5 / 0.4) = 1, a = min(1 / 0.4, 2) = 2; v = 0.8, x = 0.5 * 0.16 * 2 = 0.16.
    k = 1: 0.34 m left, wanted 0.34 / 0.4 = 0.85, a = (0.85 - 0.8) / 0.4 = 0.125; v = 0.85,
           x = 0.16 + 0.32 + 0.01 = 0.49.
    k = 2: 0.01 m left, wanted 0.025, a = (0.025 - 0.85) / 0.4 = -2.0625 -> -2; v = 0.05,
           x = 0.49 + 0.34 - 0.16 = 0.67.
    k = 3: 0.17 m past it, wanted -0.425, a = (-0.425 - 0.05) / 0.4 = -1.1875.
    The goal is elsewhere (10 m north): the plan heads for ``targets``, Eq. 8's target."""
    cfg = MPCConfig()
    data = StepData(
        np.zeros((1, 4)), np.zeros((1, 2)), np.array([[0.0, 10.0]]), np.ones(1, bool),
        targets=np.array([[0.5, 0.0]]),
    )  # fmt: skip
    plan = heading_plan(data, cfg)
    np.testing.assert_allclose(plan[0, :, 0], [2.0, 0.125, -2.0, -1.1875], atol=1e-12)
    np.testing.assert_allclose(plan[0, :, 1], 0.0, atol=1e-12)


def test_reset_forgets_the_solved_actions_of_the_last_episode():
    # An episode ends with a fresh solved plan; the next one starts with a failing step (braking applied,
    # committed unsolved): the step after must brake again, not shift that braking plan as if it were solved.
    cfg = MPCConfig()
    data = moving_data()
    memory = PlanMemory(cfg)
    memory.commit(np.zeros((2, cfg.horizon, 2)), solved=True)
    memory.reset()
    brake = memory.start(data)
    assert brake.kind == "brake"
    memory.commit(brake.accels, solved=False)
    assert memory.start(data).kind == "brake"


def test_multipliers_must_come_in_pairs():
    cfg = MPCConfig()
    memory = PlanMemory(cfg)
    plan = np.zeros((2, cfg.horizon, 2))
    memory.commit(plan, solved=True, lam_x=np.zeros_like(plan), lam_g=None)
    with pytest.raises(RuntimeError, match="commit both multipliers or neither"):
        memory.commit(plan, solved=False)


def test_a_braking_commit_leaves_no_solved_action_nor_multipliers():
    """After a solve, a step that applies braking (every robot on its goal, or a failure from a braking
    start): braking came out of no solve, so the next step starts from braking again, cold, not from the
    shifted braking plan warm-started with the old solve's multipliers."""
    cfg = MPCConfig()
    data = moving_data()
    memory = PlanMemory(cfg)
    lam = np.arange(2 * cfg.horizon * 2, dtype=float).reshape(2, cfg.horizon, 2)
    memory.commit(np.full((2, cfg.horizon, 2), 0.3), solved=True, lam_x=lam, lam_g=-lam)
    memory.commit(braking(data.states, cfg.horizon, cfg.dt, cfg.a_max), solved=False, kind="brake")
    start = memory.start(data)
    assert (start.kind, start.lam_x, start.lam_g) == ("brake", None, None)
    np.testing.assert_array_equal(start.accels, braking(data.states, cfg.horizon, cfg.dt, cfg.a_max))


def test_a_commit_of_an_unknown_kind_is_named():
    memory = PlanMemory(MPCConfig())
    with pytest.raises(ValueError, match="kind 'braking' is none of"):
        memory.commit(np.zeros((2, 4, 2)), solved=False, kind="braking")
