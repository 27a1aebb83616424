"""The gymnasium env's reward (``crowdsim.gym_env``'s docstring gives its rules) and the distances it is
computed from: each robot's closest approach to each human during a step, the relative motion a straight
segment, as CrowdNav's ``point_to_segment_dist`` takes it."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from crowdsim.conventions import PAPER_DISCOMFORT_DIST
from crowdsim.distances import closest_approach, min_robot_distance_between_steps
from crowdsim.env import Observation
from crowdsim.errors import SimulationError, real_number
from crowdsim.metrics import COLLISION_DISTANCE, DISCOMFORT_HORIZON, segments_intersect


@dataclass(frozen=True)
class RewardConfig:
    """The reward's numbers (crowdsim.gym_env's docstring), the CrowdNav fork's ``env_m.config [reward]``."""

    success: float = 1.0  # success_reward, once, on the step the robots succeed
    collision: float = -0.25  # collision_penalty, per step with a robot-human contact
    discomfort_dist: float = PAPER_DISCOMFORT_DIST  # m between boundaries (upstream CrowdNav: 0.2)
    discomfort_factor: float = 0.5  # discomfort_penalty_factor, 1/s (the penalty is scaled by dt)

    def __post_init__(self) -> None:
        for f in fields(self):
            where = f"RewardConfig.{f.name}"
            value = real_number(where, getattr(self, f.name), "a finite number", math.isfinite)
            object.__setattr__(self, f.name, value)  # frozen: numpy's scalars are stored as Python's
        if self.discomfort_dist < 0 or self.discomfort_factor < 0:
            raise SimulationError(
                f"RewardConfig.discomfort_dist and discomfort_factor must be >= 0, got "
                f"{self.discomfort_dist!r} and {self.discomfort_factor!r}"
            )

    def step_reward(
        self,
        surface_distance: float,
        *,
        success: bool,
        dt: float,
        contact_ends: bool = False,
    ) -> float:
        """The reward of one step, the last one's too (crowdsim.gym_env's rules 1-4): ``surface_distance``
        is the closest robot-human boundary distance during the step (m), ``dt`` the step (s);
        ``contact_ends``: a contact ends the episode (``end_on_collision``), so the success of the same step
        is not paid."""
        if surface_distance < 0:
            paid = success and not contact_ends
            return float(self.collision + self.success) if paid else float(self.collision)
        if success:
            return float(self.success)
        if surface_distance < self.discomfort_dist:
            return float((surface_distance - self.discomfort_dist) * self.discomfort_factor * dt)
        return 0.0


def as_reward_config(values: RewardConfig | Mapping[str, Any] | None) -> RewardConfig:
    """``values`` as a RewardConfig: itself, the default (None), or one from plain data (a YAML or JSON
    file's ``gym.make`` keywords), unknown keys named."""
    if values is None or isinstance(values, RewardConfig):
        return RewardConfig() if values is None else values
    if not isinstance(values, Mapping):
        raise SimulationError(f"reward must be a RewardConfig or a mapping of its fields, got {values!r:.80}")
    names = [f.name for f in fields(RewardConfig)]
    unknown = sorted(str(key) for key in values if key not in names)
    if unknown:
        raise SimulationError(f"reward has no field {unknown[0]!r}; expected {', '.join(names)}")
    return RewardConfig(**values)


def step_closest(before: Observation, after: Observation) -> np.ndarray:
    """``(M, N)`` closest centre distance of each robot to each human during the step, the relative motion
    taken as the segment from its start to its end (CrowdNav's ``point_to_segment_dist``;
    ``crowdsim.distances.closest_approach``, as ``min_distance_between_steps`` takes it). A replayed
    crowd's human counts only over a step it is tracked at both ends (``crowdsim.metrics``): inf otherwise."""
    start = before.human_positions[None] - before.robot_positions[:, None]  # (M, N, 2) human - robot
    end = after.human_positions[None] - after.robot_positions[:, None]
    closest = closest_approach(start, end)
    if before.human_present is not None and after.human_present is not None:
        both = np.asarray(before.human_present, dtype=bool) & np.asarray(after.human_present, dtype=bool)
        closest = np.where(both[None], closest, np.inf)
    return closest


def surface_distances(closest: np.ndarray, radius: float) -> np.ndarray:
    """``(M,)`` closest boundary distance of each robot to any human during the step, from ``step_closest``'s
    ``(M, N)`` centre distances less the sum of the radii; inf without humans."""
    if closest.shape[1] == 0:
        return np.full(closest.shape[0], math.inf)
    return closest.min(axis=1) - 2.0 * radius


def robot_pair_info(before: Observation, after: Observation, radius: float) -> dict[str, float | bool]:
    """A step's robot-robot figures for the info (not in the paper, nor in the reward): at the new state,
    ``min_distance_robots`` (m, inf with one robot) and ``robot_contact`` (below the sum of the radii); over
    the step, the relative motion a straight segment, ``min_distance_robots_between_steps`` and
    ``robot_contact_between_steps``, as ``crowdsim.metrics`` counts them for the episode."""
    now = min_robot_distance_between_steps(after.robot_positions[None])
    swept = min_robot_distance_between_steps(np.stack([before.robot_positions, after.robot_positions]))
    return {
        "min_distance_robots": now,
        "robot_contact": now < 2.0 * radius,
        "min_distance_robots_between_steps": swept,
        "robot_contact_between_steps": swept < 2.0 * radius,
    }


def state_info(obs: Observation, radius: float) -> dict[str, float | bool]:
    """A state's robot-human figures for the info, as ``crowdsim.metrics`` counts them per state:
    ``min_distance`` (centres, m; inf without humans), ``collision`` (below ``COLLISION_DISTANCE``),
    ``contact`` (below the sum of the radii) and ``discomfort`` (projected paths intersect). A replayed
    crowd's humans not tracked now are left out, as the metrics leave them."""
    humans = np.arange(obs.n_humans) if obs.human_present is None else np.flatnonzero(obs.human_present)
    hp, hv = obs.human_positions[humans], obs.human_velocities[humans]
    rp, rv = obs.robot_positions, obs.robot_velocities
    centre = np.linalg.norm(rp[:, None] - hp[None], axis=-1)
    min_distance = float(centre.min()) if centre.size else math.inf
    discomfort = segments_intersect(
        rp[:, None], (rp + DISCOMFORT_HORIZON * rv)[:, None], hp[None], (hp + DISCOMFORT_HORIZON * hv)[None]
    )
    return {
        "min_distance": min_distance,
        "collision": min_distance < COLLISION_DISTANCE,
        "contact": min_distance < 2.0 * radius,
        "discomfort": bool(np.any(discomfort)),
    }
