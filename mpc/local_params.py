"""The local NLPs' parameter vectors of one control step (mpc/nlp.py ``LocalNLP``), built once per step.

Robot ``i``'s parameters are ``[state, last action, goal, Eq. 8 target, goal slack, flocking weights of its
M-1 pairs, (with flock_distance "goals") their d_ij, the others' planned positions, every human's margins,
the predictions]``. Only the others' plans
and the predictions change between the iterations of a step; the rest is the step's, so it is assembled
once here (it went through StepData's checks and a Python loop over the pairs in every one of the ~6 builds
per robot and iteration of DMPC). The vectors are the same numbers in the same order as one
``np.concatenate`` per robot: tests/mpc/test_local_params.py holds them equal bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mpc import costs
from mpc.config import MPCConfig
from mpc.step_data import StepData


@dataclass(frozen=True)
class LocalParams:
    """Every robot's local parameters at one step, for any plans of the others and any predictions."""

    data: StepData
    # (M, 11 + M-1 [+ M-1]): state, last action, goal, target, slack, flocking weights [, d_ij]
    head: np.ndarray
    others: np.ndarray  # (M, M-1) int: robot i's others in index order
    margins: np.ndarray  # (H * N_h,) every human's margin at every step, row-major

    @classmethod
    def build(cls, data: StepData, cfg: MPCConfig, n_humans: int) -> LocalParams:
        m = data.n_robots
        others = np.array([[j for j in range(m) if j != i] for i in range(m)], dtype=np.intp)
        others = others.reshape(m, m - 1)  # (1, 0) for one robot
        pairs = np.array(
            [[costs.pair_index(i, j, m) for j in row] for i, row in enumerate(others)], dtype=np.intp
        ).reshape(m, m - 1)
        head = np.concatenate(
            [
                np.asarray(data.states, dtype=float),
                np.asarray(data.last_actions, dtype=float),
                np.asarray(data.goals, dtype=float),
                data.reference_targets(),
                data.goal_slacks()[:, None],
                data.floc_weights(cfg.pair_floc_weight(data.n_robots), cfg.flock_range)[pairs],
                *(d[pairs] for d in flock_distances(data, cfg)),  # with flock_distance "goals" only
            ],
            axis=1,
        )
        return cls(data, head, others, data.margins(cfg, n_humans))

    def rows(
        self, robots: Sequence[int] | np.ndarray, positions: np.ndarray, humans: np.ndarray
    ) -> np.ndarray:
        """``(len(robots), P)``: the parameters of each robot in ``robots`` given all robots' planned
        positions ``(M, H, 2)`` (a robot's own row unused) and the humans' predictions ``(H, N_h, 2)``."""
        robots = np.asarray(robots, dtype=np.intp)
        k = len(robots)
        positions = np.asarray(positions, dtype=float)
        humans = np.asarray(humans, dtype=float).ravel()
        return np.concatenate(
            [
                self.head[robots],
                positions[self.others[robots]].reshape(k, self.others.shape[1] * positions[0].size),
                np.broadcast_to(self.margins, (k, len(self.margins))),
                np.broadcast_to(humans, (k, len(humans))),
            ],
            axis=1,
        )

    def row(self, i: int, positions: np.ndarray, humans: np.ndarray) -> np.ndarray:
        """Robot ``i``'s parameters (``rows`` of one robot)."""
        return self.rows([i], positions, humans)[0]


def flock_distances(data: StepData, cfg: MPCConfig) -> list[np.ndarray]:
    """The NLPs' d_ij parameters, per unordered pair: none unless ``cfg.flock_distance`` is "goals"."""
    return [data.flock_distances(cfg.d_flock)] if cfg.flock_distance == "goals" else []
