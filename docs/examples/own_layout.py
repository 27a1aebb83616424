"""Your own scene: a corridor of your own starts and goals, two controllers on it, each episode recorded.

`crowdmpc simulate` and `crowdmpc sweep` run the paper's two crossings (circle and perpendicular, the humans
drawn from a seed). Any other scene, here two robots meeting two walking humans in a corridor with a third
standing in their way, is a ``crowdsim.scenarios.Layout`` of starts and goals given to the gymnasium
environment's ``reset(options={"layout": ...})``. A human whose goal is its start stands there (ORCA still
makes it step aside for whoever would walk into it). Run it from the repository root:
``python docs/examples/own_layout.py [OUT_DIR]``, then ``crowdmpc review OUT_DIR``: a table per controller,
then the two side by side.
"""

import argparse
from pathlib import Path

import gymnasium as gym

import crowdsim  # registers crowdmpc/CrowdNav-v0
from crowdsim.env import EnvConfig
from crowdsim.scenarios import Layout
from pipelines.commands import check_writable
from pipelines.errors import PipelineError
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.gym_loop import run_gym_episode


def corridor(offset: float) -> Layout:
    """Two robots eastwards, two humans westwards, one standing at ``x = offset`` (m)."""
    return Layout(
        robot_starts=[[-6.0, -0.6], [-6.0, 0.6]],
        robot_goals=[[6.0, -0.6], [6.0, 0.6]],
        human_starts=[[6.0, 0.5], [6.0, -0.5], [offset, 0.0]],
        human_goals=[[-6.0, 0.5], [-6.0, -0.5], [offset, 0.0]],  # the third stands: its goal is its start
    )


def main(out_dir: str = "runs/own_layout", controllers: tuple[str, ...] = ("cmpc", "orca")) -> None:
    config = EnvConfig()  # the paper's simulator; e.g. EnvConfig(time_limit=60.0) for a longer corridor
    # Starts and goals must lie within the environment's observation bounds (±20 m for 3 humans).
    env = gym.make(crowdsim.ENV_ID, n_humans=3, n_robots=2, config=config)
    for name in controllers:
        controller = make_controller(ControllerSpec(name, "constant_velocity"), config)
        with McapEpisodeRecorder(f"{out_dir}/{name}") as recorder:
            for offset in (-1.0, 0.0, 1.0):
                options = {"layout": corridor(offset)}
                result = run_gym_episode(controller, env, seed=0, options=options, observers=[recorder])
                m = result.metrics
                print(
                    f"{name}, standing human at x = {offset:+.0f} m: success {m.success}, "
                    f"travel time {m.travel_time:.1f} s, min distance {m.min_distance:.2f} m"
                )
        controller.close()
    print(f"wrote {out_dir}: crowdmpc review {out_dir}")


if __name__ == "__main__":
    # argparse: a folder that cannot be made (/proc/x) ended in a FileNotFoundError traceback from the
    # recorder, after both controllers were built; now one line naming OUT_DIR, before any work
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "out_dir",
        nargs="?",
        default="runs/own_layout",
        metavar="OUT_DIR",
        help="a folder per controller inside it (%(default)s)",
    )
    args = parser.parse_args()
    try:
        check_writable(Path(args.out_dir), "argument OUT_DIR", directory=True)
    except PipelineError as exc:
        parser.error(str(exc))
    main(args.out_dir)
