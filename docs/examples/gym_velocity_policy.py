"""A CrowdNav-style velocity policy through gymnasium's API, each episode recorded to MCAP.

Every robot heads for its goal at 1 m/s and is pushed away from each human within 2 m, the harder the
closer (a social-force flavour). Run it from the repository root:
``python docs/examples/gym_velocity_policy.py [EPISODES] [OUT_DIR] [CROWD]``; then ``crowdmpc review
OUT_DIR`` (or open the files in Foxglove). CROWD is ORCA's (``orca``, the default) or one of the replayed
BIWI crowds, e.g. ``eth_test`` (real people, read from ``$CROWDMPC_DATA``), where a person's row is present
only while tracked: the policy reads the ``present`` column, so it runs among either unchanged.
"""

import argparse
from pathlib import Path

import numpy as np

from crowdsim.env_config import EnvConfig
from crowdsim.gym_env import GOAL, POSITION, PRESENT
from crowdsim.gym_wrappers import VelocityControl
from crowdsim.replay import CROWDS
from pipelines.commands import check_writable
from pipelines.errors import PipelineError
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.loop.gym_loop import ObserveEpisodes, make_env
from predictors.text_table import counted


def policy(obs: np.ndarray, n_robots: int) -> np.ndarray:
    """Velocities (n_robots, 2) in m/s from the observation (rows: robots, then humans)."""
    robots, humans = obs[:n_robots], obs[n_robots:][obs[n_robots:, PRESENT] == 1]
    offset = robots[:, GOAL] - robots[:, POSITION]
    dist = np.linalg.norm(offset, axis=1, keepdims=True)
    heading = offset / np.maximum(dist, 1e-9) * np.minimum(1.0, dist)  # slow down on the last metre
    away = robots[:, None, POSITION] - humans[None, :, POSITION]  # (robots, humans, 2)
    d = np.linalg.norm(away, axis=-1, keepdims=True)
    push = (away / np.maximum(d, 1e-9) * np.clip(2.0 - d, 0.0, None)).sum(axis=1)
    return np.clip(heading + push, -1.0, 1.0)  # the velocity bound, per component


def main(
    episodes: int = 3, out_dir: str = "runs/gym_velocity_policy", crowd: str = "orca", n_humans: int = 7
) -> None:
    # gym.make("crowdmpc/CrowdNav-v0", ...) once crowdsim is imported; make_env reads a replay's recording,
    # before the recorder makes OUT_DIR (a mistyped crowd left it empty)
    base = make_env(EnvConfig(crowd=crowd), n_humans=n_humans)
    with McapEpisodeRecorder(out_dir) as recorder:
        env = VelocityControl(ObserveEpisodes(base, [recorder], controller="velocity_policy"))
        for seed in range(episodes):
            obs, _ = env.reset(seed=seed)
            done, total = False, 0.0
            while not done:
                obs, reward, terminated, truncated, info = env.step(policy(obs, base.unwrapped.max_robots))
                total, done = total + float(reward), terminated or truncated
            m = info["episode_metrics"]
            print(
                f"seed {seed}: return {total:+.2f}, success {m.success}, min distance {m.min_distance:.2f} m"
            )
    print(f"wrote {counted(len(recorder.paths), 'MCAP file')} to {out_dir}")


if __name__ == "__main__":
    # argparse: a mistyped argument ends in one line naming it (an OUT_DIR given alone was taken for
    # EPISODES, a TypeError from range; a folder that cannot be made, /proc/x, a FileNotFoundError)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("episodes", nargs="?", type=int, default=3, metavar="EPISODES", help="seeds 0.. (3)")
    parser.add_argument(
        "out_dir", nargs="?", default="runs/gym_velocity_policy", metavar="OUT_DIR", help="%(default)s"
    )
    parser.add_argument(
        "crowd", nargs="?", default="orca", choices=CROWDS, metavar="CROWD", help="orca, eth_test ..."
    )
    args = parser.parse_args()
    try:
        check_writable(Path(args.out_dir), "argument OUT_DIR", directory=True)
    except PipelineError as exc:
        parser.error(str(exc))
    main(args.episodes, args.out_dir, args.crowd)
