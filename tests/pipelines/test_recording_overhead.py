"""Recording costs at most 10% of a CMPC episode's closed-loop time (DESIGN.md, issue 5).

The time spent inside the recorder's hooks is measured within the recorded run itself, so that the load of a
shared machine affects both sides of the ratio alike (wall-clock differences between two runs do not).
Run with ``pytest -m slow tests/pipelines/test_recording_overhead.py -s`` to see the figures.
"""

from __future__ import annotations

import time

import pytest

from pipelines.closed_loop import run_episode
from pipelines.controllers import ControllerSpec, make_controller
from pipelines.recording import McapEpisodeRecorder


class TimedRecorder(McapEpisodeRecorder):
    """Accumulates the wall time spent in on_reset, on_step and on_end."""

    spent_s = 0.0

    def _timed(self, hook, *args):
        start = time.perf_counter()
        hook(*args)
        self.spent_s += time.perf_counter() - start

    def on_reset(self, obs, meta):
        self._timed(super().on_reset, obs, meta)

    def on_step(self, obs, out, next_obs):
        self._timed(super().on_step, obs, out, next_obs)

    def on_end(self, result):
        self._timed(super().on_end, result)


@pytest.mark.slow
def test_recording_adds_at_most_ten_percent_to_a_cmpc_episode(tmp_path):
    controller = make_controller(ControllerSpec(controller="cmpc", predictor="constant_velocity"))
    recorder = TimedRecorder(tmp_path)
    start = time.perf_counter()  # the controller is built: only the episodes themselves are timed
    results = [
        run_episode(controller, seed=seed, scenario="circle", n_humans=7, n_robots=3, observers=(recorder,))
        for seed in (0, 1)
    ]
    total = time.perf_counter() - start
    steps = sum(len(r.statuses) for r in results)
    loop = total - recorder.spent_s
    share = recorder.spent_s / loop
    print(
        f"\ncmpc, 2 episodes, {steps} steps: loop {loop:.2f} s, recording {recorder.spent_s:.3f} s "
        f"({1e3 * recorder.spent_s / steps:.2f} ms/step) = {100 * share:.1f} % of the loop"
    )
    assert len(recorder.paths) == 2
    assert share <= 0.10
