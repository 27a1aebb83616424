"""A minimal closed loop on the robots' own double integrator (no simulator), for the MPC tests."""

import numpy as np

from mpc.dynamics import rollout_numpy
from mpc.fallback import PlanMemory
from mpc.nlp import StepData


def drive(solver, states: np.ndarray, goals: np.ndarray, steps: int, reach: float = 0.3) -> np.ndarray:
    """Run ``solver`` (CMPC or DMPC, no humans) until every robot is within ``reach`` of its goal.

    Robots that have arrived are parked (``active`` False), as the closed-loop controller does. Returns the
    final states ``(M, 4)``.
    """
    cfg = solver.cfg
    memory = PlanMemory(cfg)
    last = np.zeros((len(states), 2))
    reached = np.zeros(len(states), dtype=bool)
    no_humans = np.zeros((cfg.horizon, 0, 2))
    for _ in range(steps):
        reached |= np.linalg.norm(states[:, :2] - goals, axis=1) < reach
        if reached.all():
            break
        data = StepData(states, last, goals, ~reached)
        start = memory.start(data)
        result = solver.solve(data, lambda robots_future: no_humans, start)
        plan = result.accels if result.solved else start.accels
        memory.commit(plan, result.solved, result.lam_x, result.lam_g, kind=start.kind)
        positions, velocities = rollout_numpy(states, plan[:, :1], cfg.dt)
        states = np.concatenate([positions[:, 0], velocities[:, 0]], axis=1)
        last = plan[:, 0]
    return states
