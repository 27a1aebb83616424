"""Robot formations: hand-computed coordinates, spacing against the MPC's d_ij and d_min, goals no robot
must pass once they are taken, the three-robot row unchanged, and the humans' sampling around 12 robots."""

import math

import numpy as np
import pytest

from crowdsim import world
from crowdsim.errors import SimulationError
from crowdsim.formations import FORMATIONS, ROBOT_SPACING, choose_formation, rank_sizes, robot_layout
from crowdsim.scenarios import MAX_ROBOTS, make_layout
from mpc.config import MPCConfig

TABLE_I = MPCConfig()
S = TABLE_I.d_flock  # lattice spacing: the flocking distance d_ij
H = S * math.sqrt(3) / 2  # rank depth of the hexagonal lattice
TRAVEL = np.array([0.0, 10.0])  # every goal is its start 10 m north
TOL = 1e-9


def _pair_distances(points):
    d = np.linalg.norm(points[:, None] - points[None], axis=-1)
    return d[np.triu_indices(len(points), k=1)]


def _segment_point_distance(a, b, p):
    ab = b - a
    t = np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0.0, 1.0)
    return float(np.linalg.norm(a + t * ab - p))


def _is_row(m, formation):
    return formation == "row" or (formation == "auto" and choose_formation(m) == "row")


def test_the_formations_read_the_mpcs_distances():
    assert (world.D_MIN, world.D_FLOCK) == (TABLE_I.d_min, TABLE_I.d_flock)
    assert TABLE_I.d_min < ROBOT_SPACING < TABLE_I.d_flock  # the row's 1 m lies between them


@pytest.mark.parametrize("m", [1, 2, 3])
def test_up_to_three_robots_keep_the_first_row(m):
    starts, goals = robot_layout(m)
    x = {1: [0.0], 2: [-0.5, 0.5], 3: [-1.0, 0.0, 1.0]}[m]
    np.testing.assert_array_equal(starts, np.stack([x, [-5.0] * m], axis=1))
    np.testing.assert_array_equal(goals, np.stack([x, [5.0] * m], axis=1))
    np.testing.assert_array_equal(robot_layout(m, "row")[0], starts)
    assert choose_formation(m) == "row"


def test_auto_picks_the_row_then_the_wedge():
    assert [choose_formation(m) for m in range(1, MAX_ROBOTS + 1)] == ["row"] * 3 + ["wedge"] * 9
    assert rank_sizes("wedge", 12) == [1, 2, 3, 4, 2]
    assert rank_sizes("wedge", 6) == [1, 2, 3] and rank_sizes("wedge", 4) == [1, 2, 1]
    assert rank_sizes("two_rows", 5) == [3, 2] and rank_sizes("two_rows", 1) == [1]


def test_five_robots_wedge_by_hand():
    # ranks 1 + 2 + 2: x slots {0}, {-S/2, S/2}, {0, S} (the tie goes right); centred: shift x by -S/4, y by H
    starts, goals = robot_layout(5)
    expected = [[-0.75 * S, 0], [-0.25 * S, H], [-0.25 * S, -H], [0.25 * S, 0], [0.75 * S, -H]]
    np.testing.assert_allclose(starts, np.add(expected, [0, -5]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(goals, starts + TRAVEL, rtol=0, atol=1e-12)
    np.testing.assert_allclose(starts[:2], [[-0.9, -5.0], [-0.3, -3.960769]], atol=1e-6)


def test_six_robots_wedge_by_hand():
    starts, goals = robot_layout(6)  # ranks 1 + 2 + 3: a triangle
    expected = [[-S, -H], [-S / 2, 0], [0, H], [0, -H], [S / 2, 0], [S, -H]]
    np.testing.assert_allclose(starts, np.add(expected, [0, -5]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(goals, starts + TRAVEL, rtol=0, atol=1e-12)


def test_twelve_robots_wedge_by_hand():
    starts, goals = robot_layout(12)  # ranks 1 + 2 + 3 + 4 + 2, five ranks centred on y = -5
    expected = [
        [-1.5 * S, -H],
        [-S, 0],
        [-S / 2, H],
        [-S / 2, -H],
        [0, 2 * H],
        [0, 0],
        [0, -2 * H],
        [S / 2, H],
        [S / 2, -H],
        [S, 0],
        [S, -2 * H],
        [1.5 * S, -H],
    ]
    np.testing.assert_allclose(starts, np.add(expected, [0, -5]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(goals, starts + TRAVEL, rtol=0, atol=1e-12)
    width, depth = np.ptp(starts, axis=0)
    assert math.isclose(width, 3 * S) and math.isclose(depth, 4 * H)  # 3.6 m x 4.2 m (the row: 11 m)


def test_six_robots_in_two_rows_by_hand():
    starts, goals = robot_layout(6, "two_rows")
    front = [[-1.25 * S, H / 2], [-0.25 * S, H / 2], [0.75 * S, H / 2]]
    back = [[-0.75 * S, -H / 2], [0.25 * S, -H / 2], [1.25 * S, -H / 2]]
    expected = [front[0], back[0], front[1], back[1], front[2], back[2]]
    np.testing.assert_allclose(starts, np.add(expected, [0, -5]), rtol=0, atol=1e-12)
    # two equal rows: the goals are the starts turned half a turn about the origin
    np.testing.assert_allclose(goals, -starts[::-1], rtol=0, atol=1e-12)


def test_the_spacing_can_be_given():
    starts, _ = robot_layout(4, "two_rows", spacing=1.0)
    h = math.sqrt(3) / 4
    np.testing.assert_allclose(starts, [[-0.75, h - 5], [-0.25, -h - 5], [0.25, h - 5], [0.75, -h - 5]])


def test_the_spacing_may_be_d_min_itself():
    # The bound is spacing >= d_min (0.8 m): two rows of 2 at 0.8 m, neighbours 0.8 m apart, is allowed.
    starts, _ = robot_layout(4, "two_rows", spacing=world.D_MIN)
    d = np.linalg.norm(starts[:, None] - starts[None], axis=-1)[np.triu_indices(4, k=1)]
    assert d.min() == pytest.approx(world.D_MIN)


def test_the_row_can_still_be_chosen_for_any_number():
    starts, goals = robot_layout(12, "row")
    np.testing.assert_array_equal(starts[:, 0], np.arange(12) - 5.5)
    np.testing.assert_array_equal(starts[:, 1], -5.0)
    np.testing.assert_array_equal(goals[:, 1], 5.0)


# the formations of a team travelling together; "antipodal" (robots trading places) has its own tests below
FORMED = [(m, f) for m in range(1, MAX_ROBOTS + 1) for f in FORMATIONS if f != "antipodal"]


@pytest.mark.parametrize("m, formation", FORMED)
def test_starts_and_goals_keep_the_spacing(m, formation):
    starts, goals = robot_layout(m, formation)
    assert starts.shape == goals.shape == (m, 2)
    np.testing.assert_allclose(goals - starts, np.tile(TRAVEL, (m, 1)), rtol=0, atol=1e-12)
    if m == 1:
        return
    d = _pair_distances(starts)
    if _is_row(m, formation):  # the first layout: 1 m, between d_min and d_ij
        assert d.min() >= TABLE_I.d_min
    else:  # the hexagonal formations: no pair closer than d_ij, neighbours exactly d_ij apart
        assert d.min() >= TABLE_I.d_flock - TOL and math.isclose(d.min(), TABLE_I.d_flock)


def _near_goals(starts, goals):
    """(i, j): robot i's straight path comes within d_min of robot j's goal."""
    m = len(starts)
    return [
        (i, j)
        for i in range(m)
        for j in range(m)
        if i != j and _segment_point_distance(starts[i], goals[i], goals[j]) < TABLE_I.d_min
    ]


@pytest.mark.parametrize("m, formation", FORMED)
def test_no_robot_must_pass_a_goal_already_taken(m, formation):
    """A robot's straight path comes within d_min only of goals of robots that start behind it: they travel
    the same 10 m north, so they get there after it has gone by. The row leaves every goal d_min clear.

    In the hexagonal formations every robot of a rank behind another is S/2 = 0.6 m to the side of one
    ahead, less than d_min = 0.8 m: so with 2 robots or more some path passes a goal, and the rule is checked.
    """
    starts, goals = robot_layout(m, formation)
    near = _near_goals(starts, goals)
    if _is_row(m, formation) or m == 1:
        assert near == []
        return
    assert near, (m, formation)
    for i, j in near:
        assert starts[j, 1] <= starts[i, 1] - TABLE_I.d_min, (m, formation, i, j)


def test_the_wedges_apex_passes_the_goals_of_the_two_behind_it():
    """Three robots in a wedge: the apex (robot 1) at x = 0, a rank depth H ahead of robots 0 and 2 at
    x = -/+S/2; its path x = 0 passes their goals 0.6 m to its side, and they start H = 1.04 m >= d_min
    behind it."""
    starts, goals = robot_layout(3, "wedge")
    np.testing.assert_allclose(starts[:, 0], [-S / 2, 0.0, S / 2], rtol=0, atol=TOL)
    np.testing.assert_allclose(starts[[0, 2], 1] - starts[1, 1], [-H, -H], rtol=0, atol=TOL)
    assert _near_goals(starts, goals) == [(1, 0), (1, 2)]


def test_bad_formations_name_the_value():
    with pytest.raises(SimulationError, match="'ring'"):
        robot_layout(4, "ring")
    with pytest.raises(SimulationError, match="'ring'"):
        make_layout("circle", 5, 4, np.random.default_rng(0), formation="ring")
    with pytest.raises(SimulationError, match="spacing.*0.5"):
        robot_layout(4, spacing=0.5)
    with pytest.raises(SimulationError, match="-2"):
        robot_layout(-2)
    with pytest.raises(SimulationError, match="n_robots must be an int >= 0, got True"):
        robot_layout(True)  # a bool is no count (True would lay out one robot)
    with pytest.raises(SimulationError, match="'row' has no ranks"):
        rank_sizes("row", 3)


def _humans_clear(layout, crossing, scenario):
    """Every human start and goal keeps the crossing's separation from the robots' starts and goals."""
    robots = np.concatenate([layout.robot_starts, layout.robot_goals])
    if crossing == "v1":  # each start and goal against every robot start and goal
        for points in (layout.human_starts, layout.human_goals):
            assert np.linalg.norm(points[:, None] - robots[None], axis=-1).min() >= 0.8
    elif scenario == "circle":  # the fork: starts against starts, goals against goals
        pairs = ((layout.human_starts, layout.robot_starts), (layout.human_goals, layout.robot_goals))
        for humans, placed in pairs:
            assert np.linalg.norm(humans[:, None] - placed[None], axis=-1).min() >= 1.1


@pytest.mark.parametrize("crossing", ["paper", "v1"])
@pytest.mark.parametrize("scenario", ["circle", "perpendicular"])
@pytest.mark.parametrize("m", [4, 5, 6, 7, 12])
def test_humans_are_placed_around_every_formation(crossing, scenario, m):
    # 17-18 humans enlarge the circle onto the robots' ranks: the tightest fit
    for n_humans, seeds in ((5, 2), (9, 2), (17, 3), (18, 3), (50, 1)):
        for seed in range(seeds):
            layout = make_layout(scenario, n_humans, m, np.random.default_rng(seed), crossing=crossing)
            np.testing.assert_array_equal(layout.robot_starts, robot_layout(m)[0])
            assert layout.human_starts.shape == layout.human_goals.shape == (n_humans, 2)
            _humans_clear(layout, crossing, scenario)


def test_the_antipodal_circle_by_hand():
    """Robots trading places: on a 3.5 m circle from (0, -3.5) anticlockwise, each bound for the opposite
    point; exact zeros, never -0.0, where cos and sin should give them (opposite robots then meet exactly
    head-on, which mpc/head_on.py breaks); neighbours 7 sin(pi / M) m apart; the spacing does not apply."""
    starts, goals = robot_layout(3, "antipodal")
    h = 3.5 * math.sqrt(3) / 2
    np.testing.assert_allclose(starts, [[0.0, -3.5], [h, 1.75], [-h, 1.75]], rtol=0, atol=1e-12)
    np.testing.assert_allclose(goals, [[0.0, 3.5], [-h, -1.75], [h, -1.75]], rtol=0, atol=1e-12)
    starts, goals = robot_layout(4, "antipodal")
    np.testing.assert_array_equal(starts, [[0.0, -3.5], [3.5, 0.0], [0.0, 3.5], [-3.5, 0.0]])
    np.testing.assert_array_equal(goals, [[0.0, 3.5], [-3.5, 0.0], [0.0, -3.5], [3.5, 0.0]])
    for m in range(1, MAX_ROBOTS + 1):
        starts, goals = robot_layout(m, "antipodal")
        assert not np.signbit(starts[starts == 0]).any() and not np.signbit(goals[goals == 0]).any()
        if m > 1:
            assert math.isclose(_pair_distances(starts).min(), 7 * math.sin(math.pi / m), rel_tol=1e-12)
    assert robot_layout(3, "antipodal", spacing=2.0)[0].tolist() == robot_layout(3, "antipodal")[0].tolist()


@pytest.mark.parametrize("scenario", ["circle", "perpendicular"])
@pytest.mark.parametrize("m", [2, 4, 12])
def test_people_are_placed_clear_of_robots_trading_places(scenario, m):
    """On a 5 m circle the robots stood where the crossings start people: the perpendicular sampler, which
    keeps its last draw after 100, started people on robots (13 of 100 crowds of 16), and 12 robots left 16
    people of the circle no room. At 3.5 m every start keeps the samplers' 1.1 m from every robot."""
    for n_humans in (5, 12, 16, 20, 50):
        for seed in range(4):
            layout = make_layout(scenario, n_humans, m, np.random.default_rng(seed), formation="antipodal")
            gaps = np.linalg.norm(layout.human_starts[:, None] - layout.robot_starts[None], axis=-1)
            assert gaps.min() >= 1.1, (n_humans, seed)


def test_the_formations_stay_importable_from_scenarios():
    """They lived in crowdsim.scenarios before crowdsim.formations: code written then still imports them."""
    import crowdsim.formations as formations
    import crowdsim.scenarios as scenarios

    for name in ("Formation", "FORMATIONS", "choose_formation", "robot_layout"):
        assert getattr(scenarios, name) is getattr(formations, name), name
