"""``EnvConfig.formation``: the robots' formation chosen for every episode of a run (``[env] formation``)."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.formations import robot_layout
from crowdsim.scenarios import make_layout
from pipelines.cli import main


@pytest.mark.parametrize("formation", ["row", "wedge", "two_rows"])
def test_the_config_formation_places_the_robots(formation):
    obs = CrowdEnv(EnvConfig(formation=formation)).reset(4, "circle", 5, 6)
    starts, goals = robot_layout(6, formation)
    np.testing.assert_array_equal(obs.robot_positions, starts)
    np.testing.assert_array_equal(obs.robot_goals, goals)
    # the crowd is sampled as make_layout samples it for that formation, from the same seed
    layout = make_layout("circle", 5, 6, np.random.default_rng(4), formation=formation)
    np.testing.assert_array_equal(obs.human_positions, layout.human_starts)


def test_auto_is_the_default_and_changes_nothing():
    default, auto = (
        CrowdEnv().reset(7, "perpendicular", 7),
        CrowdEnv(EnvConfig(formation="auto")).reset(7, "perpendicular", 7),
    )
    np.testing.assert_array_equal(default.robot_positions, auto.robot_positions)
    np.testing.assert_array_equal(default.human_positions, auto.human_positions)
    # auto: the paper's row for 3 robots, a wedge from 4
    np.testing.assert_array_equal(default.robot_positions, robot_layout(3, "row")[0])
    np.testing.assert_array_equal(
        CrowdEnv().reset(0, "circle", 3, 5).robot_positions, robot_layout(5, "wedge")[0]
    )


def test_an_unknown_formation_is_refused():
    with pytest.raises(SimulationError, match=r"EnvConfig.formation must be one of \['auto', 'row'"):
        EnvConfig(formation="hexagon")


def test_the_formation_comes_from_the_command_line(tmp_path, capsys):
    report = tmp_path / "run.json"
    argv = ["--set", "env.formation=two_rows", "simulate", "--controller", "straight", "--robots", "4"]
    assert main([*argv, "--humans", "1", "--episodes", "1", "--no-progress", "--json", str(report)]) == 0
    assert '"formation": "two_rows"' in report.read_text()
    assert "| paper/visible | formation two_rows | scenario circle |" in capsys.readouterr().out
    assert main(["--set", "env.formation=hexagon", "simulate", "--controller", "straight"]) == 2
    assert (
        "env.formation: must be one of ['auto', 'row', 'wedge', 'two_rows', 'antipodal'], got 'hexagon'"
        in (capsys.readouterr().err)
    )


@pytest.mark.parametrize(
    ("formation", "n_robots", "radius", "spacing"),
    [("row", 3, 0.55, 1.0), ("auto", 2, 0.501, 1.0), ("wedge", 4, 0.61, 1.2), ("two_rows", 4, 0.7, 1.2)],
)
def test_a_radius_at_which_the_formations_robots_overlap_is_refused(formation, n_robots, radius, spacing):
    """The formations' spacing does not follow the radius, the simulator has no robot-robot contact and the
    metrics count robot-human contact only: at radius 0.55 m the row's robots, 1 m apart, drove a whole
    episode inside each other and `simulate` reported success without a contact."""
    env = CrowdEnv(EnvConfig(radius=radius, formation=formation))
    with pytest.raises(SimulationError, match=rf"neighbours {spacing:g} m apart, in contact from the start"):
        env.reset(0, "circle", 3, n_robots)
    # touching is not overlapping; a single robot has no neighbour
    CrowdEnv(EnvConfig(radius=spacing / 2, formation=formation)).reset(0, "circle", 3, n_robots)
    CrowdEnv(EnvConfig(radius=radius, formation=formation)).reset(0, "circle", 3, 1)


def test_the_overlap_refusal_is_one_line_naming_the_setting(capsys):
    argv = [
        "simulate",
        "--controller",
        "straight",
        "--humans",
        "3",
        "--set",
        "world.radius=0.55",
        "--no-progress",
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "crowdmpc simulate: error: radius 0.55 m: the row formation of 3 robots puts neighbours 1 m apart, "
        "in contact from the start (2 x radius = 1.1 m); space them out ([env] robot_spacing, m between "
        "neighbours) or use [world] radius <= 0.5 m"
    ]
    # the way out it names works (another formation did not: the wedge's neighbours are 1.2 m apart)
    assert main([*argv, "--set", "env.robot_spacing=1.2", "--episodes", "1"]) == 0


def test_the_gymnasium_constructor_warns_of_a_formation_its_resets_refuse():
    """gym.make took a radius at which every reset of its formation was then refused, the first word of it
    at the first reset; it warns now, naming the way out. A warning, not a refusal: hand-built layouts
    (``options["layout"]``) do not use the formation."""
    import warnings

    import gymnasium as gym

    from crowdsim import ENV_ID
    from crowdsim.errors import LayoutWarning

    with pytest.warns(LayoutWarning, match=r"neighbours 1 m apart, in contact .*: a reset without options"):
        env = gym.make(ENV_ID, config=EnvConfig(radius=0.6), n_humans=0)
    with pytest.raises(SimulationError, match="in contact from the start"):
        env.reset(seed=0)
    starts = np.array([[-1.5, -4.0], [1.5, -4.0]])
    layout = make_layout("circle", 0, 2, np.random.default_rng(0))
    layout = type(layout)(starts, starts * [1.0, -1.0], layout.human_starts, layout.human_goals)
    env.reset(seed=0, options={"layout": layout})  # the radius the user wanted, for layouts of their own
    with warnings.catch_warnings():
        warnings.simplefilter("error", LayoutWarning)
        gym.make(ENV_ID, config=EnvConfig(radius=0.6, robot_spacing=1.3)).reset(seed=0)
        gym.make(ENV_ID, config=EnvConfig(radius=0.6), n_robots=1).reset(seed=0)


def test_the_antipodal_circle_takes_neither_slots_nor_a_spacing():
    """An even team's goals are its own starts: slots would hand every robot its start, and the episode would
    succeed at once; the circle's spacing is its own."""
    with pytest.raises(SimulationError, match="goal_assignment 'slots' would deal the goals anew"):
        EnvConfig(formation="antipodal", goal_assignment="slots")
    with pytest.raises(SimulationError, match="robot_spacing does not apply to formation 'antipodal'"):
        EnvConfig(formation="antipodal", robot_spacing=1.3)
    obs = CrowdEnv(EnvConfig(formation="antipodal")).reset(0, "circle", 5, 4)
    np.testing.assert_array_equal(obs.robot_goals, [[0.0, 3.5], [-3.5, 0.0], [0.0, -3.5], [3.5, 0.0]])
    with pytest.raises(SimulationError, match=r"antipodal formation of 12 robots .* use \[world\] radius <="):
        CrowdEnv(EnvConfig(formation="antipodal", radius=1.0)).reset(0, "circle", 0, 12)


def test_simulate_runs_robots_trading_places_and_says_what_to_set(capsys):
    """Four robots crossing the circle among nobody: every pair flocking, the controller's note names
    flock_range (and the formation's goal-room note stays silent: its advice is for a team); with it they
    arrive, no two closer than d_min."""
    args = ["simulate", "--controller", "cmpc", "--humans", "0", "--robots", "4", "--no-progress"]
    args += ["--set", "env.formation=antipodal", "--json", "-"]
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "note: robots 0 and 1 are bound for goals 4.9 m apart by separate ways" in captured.err
    assert "closest goals" not in captured.err
    assert main([*args, "--set", "mpc.flock_range=2"]) == 0
    import json

    (episode,) = json.loads(capsys.readouterr().out)["episodes"]
    assert episode["metrics"]["success"] and episode["metrics"]["min_distance_robots"] > 0.8
