"""The closed loop commutes with the plane's symmetries: move, turn or mirror a layout, or renumber its
people, and every robot and human takes the moved path, step by step.

The paper's game has no preferred place, axis or numbering: its costs (Eqs. 7-15) depend on distances,
its bounds (Eq. 6) are per component and symmetric about zero, and Jacobi's best responses (Algorithm 2)
are taken from the same u^(j-1) whatever the robots' order. So an axis-dependent constant, an
order-dependent tie-break or a dict/set iteration order in the code shows up here as a path that does not
map back. What may differ is floating point: a solver stops at its tolerance, and a change in rounding
(a translation, x and y swapped) moves a solution by about that tolerance, then the closed loop carries
it. DMPC's paths, 3 robots and 7 humans, stay within 1.2e-8 m over whole episodes (measured at 5e354b0:
seeds 0-7, both scenarios, these transforms and renumberings); with 5 robots a 1e-9 m difference grows
past 1e-6 m after 10-40 steps, as in any closed loop that amplifies rounding, so the check stops at 12
steps. CMPC's one joint NLP moves by its solver_tol (1e-6) from the second step: 2e-6 m, at most 2e-5 m
over 30 steps (seeds 0, 3, 4); hence its 1e-4 m. An x-dependent bound in the initial strategy
(mpc/dynamics.py ``clip_to_bounds``, -a_max scaled by 0.8 in y) moved DMPC's paths by 3 mm in 12 steps.

Not checked, as expected to differ: CMPC under a mirror in x (at its first step, robots in a row at
x = -1, 0, 1 with the humans mirrored, it reaches another local optimum of the nonconvex joint NLP, the
middle robot going first instead of the outer two: a local solver's iterates are not sign-equivariant);
a rotation other than a multiple of 90 degrees (Eq. 6's bounds are per component); Gauss-Seidel or
in-turn updates under a robot permutation (the update order is the robots' order, Algorithm 2 line 4
and its repairs); for the in-turn update, an exact tie between two mirror-image robots' improvements
(broken in robot order, which a mirror swaps).
"""

from collections.abc import Callable

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.scenarios import Layout, make_layout
from pipelines.loop.controllers import ControllerSpec, make_controller

STEPS = 12
TOLERANCE_M = {"dmpc": 1e-6, "cmpc": 1e-4}
SHIFT = np.array([3.3, -1.7])
# The wall-time budget of a step (mpc.time_limit_s, 1 s) stops IBR where the clock says, so a step that
# reaches it depends on the machine's load (the likely cause of a 0.046 m DMPC translation gap seen once at
# load 3-6): with the budget set to 1-3 ms, runs of the same pair differ by 1e-15 to 1.8 m run to run.
NO_BUDGET = (("time_limit_s", 3600.0),)

Map = Callable[[np.ndarray], np.ndarray]
# name: (forward on points, its inverse)
TRANSFORMS: dict[str, tuple[Map, Map]] = {
    "translation": (lambda p: p + SHIFT, lambda p: p - SHIFT),
    "rot90": (
        lambda p: np.stack([-p[..., 1], p[..., 0]], -1),
        lambda p: np.stack([p[..., 1], -p[..., 0]], -1),
    ),
    "mirror_x": (lambda p: p * [-1.0, 1.0], lambda p: p * [-1.0, 1.0]),
    "mirror_y": (lambda p: p * [1.0, -1.0], lambda p: p * [1.0, -1.0]),
    "point_reflection": (lambda p: -p, lambda p: -p),
}


def _paths(controller, layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """Robot and human positions over the first STEPS steps of a closed loop from ``layout``."""
    env = CrowdEnv()
    obs = env.reset_layout(layout)
    controller.reset(obs)
    for _ in range(STEPS):
        obs, done, _ = env.step(controller.act(obs).accelerations)
        if done:
            break
    trajectory = env.trajectory()
    return trajectory.robot_positions, trajectory.human_positions


def _moved(layout: Layout, f: Map, robots: np.ndarray, humans: np.ndarray) -> Layout:
    return Layout(
        robot_starts=f(layout.robot_starts)[robots],
        robot_goals=f(layout.robot_goals)[robots],
        human_starts=f(layout.human_starts)[humans],
        human_goals=f(layout.human_goals)[humans],
    )


def _largest_gap(controller, layout: Layout, f: Map, g: Map, robots: np.ndarray, humans: np.ndarray) -> float:
    """The largest distance, over the steps and people, between the paths from ``layout`` and the paths
    from its image under ``f`` with robots and humans renumbered, mapped back by ``g``."""
    base_r, base_h = _paths(controller, layout)
    moved_r, moved_h = _paths(controller, _moved(layout, f, robots, humans))
    assert moved_r.shape == base_r.shape, "one episode ended earlier than the other"
    back_r = g(moved_r)[:, np.argsort(robots)]
    back_h = g(moved_h)[:, np.argsort(humans)]
    return float(max(np.abs(back_r - base_r).max(), np.abs(back_h - base_h).max()))


@pytest.fixture(scope="module")
def controllers():
    made = {
        kind: make_controller(ControllerSpec(kind, "constant_velocity", mpc_overrides=NO_BUDGET))
        for kind in TOLERANCE_M
    }
    yield made
    for controller in made.values():
        controller.close()


CHECKED = [(kind, name) for kind in TOLERANCE_M for name in sorted(TRANSFORMS)]
CHECKED.remove(("cmpc", "mirror_x"))  # another local optimum of the joint NLP (module docstring)


@pytest.mark.parametrize("scenario, seed", [("circle", 0), ("perpendicular", 3)])
@pytest.mark.parametrize("kind, transform", CHECKED)
def test_mpc_paths_move_with_the_layout(controllers, kind, transform, scenario, seed):
    layout = make_layout(scenario, 4, 3, np.random.default_rng(seed))
    f, g = TRANSFORMS[transform]
    identity = np.arange(3), np.arange(4)
    assert _largest_gap(controllers[kind], layout, f, g, *identity) < TOLERANCE_M[kind]


@pytest.mark.parametrize("scenario, seed", [("circle", 1), ("perpendicular", 2)])
@pytest.mark.parametrize("kind", sorted(TOLERANCE_M))
def test_mpc_paths_do_not_depend_on_how_robots_and_humans_are_numbered(controllers, kind, scenario, seed):
    layout = make_layout(scenario, 4, 3, np.random.default_rng(seed))
    same = lambda p: p  # noqa: E731
    robots, humans = np.array([2, 0, 1]), np.array([3, 1, 0, 2])
    assert _largest_gap(controllers[kind], layout, same, same, robots, humans) < TOLERANCE_M[kind]


def test_a_mirrored_layout_that_differs_is_caught():
    """The check can fail: a controller with an axis-dependent constant (a push along +x) does not move
    with a mirrored layout."""

    class PushedRight:
        def __init__(self):
            self.inner = make_controller(ControllerSpec("straight"))

        def reset(self, obs):
            self.inner.reset(obs)

        def act(self, obs):
            out = self.inner.act(obs)
            out.accelerations[:, 0] += 0.1
            return out

    layout = make_layout("circle", 2, 2, np.random.default_rng(0))
    f, g = TRANSFORMS["mirror_y"]
    assert _largest_gap(PushedRight(), layout, f, g, np.arange(2), np.arange(2)) < TOLERANCE_M["dmpc"]
    f, g = TRANSFORMS["mirror_x"]
    assert _largest_gap(PushedRight(), layout, f, g, np.arange(2), np.arange(2)) > 0.01
