"""crowdmpc as a library in one long-lived process (a notebook, a training loop, a parameter search): what a
call holds must be released when it returns or raises, so that the next call in the same process works
and nothing builds up."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from crowdsim.env_config import EnvConfig
from crowdsim.gym_env import CrowdNavEnv
from pipelines.errors import PipelineError
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.episode import run_episodes
from pipelines.loop.gym_loop import ObserveEpisodes


def _open_files_under(folder: Path) -> list[str]:
    """The files of this process's descriptors that lie in ``folder``."""
    found = []
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:  # the descriptor listdir itself used, closed since
            continue
        if target.startswith(str(folder)):
            found.append(target)
    return found


class _CtrlCAtStep:
    """Ctrl-C landing in the ``at``-th step of an episode."""

    def __init__(self, at: int) -> None:
        self.at, self.steps = at, 0

    def on_reset(self, obs, meta) -> None:
        pass

    def on_step(self, obs, out, next_obs) -> None:
        self.steps += 1
        if self.steps == self.at:
            raise KeyboardInterrupt

    def on_end(self, result) -> None:
        pass


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="reads the process's descriptors in /proc")
def test_an_interrupted_run_releases_the_recording_its_factory_made(tmp_path):
    """A notebook keeps the traceback of a cell interrupted by Ctrl-C (``sys.last_traceback``), and with it
    the recorder ``observers_factory`` made: its ``.part`` stayed open and locked, and running the cell
    again in the same process was refused as "another run is recording that episode into this folder"."""

    def run(*extra):
        return run_episodes(
            ControllerSpec("orca"),
            episodes=2,
            seed=0,
            scenario="circle",
            n_humans=3,
            n_robots=2,
            observers_factory=lambda: (McapEpisodeRecorder(tmp_path), *extra),
            progress=False,
        )

    with pytest.raises(KeyboardInterrupt) as caught:  # kept, as the notebook keeps it
        run(_CtrlCAtStep(3))
    assert _open_files_under(tmp_path) == []
    results = run()  # the cell run again
    assert [r.seed for r in results] == [0, 1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["circle_seed000000.mcap", "circle_seed000001.mcap"]
    assert _open_files_under(tmp_path) == []
    assert caught.value is not None


def _episodes(env: ObserveEpisodes, seeds: range) -> None:
    for seed in seeds:
        env.reset(seed=seed)
        done = False
        while not done:
            *_, terminated, truncated, _ = env.step(np.zeros((2, 2)))
            done = terminated or truncated


def test_a_training_loop_keeps_the_latest_episodes_not_every_one():
    """``ObserveEpisodes.results`` kept every finished episode with its trajectories: a training loop's
    memory grew by 12 KB an episode (7 humans), without end. Now the latest ``buffer_length``."""

    def observed(**kwargs) -> ObserveEpisodes:
        base = CrowdNavEnv(n_humans=2, n_robots=2, config=EnvConfig(time_limit=0.8, timeout_margin=0.0))
        return ObserveEpisodes(base, [], **kwargs)

    env = observed()
    _episodes(env, range(150))
    assert len(env.results) == 100 and [r.seed for r in env.results] == list(range(50, 150))
    env = observed(buffer_length=3)
    _episodes(env, range(5))
    assert [r.seed for r in env.results] == [2, 3, 4]
    env = observed(buffer_length=None)  # every one, on request
    _episodes(env, range(120))
    assert len(env.results) == 120
    for bad in (0, -1, True, 2.5, "10"):
        with pytest.raises(PipelineError, match="buffer_length must be an int >= 1 or None"):
            observed(buffer_length=bad)


def test_the_kept_episodes_are_still_a_list():
    """``results`` was a list, and a deque(maxlen=...) that kept the latest episodes refused what users do
    with one: ``env.results[-10:]`` raised TypeError, and ``env.results == []`` was False when empty."""
    base = CrowdNavEnv(n_humans=2, n_robots=2, config=EnvConfig(time_limit=0.8, timeout_margin=0.0))
    env = ObserveEpisodes(base, [], buffer_length=3)
    assert env.results == []
    _episodes(env, range(5))
    assert [r.seed for r in env.results[-2:]] == [3, 4]
    assert [r.seed for r in env.results + []] == [2, 3, 4]


def test_a_numpy_integer_is_a_buffer_length():
    """A length computed with numpy (``np.int64``) is no ``int``: it was refused as "must be an int"."""
    base = CrowdNavEnv(n_humans=2, n_robots=2, config=EnvConfig(time_limit=0.8, timeout_margin=0.0))
    env = ObserveEpisodes(base, [], buffer_length=np.int64(2))
    _episodes(env, range(3))
    assert [r.seed for r in env.results] == [1, 2] and type(env.buffer_length) is int
    for bad in (np.int64(0), np.float64(2.0), np.bool_(True)):
        with pytest.raises(PipelineError, match="buffer_length must be an int >= 1 or None"):
            ObserveEpisodes(base, [], buffer_length=bad)
