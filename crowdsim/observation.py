"""What a controller sees at one step: ``Observation``, ``CrowdEnv``'s answer (crowdsim.env, which offers it
too: plugins import it from there)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Observation:
    """What a controller sees at one step (robots first, then humans, everywhere agents are stacked)."""

    time: float  # s since episode start
    step: int
    robot_positions: np.ndarray  # (M, 2) m
    robot_velocities: np.ndarray  # (M, 2) m/s
    robot_goals: np.ndarray  # (M, 2) m
    robot_last_actions: np.ndarray  # (M, 2) m/s^2, last applied (clipped) acceleration, zeros at start
    robot_reached: np.ndarray  # (M,) bool, robot has been within its radius of its goal at some step
    human_positions: np.ndarray  # (N, 2) m
    human_velocities: np.ndarray  # (N, 2) m/s
    human_goals: np.ndarray  # (N, 2) m
    history: np.ndarray  # (history_len, M+N, 2) last positions, robots first; row -1 = now; padded at start
    radius: float  # m, every agent
    dt: float  # s
    # (N,) int, the positions of each human really observed, padding excluded (a tracker's track lengths; the
    # MPC replaces the padding, predictors/backfill.py); None: step + 1 for every human, as in the simulator,
    # where all are present from the start
    human_observed: np.ndarray | None = None
    # (N,) bool, the humans tracked now in a replayed crowd (crowdsim.replay); None: every human is there
    human_present: np.ndarray | None = None

    @property
    def n_robots(self) -> int:
        return len(self.robot_positions)

    @property
    def n_humans(self) -> int:
        return len(self.human_positions)

    def humans_in_view(self, radius: float) -> np.ndarray:
        """``(N,)`` bool: the humans within ``radius`` m of some robot, and tracked now in a replayed crowd;
        what a sensor of that range sees (pipelines.loop.sensing, crowdsim.gym_wrappers.SensorRange)."""
        if not self.n_robots:
            return np.zeros(self.n_humans, dtype=bool)
        distance = np.linalg.norm(self.human_positions[:, None] - self.robot_positions[None], axis=-1)
        near = (distance <= radius).any(axis=1)
        return near if self.human_present is None else near & np.asarray(self.human_present, dtype=bool)


def array_copies(obs: Observation) -> dict[str, Any]:
    """Copies of ``obs``'s array fields, by name: an observation handed to someone who may change its arrays
    in place (a policy, a controller) without moving what its giver computes from (rewards, recordings)."""
    return {f.name: np.array(v) for f in fields(obs) if isinstance(v := getattr(obs, f.name), np.ndarray)}
