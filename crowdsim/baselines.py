"""Two robot controllers that need no prediction or optimisation, so the simulator is useful on its own.

Both have ``name``, ``reset`` and ``act`` and return ``crowdsim.control.ControlOutput``;
``pipelines.loop.baselines`` makes them closed-loop controllers.

* ``straight``: track a velocity pointing at the goal, ignoring humans and the other robots. Its speed is
  ``v_max`` unless braking must begin: the largest next speed ``v'`` from which a constant deceleration
  ``b = a_max / 2`` (half the bound: margin for the per-axis clipping) still stops on the goal after this
  step, ``v'^2 / (2 b) <= d - tau (v + v') / 2`` with ``v`` the current speed towards the goal and ``d`` the
  distance to it. ``v'^2 / (2 b)`` is the distance of continuous braking, but the robot stops in whole
  steps: from ``v' < b tau`` its last step travels ``tau v' / 2``, farther. So it may pass the goal by up
  to about ``b tau^2 / 8`` (2 cm with Table I's bounds, e.g. on the way to a goal 7 m along each axis)
  and settles back onto it; where the distances fall on the profile's steps (2 m straight ahead) it stops
  on the goal exactly.
* ``orca``: the robots are ORCA agents like the humans (same parameters, same radius margin, preferred
  velocity towards their goals, max speed ``v_max``), each avoiding every other agent with its current
  velocity.

Both turn a desired velocity into the acceleration ``(v_desired - v) / tau`` clipped per component to
``±a_max``; the environment clips again for the velocity bound.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from crowdsim.control import ControlOutput
from crowdsim.orca import OrcaParams, orca_velocities, preferred_velocities
from crowdsim.world import A_MAX, V_MAX

if TYPE_CHECKING:
    from crowdsim.env import Observation

DEFAULT_PARAMS = OrcaParams()  # CrowdNav's RVO2 parameters


def _output(accelerations: np.ndarray, started: float) -> ControlOutput:
    return ControlOutput(accelerations=accelerations, solve_time_s=time.perf_counter() - started)


class StraightController:
    """Head for the goal at full speed, brake to stop on it; blind to everyone else."""

    name = "straight"

    def __init__(self, *, v_max: float = V_MAX, a_max: float = A_MAX):
        self.v_max = v_max  # m/s, per component, Eq. (6)
        self.a_max = a_max  # m/s^2, per component, Eq. (6)

    def reset(self, obs: Observation) -> None:
        pass

    def desired_velocities(self, obs: Observation) -> np.ndarray:
        offset = obs.robot_goals - obs.robot_positions
        dist = np.linalg.norm(offset, axis=1)
        unit = offset / np.where(dist > 0, dist, 1.0)[:, None]
        tau, b = obs.dt, 0.5 * self.a_max
        towards = np.einsum("mi,mi->m", obs.robot_velocities, unit)
        # v'^2 / (2 b) + tau v' / 2 <= slack: the positive root of the quadratic.
        slack = np.maximum(dist - 0.5 * tau * towards, 0.0)
        v_next = b * (np.sqrt(0.25 * tau**2 + 2.0 * slack / b) - 0.5 * tau)
        return unit * np.minimum(self.v_max, v_next)[:, None]

    def act(self, obs: Observation) -> ControlOutput:
        started = time.perf_counter()
        a = (self.desired_velocities(obs) - obs.robot_velocities) / obs.dt
        return _output(np.clip(a, -self.a_max, self.a_max), started)


class OrcaController:
    """Robots as ORCA agents among the humans (CrowdNav's ORCA policy for the robot, one per robot)."""

    name = "orca"

    def __init__(
        self,
        *,
        v_max: float = V_MAX,
        a_max: float = A_MAX,
        params: OrcaParams = DEFAULT_PARAMS,
        radius_margin: float = 0.01,
    ):
        self.v_max = v_max  # m/s, preferred speed and ORCA max speed
        self.a_max = a_max  # m/s^2, per component
        self.params = params
        self.radius_margin = radius_margin  # m, as the environment gives its humans (CrowdNav)

    def reset(self, obs: Observation) -> None:
        pass

    def desired_velocities(self, obs: Observation) -> np.ndarray:
        m = obs.n_robots
        positions = np.concatenate([obs.robot_positions, obs.human_positions])
        velocities = np.concatenate([obs.robot_velocities, obs.human_velocities])
        pref = preferred_velocities(obs.robot_positions, obs.robot_goals, self.v_max, stop_radius=obs.radius)
        v, _ = orca_velocities(
            positions,
            velocities,
            pref,
            obs.radius + self.radius_margin,
            self.v_max,
            self.params,
            obs.dt,
            agents=np.arange(m),
        )
        return v

    def act(self, obs: Observation) -> ControlOutput:
        started = time.perf_counter()
        a = (self.desired_velocities(obs) - obs.robot_velocities) / obs.dt
        return _output(np.clip(a, -self.a_max, self.a_max), started)
