"""Constant-velocity baseline: every human keeps its last observed velocity (robot plans do not matter)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from predictors.base import DT, check_history, check_humans, check_rollout_inputs, check_sizes
from predictors.errors import PredictorError


def last_state(history: np.ndarray, mask: np.ndarray, agents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position at the current step (the history's last) and velocity of each agent in ``agents``: ``(n, 2)``.

    The velocity is the last finite difference between two consecutive observed steps; an agent seen only
    once (or never twice in a row at the end) gets zero velocity rather than a guess. An agent not seen at the
    current step is extrapolated to it at that velocity from where it was last seen, as the learned predictors
    impute it: its forecast would otherwise lag by the steps it was missing.
    """
    agents = np.asarray(agents, dtype=int)
    current = history.shape[0] - 1
    pos = np.zeros((len(agents), 2))
    vel = np.zeros((len(agents), 2))
    for k, a in enumerate(agents):
        seen = np.flatnonzero(mask[:, a])
        if seen.size == 0:
            raise PredictorError(f"agent {a} is never observed in the history; it cannot be predicted")
        last = seen[-1]
        pos[k] = history[last, a]
        if last >= 1 and mask[last - 1, a]:
            vel[k] = (history[last, a] - history[last - 1, a]) / DT
        if last < current:  # only then: an agent seen now keeps its observed position bit for bit
            pos[k] += (current - last) * DT * vel[k]
    return pos, vel


class ConstantVelocity:
    name = "constant_velocity"

    def __init__(self, obs_len: int = 2):
        if obs_len < 1:
            raise PredictorError(f"obs_len must be >= 1, got {obs_len}")
        self.obs_len = obs_len

    def rollout(self, history, mask, robots_future, humans, horizon=None):
        history, mask = np.asarray(history, dtype=float), np.asarray(mask, dtype=bool)  # lists too, as nets'
        future = None if robots_future is None else np.asarray(robots_future, dtype=float)
        horizon = check_rollout_inputs(history, mask, future, humans, horizon)
        pos, vel = last_state(history, mask, humans)
        steps = np.arange(1, horizon + 1, dtype=float)[:, None, None]
        return pos[None] + steps * DT * vel[None]

    def encode(self, history, mask, humans):
        history, mask = np.asarray(history, dtype=float), np.asarray(mask, dtype=bool)
        check_history(history, mask)  # as rollout
        humans = check_humans(humans, np.shape(history)[1])  # as rollout: a repeat or a mask is refused
        pos, vel = last_state(history, mask, humans)
        return np.concatenate([pos.ravel(), vel.ravel()]).astype(np.float64)

    def context_size(self, n_humans: int, n_robots: int) -> int:
        check_sizes(n_humans, n_robots)
        return 4 * n_humans

    def to_casadi(self, n_humans: int, n_robots: int, horizon: int) -> ca.Function:
        check_sizes(n_humans, n_robots, horizon)
        context = ca.MX.sym("context", self.context_size(n_humans, n_robots))
        robots_future = ca.MX.sym("robots_future", horizon * n_robots * 2)
        pos = context[: 2 * n_humans]
        vel = context[2 * n_humans :]
        steps = [pos + (h + 1) * DT * vel for h in range(horizon)]
        out = ca.vertcat(*steps) if steps else ca.MX(0, 1)
        return ca.Function(
            self.name, [context, robots_future], [out], ["context", "robots_future"], ["humans_future"]
        )
