"""What MCAP recording adds to the closed-loop time of an episode (issue 5 asks for at most 10%).

The time spent inside the recorder's hooks is measured within the recorded run itself, so that the load of a
shared machine affects both sides of the ratio alike (wall-clock differences between two runs do not).

    nice -n 10 .venv/bin/python benchmarks/recording_overhead.py
    nice -n 10 .venv/bin/python benchmarks/recording_overhead.py --controller orca --episodes 4
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import episode_count, human_count, predictor_name, run_main  # noqa: E402


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


def measure(controller_name: str, predictor: str, episodes: int, humans: int) -> dict:
    controller = make_controller(ControllerSpec(controller=controller_name, predictor=predictor))
    with tempfile.TemporaryDirectory() as out:
        recorder = TimedRecorder(out)
        start = time.perf_counter()  # the controller is built: only the episodes themselves are timed
        results = [
            run_episode(controller, seed=seed, scenario="circle", n_humans=humans, observers=(recorder,))
            for seed in range(episodes)
        ]
        total = time.perf_counter() - start
    steps = sum(len(r.statuses) for r in results)
    loop = total - recorder.spent_s
    return {
        "controller": controller_name,
        # as the episodes record it: None for a baseline, which predicts nothing whatever --predictor says
        "predictor": results[0].predictor,
        "episodes": episodes,
        "steps": steps,
        "loop_s": loop,
        "recording_s": recorder.spent_s,
        "recording_ms_per_step": 1e3 * recorder.spent_s / steps,
        "overhead_percent": 100 * recorder.spent_s / loop,
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--controller", default="cmpc", choices=["cmpc", "dmpc", "orca", "straight"])
    parser.add_argument("--predictor", type=predictor_name, default="constant_velocity")
    parser.add_argument("--episodes", type=episode_count, default=4)
    parser.add_argument("--humans", type=human_count, default=7)
    args = parser.parse_args()
    row = measure(args.controller, args.predictor, args.episodes, args.humans)
    print(
        f"{row['controller']} ({row['predictor'] or 'no predictor'}), {counted(row['episodes'], 'episode')}, "
        f"{row['steps']} steps: "
        f"loop {row['loop_s']:.2f} s, recording {row['recording_s']:.3f} s "
        f"({row['recording_ms_per_step']:.2f} ms/step) = {row['overhead_percent']:.1f} % of the loop"
    )
    print(json.dumps(row))


if __name__ == "__main__":
    raise SystemExit(run_main(main))
