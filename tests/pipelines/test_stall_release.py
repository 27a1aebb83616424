"""The controller releases stalled robots from flocking (mpc/stall.py) only when asked to, and records it."""

import numpy as np

from crowdsim.env import CrowdEnv
from pipelines.loop.controllers import ControllerSpec, make_controller


def _run(overrides: tuple, steps: int = 4) -> tuple[list, list]:
    controller = make_controller(ControllerSpec("cmpc", "constant_velocity", mpc_overrides=overrides))
    env = CrowdEnv()
    obs = env.reset(0, "circle", 3, 3)
    controller.reset(obs)
    records, distances = [], []
    for _ in range(steps):
        distances.append(np.linalg.norm(obs.robot_positions - obs.robot_goals, axis=1))
        out = controller.act(obs)
        records.append(out.extra.get("unflocked"))
        obs, _, _ = env.step(out.accelerations)
    return records, distances


def test_robots_are_released_after_a_window_without_progress():
    """A 0.4 s window (one step). At the first step there is no window yet. From rest, a_max = 2 m/s^2 moves
    a robot at most 0.16 m in 0.4 s, under the 0.25 m of progress: at the second step all three are
    stalled. Later, the released robots are those whose distance to the goal fell by less than 0.25 m
    over the last step, as the observations say."""
    records, distances = _run((("stall_release_s", 0.4),))
    assert records[0] is None
    assert records[1] == [0, 1, 2]
    for k in (2, 3):
        expected = np.flatnonzero(distances[k - 1] - distances[k] < 0.25).tolist()
        assert (records[k] or []) == expected
    assert any(records[k] != [0, 1, 2] for k in (2, 3))  # they got going


def test_the_papers_controller_never_releases_flocking():
    assert _run(())[0] == [None] * 4
