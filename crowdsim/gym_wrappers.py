"""Wrappers of ``crowdmpc/CrowdNav-v0`` (``crowdsim.gym_env``).

``VelocityControl`` takes what CrowdNav policies output, a velocity per robot (holonomic ``ActionXY``), and
turns it into the acceleration the environment takes with a bounded proportional tracker:

    a = clip(k (v_cmd - v), -a_max, a_max)   per component, k = gain (default 1 / dt)

With the default gain the new velocity ``v' = v + dt a`` is the command itself whenever
``|v_cmd - v| <= a_max dt`` per component (0.8 m/s with Table I), and otherwise moves ``a_max dt`` towards
it: the command is reached as fast as the acceleration bound allows, with no overshoot. A smaller gain
(``0 < gain <= 1 / dt``) tracks more gently. The command space is ``Box(-v_max, v_max, (max_robots, 2))``,
the velocity bound of Eq. (6); rows past the episode's robots are ignored. ``crowdsim.baselines`` turns its
desired velocities into accelerations by this same rule, so a baseline's velocities through this wrapper
drive exactly as the baseline does.

``SensorRange`` shows a policy what a robot team with a range-limited sensor sees: the humans farther than
``radius`` metres from every robot become padding rows (all zeros, present 0), as people out of view are;
the reward, the info's figures and the episode's metrics stay the simulator's, over every human, as behind
``crowdmpc simulate --sensor-range`` (``pipelines.loop.sensing``, whose visibility rule this is: within
``radius`` of some robot, tracked now in a replayed crowd). It shows positions and velocities, not a
tracker's history.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from crowdsim.env import Observation
from crowdsim.errors import SimulationError, counted
from crowdsim.gym_env import CrowdNavEnv, numbers
from crowdsim.world import is_sensor_range


class VelocityControl(gym.ActionWrapper[np.ndarray, np.ndarray, np.ndarray], gym.utils.RecordConstructorArgs):
    """Velocity commands in, accelerations out (module docstring).

    :param env: a ``crowdmpc/CrowdNav-v0`` environment, possibly wrapped, but by no action wrapper: those
        (``RescaleAction``) go outside, or the accelerations computed here would be read as other numbers.
    :param gain: k in 1/s, in ``(0, 1/dt]``; default ``1/dt``.
    """

    def __init__(self, env: gym.Env[np.ndarray, np.ndarray], *, gain: float | None = None):
        gain = gain.item() if isinstance(gain, np.generic) else gain  # np.float32 from a sweep's numbers
        # env.spec can rebuild the wrapper, and write it as JSON (numpy's scalars are not JSON)
        gym.utils.RecordConstructorArgs.__init__(self, gain=gain)
        gym.ActionWrapper.__init__(self, env)
        base = env.unwrapped
        if not isinstance(base, CrowdNavEnv):
            raise SimulationError(f"VelocityControl wraps a CrowdNavEnv, got {type(base).__name__}")
        for inner in _wrappers(env):  # twice, velocities were taken for velocities twice over
            if isinstance(inner, VelocityControl):
                raise SimulationError("VelocityControl wraps an environment that has one already")
        _check_takes_accelerations(env, base)
        cfg = base.config
        gain = 1.0 / cfg.dt if gain is None else gain
        if isinstance(gain, bool) or not isinstance(gain, int | float) or not 0 < gain <= 1.0 / cfg.dt:
            raise SimulationError(f"gain must be a number in (0, 1/dt = {1.0 / cfg.dt:g}] 1/s, got {gain!r}")
        self.gain = float(gain)
        self._period = cfg.dt if gain == 1.0 / cfg.dt else 1.0 / self.gain  # divide as the baselines do
        self.a_max = cfg.a_max
        self.action_space = spaces.Box(-cfg.v_max, cfg.v_max, (base.max_robots, 2), dtype=np.float64)
        # the velocities tracked are the environment's own: the info's copy is the policy's to change in place
        self._base = base
        self._native: Observation | None = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(seed=seed, options=options)
        self._native = self._base.observation
        return obs, info

    def step(self, action: np.ndarray) -> tuple[np.ndarray, Any, bool, bool, dict[str, Any]]:
        result = super().step(action)
        self._native = self._base.observation
        return result

    def action(self, action: np.ndarray) -> np.ndarray:
        """The accelerations that track the commanded velocities ``action`` ``(max_robots, 2)`` m/s."""
        if self._native is None:
            raise SimulationError("step() called before reset()")
        command = numbers(action, "velocity action")
        if command.shape != self.action_space.shape:
            raise SimulationError(
                f"velocity action must be a {self.action_space.shape} array, got shape {command.shape}"
            )
        m = self._native.n_robots
        if not np.isfinite(command[:m]).all():  # inf was clipped to a_max, NaN refused as accelerations
            bad = int((~np.isfinite(command[:m])).sum())
            raise SimulationError(
                f"velocity action must be finite for the episode's {counted(m, 'robot')}, got "
                f"{counted(bad, 'non-finite entry', 'non-finite entries')}"
            )
        accelerations = np.zeros_like(command)
        tracked = (command[:m] - self._native.robot_velocities) / self._period
        accelerations[:m] = np.clip(tracked, -self.a_max, self.a_max)
        return accelerations


class SensorRange(
    gym.ObservationWrapper[np.ndarray, np.ndarray, np.ndarray], gym.utils.RecordConstructorArgs
):
    """The humans beyond ``radius`` m of every robot as padding rows (module docstring).

    :param env: a ``crowdmpc/CrowdNav-v0`` environment, possibly wrapped, but by no observation wrapper
        other than a ``SensorRange``: those (``FlattenObservation``) go outside, as the rows zeroed here are
        the environment's own.
    :param radius: the sensor's range in m, finite and > 0.
    """

    def __init__(self, env: gym.Env[np.ndarray, np.ndarray], *, radius: float):
        radius = radius.item() if isinstance(radius, np.generic) else radius  # np.int64(3) read as no range
        gym.utils.RecordConstructorArgs.__init__(self, radius=radius)  # Python's numbers: JSON, as gain
        gym.ObservationWrapper.__init__(self, env)
        base = env.unwrapped
        if not isinstance(base, CrowdNavEnv):
            raise SimulationError(f"SensorRange wraps a CrowdNavEnv, got {type(base).__name__}")
        _check_gives_rows(env, base)
        if not is_sensor_range(radius):
            raise SimulationError(f"radius must be a finite number of metres > 0, got {radius!r}")
        self.radius = float(radius)
        self._base = base

    def observation(self, observation: np.ndarray) -> np.ndarray:
        """``observation`` with the rows of the humans out of view zeroed, judged on the simulator's own
        state (``CrowdNavEnv.observation``: the array's positions are clipped to its bounds)."""
        obs = self._base.observation
        seen = obs.humans_in_view(self.radius)
        out = observation.copy()
        rows = self._base.max_robots
        out[rows : rows + obs.n_humans][~seen] = 0.0
        return out


def _wrappers(env: gym.Env[Any, Any]) -> list[gym.Wrapper[Any, Any, Any, Any]]:
    """The wrappers of ``env`` from the outermost in (``env`` itself first when it is one)."""
    found = []
    while isinstance(env, gym.Wrapper):
        found.append(env)
        env = env.env
    return found


def _changer(env: gym.Env[Any, Any], base: CrowdNavEnv, space: str, kind: type, own: type) -> str | None:
    """The innermost wrapper below ``env`` (``env`` included) that is a ``kind`` (an ``ObservationWrapper``
    or ``ActionWrapper``) other than ``own``, or that makes the ``space`` attribute other than the base's."""
    for wrapper in reversed(_wrappers(env)):
        if isinstance(wrapper, kind) and not isinstance(wrapper, own):
            return type(wrapper).__name__
        if getattr(wrapper, space) != getattr(base, space):
            return type(wrapper).__name__
    return None


def _check_takes_accelerations(env: gym.Env[Any, Any], base: CrowdNavEnv) -> None:
    """VelocityControl computes the environment's own accelerations (m/s^2, ``base.config.a_max``): an
    action wrapper below it (``RescaleAction``) turned them into other numbers, 0.2 m/s reached 0.4."""
    changer = _changer(env, base, "action_space", gym.ActionWrapper, VelocityControl)
    if changer is not None:
        raise SimulationError(
            f"VelocityControl must wrap the environment's own accelerations, but {changer} lies between; "
            "put action wrappers (RescaleAction, ClipAction, ...) outside VelocityControl"
        )


def _check_gives_rows(env: gym.Env[Any, Any], base: CrowdNavEnv) -> None:
    """SensorRange zeroes rows of the environment's own ``(rows, 7)`` array: below a wrapper that flattens,
    stacks or rescales it (``FlattenObservation``), it zeroed other numbers and left the humans in view."""
    changer = _changer(env, base, "observation_space", gym.ObservationWrapper, SensorRange)
    if changer is not None:
        raise SimulationError(
            f"SensorRange must wrap the environment's own {base.observation_space.shape} observation, but "
            f"{changer} lies between; put observation wrappers (FlattenObservation, FrameStackObservation, "
            "NormalizeObservation, ...) outside SensorRange"
        )
