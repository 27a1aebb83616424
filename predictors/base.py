"""The contract every pedestrian predictor fulfils (DESIGN.md, "Predictors").

Agent layout used throughout the project
----------------------------------------
* ``history``: ``(L, N, 2)`` positions in metres of *all* agents over the last ``L`` observed steps
  (row ``L-1`` is the current time ``t``), sampled every ``DT`` seconds.
* ``mask``: ``(L, N)`` bool, True where the agent was observed (TrajNet++ scenes have partial tracks).
* ``humans``: 1-D int array of the distinct indices (into ``N``) of the agents whose future is predicted.
  Every other index is a robot; robots are taken in increasing index order.
* ``robots_future``: ``(H, M, 2)`` the robots' planned positions at ``t+1 .. t+H``, or ``None`` when there
  are no robots whose plan is known (dataset evaluation: every agent is predicted by the model).

Recursive single-step prediction, Eq. (1): each step predicts the next position of every agent; the humans'
predictions are fed back, the robots' are replaced by their planned positions. This is the coupling.

The symbolic twin
-----------------
``encode(history, mask, humans)`` computes numerically everything that depends only on the observed past
(e.g. LSTM states after the ``L`` observed steps) and returns it as one flat float64 ``context`` vector whose
agent order is: ``humans`` in the given order, then the robots in increasing index order.

``to_casadi(n_humans, n_robots, horizon)`` returns a ``casadi.Function`` with

* input 0 ``context``: ``(context_size(n_humans, n_robots), 1)``
* input 1 ``robots_future``: ``(horizon * n_robots * 2, 1)``, ``robots_future.reshape(-1)`` (order h, m, xy)

and output 0 ``humans_future``: ``(horizon * n_humans * 2, 1)``, ``(H, N_h, 2).reshape(-1)``, such that
``f(encode(...), robots_future.ravel())`` equals ``rollout(...)`` to 1e-6 in float64 (a contract test).
``to_casadi`` takes the number of robots as well as the number of humans (DESIGN.md's sketch has a single
``n_agents``) because the two play different roles in the recursion.
"""

from __future__ import annotations

import numbers
from typing import TYPE_CHECKING, Final, Protocol, runtime_checkable

import casadi as ca
import numpy as np

from crowdsim import world
from predictors.errors import PredictorError, short_repr

if TYPE_CHECKING:
    from crowdsim.env import EnvConfig, Observation

# TrajNet++ samples at 2.5 Hz and observes 9 steps (Kothari et al. 2021); the paper's MPC uses tau = 0.4 s.
# One source with the simulator and the MPC: crowdsim.world.
DT: Final[float] = world.DT
OBS_LEN: Final[int] = world.OBS_LEN
PRED_LEN: Final[int] = 12
SCENE_LENGTH: Final[int] = OBS_LEN + PRED_LEN  # steps of a TrajNet++ scene's primary


def check_steps(obs_len: object, pred_len: object, what: str = "") -> None:
    """PredictorError (``what`` first, e.g. the model) unless ``obs_len`` and ``pred_len`` are integers,
    ``obs_len >= 2`` (a displacement needs two observed steps) and ``pred_len >= 1``: the training modules
    took any, and failed in the first step's indexing ("index -2 is out of bounds") or in a contract check
    that blamed the net's outputs."""
    whole = all(isinstance(n, numbers.Integral) and not isinstance(n, bool) for n in (obs_len, pred_len))
    if not whole or not (obs_len >= 2 and pred_len >= 1):  # type: ignore[operator]
        raise PredictorError(
            f"{what + ': ' if what else ''}need integers obs_len >= 2 (a displacement needs two observed "
            f"steps) and pred_len >= 1, got obs_len={short_repr(obs_len)}, pred_len={short_repr(pred_len)}"
        )


@runtime_checkable
class Predictor(Protocol):
    name: str
    obs_len: int  # number of observed steps the model uses (L)

    def rollout(
        self,
        history: np.ndarray,
        mask: np.ndarray,
        robots_future: np.ndarray | None,
        humans: np.ndarray,
        horizon: int | None = None,
    ) -> np.ndarray:
        """Predicted human positions ``(H, N_h, 2)``; ``horizon`` is needed when ``robots_future`` is None."""
        ...

    def encode(self, history: np.ndarray, mask: np.ndarray, humans: np.ndarray) -> np.ndarray:
        """The numeric summary of the observed past that ``to_casadi``'s function takes as ``context``."""
        ...

    def context_size(self, n_humans: int, n_robots: int) -> int: ...

    def to_casadi(self, n_humans: int, n_robots: int, horizon: int) -> ca.Function: ...


@runtime_checkable
class ObservingPredictor(Predictor, Protocol):
    """A predictor that needs more than the observed positions: the closed loop hands it each observation and
    the simulator's settings before it predicts (the ORCA oracle reads the humans' goals and velocities)."""

    def observe(self, obs: Observation, env_config: EnvConfig) -> None: ...


def robot_indices(n_agents: int, humans: np.ndarray) -> np.ndarray:
    """Indices of the robots: every agent that is not a human, in increasing order."""
    is_human = np.zeros(n_agents, dtype=bool)
    is_human[np.asarray(humans, dtype=int)] = True
    return np.flatnonzero(~is_human)


def check_humans(humans: np.ndarray, n_agents: int) -> np.ndarray:
    """``humans`` as a 1-D integer array of distinct indices into ``n_agents`` agents; PredictorError (a
    ValueError) otherwise.

    Each check stops a silent misreading: a repeated index makes that human a neighbour of its own copy (the
    pooling moves its forecast by centimetres), and a boolean mask ``[True, False, True]`` would be taken for
    the indices ``[1, 0, 1]``. An empty array selects no one whatever its dtype: ``np.array([])`` is float.
    """
    humans = np.asarray(humans)
    if humans.ndim != 1:
        raise PredictorError(f"humans must be a 1-D array of agent indices, got shape {humans.shape}")
    if humans.size == 0:
        return humans.astype(int)
    if not np.issubdtype(humans.dtype, np.integer):  # bool is not an integer dtype in numpy
        hint = " (a boolean mask? pass np.flatnonzero(mask))" if humans.dtype == bool else ""
        raise PredictorError(f"humans must be integer agent indices, got dtype {humans.dtype}{hint}")
    if humans.min() < 0 or humans.max() >= n_agents:
        raise PredictorError(
            f"humans must be indices into {n_agents} agents (0..{n_agents - 1}), "
            f"got {short_repr(humans.tolist())}"
        )
    values, counts = np.unique(humans, return_counts=True)
    if (counts > 1).any():
        raise PredictorError(
            f"humans must be distinct agent indices; {short_repr(values[counts > 1].tolist())} repeated"
        )
    return humans


def check_horizon(horizon: int, what: str) -> int:
    """``horizon`` if it is a whole number of steps, at least one (``to_casadi``'s bound); PredictorError
    naming ``what`` otherwise.

    A recursion of zero or fewer steps predicts nothing: the learned predictors used to return one step
    anyway, constant velocity an empty array. 3.5 steps were 3 and True one."""
    if isinstance(horizon, bool | np.bool_) or not isinstance(horizon, int | np.integer):
        raise PredictorError(f"{what} must be a whole number of steps, got {short_repr(horizon)}")
    if horizon < 1:
        raise PredictorError(f"{what} must be at least 1 step, got {horizon}")
    return int(horizon)


def check_sizes(n_humans: int, n_robots: int, horizon: int | None = None) -> None:
    """PredictorError unless the counts of a CasADi twin are whole numbers >= 0 and ``horizon`` is one
    >= 1: CasADi's own refusals named none of them, and constant velocity's context of "2" humans was
    "2222"."""
    for name, count in (("n_humans", n_humans), ("n_robots", n_robots)):
        if isinstance(count, bool | np.bool_) or not isinstance(count, int | np.integer) or count < 0:
            raise PredictorError(f"{name} must be a whole number >= 0, got {short_repr(count)}")
    if horizon is not None:
        check_horizon(horizon, "horizon")


def check_history(history: np.ndarray, mask: np.ndarray) -> None:
    """PredictorError unless ``history`` is ``(L, N, 2)``, ``mask`` ``(L, N)`` and each observed position
    finite.

    An unobserved entry may hold anything (TrajNet++ marks absence with NaN). An observed NaN is absence left
    out of ``mask``: the learned predictors' pooling spread it to every agent's forecast, while their CasADi
    twin turned it into finite numbers, and constant velocity returned NaN for that agent."""
    if history.ndim != 3 or history.shape[2] != 2:
        raise PredictorError(f"history must have shape (L, N, 2), got {history.shape}")
    if mask.shape != history.shape[:2]:
        raise PredictorError(f"mask must have shape {history.shape[:2]}, got {mask.shape}")
    bad = np.argwhere(mask.astype(bool) & ~np.isfinite(history).all(axis=-1))
    if bad.size:
        step, agent = bad[0]
        raise PredictorError(
            f"history[{step}, {agent}] is {history[step, agent].tolist()}, not a finite position, where mask "
            f"marks agent {agent} observed ({len(bad)} such entries); mark absent entries False in mask"
        )


def check_rollout_inputs(
    history: np.ndarray,
    mask: np.ndarray,
    robots_future: np.ndarray | None,
    humans: np.ndarray,
    horizon: int | None,
) -> int:
    """Validate shapes shared by every predictor, and that the positions it is given are finite; return the
    horizon H (>= 1)."""
    check_history(history, mask)
    n_agents = history.shape[1]
    n_robots = n_agents - len(check_humans(humans, n_agents))
    if robots_future is None:
        if horizon is None:
            raise PredictorError("horizon is required when robots_future is None")
        return check_horizon(horizon, "horizon")
    if robots_future.ndim != 3 or robots_future.shape[1:] != (n_robots, 2):
        raise PredictorError(f"robots_future must have shape (H, {n_robots}, 2), got {robots_future.shape}")
    if not np.isfinite(robots_future).all():
        raise PredictorError("robots_future holds a non-finite position; a robot plan is finite positions")
    if horizon is not None and horizon != robots_future.shape[0]:
        length = robots_future.shape[0]
        raise PredictorError(f"horizon {horizon} disagrees with robots_future of length {length}")
    return check_horizon(robots_future.shape[0], "robots_future's length H")
