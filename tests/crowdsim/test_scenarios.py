"""Scenario layouts: the robot row, the humans' geometry and separation, seeding, bad sizes."""

import numpy as np
import pytest

import crowdsim.scenarios as scenarios
from crowdsim.errors import SimulationError
from crowdsim.formations import robot_layout
from crowdsim.scenarios import make_layout


def test_robot_row_three_robots_and_twelve():
    starts, goals = robot_layout(3)
    np.testing.assert_array_equal(starts, [[-1, -5], [0, -5], [1, -5]])
    np.testing.assert_array_equal(goals, [[-1, 5], [0, 5], [1, 5]])
    starts, goals = robot_layout(12, "row")
    np.testing.assert_allclose(starts[[0, -1], 0], [-5.5, 5.5])
    np.testing.assert_allclose(np.diff(starts[:, 0]), 1.0)
    np.testing.assert_array_equal(robot_layout(1)[0], [[0, -5]])


def _separation_ok(layout, min_dist=0.8):
    """v1: each human's start and goal lie >= min_dist from every start and goal placed before."""
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


def _paper_separation_ok(layout, min_dist=1.1):
    """paper: each human's start lies >= min_dist from every placed start, its goal from every placed goal."""
    starts, goals = [*layout.robot_starts], [*layout.robot_goals]
    for start, goal in zip(layout.human_starts, layout.human_goals, strict=True):
        if np.linalg.norm(np.asarray(starts) - start, axis=1).min() < min_dist:
            return False
        if np.linalg.norm(np.asarray(goals) - goal, axis=1).min() < min_dist:
            return False
        starts.append(start)
        goals.append(goal)
    return True


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("crossing", ["paper", "v1"])
def test_circle_crossing_geometry(seed, crossing):
    layout = make_layout("circle", 9, 3, np.random.default_rng(seed), crossing=crossing)
    r = np.linalg.norm(layout.human_starts, axis=1)
    # radius 5 plus noise of at most 0.5 m per coordinate
    assert np.all(r > 5 - 0.5 * np.sqrt(2)) and np.all(r < 5 + 0.5 * np.sqrt(2))
    np.testing.assert_array_equal(layout.human_goals, -layout.human_starts)
    assert _separation_ok(layout) if crossing == "v1" else _paper_separation_ok(layout)


@pytest.mark.parametrize("seed", range(5))
def test_paper_circle_keeps_1_1_m_between_starts_and_between_goals(seed):
    layout = make_layout("circle", 9, 3, np.random.default_rng(seed))  # the paper profile is the default
    for points in (layout.human_starts, layout.human_goals):
        d = np.linalg.norm(points[:, None] - points[None], axis=-1)
        assert d[np.triu_indices(9, k=1)].min() >= 1.1


@pytest.mark.parametrize("seed", range(5))
def test_paper_perpendicular_geometry(seed):
    layout = make_layout("perpendicular", 7, 3, np.random.default_rng(seed))
    sx, sy = layout.human_starts.T
    assert np.all((np.abs(sx) >= 5.0) & (np.abs(sx) <= 6.0))  # U(1.0, 1.2) * 5
    assert np.all(np.abs(sy) <= 5.0)
    # goal = (-px, py) + U[-0.5, 0.5) per coordinate
    assert np.all(np.abs(layout.human_goals - np.stack([-sx, sy], axis=1)) <= 0.5)
    assert _paper_separation_ok(layout)  # 7 humans (the fork's crowd) fit without giving up


def test_paper_draw_order_by_hand():
    # One human and no robots: nothing is rejected, so the draws can be replayed from the same seed.
    layout = make_layout("perpendicular", 1, 0, np.random.default_rng(3))
    rng = np.random.default_rng(3)
    sign = -1.0 if rng.random() > 0.5 else 1.0
    px = rng.uniform(1.0, 1.2) * 5.0 * sign
    py = (rng.random() - 0.5) * 10.0
    gx = -px + (rng.random() - 0.5)
    gy = py + (rng.random() - 0.5)
    np.testing.assert_array_equal(layout.human_starts, [[px, py]])
    np.testing.assert_array_equal(layout.human_goals, [[gx, gy]])
    layout = make_layout("circle", 1, 0, np.random.default_rng(3))
    rng = np.random.default_rng(3)
    angle = rng.random() * 2.0 * np.pi
    start = [5.0 * np.cos(angle) + rng.random() - 0.5, 5.0 * np.sin(angle) + rng.random() - 0.5]
    np.testing.assert_allclose(layout.human_starts, [start], rtol=0, atol=1e-15)


def test_paper_perpendicular_keeps_the_last_draw_after_100():
    # 16 humans overfill the 1 m wide strips at x in [5, 6]: the fork keeps its 100th draw rather than
    # failing, so a layout always exists, but then some starts (or goals) are closer than 1.1 m.
    layouts = [make_layout("perpendicular", 16, 3, np.random.default_rng(seed)) for seed in range(5)]
    assert not all(_paper_separation_ok(layout) for layout in layouts)


@pytest.mark.parametrize("seed", range(5))
def test_perpendicular_crossing_geometry(seed):
    layout = make_layout("perpendicular", 9, 3, np.random.default_rng(seed), crossing="v1")
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
    for crossing, ok in (("v1", _separation_ok), ("paper", _paper_separation_ok)):
        layout = make_layout("circle", 50, 3, np.random.default_rng(0), crossing=crossing)
        r = np.linalg.norm(layout.human_starts, axis=1)
        assert np.all(np.abs(r - 5 * 50 / 16) < 0.5 * np.sqrt(2))
        assert ok(layout)
    layout = make_layout("perpendicular", 50, 12, np.random.default_rng(0), crossing="v1")
    assert _separation_ok(layout)
    layout = make_layout("perpendicular", 50, 12, np.random.default_rng(0))
    assert np.abs(layout.human_starts[:, 1]).max() > 5.0  # the square's vertical extent grew


# Layouts of the first simulator (4 humans, 3 robots), recorded before the profiles existed: the v1
# crossing must reproduce them bit for bit. (Goals of the circle are -starts.)
V1_LAYOUTS = {
    ("circle", 0): (
        [
            [-3.4902946041579606, -4.250051377134366],
            [5.286334377261816, 0.9310538299529497],
            [-3.689573454776717, -3.061353303396766],
            [4.905529822273047, -2.48091261672687],
        ],
        None,
    ),
    ("circle", 7): (
        [
            [-3.136198734300369, -3.26196831426079],
            [5.31849247485067, 0.46245367810475196],
            [-5.095834315252745, 0.7789777813654724],
            [-4.22468447631093, -1.3565366236754857],
        ],
        None,
    ),
    ("perpendicular", 0): (
        [
            [-4.081947047872389, -2.302132862361297],
            [-5.458993121967997, 1.0663577576717986],
            [-5.714808553175139, -4.9726149982985195],
            [5.082922440498184, 3.631789223498866],
        ],
        [
            [4.033055271057059, -1.9888626231610245],
            [5.087249982930846, 1.501430181459567],
            [4.067171150610928, -4.742959551868576],
            [-4.599423781074769, 3.5544764446965242],
        ],
    ),
    ("perpendicular", 7): (
        [
            [-5.551371380490387, 3.9721380096957546],
            [-5.642456836765533, -4.947346954344253],
            [4.509739175308249, -2.2157438789922668],
            [-5.585323838427506, 4.955002834343927],
        ],
        [
            [4.450414379981184, 3.77230429460698],
            [5.594138857504093, -4.979412001500532],
            [-4.890152611765293, -2.2111956200343137],
            [5.244358458882325, 5.443962982025812],
        ],
    ),
}


@pytest.mark.parametrize("scenario, seed", list(V1_LAYOUTS))
def test_v1_layouts_are_the_first_simulators(scenario, seed):
    layout = make_layout(scenario, 4, 3, np.random.default_rng(seed), crossing="v1")
    starts, goals = V1_LAYOUTS[scenario, seed]
    np.testing.assert_array_equal(layout.human_starts, starts)
    np.testing.assert_array_equal(layout.human_goals, -np.asarray(starts) if goals is None else goals)


def test_bad_sizes_name_the_value(monkeypatch):
    rng = np.random.default_rng(0)
    with pytest.raises(SimulationError, match="'triangle'"):
        make_layout("triangle", 5, 3, rng)
    with pytest.raises(SimulationError, match="-1"):
        make_layout("circle", -1, 3, rng)
    with pytest.raises(SimulationError, match="2.5"):
        make_layout("circle", 2.5, 3, rng)
    # bools are ints to Python, but no count (True would silently mean one)
    with pytest.raises(SimulationError, match="n_humans must be an int, got True"):
        make_layout("circle", True, 3, rng)
    with pytest.raises(SimulationError, match="n_robots must be an int, got True"):
        make_layout("circle", 5, True, rng)
    with pytest.raises(SimulationError, match="crossing 'v2'"):
        make_layout("circle", 5, 3, rng, crossing="v2")
    with pytest.raises(SimulationError, match="spawn_separation.*-1"):
        make_layout("circle", 5, 3, rng, spawn_separation=-1.0)
    # a nan radius or speed failed every draw ("could not place human 1 ...; use fewer agents"), and a
    # negative radius was taken
    for name, bad in [("radius", -5.0), ("radius", 0.0), ("radius", np.nan), ("v_pref", np.nan)]:
        with pytest.raises(SimulationError, match=rf"^{name} must be a finite number > 0 m.*, got {bad!r}$"):
            make_layout("circle", 5, 3, rng, **{name: bad})
    for scenario in ("circle", "perpendicular"):
        with pytest.raises(SimulationError, match=r"^v_pref must be a finite number > 0 m/s, got inf$"):
            make_layout(scenario, 5, 3, rng, v_pref=np.inf)
    # 0 is allowed (>= 0): the humans then keep only the two radii, 0.6 m, from each other
    tight = make_layout("circle", 9, 3, rng, spawn_separation=0.0)
    assert _paper_separation_ok(tight, min_dist=0.6)
    monkeypatch.setattr(scenarios, "MAX_TRIES", 1)
    for crossing in ("paper", "v1"):
        with pytest.raises(SimulationError, match="n_humans=16"):
            make_layout("circle", 16, 3, rng, crossing=crossing)
    make_layout("perpendicular", 16, 3, rng)  # the fork's square crossing gives up, never fails


@pytest.mark.parametrize("crossing", ["paper", "v1"])
def test_a_layout_too_spread_to_sample_names_the_distance_it_asked_for(crossing):
    """`--set env.spawn_separation=50 --humans 1 --robots 1` said "could not place human 1 of n_humans=1 ...
    with 1 robots ...; use fewer agents": there were no fewer to use. The distance the draws must keep, and
    what sets it, are what the user can change."""
    rng = np.random.default_rng(0)
    with pytest.raises(SimulationError) as caught:
        make_layout("circle", 1, 1, rng, crossing=crossing, spawn_separation=50.0)
    message = str(caught.value)
    assert "each start and goal 50.6 m apart (2 x radius + spawn_separation)" in message
    assert message.endswith("use fewer agents, or a smaller spawn_separation or radius")
