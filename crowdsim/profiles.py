"""Named simulation conventions: the paper's (default) and this project's first simulator's.

* ``"paper"`` follows the authors' public CrowdNav fork (vaishnavtvHRI/CrowdNav, ``crowd_nav/configs/
  env_m.config`` and ``crowd_sim/envs/crowd_sim.py``): 0.4 s steps, 40 s time limit checked as
  ``global_time >= time_limit - 1`` before a step (98 steps), circle radius 5 m, square width 10 m, radii
  0.3 m, v_pref 1 m/s, spawn separation ``r_i + r_j + discomfort_dist + 0.1 = 1.1`` m with the fork's
  ``discomfort_dist = 0.4``, its circle- and square-crossing samplers (``crowdsim.crossings``), success when
  every robot is within its radius of its goal at the same step (``all(reaching_goal)``), humans that see
  the robots (``[robot] visible = true``) and stop at their goals.
* ``"v1"``: this project's first simulator, bit for bit: 30 s time limit without margin (75 steps), 0.8 m
  spawn separation, its own perpendicular geometry, success once every robot has reached its goal at least
  once. Only its history is longer (9 rows, ``world.OBS_LEN``, where the first simulator kept 8), which
  changes the episodes of a network predictor (docs/results.md, Table III).

Where the robots start and end is not public; both profiles keep ``crowdsim.scenarios.robot_layout``'s
formation (the row up to 3 robots), which isolates the published conventions. Visibility is chosen
separately (``make_env_config``); CrowdNav's own default is invisible robots, the fork's configuration
visible ones.
"""

from __future__ import annotations

import dataclasses
from typing import Final

from crowdsim.conventions import V1_SPAWN_SEPARATION, V1_TIME_LIMIT, V1_TIMEOUT_MARGIN
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError

PROFILES: Final[dict[str, EnvConfig]] = {
    "paper": EnvConfig(),  # EnvConfig's defaults are the paper profile with visible robots
    "v1": EnvConfig(
        profile="v1",
        time_limit=V1_TIME_LIMIT,
        timeout_margin=V1_TIMEOUT_MARGIN,
        spawn_separation=V1_SPAWN_SEPARATION,
        crossing="v1",
        success_rule="first_reach",
    ),
}
VISIBILITY: Final[tuple[str, str]] = ("visible", "invisible")


def make_env_config(profile: str = "paper", visibility: str = "visible") -> EnvConfig:
    """The named profile's EnvConfig with the robots visible to the humans' ORCA or not."""
    if profile not in PROFILES:
        raise SimulationError(f"unknown profile {profile!r}; choose from {sorted(PROFILES)}")
    if visibility not in VISIBILITY:
        raise SimulationError(f"unknown visibility {visibility!r}; choose from {list(VISIBILITY)}")
    return dataclasses.replace(PROFILES[profile], robots_visible=visibility == "visible")
