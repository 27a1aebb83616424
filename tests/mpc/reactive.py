"""A toy predictor for the MPC tests whose predictions depend on the robots' plan (linearly).

Humans keep their last velocity and are displaced by ``gain`` times the displacement of the robots' mean
position from now: enough coupling for IBR to need several iterations, and linear, so that the first-order
coupled model is exact.
"""

import casadi as ca
import numpy as np

from predictors.base import DT, check_rollout_inputs, robot_indices


class ReactivePredictor:
    name = "reactive_toy"
    obs_len = 2

    def __init__(self, gain: float = 0.5):
        self.gain = gain

    def _state(self, history, humans):
        robots = robot_indices(history.shape[1], humans)
        pos = history[-1, humans]
        vel = (history[-1, humans] - history[-2, humans]) / DT
        return pos, vel, history[-1, robots].mean(axis=0)

    def rollout(self, history, mask, robots_future, humans, horizon=None):
        horizon = check_rollout_inputs(history, mask, robots_future, humans, horizon)
        pos, vel, robots_now = self._state(history, humans)
        steps = np.arange(1, horizon + 1, dtype=float)[:, None, None]
        shift = self.gain * (robots_future.mean(axis=1) - robots_now)[:, None, :]
        return pos[None] + steps * DT * vel[None] + shift

    def encode(self, history, mask, humans):
        pos, vel, robots_now = self._state(history, humans)
        return np.concatenate([pos.ravel(), vel.ravel(), robots_now])

    def context_size(self, n_humans, n_robots):
        return 4 * n_humans + 2

    def to_casadi(self, n_humans, n_robots, horizon):
        context = ca.MX.sym("context", self.context_size(n_humans, n_robots))
        robots_future = ca.MX.sym("robots_future", horizon * n_robots * 2)
        pos = ca.reshape(context[: 2 * n_humans], 2, n_humans)
        vel = ca.reshape(context[2 * n_humans : 4 * n_humans], 2, n_humans)
        robots_now = context[4 * n_humans :]
        plan = ca.reshape(robots_future, 2, horizon * n_robots)
        out = []
        for h in range(horizon):
            mean = ca.sum2(plan[:, h * n_robots : (h + 1) * n_robots]) / n_robots
            out.append(
                ca.vec(pos + (h + 1) * DT * vel + ca.repmat(self.gain * (mean - robots_now), 1, n_humans))
            )
        return ca.Function(self.name, [context, robots_future], [ca.vertcat(*out)])
