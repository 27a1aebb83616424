"""The ORCA-ground-truth oracle: predict the humans by simulating them forward with the simulator's own ORCA.

The predictor-swap ablation needs an upper bound on what a better predictor could buy: a model that knows
what the learned ones must guess, namely each human's goal and the exact rule the humans move by. Given the
current state (positions, velocities, goals) and the robots' planned positions, the oracle repeats the
environment's human update (``crowdsim.env``, step 1 and 3) ``H`` times:

* the humans' ORCA velocities from everyone's current positions and velocities, robots included, with the
  environment's parameters (radius plus CrowdNav's margin, preferred speed, neighbours, time horizon) and
  preferred velocities towards their goals, zero once within their radius of it;
* humans move ``p' = p + tau v'``; robots move to their planned positions, and their velocity is the double
  integrator's end-of-step velocity ``v' = 2 (s' - s) / tau - v`` (exact for a plan that obeys Eq. 2).

So its one-step prediction is exactly what the simulator will do when the robots apply the plan's first
action, and its whole prediction is exact if they follow the plan. It is registered like every predictor
(``predictors.registry``); it is the one predictor that reads the simulator (its ORCA is the humans' own
rule), which the layering test allows for this module only. It needs the humans' goals and velocities, which
are not in the history a predictor normally gets, so it is an ``ObservingPredictor``: the MPC controller hands
it each observation and the simulator's settings before it predicts. It is numeric only: it has no CasADi twin
(ORCA's linear programs are not smooth), so it works with iterated best response (``coupling="ibr"``), not
inside the coupled NLP.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Final

import numpy as np

from crowdsim.env import EnvConfig
from crowdsim.orca import orca_velocities, preferred_velocities
from predictors.base import check_rollout_inputs
from predictors.errors import NoCasadiTwin, PredictorError
from predictors.text_table import counted

if TYPE_CHECKING:
    import casadi as ca

    from crowdsim.env import Observation

ORACLE_PREDICTOR: Final[str] = "orca_oracle"


class OrcaOracle:
    """A ``Predictor`` (rollout only) that simulates the humans' ORCA forward from the observed state."""

    name = ORACLE_PREDICTOR
    obs_len = 1  # only the current state matters: ORCA is memoryless

    def __init__(self) -> None:
        self.env_config = EnvConfig()
        self._obs: Observation | None = None

    def observe(self, obs: Observation, env_config: EnvConfig) -> None:
        """The state the next rollouts start from (velocities and goals are not in the history) and the
        simulator's settings the humans move by (ORCA parameters, whether they see the robots). The humans'
        goals and velocities must be finite: a NaN goal (an unknown one, on a real robot) made every
        prediction NaN, and every step fell back to the shifted plan without a word."""
        for name in ("human_goals", "human_velocities"):
            values = np.asarray(getattr(obs, name), dtype=float)
            bad = np.flatnonzero(~np.isfinite(values).all(axis=-1)) if values.ndim == 2 else np.zeros(0, int)
            if len(bad):
                raise PredictorError(
                    f"obs.{name} of human {bad[0]} is not finite ({values[bad[0]].tolist()}): the ORCA "
                    "oracle moves the humans by the simulator's rules, from their goals and velocities; "
                    "without them, predict with a model (--predictor constant_velocity, say)"
                )
        self._obs = obs
        self.env_config = env_config

    def rollout(
        self,
        history: np.ndarray,
        mask: np.ndarray,
        robots_future: np.ndarray | None,
        humans: np.ndarray,
        horizon: int | None = None,
    ) -> np.ndarray:
        """Predicted positions ``(H, N_h, 2)`` of ``humans``; agent layout as ``Observation.history``: the
        robots first, then the humans. Without ``robots_future`` the robots keep their velocity."""
        horizon = check_rollout_inputs(history, mask, robots_future, humans, horizon)
        obs = self._obs
        if obs is None:
            raise PredictorError("the ORCA oracle predicts from an observation: call observe(obs) first")
        m, n = obs.n_robots, obs.n_humans
        now = np.concatenate([obs.robot_positions, obs.human_positions])
        if history.shape[1] != m + n or not np.allclose(history[-1], now, atol=1e-9):
            raise PredictorError(
                "the ORCA oracle got a history whose current positions are not those of the observation it "
                f"was told ({history.shape[1]} agents, {counted(m, 'robot')} + {counted(n, 'human')}): call "
                "observe(obs) every step"
            )
        humans = np.asarray(humans, dtype=int)
        if humans.size and humans.min() < m:
            raise PredictorError(f"the ORCA oracle predicts humans (indices >= {m}), got indices {humans}")
        if robots_future is None:
            steps = np.arange(1, horizon + 1, dtype=float)[:, None, None]
            robots_future = obs.robot_positions[None] + steps * obs.dt * obs.robot_velocities[None]
        return self.simulate(obs, np.asarray(robots_future, dtype=float))[:, humans - m]

    def simulate(self, obs: Observation, robots_future: np.ndarray) -> np.ndarray:
        """Every human's positions ``(H, N, 2)`` at t+1..t+H, the robots on ``robots_future (H, M, 2)``."""
        cfg = self.env_config
        dt = obs.dt
        m = obs.n_robots
        rp, rv = obs.robot_positions.astype(float), obs.robot_velocities.astype(float)
        hp, hv = obs.human_positions.astype(float), obs.human_velocities.astype(float)
        humans = np.arange(m, m + obs.n_humans)
        out = np.empty((len(robots_future), obs.n_humans, 2))
        # Invisible robots (EnvConfig.robots_visible False) are not in the humans' ORCA at all.
        seen = m if cfg.robots_visible else 0
        if not cfg.robots_visible:
            humans = humans - m
        for k, robots_next in enumerate(robots_future):
            pref = preferred_velocities(hp, obs.human_goals, cfg.v_pref, stop_radius=obs.radius)
            hv, _ = orca_velocities(
                np.concatenate([rp[:seen], hp]),
                np.concatenate([rv[:seen], hv]),
                pref,
                obs.radius + cfg.orca_radius_margin,
                cfg.v_pref,
                cfg.orca,
                dt,
                agents=humans,
            )
            hp = hp + dt * hv
            rv = 2.0 * (robots_next - rp) / dt - rv
            rp = robots_next
            out[k] = hp
        return out

    # The symbolic face of the protocol: ORCA's piecewise linear programs have no useful derivatives.
    def encode(self, history: np.ndarray, mask: np.ndarray, humans: np.ndarray) -> np.ndarray:
        raise NoCasadiTwin(_NO_CASADI)

    def context_size(self, n_humans: int, n_robots: int) -> int:
        raise NoCasadiTwin(_NO_CASADI)

    def to_casadi(self, n_humans: int, n_robots: int, horizon: int) -> ca.Function:
        raise NoCasadiTwin(_NO_CASADI)


_NO_CASADI = (
    "the ORCA oracle has no CasADi twin (ORCA is not differentiable): use it with coupling='ibr', "
    "not inside the coupled NLP"
)
