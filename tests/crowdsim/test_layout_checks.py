"""What CrowdEnv.reset_layout refuses (named) and warns of, a scenario without a sampler, and the sampling
facts crowdsim/scenarios.py's docstring states (checked on a few seeds)."""

import warnings

import numpy as np
import pytest

import crowdsim.scenarios as scenarios
from crowdsim.crossings import place_humans_paper, place_humans_v1
from crowdsim.env import CrowdEnv
from crowdsim.errors import LayoutWarning, SimulationError
from crowdsim.scenarios import Layout, make_layout, start_overlaps
from crowdsim.world import MOST_COORDINATE


def scene(humans=((3.0, 0.0),), human_goals=None, robots=((0.0, 0.0),), robot_goals=((0.0, 5.0),)) -> Layout:
    """Robots and humans at ``robots`` and ``humans``; a human's goal is its start unless given."""
    return Layout(
        robot_starts=np.array(robots, dtype=float).reshape(-1, 2),
        robot_goals=np.array(robot_goals, dtype=float).reshape(-1, 2),
        human_starts=np.array(humans, dtype=float).reshape(-1, 2),
        human_goals=np.array(humans if human_goals is None else human_goals, dtype=float).reshape(-1, 2),
    )


# ------------------------------------------------------------------------------------- refused, by name
@pytest.mark.parametrize(
    "layout, message",
    [
        (scene(humans=((3.0, 0.0), (np.nan, 1.0))), r"layout.human_starts\[1\] is \[nan, 1.0\]"),
        (scene(human_goals=((np.inf, 0.0),)), r"layout.human_goals\[0\] is \[inf, 0.0\]"),
        (scene(robots=((0.0, -np.inf),)), r"layout.robot_starts\[0\] is \[0.0, -inf\]"),
        (scene(robot_goals=((np.nan, np.nan),)), r"layout.robot_goals\[0\] is \[nan, nan\]"),
        # two bad rows: the first one is named
        (
            scene(humans=((3.0, 0.0), (np.nan, 1.0), (4.0, 0.0), (np.inf, 2.0))),
            r"layout.human_starts\[1\] is \[nan, 1.0\]",
        ),
    ],
)
def test_a_non_finite_start_or_goal_is_refused_by_field_and_row(layout, message):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # before the check, ORCA's NaN came with RuntimeWarnings
        with pytest.raises(SimulationError, match=message + ": every coordinate must be finite"):
            CrowdEnv().reset_layout(layout)


@pytest.mark.parametrize(
    "field, beyond",
    [("robot_starts", (2e9, 0.0)), ("robot_goals", (0.0, -1.5e9)), ("human_starts", (0.0, 2e9))],
)
def test_a_start_or_goal_beyond_the_largest_coordinate_is_refused_by_field_and_row(field, beyond):
    """A layout past crowdsim.world.MOST_COORDINATE was taken: a start there failed at the first step inside
    ORCA ("orca_velocities: every positions component must be ..."), naming no field of the layout, and a
    goal there lies beyond any agent's reach in an episode (8.6e6 m at most)."""
    layout = scene(humans=((3.0, 0.0), (4.0, 0.0)))
    rows = np.array(getattr(layout, field))
    rows[-1] = beyond
    with pytest.raises(SimulationError) as exc:
        CrowdEnv().reset_layout(Layout(**{**vars(layout), field: rows}))
    assert str(exc.value) == (
        f"layout.{field}[{len(rows) - 1}] is {list(beyond)}: every coordinate must be finite and within "
        "±1e+09 m (1 bad row(s))"
    )
    edge = np.where(np.array(beyond) != 0.0, np.sign(beyond) * MOST_COORDINATE, 0.0)
    rows[-1] = edge
    env = CrowdEnv()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env.reset_layout(Layout(**{**vars(layout), field: rows}))
        env.step(np.zeros((1, 2)))  # at the bound, ORCA takes it


def test_wrong_shapes_and_types_are_refused_by_field():
    good = scene()
    bad = {
        "human_starts": (np.zeros(2), r"layout.human_starts must be a \(N, 2\) array, got shape \(2,\)"),
        "robot_goals": (np.zeros((1, 3)), r"layout.robot_goals must be a \(M, 2\) array, got shape \(1, 3\)"),
        "human_goals": (np.zeros((2, 2)), "layout.human_starts has 1 row but layout.human_goals 2"),
        "robot_starts": ([["a", "b"]], r"layout.robot_starts must be a \(M, 2\) array of numbers"),
    }
    for name, (value, message) in bad.items():
        fields = {f: getattr(good, f) for f in ("robot_starts", "robot_goals", "human_starts", "human_goals")}
        with pytest.raises(SimulationError, match=message):
            CrowdEnv().reset_layout(Layout(**(fields | {name: value})))
    with pytest.raises(SimulationError, match="layout must be a crowdsim.scenarios.Layout, got dict"):
        CrowdEnv().reset_layout({"robot_starts": good.robot_starts})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("starts", "held"),
    [
        ([["3", "0"]], "<U1"),
        (np.array([[True, False]]), "bool"),
        (np.array([[3.0, "0"]], dtype=object), "str"),
        (np.array([[3.0, np.True_]], dtype=object), "bool"),
    ],
)
def test_texts_and_booleans_are_no_coordinates(starts, held):
    """The float conversion read "3" as a human at 3 m and True as one at 1 m, where CrowdEnv.step refuses
    such accelerations; the gym env's options["layout"] takes the same check."""
    from crowdsim.gym_env import CrowdNavEnv

    layout = Layout([[0.0, 0.0]], [[0.0, 5.0]], starts, [[3.0, 0.0]])  # type: ignore[arg-type]
    refusal = f"layout.human_starts must hold real numbers, got {held} values"
    with pytest.raises(SimulationError, match=refusal):
        CrowdEnv().reset_layout(layout)
    with pytest.raises(SimulationError, match=refusal):
        CrowdNavEnv(n_robots=1, n_humans=1).reset(seed=0, options={"layout": layout})


def test_lists_are_taken_as_arrays():
    layout = Layout([[0.0, 0.0]], [[0.0, 5.0]], [[3, 0]], [[3, 0]])  # type: ignore[arg-type]
    obs = CrowdEnv().reset_layout(layout)
    assert obs.human_positions.dtype == float and obs.human_positions.tolist() == [[3.0, 0.0]]


# ----------------------------------------------------------------------------------- warned, and run
def test_starts_in_contact_warn_naming_the_pair_and_the_episode_runs():
    layout = scene(humans=((3.0, 0.0), (0.5, 0.0), (3.2, 0.3)))  # 0.5 m from the robot; 0.36 m apart
    with pytest.warns(LayoutWarning) as caught:
        obs = CrowdEnv().reset_layout(layout)
    assert len(caught) == 1
    assert str(caught[0].message) == (
        "layout: 2 pair(s) of agents start closer than 2 x radius = 0.6 m, in contact from the first step, "
        "e.g. robot_starts[0] and human_starts[1] 0.5 m apart"
    )
    assert obs.human_positions[1].tolist() == [0.5, 0.0]


def test_starts_exactly_two_radii_apart_do_not_warn():
    assert start_overlaps(scene(humans=((0.6, 0.0),))) == []
    assert start_overlaps(scene(humans=((0.59, 0.0),))) == [("robot_starts[0]", "human_starts[0]", 0.59)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        CrowdEnv().reset_layout(scene(humans=((0.6, 0.0), (0.0, 5.0))))  # a human on the robot's goal: fine


def test_robot_goals_in_contact_warn_naming_the_pair():
    """Two robots given one goal ran silently: straight-line robots reached it "with success" 0.02 m apart
    (the simulator has no robot-robot contact, the metrics count robot-human contact only), and CMPC, whose
    Eq. 12 keeps them d_min apart, timed out with no word why. Goals 2 radii apart, and humans' goals, do not
    warn."""
    layout = scene(
        robots=((-1.0, 0.0), (1.0, 0.0), (0.0, -2.0)), robot_goals=((0.0, 5.0), (0.0, 5.0), (0.4, 5.0))
    )
    with pytest.warns(LayoutWarning) as caught:
        CrowdEnv().reset_layout(layout)
    assert [str(w.message) for w in caught] == [
        "layout: 3 pair(s) of robot goals closer than 2 x radius = 0.6 m: robots on both goals would "
        "overlap, e.g. robot_goals[0] and robot_goals[1] 0 m apart"
    ]
    apart = scene(robots=((-1.0, 0.0), (1.0, 0.0)), robot_goals=((0.0, 5.0), (0.6, 5.0)))
    shared = scene(humans=((3.0, 0.0), (4.0, 0.0)), human_goals=((-3.0, 0.0), (-3.0, 0.0)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        CrowdEnv().reset_layout(apart)
        CrowdEnv().reset_layout(shared)


def test_reset_runs_the_perpendicular_samplers_overlaps_silently_but_reset_layout_warns():
    # seed 0..: the first 16-human perpendicular layout whose human starts overlap (the fork's 100 draws)
    seed = next(
        s for s in range(20) if start_overlaps(make_layout("perpendicular", 16, 3, np.random.default_rng(s)))
    )
    layout = make_layout("perpendicular", 16, 3, np.random.default_rng(seed))
    env = CrowdEnv()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        obs = env.reset(seed, "perpendicular", 16, 3)
    np.testing.assert_array_equal(obs.human_positions, layout.human_starts)
    with pytest.warns(LayoutWarning, match="in contact from the first step, e.g. human_starts"):
        env.reset_layout(layout)


# ----------------------------------------------------------------------------- a scenario without a sampler
@pytest.mark.parametrize("crossing", ["paper", "v1"])
def test_a_scenario_without_a_sampler_raises_instead_of_running_another(monkeypatch, crossing):
    monkeypatch.setattr(scenarios, "SCENARIOS", (*scenarios.SCENARIOS, "corridor"))
    message = f"crossing '{crossing}' has no sampler for scenario 'corridor'; choose from"
    with pytest.raises(SimulationError, match=message):
        make_layout("corridor", 5, 3, np.random.default_rng(0), crossing=crossing)
    placer = {"paper": place_humans_paper, "v1": place_humans_v1}[crossing]
    with pytest.raises(SimulationError, match=r"\['circle', 'perpendicular'\]"):
        kwargs = {"min_dist": 1.1, "v_pref": 1.0, "scale": 1.0, "max_tries": 10}
        placer("corridor", 0, np.zeros((0, 2)), np.zeros((0, 2)), np.random.default_rng(0), **kwargs)


def test_the_paper_env_refuses_an_unknown_scenario_added_to_the_list(monkeypatch):
    monkeypatch.setattr(scenarios, "SCENARIOS", (*scenarios.SCENARIOS, "corridor"))
    with pytest.raises(SimulationError, match="no sampler for scenario 'corridor'"):
        CrowdEnv().reset(0, "corridor", 5, 3)


# ------------------------------------------------------------------ the sampling facts the docstring states
def _closest_to_a_robot_goal(seed: int) -> float:
    layout = make_layout("circle", 9, 3, np.random.default_rng(seed))
    return float(np.linalg.norm(layout.human_starts[:, None] - layout.robot_goals[None], axis=-1).min())


def test_paper_circle_humans_may_start_on_a_robots_goal():
    # starts are checked against starts only (the fork), not against the robots' goals: 228 of 300 seeds
    assert sum(_closest_to_a_robot_goal(s) < 0.6 for s in range(20)) > 10


def test_paper_perpendicular_overlaps_at_9_humans_as_documented():
    overlapping = [
        s for s in range(100) if start_overlaps(make_layout("perpendicular", 9, 3, np.random.default_rng(s)))
    ]
    assert len(overlapping) == 3
    assert not any(start_overlaps(make_layout("circle", 16, 3, np.random.default_rng(s))) for s in range(20))


def test_the_circle_crowd_changes_with_the_number_of_robots_but_not_with_more_humans():
    env = CrowdEnv()
    one = env.reset(5, "circle", 7, 1).human_positions
    for m in (3, 6):
        other = env.reset(5, "circle", 7, m).human_positions
        same = [i for i in range(7) if np.array_equal(one[i], other[i])]
        assert same == [4, 5, 6]
        np.testing.assert_array_equal(other[:3], one[1:4])  # humans 1-3 move up one place
    perpendicular = env.reset(5, "perpendicular", 7, 1).human_positions
    for m in (3, 6, 12):
        np.testing.assert_array_equal(env.reset(5, "perpendicular", 7, m).human_positions, perpendicular)
    for scenario in ("circle", "perpendicular"):
        sixteen = env.reset(5, scenario, 16, 3).human_positions
        for n in (5, 9):
            np.testing.assert_array_equal(env.reset(5, scenario, n, 3).human_positions, sixteen[:n])
