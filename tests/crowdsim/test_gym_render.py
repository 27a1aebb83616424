"""What the gymnasium environment's render() frame says of its episode: the time, and once the environment
ended it, how, in the words of simulate's and review's titles (crowdsim.outcome.outcome_text)."""

import numpy as np
import pytest

from crowdsim.env_config import EnvConfig
from crowdsim.gym_env import CrowdNavEnv
from crowdsim.gym_wrappers import VelocityControl
from crowdsim.scenarios import Layout


def _layout(goal: tuple[float, float], human: tuple[float, float]) -> Layout:
    """A robot at rest at the origin heading for ``goal``, a human standing at ``human``."""
    point = np.array([human])
    return Layout(np.zeros((1, 2)), np.array([goal]), point, point)


def _last_title(monkeypatch, env, options, action, steps=1000) -> str:
    import crowdsim.plotting

    titles = []
    monkeypatch.setattr(crowdsim.plotting, "render_frame", lambda traj, title, **kw: titles.append(title))
    env.reset(seed=0, options=options)
    for _ in range(steps):
        *_, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    env.render()
    return titles[-1]


@pytest.mark.filterwarnings("ignore:.*apart")  # the contact layout starts the two in contact on purpose
def test_the_last_frame_says_how_the_episode_ended(monkeypatch):
    """The last frame of a success, of a contact that end_on_collision ended and of a truncation at the time
    limit was titled as any other, "layout: t = 0.4 s"; a running episode's frame gives the time alone."""
    running = CrowdNavEnv(n_humans=3, render_mode="rgb_array")
    assert _last_title(monkeypatch, running, None, np.zeros((3, 2)), steps=3) == "circle, seed 0: t = 1.2 s"
    walker = VelocityControl(CrowdNavEnv(n_robots=1, n_humans=1, render_mode="rgb_array"))
    south = np.array([[0.0, -1.0]])
    title = _last_title(monkeypatch, walker, {"layout": _layout((0.0, -2.0), (3.0, 3.0))}, south)
    assert title == "layout: t = 2 s\nsuccess in 2 s"
    touched = CrowdNavEnv(n_robots=1, n_humans=1, render_mode="rgb_array", end_on_collision=True)
    title = _last_title(monkeypatch, touched, {"layout": _layout((0.0, -5.0), (0.0, 0.5))}, np.zeros((1, 2)))
    assert title == "layout: t = 0.4 s\nrobot-human contact at 0.4 s (time limit 40 s)"
    limited = CrowdNavEnv(n_humans=3, render_mode="rgb_array", config=EnvConfig(time_limit=6))
    title = _last_title(monkeypatch, limited, None, np.zeros((3, 2)))
    assert title == "circle, seed 0: t = 5.2 s\ntimeout at 5.2 s (time limit 6 s)"
