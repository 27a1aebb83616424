"""ORCA against hand-computed cases, brute-force geometry and an independent optimiser."""

import math
import re
import warnings

import numpy as np
import pytest

from crowdsim.errors import SimulationError
from crowdsim.orca import (
    OrcaParams,
    nearest_neighbors,
    orca_halfplanes,
    orca_velocities,
    preferred_velocities,
)

PARAMS = OrcaParams()  # neighbour distance 10 m, 10 neighbours, time horizon 5 s
DT = 0.4


def rvo_step(positions, velocities, goals, radius=0.3, speed=1.0, dt=DT, params=PARAMS):
    """One RVO2 doStep for everyone: new velocities from the current state, then move."""
    pref = preferred_velocities(positions, goals, speed, stop_radius=radius)
    new, lp3 = orca_velocities(positions, velocities, pref, radius, speed, params, dt)
    return positions + dt * new, new, lp3


def test_params_validation_names_the_value():
    with pytest.raises(SimulationError, match="max_neighbors.*-1"):
        OrcaParams(max_neighbors=-1)
    with pytest.raises(SimulationError, match="time_horizon.*0"):
        OrcaParams(time_horizon=0.0)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        # squared: 1e300 passed and ended the first step in OverflowError
        (
            {"neighbor_dist": 1e300},
            "neighbor_dist must be a number > 0 and at most 1e+06 m, or inf (every agent)",
        ),
        ({"neighbor_dist": math.nan}, "neighbor_dist must be a number > 0"),
        # 1 / time_horizon scales positions: 1e-305 overflowed the velocity obstacles
        ({"time_horizon": 1e-305}, "time_horizon must be a number of at least 1e-06 s, got 1e-305"),
    ],
)
def test_lengths_and_times_whose_squares_or_quotients_overflow_are_refused(settings, message):
    with pytest.raises(SimulationError, match=re.escape(message)):
        OrcaParams(**settings)


def test_every_agent_is_a_neighbour_at_an_infinite_neighbour_distance():
    # 4 m apart head-on (test_a_neighbour_out_of_range_sets_no_line): a line at 1e6 m and at inf, as at 10 m.
    p = np.array([[-2.0, 0.0], [2.0, 0.0]])
    for dist in (1e6, math.inf):
        _, _, counts = orca_halfplanes(
            p, np.zeros((2, 2)), np.full(2, 0.3), np.arange(2), OrcaParams(neighbor_dist=dist), DT
        )
        np.testing.assert_array_equal(counts, [1, 1])


def test_preferred_velocity_unit_far_raw_near_zero_at_goal():
    positions = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    goals = np.array([[3.0, 4.0], [0.6, 0.0], [0.2, 0.0]])
    pref = preferred_velocities(positions, goals, 1.0, stop_radius=0.3)
    np.testing.assert_allclose(pref, [[0.6, 0.8], [0.6, 0.0], [0.0, 0.0]])


def test_one_agent_alone_walks_straight_at_preferred_speed():
    p = np.array([[0.0, 0.0]])
    v = np.zeros((1, 2))
    goal = np.array([[6.0, 0.0]])
    xs = []
    for _ in range(12):
        p, v, lp3 = rvo_step(p, v, goal)
        xs.append(p[0].copy())
        assert not lp3.any()
    xs = np.array(xs)
    # The goal is still more than 1 m away at x = 4.8, so the first 12 steps are all at 1 m/s.
    np.testing.assert_allclose(xs[:, 0], 0.4 * np.arange(1, 13), atol=1e-12)
    np.testing.assert_allclose(xs[:, 1], 0.0, atol=1e-15)
    # Then: 1.2 m away -> 1 m/s -> x = 5.2; 0.8 m away -> v = 0.8 -> 5.52; 0.48 away -> v = 0.48 -> 5.712.
    for expected in (5.2, 5.52, 5.712):
        p, v, _ = rvo_step(p, v, goal)
        assert p[0, 0] == pytest.approx(expected, abs=1e-12)
    # 0.288 m from the goal, within its radius: it stops there.
    p, v, _ = rvo_step(p, v, goal)
    np.testing.assert_allclose(v, 0.0)
    assert p[0, 0] == pytest.approx(5.712, abs=1e-12)


def test_head_on_first_step_hand_computed():
    # A at (-2, 0), B at (2, 0), both still, radii 0.3 (R = 0.6), tau_h = 5 s.
    # w = 0 - (4, 0)/5 = (-0.8, 0): behind the cut-off centre -> project on the cut-off circle:
    # u = (R/5 - 0.8) * (-1, 0) = (0.68, 0); A's line: point (0.34, 0), direction (0, 1) -> v_x <= 0.34.
    p = np.array([[-2.0, 0.0], [2.0, 0.0]])
    v = np.zeros((2, 2))
    points, dirs, counts = orca_halfplanes(p, v, np.full(2, 0.3), np.arange(2), PARAMS, DT)
    np.testing.assert_array_equal(counts, [1, 1])
    np.testing.assert_allclose(points[0, 0], [0.34, 0.0], atol=1e-12)
    np.testing.assert_allclose(dirs[0, 0], [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(points[1, 0], [-0.34, 0.0], atol=1e-12)
    np.testing.assert_allclose(dirs[1, 0], [0.0, -1.0], atol=1e-12)
    pref = np.array([[1.0, 0.0], [-1.0, 0.0]])
    new, lp3 = orca_velocities(p, v, pref, 0.3, 1.0, PARAMS, DT)
    np.testing.assert_allclose(new, [[0.34, 0.0], [-0.34, 0.0]], atol=1e-12)
    assert not lp3.any()


def test_leg_projection_hand_computed():
    # A at 0 moving (1, 0), B at (2, 0) still: w = (1, 0) - (2, 0)/5 = (0.6, 0) points ahead -> legs.
    # det(rel, w) = 0 -> right leg: direction -(2 leg, -2 R)/4 with leg = sqrt(4 - 0.36) = sqrt(3.64),
    # i.e. (-sqrt(0.91), 0.3); u = (v.d) d - v = (0.91 - 1, -0.3 sqrt(0.91)); point = v + u/2.
    p = np.array([[0.0, 0.0], [2.0, 0.0]])
    v = np.array([[1.0, 0.0], [0.0, 0.0]])
    points, dirs, _ = orca_halfplanes(p, v, np.full(2, 0.3), np.array([0]), PARAMS, DT)
    s = math.sqrt(0.91)
    np.testing.assert_allclose(dirs[0, 0], [-s, 0.3], atol=1e-12)
    np.testing.assert_allclose(points[0, 0], [1.0 - 0.045, -0.15 * s], atol=1e-12)


def test_head_on_pass_symmetrically_without_contact():
    # Offset by 0.1 m laterally so the symmetry between "pass left" and "pass right" is broken; the motion
    # stays point-symmetric about the origin (B's state is exactly minus A's).
    p = np.array([[-4.0, -0.05], [4.0, 0.05]])
    v = np.zeros((2, 2))
    goals = np.array([[4.0, -0.05], [-4.0, 0.05]])
    min_dist, max_lateral = np.inf, 0.0
    for _ in range(40):
        p, v, lp3 = rvo_step(p, v, goals)
        assert not lp3.any()
        np.testing.assert_allclose(p[1], -p[0], atol=1e-12)
        min_dist = min(min_dist, np.linalg.norm(p[1] - p[0]))
        max_lateral = max(max_lateral, abs(p[0, 1] + 0.05))
    assert min_dist >= 0.6 - 1e-9
    assert max_lateral > 0.15  # they did step aside
    np.testing.assert_allclose(p, goals, atol=0.3)  # and both arrived


def test_perfectly_aligned_head_on_slows_down_but_never_touches():
    # RVO2 has no tie-breaker: exactly aligned agents get no lateral component and stop facing each other
    # (the known symmetric deadlock); ORCA still keeps them apart.
    p = np.array([[-2.0, 0.0], [2.0, 0.0]])
    v = np.zeros((2, 2))
    goals = np.array([[2.0, 0.0], [-2.0, 0.0]])
    for _ in range(60):
        p, v, _ = rvo_step(p, v, goals)
        assert np.linalg.norm(p[1] - p[0]) >= 0.6 - 1e-9
    np.testing.assert_allclose(p[:, 1], 0.0, atol=1e-15)
    assert np.abs(v).max() < 0.05


def test_overlapping_agents_move_apart_in_one_step():
    # A at 0, B at (0.4, 0), still, R = 0.6: w = 0 - (0.4, 0)/dt = (-1, 0), |w| = 1;
    # u = (0.6/0.4 - 1) * (-1, 0) = (-0.5, 0); A's line: point (-0.25, 0), direction (0, 1) -> v_x <= -0.25.
    p = np.array([[0.0, 0.0], [0.4, 0.0]])
    v = np.zeros((2, 2))
    pref = np.zeros((2, 2))
    new, lp3 = orca_velocities(p, v, pref, 0.3, 1.0, PARAMS, DT)
    np.testing.assert_allclose(new, [[-0.25, 0.0], [0.25, 0.0]], atol=1e-12)
    assert not lp3.any()
    p_next = p + DT * new
    assert np.linalg.norm(p_next[1] - p_next[0]) == pytest.approx(0.6, abs=1e-12)


def test_dense_case_uses_the_3d_program():
    # An agent with four overlapping neighbours at 0.4 m (N, S, E, W): each demands moving away from it at
    # 0.25 m/s, so v_x <= -0.25 and v_x >= 0.25 at once: the 2-D program is infeasible. The 3-D program
    # minimises the largest violation, max(v_x + .25, .25 - v_x, v_y + .25, .25 - v_y), uniquely at v = 0.
    p = np.array([[0.0, 0.0], [0.4, 0.0], [-0.4, 0.0], [0.0, 0.4], [0.0, -0.4]])
    v = np.zeros((5, 2))
    pref = np.array([[1.0, 0.0]])
    new, lp3 = orca_velocities(p, v, pref, 0.3, 1.0, PARAMS, DT, agents=np.array([0]))
    assert lp3[0]
    np.testing.assert_allclose(new[0], [0.0, 0.0], atol=1e-9)


def test_neighbours_are_the_nearest_within_range_sorted():
    params = OrcaParams(neighbor_dist=3.0, max_neighbors=2)
    p = np.array([[0.0, 0.0], [2.5, 0.0], [1.0, 0.0], [0.0, 2.0], [10.0, 0.0]])
    idx, valid = nearest_neighbors(p, np.array([0, 4]), params)
    np.testing.assert_array_equal(idx[0], [2, 3])  # 1 m, then 2 m; 2.5 m is the third nearest: dropped
    np.testing.assert_array_equal(valid[0], [True, True])
    np.testing.assert_array_equal(valid[1], [False, False])  # agent 4 is 7.5 m from everyone


def _in_truncated_vo(x, rel, radius, horizon):
    """Brute-force membership: relative velocity x collides within horizon (some t in [0, tau])."""
    xx = np.einsum("...i,...i->...", x, x)
    t = np.clip(np.einsum("...i,i->...", x, rel) / np.where(xx > 0, xx, 1.0), 0.0, horizon)
    return np.linalg.norm(rel - t[..., None] * x, axis=-1) < radius


@pytest.mark.parametrize(
    "rel, rel_vel",
    [
        ((2.0, 0.5), (0.3, 0.4)),  # outside, nearest the left leg
        ((2.0, 0.0), (1.0, -0.3)),  # inside, nearest the right leg
        ((1.5, 1.0), (0.1, 0.1)),  # inside the cut-off disc region
        ((3.0, 0.0), (-0.2, 0.1)),  # behind the cut-off circle
    ],
)
def test_halfplane_is_the_smallest_exit_from_the_truncated_vo(rel, rel_vel):
    # The ORCA paper: u = (closest point of the VO boundary to the relative velocity) - relative velocity.
    # Brute force: the boundary cells of a fine grid of the VO's membership test.
    rel, rel_vel = np.array(rel), np.array(rel_vel)
    p = np.array([[0.0, 0.0], rel])
    v = np.array([rel_vel, [0.0, 0.0]])
    points, dirs, _ = orca_halfplanes(p, v, np.full(2, 0.3), np.array([0]), PARAMS, DT)
    u = 2.0 * (points[0, 0] - v[0])
    h = 0.004
    g = np.arange(-2.0, 2.0, h)
    grid = rel_vel + np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1)
    inside = _in_truncated_vo(grid, rel, 0.6, PARAMS.time_horizon)
    edge = inside ^ np.roll(inside, 1, 0) | inside ^ np.roll(inside, 1, 1)
    nearest = np.linalg.norm(grid[edge] - rel_vel, axis=1).min()
    assert np.linalg.norm(u) == pytest.approx(nearest, abs=2 * h)
    # rel_vel + u lies on the boundary: just beyond it (along u) is outside, just before it inside.
    unit = u / np.linalg.norm(u)
    was_inside = _in_truncated_vo(rel_vel, rel, 0.6, PARAMS.time_horizon)
    assert _in_truncated_vo(rel_vel + u + 1e-6 * unit, rel, 0.6, PARAMS.time_horizon) != was_inside
    assert _in_truncated_vo(rel_vel + u - 1e-6 * unit, rel, 0.6, PARAMS.time_horizon) == was_inside
    # The line is perpendicular to u (where u is not tiny).
    assert abs(np.dot(dirs[0, 0], u)) <= 1e-9 * max(1.0, np.linalg.norm(u))


def _violation(v, points, dirs):
    return dirs[:, 0] * (points[:, 1] - v[1]) - dirs[:, 1] * (points[:, 0] - v[0])


def test_2d_program_finds_the_closest_feasible_velocity_to_the_preferred_one():
    optimize = pytest.importorskip("scipy.optimize")
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(60):
        p = rng.uniform(-3, 3, (6, 2))
        if np.linalg.norm(p[:, None] - p[None], axis=-1)[np.triu_indices(6, 1)].min() < 0.7:
            continue
        v = rng.uniform(-0.7, 0.7, (6, 2))
        pref = rng.uniform(-1.5, 1.5, (1, 2))
        new, lp3 = orca_velocities(p, v, pref, 0.3, 1.0, PARAMS, DT, agents=np.array([0]))
        if lp3[0]:
            continue
        points, dirs, c = orca_halfplanes(p, v, np.full(6, 0.3), np.array([0]), PARAMS, DT)
        points, dirs = points[0, : c[0]], dirs[0, : c[0]]
        assert _violation(new[0], points, dirs).max() <= 1e-9
        assert np.linalg.norm(new[0]) <= 1.0 + 1e-9
        cons = [
            {"type": "ineq", "fun": lambda x, p=points, d=dirs: -_violation(x, p, d)},
            {"type": "ineq", "fun": lambda x: 1.0 - x @ x},
        ]

        def distance_sq(x, target=pref[0]):
            return np.sum((x - target) ** 2)

        ref = optimize.minimize(distance_sq, new[0], constraints=cons, method="SLSQP", tol=1e-12)
        assert np.sum((new[0] - pref[0]) ** 2) <= ref.fun + 1e-7
        checked += 1
    assert checked >= 20


def test_3d_program_minimises_the_largest_violation():
    optimize = pytest.importorskip("scipy.optimize")
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(200):
        p = rng.uniform(-0.7, 0.7, (7, 2))
        v = rng.uniform(-1, 1, (7, 2))
        pref = rng.uniform(-1, 1, (1, 2))
        new, lp3 = orca_velocities(p, v, pref, 0.3, 1.0, PARAMS, DT, agents=np.array([0]))
        if not lp3[0]:
            continue
        points, dirs, c = orca_halfplanes(p, v, np.full(7, 0.3), np.array([0]), PARAMS, DT)
        points, dirs = points[0, : c[0]], dirs[0, : c[0]]
        # min t  s.t.  violation_i(v) <= t,  |v| <= 1
        cons = [
            {"type": "ineq", "fun": lambda x, p=points, d=dirs: x[2] - _violation(x[:2], p, d)},
            {"type": "ineq", "fun": lambda x: 1.0 - x[:2] @ x[:2]},
        ]
        best = np.inf
        for start in (np.zeros(2), new[0]):
            x0 = np.append(start, _violation(start, points, dirs).max())
            ref = optimize.minimize(lambda x: x[2], x0, constraints=cons, method="SLSQP", tol=1e-12)
            best = min(best, ref.fun)
        assert best > 0.0  # the 2-D program was right: no velocity satisfies every line
        assert _violation(new[0], points, dirs).max() <= best + 1e-6
        assert np.linalg.norm(new[0]) <= 1.0 + 1e-9
        checked += 1
    assert checked >= 10


def test_preferred_velocity_boundaries_are_strict():
    # CrowdNav scales the goal offset only when it is longer than 1 m: exactly 1 m away gives the raw offset
    # (1 m/s) even at v_pref = 1.5; the stop radius is strict too: exactly 0.3 m away it still walks.
    positions = np.zeros((3, 2))
    goals = np.array([[1.0, 0.0], [0.0, 0.3], [2.0, 0.0]])
    pref = preferred_velocities(positions, goals, 1.5, stop_radius=0.3)
    np.testing.assert_allclose(pref, [[1.0, 0.0], [0.0, 0.3], [1.5, 0.0]])


def test_neighbour_range_is_strict_and_rows_hold_a_minus_one():
    # neighbor_dist 3: the agent exactly 3 m away is not a neighbour. With max_neighbors 10 and 3 agents
    # there are K = min(10, 3 - 1) = 2 slots per row (an agent is never its own neighbour).
    params = OrcaParams(neighbor_dist=3.0, max_neighbors=10)
    p = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 2.0]])
    idx, valid = nearest_neighbors(p, np.array([0]), params)
    assert idx.shape == valid.shape == (1, 2)
    np.testing.assert_array_equal(idx[0], [2, 1])
    np.testing.assert_array_equal(valid[0], [True, False])


def test_unequal_radii_add_up():
    # As the head-on case with radii 0.3 and 0.5: R = 0.8, w = (-0.8, 0), u = (0.8/5 - 0.8) (-1, 0) =
    # (0.64, 0): A's line at (0.32, 0), B's at (-0.32, 0) (the same R for both).
    p = np.array([[-2.0, 0.0], [2.0, 0.0]])
    points, _, _ = orca_halfplanes(p, np.zeros((2, 2)), np.array([0.3, 0.5]), np.arange(2), PARAMS, DT)
    np.testing.assert_allclose(points[:, 0], [[0.32, 0.0], [-0.32, 0.0]], atol=1e-12)


def test_a_max_speed_other_than_one_bounds_the_2d_program():
    # Head-on as above (A's line v_x <= 0.34), max speed 0.5, preferred (1, 1): the optimum slides up the
    # line to the 0.5 m/s circle, (0.34, sqrt(0.25 - 0.34^2)) = (0.34, 0.3666).
    p = np.array([[-2.0, 0.0], [2.0, 0.0]])
    new, lp3 = orca_velocities(
        p, np.zeros((2, 2)), np.array([[1.0, 1.0]]), 0.3, 0.5, PARAMS, DT, np.array([0])
    )
    np.testing.assert_allclose(new[0], [0.34, math.sqrt(0.25 - 0.34**2)], atol=1e-12)
    assert not lp3[0]


def test_parallel_lines_that_leave_room_keep_the_2d_program():
    # Agent at 0 between W at (-1.9, 0) (nearer: line 0) and E at (2, 0), everyone still.
    # W: w = (0.38, 0), u = (0.6/5 - 0.38) (1, 0) = (-0.26, 0) -> v_x >= -0.13;
    # E: w = (-0.4, 0), u = (0.28, 0) -> v_x <= 0.14. Parallel, opposite, with a strip between them:
    # preferred (1, 0.5) lands on E's line at (0.14, 0.5), no 3-D program.
    p = np.array([[0.0, 0.0], [2.0, 0.0], [-1.9, 0.0]])
    new, lp3 = orca_velocities(
        p, np.zeros((3, 2)), np.array([[1.0, 0.5]]), 0.3, 1.0, PARAMS, DT, np.array([0])
    )
    np.testing.assert_allclose(new[0], [0.14, 0.5], atol=1e-12)
    assert not lp3[0]


def test_3d_program_with_two_opposite_parallel_lines():
    # Overlapping neighbours E and W at 0.4 m: v_x <= -0.25 and v_x >= 0.25 (as in the dense case). The
    # largest violation max(v_x + 0.25, 0.25 - v_x) is smallest, 0.25, at v_x = 0 whatever v_y.
    p = np.array([[0.0, 0.0], [0.4, 0.0], [-0.4, 0.0]])
    new, lp3 = orca_velocities(
        p, np.zeros((3, 2)), np.array([[0.0, 1.0]]), 0.3, 1.0, PARAMS, DT, np.array([0])
    )
    assert lp3[0]
    assert new[0, 0] == pytest.approx(0.0, abs=1e-12)
    assert np.linalg.norm(new[0]) <= 1.0 + 1e-12


def test_touching_agents_take_the_collision_branch():
    # A at 0 moving (0, 1), B still at (0.6, 0): exactly touching (|r| = R = 0.6), which RVO2 treats as a
    # collision: c = u - r / dt = (0, 1) - (1.5, 0) = (-1.5, 1), |c| = sqrt(3.25); direction (c_y, -c_x) / |c|
    # = (1, 1.5) / sqrt(3.25); point = v + (R / dt - |c|) c / (2 |c|). (The leg branch would give the line
    # through v along (0, 1).)
    p = np.array([[0.0, 0.0], [0.6, 0.0]])
    v = np.array([[0.0, 1.0], [0.0, 0.0]])
    points, dirs, _ = orca_halfplanes(p, v, np.full(2, 0.3), np.array([0]), PARAMS, DT)
    c = math.sqrt(3.25)
    np.testing.assert_allclose(dirs[0, 0], [1.0 / c, 1.5 / c], atol=1e-12)
    scale = (1.5 - c) / c / 2.0
    np.testing.assert_allclose(points[0, 0], [-1.5 * scale, 1.0 + scale], atol=1e-12)


def test_the_zero_over_zero_overlap_pushes_apart():
    # A at 0 moving (1, 0) towards B still at (0.4, 0): u = r / dt exactly, RVO2's 0/0 (module docstring).
    # The unit vector from the neighbour to the agent stands in for c: A's c = (-1, 0), u = (0.6/0.4) c =
    # (-1.5, 0), line through (1, 0) + u / 2 = (0.25, 0) along (0, 1): v_x <= 0.25; B mirrored: v_x >= 0.75.
    # Standing still is fine for A; B moves off at 0.75 m/s: 0.4 + 0.4 * 0.75 = 0.7 m apart after the step.
    p = np.array([[0.0, 0.0], [0.4, 0.0]])
    v = np.array([[1.0, 0.0], [0.0, 0.0]])
    points, dirs, _ = orca_halfplanes(p, v, np.full(2, 0.3), np.arange(2), PARAMS, DT)
    np.testing.assert_allclose(points[:, 0], [[0.25, 0.0], [0.75, 0.0]], atol=1e-12)
    np.testing.assert_allclose(dirs[:, 0], [[0.0, 1.0], [0.0, -1.0]], atol=1e-12)
    new, _ = orca_velocities(p, v, np.zeros((2, 2)), 0.3, 1.0, PARAMS, DT)
    np.testing.assert_allclose(new, [[0.0, 0.0], [0.75, 0.0]], atol=1e-12)


def test_two_agents_at_the_same_point_are_pushed_opposite_ways():
    # A and B both still at 0, both preferring (0, 1): c = u - r / dt = 0 and r = 0, so there is no line of
    # centres. The lower index takes c = (1, 0): u = (0.6/0.4) c = (1.5, 0), point (0.75, 0), direction
    # (0, -1), v_x >= 0.75; B mirrored, v_x <= -0.75. The closest velocity to (0, 1) within speed 1 is
    # (+-0.75, sqrt(1 - 0.75^2)). One direction for both pushed the pair the same way for ever.
    p = np.zeros((2, 2))
    v = np.zeros((2, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the branches np.where does not take hold 0/0
        points, dirs, _ = orca_halfplanes(p, v, np.full(2, 0.3), np.arange(2), PARAMS, DT)
        new, _ = orca_velocities(p, v, np.array([[0.0, 1.0], [0.0, 1.0]]), 0.3, 1.0, PARAMS, DT)
    np.testing.assert_allclose(points[:, 0], [[0.75, 0.0], [-0.75, 0.0]], atol=1e-12)
    np.testing.assert_allclose(dirs[:, 0], [[0.0, -1.0], [0.0, 1.0]], atol=1e-12)
    np.testing.assert_allclose(new, [[0.75, math.sqrt(0.4375)], [-0.75, math.sqrt(0.4375)]], atol=1e-9)


def test_an_overlap_the_max_speed_cannot_undo_goes_away_at_full_speed():
    # As test_overlapping_agents_move_apart_in_one_step (A's line v_x <= -0.25), but at max speed 0.2 m/s the
    # disc lies wholly outside the line: the 3-D program from line 0, with nothing to project, returns
    # max speed times the line's inward normal (1, 0) rotated, i.e. (-0.2, 0) for A and (0.2, 0) for B.
    p = np.array([[0.0, 0.0], [0.4, 0.0]])
    new, lp3 = orca_velocities(p, np.zeros((2, 2)), np.zeros((2, 2)), 0.3, 0.2, PARAMS, DT)
    assert lp3.all()
    np.testing.assert_allclose(new, [[-0.2, 0.0], [0.2, 0.0]], atol=1e-12)


def test_the_time_horizon_is_a_parameter():
    # The head-on case with time_horizon 2 s: w = 0 - (4, 0)/2 = (-2, 0), on the cut-off circle:
    # u = (0.6/2 - 2) (-1, 0) = (1.7, 0), A's line at (0.85, 0).
    params = OrcaParams(time_horizon=2.0)
    p = np.array([[-2.0, 0.0], [2.0, 0.0]])
    points, _, _ = orca_halfplanes(p, np.zeros((2, 2)), np.full(2, 0.3), np.array([0]), params, DT)
    np.testing.assert_allclose(points[0, 0], [0.85, 0.0], atol=1e-12)


def test_a_neighbour_out_of_range_sets_no_line():
    # Head-on 4 m apart with neighbor_dist 3 m: the slot exists (K = 1) but is not valid, so A keeps its
    # preferred velocity (1, 0) instead of the v_x <= 0.34 it would get in range.
    params = OrcaParams(neighbor_dist=3.0)
    p = np.array([[-2.0, 0.0], [2.0, 0.0]])
    _, _, counts = orca_halfplanes(p, np.zeros((2, 2)), np.full(2, 0.3), np.arange(2), params, DT)
    np.testing.assert_array_equal(counts, [0, 0])
    new, _ = orca_velocities(p, np.zeros((2, 2)), np.array([[1.0, 0.0], [-1.0, 0.0]]), 0.3, 1.0, params, DT)
    np.testing.assert_allclose(new, [[1.0, 0.0], [-1.0, 0.0]])
