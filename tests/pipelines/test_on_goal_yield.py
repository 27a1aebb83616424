"""on_goal="yield": robots parked 1.2 m apart no longer wall off a goal behind them (mpc/config.py)."""

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.scenarios import Layout
from mpc.config import MPCConfig
from mpc.nlp import JointNLP, StepData
from pipelines.loop.controllers import ControllerSpec, make_controller

# Robots 0 and 1 start on their goals 1.2 m apart (the formations' spacing); robot 2's goal lies just behind
# the gap between them. Passing needs about 2 x 1.03 m (where the Eq. 12 penalty becomes negligible).
GAP = Layout(
    robot_starts=np.array([[-0.6, 0.0], [0.6, 0.0], [0.0, -3.0]]),
    robot_goals=np.array([[-0.6, 0.0], [0.6, 0.0], [0.0, 1.0]]),
    human_starts=np.zeros((0, 2)),
    human_goals=np.zeros((0, 2)),
)


def _run(on_goal: str, steps: int = 30) -> tuple[bool, np.ndarray]:
    controller = make_controller(
        ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("on_goal", on_goal),))
    )
    env = CrowdEnv()
    obs = env.reset_layout(GAP)
    controller.reset(obs)
    for _ in range(steps):
        obs, done, _ = env.step(controller.act(obs).accelerations)
        if done:
            return True, obs.robot_positions
    return False, obs.robot_positions


def test_parked_robots_that_track_their_goals_wall_off_the_goal_behind_them():
    done, positions = _run("track")
    assert not done
    np.testing.assert_allclose(positions[:2], GAP.robot_goals[:2], atol=0.02)  # they never moved
    assert positions[2, 1] < -0.5  # robot 2 waits in front of the gap


def test_parked_robots_that_yield_let_the_teammate_through_and_return():
    done, positions = _run("yield")
    assert done  # every robot within its radius of its goal at the same step (the paper profile's rule)
    assert np.all(np.linalg.norm(positions - GAP.robot_goals, axis=1) < 0.3)


def test_goal_slack_divides_eq7_by_distance_plus_delta_plus_slack():
    """Robot 0 on its goal, a plan that moves it: Eq. 7's term falls by (0 + delta) / (0 + delta + slack)."""
    cfg = MPCConfig(w_acce=0.0, w_jerk=0.0, w_coll=1.0, w_floc=0.0)
    nlp = JointNLP(cfg, 1, 1)
    far = np.full((cfg.horizon, 1, 2), 100.0)  # one human, too far for Eq. 11 to count
    state = np.array([[0.0, 0.0, 0.0, 0.0]])
    base = dict(states=state, last_actions=np.zeros((1, 2)), goals=np.zeros((1, 2)), active=np.ones(1, bool))
    accels = np.full((1, cfg.horizon, 2), 0.5)
    paper = nlp.potential(accels, StepData(**base), far)
    slack = nlp.potential(accels, StepData(**base, goal_slack=np.array([0.5])), far)
    assert slack == pytest.approx(paper * cfg.delta / (cfg.delta + 0.5), rel=1e-9)
    with pytest.raises(ValueError, match="goal_slack"):
        nlp.potential(accels, StepData(**base, goal_slack=np.array([-1.0])), far)


# Both robots have arrived at reset, robot 1 0.25 m from its goal; one shove of 1 m/s^2 (0.08 m further in a
# step of 0.4 s) takes it outside its 0.3 m radius, moving away at 0.4 m/s.
BOTH_ARRIVED = Layout(
    robot_starts=np.array([[-0.6, 0.0], [0.85, 0.0]]),
    robot_goals=np.array([[-0.6, 0.0], [0.6, 0.0]]),
    human_starts=np.zeros((0, 2)),
    human_goals=np.zeros((0, 2)),
)


@pytest.mark.parametrize("on_goal", ["track", "yield"])
def test_a_robot_pushed_off_its_goal_after_everyone_arrived_gets_back(on_goal):
    """Every robot has arrived once, but the paper's success rule wants them on their goals at the same
    step: the controller must bring robot 1 back, not brake everyone (which froze it off its goal)."""
    controller = make_controller(
        ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("on_goal", on_goal),))
    )
    env = CrowdEnv()
    obs = env.reset_layout(BOTH_ARRIVED)
    controller.reset(obs)
    assert obs.robot_reached.all()
    obs, done, _ = env.step(np.array([[0.0, 0.0], [1.0, 0.0]]))
    assert not done and obs.robot_reached.all()
    assert obs.robot_positions[1, 0] - 0.6 == pytest.approx(0.33)
    for _ in range(20):
        obs, done, info = env.step(controller.act(obs).accelerations)
        if done:
            break
    assert done and info["success"]
