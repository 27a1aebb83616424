"""Synthetic TrajNet++ data from the ORCA crowd simulator, to train predictors on the pedestrians they meet
in closed loop (an ablation the paper does not have).

Each episode is one seeded simulator episode (episode ``i`` uses ``seed + i``) sampled every 0.4 s = 2.5 Hz,
TrajNet++'s rate. Without robots the episode runs until every human is within its radius of its goal (or the
time limit, ``EnvConfig.time_limit`` of the config given); with robots, three ORCA-driven robots
(``crowdsim.baselines.OrcaController``) join the crowd and the episode ends when they have all arrived, as in
closed loop.

Tracks: frame ids advance by 10 per step, the convention of the BIWI hotel sequence in TrajNet++. Episodes
occupy disjoint frame ranges and every agent of every episode has its own pedestrian id, so no scene mixes
two episodes. Scenes are cut by ``predictors.data.prepare.build_scenes`` (21-step windows, stride 2, the
TrajNet++ converter's filters). Robots are in the tracks (they are neighbours that the humans reacted to) but
never primaries: only scenes of human primaries are written.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, Final

import numpy as np

from crowdsim.baselines import OrcaController
from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from crowdsim.world import RECORDED_DT, RECORDED_FPS
from pipelines.errors import PipelineError

FRAME_STEP: Final[int] = 10  # frame ids per 0.4 s step (BIWI hotel's numbering in TrajNet++)
SYNTH_ROBOTS: Final[int] = 3  # robots per episode with with_robots=True (the paper's default team)


def episode_tracks(
    env: CrowdEnv,
    seed: int,
    scenario: str,
    n_humans: int,
    n_robots: int,
    frame_offset: int,
    id_offset: int,
) -> tuple[np.ndarray, int, bool]:
    """Run one episode; returns ``(tracks (R, 4) rows frame, id, x, y; number of rows per agent; success)``.

    Agent ``a`` (robots first, then humans) gets pedestrian id ``id_offset + a``.
    """
    obs = env.reset(seed, scenario, n_humans, n_robots)
    controller = OrcaController() if n_robots else None
    if controller is not None:
        controller.reset(obs)
    done = False
    info: dict[str, Any] = {}
    while not done:
        action = controller.act(obs).accelerations if controller is not None else np.zeros((0, 2))
        obs, done, info = env.step(action)
    traj = env.trajectory()
    positions = np.concatenate([traj.robot_positions, traj.human_positions], axis=1)  # (T+1, A, 2)
    steps, agents = positions.shape[:2]
    frames = frame_offset + FRAME_STEP * np.repeat(np.arange(steps), agents)
    ids = id_offset + np.tile(np.arange(agents), steps)
    tracks = np.column_stack([frames, ids, positions.reshape(-1, 2)])
    return tracks, steps, bool(info.get("success", False))


def _check_request(episodes: int, n_humans: int, n_robots: int, seed: int, env_config: EnvConfig) -> None:
    """PipelineError, before any episode runs, for a request ``synthesize`` cannot write scenes for."""
    for name, value, least in (("episodes", episodes, 1), ("n_humans", n_humans, 1), ("seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise PipelineError(f"{name} must be an int >= {least}, got {value!r}")
    if not math.isclose(env_config.dt * RECORDED_FPS, 1.0, rel_tol=1e-9):
        # the scenes are written at TrajNet++'s 2.5 fps, whatever the step: another dt made slower or faster
        # walkers out of the same frames (dt = 0.2 s wrote 1 m/s pedestrians as 0.4 m/s ones)
        raise PipelineError(
            f"env_config.dt must be {RECORDED_DT:g} s (TrajNet++ scenes are {RECORDED_FPS:g} fps), "
            f"got {env_config.dt:g} s"
        )
    if n_humans + n_robots < 2:  # refused after every episode had run, when no scene came out
        raise PipelineError(
            "1 human without robots makes no TrajNet++ scene (a scene needs two agents' rows over its 21 "
            "steps): give 2 humans or more (--humans) or the robots (--with-robots)"
        )


def synthesize(
    out_path: str | Path,
    episodes: int,
    n_humans: int,
    seed: int,
    scenario: str = "circle",
    with_robots: bool = False,
    *,
    categorize: bool = False,
    env_config: EnvConfig | None = None,
    progress: bool | None = False,
) -> dict[str, Any]:
    """Simulate ``episodes`` ORCA crowds and write their TrajNet++ scenes to ``out_path`` (ndjson), with a bar
    of the episodes when ``progress`` (None: on a terminal only; up to 100 000 episodes ran in silence).

    ``categorize`` gives every scene its TrajNet++ type and applies TrajNet++'s acceptance (drops 90 % of
    static scenes); it costs a Kalman fit (~50 ms) per scene, so it is off by default (tags 0, all kept).
    Returns a summary: counts of episodes, scenes, the pedestrians and rows written, and episodes that hit
    the time limit.
    """
    from predictors.data.trajnet_scenes import build_scenes, write_ndjson
    from predictors.progress import progress_bar
    from predictors.text_table import counted

    env_config = env_config or EnvConfig()
    n_robots = SYNTH_ROBOTS if with_robots else 0
    _check_request(episodes, n_humans, n_robots, seed, env_config)
    env = CrowdEnv(env_config)
    all_tracks: list[np.ndarray] = []
    robot_ids: list[np.ndarray] = []
    frame_offset = id_offset = 0
    timeouts = 0
    for i in progress_bar(range(episodes), show=progress, desc=f"synth {scenario}", unit="ep"):
        tracks, steps, success = episode_tracks(
            env, seed + i, scenario, n_humans, n_robots, frame_offset, id_offset
        )
        all_tracks.append(tracks)
        robot_ids.append(id_offset + np.arange(n_robots))
        timeouts += not success
        frame_offset += FRAME_STEP * steps  # the next episode starts on the next unused frame
        id_offset += n_robots + n_humans
    tracks = np.concatenate(all_tracks)
    robots = set(np.concatenate(robot_ids).tolist())

    scenes = build_scenes(tracks, frame_step=FRAME_STEP, categorize_scenes=categorize, seed=seed)
    # Human primaries only, renumbered so that scene ids stay consecutive.
    scenes = [
        dataclasses.replace(s, id=k) for k, s in enumerate(x for x in scenes if x.primary not in robots)
    ]
    if not scenes:
        raise PipelineError(
            f"no TrajNet++ scene (21 steps) came out of {episodes} episode(s) of "
            f"{counted(n_humans, 'human')} in {scenario!r}; episodes are too short or too sparse"
        )
    out_path = Path(out_path)
    written = tracks[write_ndjson(out_path, scenes, tracks)]
    return {
        "path": str(out_path),
        "episodes": episodes,
        "scenario": scenario,
        "humans_per_episode": n_humans,
        "robots_per_episode": n_robots,
        "scenes": len(scenes),
        # what the file holds: an agent, or a row, that no scene needs is simulated but not written
        "pedestrians": len(np.unique(written[:, 1])),
        "rows": len(written),
        "timeouts": timeouts,
    }
