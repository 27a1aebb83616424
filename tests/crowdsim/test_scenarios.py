"""Scenario layouts: the robot row, the humans' geometry and separation, seeding, bad sizes."""

import numpy as np
import pytest

import crowdsim.scenarios as scenarios
from crowdsim.errors import SimulationError
from crowdsim.scenarios import make_layout, robot_layout


def test_robot_row_three_robots_and_twelve():
    starts, goals = robot_layout(3)
    np.testing.assert_array_equal(starts, [[-1, -5], [0, -5], [1, -5]])
    np.testing.assert_array_equal(goals, [[-1, 5], [0, 5], [1, 5]])
    starts, goals = robot_layout(12)
    np.testing.assert_allclose(starts[[0, -1], 0], [-5.5, 5.5])
    np.testing.assert_allclose(np.diff(starts[:, 0]), 1.0)
    np.testing.assert_array_equal(robot_layout(1)[0], [[0, -5]])


def _separation_ok(layout, min_dist=0.8):
    """Each human's start and goal lie >= min_dist from every start and goal of the agents placed before."""
    placed = [*layout.robot_starts, *layout.robot_goals]
    for start, goal in zip(layout.human_starts, layout.human_goals, strict=True):
        pts = np.asarray(placed)
        if (
            min(np.linalg.norm(pts - start, axis=1).min(), np.linalg.norm(pts - goal, axis=1).min())
            < min_dist
        ):
            return False
        placed += [start, goal]
    return True


@pytest.mark.parametrize("seed", range(5))
def test_circle_crossing_geometry(seed):
    layout = make_layout("circle", 9, 3, np.random.default_rng(seed))
    r = np.linalg.norm(layout.human_starts, axis=1)
    # radius 5 plus noise of at most 0.5 m per coordinate
    assert np.all(r > 5 - 0.5 * np.sqrt(2)) and np.all(r < 5 + 0.5 * np.sqrt(2))
    np.testing.assert_array_equal(layout.human_goals, -layout.human_starts)
    assert _separation_ok(layout)


@pytest.mark.parametrize("seed", range(5))
def test_perpendicular_crossing_geometry(seed):
    layout = make_layout("perpendicular", 9, 3, np.random.default_rng(seed))
    sx, gx = layout.human_starts[:, 0], layout.human_goals[:, 0]
    assert np.all((np.abs(sx) >= 4) & (np.abs(sx) <= 6)) and np.all(np.sign(sx) == -np.sign(gx))
    assert np.all(np.abs(layout.human_starts[:, 1]) <= 5)
    assert np.all(np.abs(layout.human_goals[:, 1] - layout.human_starts[:, 1]) <= 0.5)  # nearly horizontal
    assert _separation_ok(layout)


def test_same_seed_same_layout():
    a = make_layout("circle", 7, 3, np.random.default_rng(42))
    b = make_layout("circle", 7, 3, np.random.default_rng(42))
    c = make_layout("circle", 7, 3, np.random.default_rng(43))
    np.testing.assert_array_equal(a.human_starts, b.human_starts)
    assert not np.array_equal(a.human_starts, c.human_starts)


def test_large_crowds_enlarge_the_geometry():
    layout = make_layout("circle", 50, 3, np.random.default_rng(0))
    r = np.linalg.norm(layout.human_starts, axis=1)
    assert np.all(np.abs(r - 5 * 50 / 16) < 0.5 * np.sqrt(2))
    assert _separation_ok(layout)
    layout = make_layout("perpendicular", 50, 12, np.random.default_rng(0))
    assert _separation_ok(layout)


def test_bad_sizes_name_the_value(monkeypatch):
    rng = np.random.default_rng(0)
    with pytest.raises(SimulationError, match="'triangle'"):
        make_layout("triangle", 5, 3, rng)
    with pytest.raises(SimulationError, match="-1"):
        make_layout("circle", -1, 3, rng)
    with pytest.raises(SimulationError, match="2.5"):
        make_layout("circle", 2.5, 3, rng)
    monkeypatch.setattr(scenarios, "MAX_TRIES", 1)
    with pytest.raises(SimulationError, match="n_humans=16"):
        make_layout("circle", 16, 3, rng)
