"""Guidance's disc radius (``MPCConfig.guidance_clearance``): d_min plus the margin, or the distance Eq. 11's
soft penalty keeps in practice. By hand, and a gap between two standing humans that only the second closes."""

import math

import numpy as np
import pytest

from crowdsim.scenarios import Layout
from mpc.config import MPCConfig
from mpc.errors import MPCConfigError
from pipelines.loop.controllers import ControllerSpec, make_controller
from tests.pipelines.test_motion_margins import act_once_standing


def test_clearance_by_hand():
    """Table I: d_min 0.8, w_coll 1e7, mu 30, w_goal 10. The penalty's tail adds ln(1e7 / 300) / 30 =
    0.3471 m^2 to (d_min + m)^2: 0.9936 m without margin, 1.0179 m with m = 0.03."""
    assert MPCConfig().guidance_clearance == "margin"
    assert MPCConfig().standing_clearance(0.03) == pytest.approx(0.83, abs=1e-12)
    penalty = MPCConfig(guidance_clearance="penalty")
    assert penalty.standing_clearance(0.0) == pytest.approx(
        math.sqrt(0.64 + math.log(1e7 / 300) / 30), rel=1e-12
    )
    assert penalty.standing_clearance(0.0) == pytest.approx(0.9936, abs=1e-4)
    assert penalty.standing_clearance(0.03) == pytest.approx(1.0179, abs=1e-4)
    # a penalty weaker than the goal term has no tail worth avoiding: the margin's disc
    assert penalty.replace(w_coll=100.0).standing_clearance(0.03) == pytest.approx(0.83, abs=1e-12)
    with pytest.raises(MPCConfigError, match="guidance_clearance") as info:
        MPCConfig(guidance_clearance="wide")
    assert "'wide'" in str(info.value)


def _guided(clearance: str) -> dict:
    """The 9th step's guided robots: one robot 8 m below a gap of 1.8 m between two standing humans (1.8 >
    2 x 0.8, < 2 x 0.99), its goal 8 m above it."""
    humans = np.array([[-0.9, 0.0], [0.9, 0.0]])
    layout = Layout(
        robot_starts=np.array([[0.0, -8.0]]),
        robot_goals=np.array([[0.0, 8.0]]),
        human_starts=humans,
        human_goals=humans,
    )
    overrides = (("guidance", "standing"), ("guidance_clearance", clearance))
    controller = make_controller(ControllerSpec("cmpc", "constant_velocity", mpc_overrides=overrides))
    obs, out = act_once_standing(controller, layout)
    assert obs.robot_positions[0, 1] < -3.0  # still well below the gap
    return out.extra.get("guided", {})


def test_a_gap_open_to_the_margin_discs_is_closed_to_the_penalty_discs():
    assert _guided("margin") == {}  # the straight line passes 0.9 m from each human: clear of 0.8 m discs
    guided = _guided("penalty")
    assert list(guided) == [0]
    assert abs(guided[0][0]) > 0.9  # round one of the humans, not through the gap


@pytest.mark.parametrize(("horizon", "v_max", "start"), [(4, 1.0, -3.0), (15, 1.0, -6.0), (4, 2.0, -8.0)])
def test_a_guided_target_lies_beyond_the_horizons_reach(horizon, v_max, start):
    """Eq. 8's reference stops on its target, so a guided target nearer than the horizon covers at v_max
    stops the reference short of the horizon's end. A target was prolonged to 2 m whatever the horizon and
    the bound: here it was the corner itself, 3.16 m ahead at 15 steps (the reference stood still over its
    last 7) and 2.81 m ahead at 2 m/s (its 4th step at half speed). One robot behind a standing human,
    nothing else to enter: the target is v_max (H + 1) tau ahead, at least 2 m.
    ``start``: where the robot is still below the human at the first guided step."""
    from crowdsim.env import CrowdEnv
    from crowdsim.env_config import EnvConfig

    human = np.array([[0.0, 0.0]])
    layout = Layout(
        robot_starts=np.array([[0.3, start]]),
        robot_goals=np.array([[0.3, 6.0]]),
        human_starts=human,
        human_goals=human,
    )
    env_config = EnvConfig(v_max=v_max, robots_visible=False)  # the human stands whatever comes
    overrides = (("guidance", "standing"), ("horizon", horizon))
    controller = make_controller(ControllerSpec("cmpc", mpc_overrides=overrides), env_config)
    env = CrowdEnv(env_config)
    obs = env.reset_layout(layout)
    controller.reset(obs)
    for _ in range(8):  # motion classes need 8 observations before the human counts as standing
        obs, _, _ = env.step(controller.act(obs).accelerations)
    out = controller.act(obs)
    guided = out.extra.get("guided", {})
    assert list(guided) == [0]
    ahead = float(np.linalg.norm(np.array(guided[0]) - obs.robot_positions[0]))
    expected = max(2.0, v_max * (horizon + 1) * 0.4)
    assert ahead == pytest.approx(expected, abs=1e-3)
    assert ahead > v_max * horizon * 0.4


def test_guidance_standing_without_two_rows_of_history_is_refused_naming_the_history_kept():
    """Guidance tells who stands still from the humans' motion over the history. The ORCA oracle reads one
    row, so [world] obs_len = 1 passed every check, and every episode failed at its first step in the
    classifier's words ("history must have shape (L >= 2, N, 2), got (1, 7, 2)"), naming neither guidance nor
    obs_len."""
    from crowdsim.env_config import EnvConfig
    from pipelines.errors import PipelineError

    overrides = (("guidance", "standing"),)
    spec = ControllerSpec("cmpc", predictor="orca_oracle", mpc_overrides=overrides)
    with pytest.raises(PipelineError) as refused:
        make_controller(spec, EnvConfig(history_len=1))
    assert str(refused.value) == (
        "guidance 'standing' reads 2 observed steps but the simulator keeps 1 ([world] obs_len): set [world] "
        "obs_len >= 2 (e.g. --set world.obs_len=2)"
    )
    make_controller(spec, EnvConfig(history_len=2))  # two rows tell a motion
    make_controller(ControllerSpec("cmpc", predictor="orca_oracle"), EnvConfig(history_len=1))  # no guidance


def test_a_goal_weight_below_its_least_value_is_refused_where_it_is_given(capsys):
    """Guidance's penalty disc divides by mu w_goal: w_goal = 5e-324 (a float > 0, which the schema took)
    with mu at its least value made that zero, and simulate's first guided step raised ZeroDivisionError.
    With every number at its least value or bound together the disc is finite."""
    from mpc.config import MAX_WEIGHT, MPC_LEAST
    from tests.cli_calls import one_line
    from tests.cli_calls import run_cli as run

    least = {name: value for name, (value, _) in MPC_LEAST.items()}
    widest = MPCConfig(guidance_clearance="penalty", w_coll=MAX_WEIGHT, **least)
    assert math.isfinite(widest.standing_clearance(0.0))
    argv = ["simulate", "--controller", "cmpc", "--episodes", "1", "--humans", "2", "--set", "mpc.mu=1e-3"]
    argv += ["--set", "mpc.guidance=standing", "--set", "mpc.guidance_clearance=penalty"]
    code, _, err = run(capsys, *argv, "--set", "mpc.w_goal=5e-324")
    assert code == 2 and one_line(err).endswith("--set mpc.w_goal: must be at least 1e-40, got 5e-324")
