"""A short recorded episode for the MCAP tests: the real simulator, a hand-made controller output per step.

The robots are commanded straight at their goals; the "plan" and "prediction" are simple closed forms of the
observation (so a test can recompute them), and every IBR iteration's prediction is a scaled copy.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.env import CrowdEnv, Observation
from crowdsim.env_config import EnvConfig
from crowdsim.metrics import episode_metrics
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.loop.controllers import ControlOutput
from pipelines.loop.episode import EpisodeResult

HORIZON = 4


@dataclass
class RecordedEpisode:
    path: Path
    observations: list[Observation]  # (steps + 1) states, the last one terminal
    outputs: list[ControlOutput]
    result: EpisodeResult
    meta: dict[str, Any]


def control_output(obs: Observation, *, with_plan: bool = True, step_iterations: int = 2) -> ControlOutput:
    accelerations = np.clip(obs.robot_goals - obs.robot_positions, -3.0, 3.0)  # beyond a_max: gets clipped
    ahead = np.arange(1, HORIZON + 1, dtype=float)
    plan = obs.robot_positions[:, None, :] + 0.1 * ahead[None, :, None]  # (M, H, 2)
    prediction = obs.human_positions[None] + obs.dt * ahead[:, None, None] * obs.human_velocities[None]
    return ControlOutput(
        accelerations=accelerations,
        solve_time_s=0.01 * (obs.step + 1),
        status="ok" if obs.step % 3 else "Solve_Succeeded",
        iterations=step_iterations,
        fallback="shifted" if obs.step == 2 else None,
        potential=float(obs.step) + 0.5 if obs.step != 1 else float("nan"),
        plan=plan if with_plan else None,
        prediction=prediction if with_plan else None,
        iteration_predictions=tuple(prediction * (1.0 + 0.01 * k) for k in range(step_iterations)),
        extra={"lp3": np.int64(obs.step), "gap": np.float64(0.25)},
    )


def record_episode(
    out_dir: Path,
    *,
    seed: int = 7,
    scenario: str = "circle",
    n_humans: int = 4,
    n_robots: int = 3,
    steps: int = 5,
    record_iterations: bool = False,
    with_plan: bool = True,
    end: bool = True,
    config: dict | None = None,
    predictor_sha256: str = "ab" * 32,
) -> RecordedEpisode:
    """Run ``steps`` steps (or to the end of the episode) through a McapEpisodeRecorder (``config``: more
    settings of its "config" metadata; ``predictor_sha256``: the weights it names)."""
    env = CrowdEnv(EnvConfig(time_limit=steps * 0.4, timeout_margin=0.0))
    obs = env.reset(seed, scenario, n_humans, n_robots)
    meta = {
        "seed": seed,
        "scenario": scenario,
        "n_humans": n_humans,
        "n_robots": n_robots,
        "controller": "handmade",
        "predictor": "constant_velocity",
        "predictor_sha256": predictor_sha256,
        "config": {"env": {"dt": 0.4, "radius": 0.3}, "horizon": HORIZON, **(config or {})},
    }
    recorder = McapEpisodeRecorder(out_dir, record_iterations=record_iterations, run_meta={"argv": ["test"]})
    recorder.on_reset(obs, meta)
    observations, outputs = [obs], []
    done = False
    while not done:
        out = control_output(obs, with_plan=with_plan)
        next_obs, done, _ = env.step(out.accelerations)
        recorder.on_step(obs, out, next_obs)
        observations.append(next_obs)
        outputs.append(out)
        obs = next_obs
    traj = env.trajectory()
    result = EpisodeResult(
        seed=seed,
        scenario=scenario,
        n_humans=n_humans,
        n_robots=n_robots,
        controller="handmade",
        predictor="constant_velocity",
        predictor_sha256="ab" * 32,
        metrics=episode_metrics(traj),
        robot_positions=traj.robot_positions,
        human_positions=traj.human_positions,
        robot_goals=traj.robot_goals,
        human_goals=traj.human_goals,
        solve_times_s=np.array([o.solve_time_s for o in outputs]),
        statuses=tuple(o.status for o in outputs),
        fallbacks=tuple(o.fallback for o in outputs),
        iterations=np.array([o.iterations for o in outputs]),
    )
    if end:
        recorder.on_end(result)
    else:
        recorder.close()
    return RecordedEpisode(recorder.paths[-1], observations, outputs, result, meta)


def cut_before_episode_metadata(data: bytes) -> bytes:
    """A recording's bytes up to its "episode" metadata record: the header and the "crowdmpc" record alone, a
    run killed before the rest reached the file (one cut before the "crowdmpc" record reads nothing)."""
    header_end = 8 + 9 + int.from_bytes(data[9:17], "little")
    return data[: header_end + 9 + int.from_bytes(data[header_end + 1 : header_end + 9], "little")]
