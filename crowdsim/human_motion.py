"""The humans' step of ``CrowdEnv`` (crowdsim.env's docstring, steps 1 and 3): ORCA's humans, or a replayed
crowd's tracks, one step on from the current state of everyone. Pure functions of that state, apart from the
simulator's bookkeeping, so that ``CrowdEnv`` keeps the episode and this the rule of the humans' motion."""

from __future__ import annotations

import numpy as np

from crowdsim.env_config import EnvConfig
from crowdsim.orca import orca_velocities, preferred_velocities
from crowdsim.reaction import reactive_step, reacts
from crowdsim.replay import ReplayEpisode


def humans_next(
    cfg: EnvConfig,
    replay: ReplayEpisode | None,
    step: int,
    robots: tuple[np.ndarray, np.ndarray],
    humans: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The humans' positions and velocities one step on, decided from the current state of everyone
    (before any agent moves), and which humans' ORCA linear program was infeasible.

    ``robots``: positions and velocities ``(M, 2)``; ``humans``: positions, velocities and goals ``(N, 2)``;
    ``replay``: the replayed crowd's episode (None for ORCA's), at ``step`` steps into the episode.
    """
    rp, rv = robots
    hp, hv, hg = humans
    if replay is None:
        velocities, lp3 = orca_humans(cfg, rp, rv, hp, hv, hg)
        return hp + cfg.dt * velocities, velocities, lp3
    row = replay.past + step
    if reacts(cfg.crowd) and cfg.robots_visible:
        return reactive_step(
            replay,
            row,
            hp,
            hv,
            rp,
            rv,
            radius=cfg.radius + cfg.orca_radius_margin,
            params=cfg.orca,
            dt=cfg.dt,
        )
    # real tracks played back, where the recording has them (its step, not dt times a rounded velocity)
    return replay.positions[row + 1], replay.velocities[row + 1], np.zeros(0, dtype=bool)


def orca_humans(
    cfg: EnvConfig, rp: np.ndarray, rv: np.ndarray, hp: np.ndarray, hv: np.ndarray, hg: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Every human's ORCA velocity, decided from the current state of everyone it sees (before any agent
    moves: robots ``rp, rv``, humans ``hp, hv`` bound for ``hg``), and which humans' linear program was
    infeasible."""
    m = len(rp)
    if cfg.robots_visible:
        positions = np.concatenate([rp, hp])
        velocities = np.concatenate([rv, hv])
        agents = np.arange(m, m + len(hp))
    else:
        positions, velocities, agents = hp, hv, np.arange(len(hp))
    pref = preferred_velocities(hp, hg, cfg.v_pref, stop_radius=cfg.radius)
    return orca_velocities(
        positions,
        velocities,
        pref,
        cfg.radius + cfg.orca_radius_margin,
        cfg.v_pref,
        cfg.orca,
        cfg.dt,
        agents=agents,
    )
