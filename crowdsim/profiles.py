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

Where the robots start and end is not public; both profiles keep ``crowdsim.formations.robot_layout``'s
formation (the row up to 3 robots), which isolates the published conventions. Visibility is chosen
separately (``make_env_config``); CrowdNav's own default is invisible robots, the fork's configuration
visible ones.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, Final

from crowdsim.conventions import V1_SPAWN_SEPARATION, V1_TIME_LIMIT, V1_TIMEOUT_MARGIN
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.orca import OrcaParams

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
    if not isinstance(profile, str) or profile not in PROFILES:  # a list from plain data is unhashable
        raise SimulationError(f"unknown profile {profile!r}; choose from {sorted(PROFILES)}")
    if visibility not in VISIBILITY:
        raise SimulationError(f"unknown visibility {visibility!r}; choose from {list(VISIBILITY)}")
    return dataclasses.replace(PROFILES[profile], robots_visible=visibility == "visible")


def as_env_config(values: EnvConfig | Mapping[str, Any] | None) -> EnvConfig:
    """``values`` as an EnvConfig: itself, the default (None), or one from plain data, as a YAML or JSON file
    gives ``gym.make``'s keywords (RL Zoo's ``env_kwargs``): ``profile`` and ``visibility`` choose the
    conventions as ``make_env_config`` does (an EnvConfig's own ``profile`` is only its label), ``orca`` is a
    mapping of ``OrcaParams``' fields, and every other key an EnvConfig field replacing the profile's."""
    if values is None or isinstance(values, EnvConfig):
        return EnvConfig() if values is None else values
    if not isinstance(values, Mapping) or not all(isinstance(key, str) for key in values):
        raise SimulationError(f"config must be an EnvConfig or a mapping of its fields, got {values!r:.80}")
    rest = dict(values)
    if "visibility" in rest and "robots_visible" in rest:
        raise SimulationError("config gives both visibility and robots_visible: give one")
    base = make_env_config(rest.pop("profile", "paper"), rest.pop("visibility", "visible"))
    known = [f.name for f in dataclasses.fields(EnvConfig) if f.name != "profile"]
    unknown = sorted(set(rest) - set(known))
    if unknown:
        raise SimulationError(
            f"config has no field {unknown[0]!r}; expected profile, visibility or one of {', '.join(known)}"
        )
    names = [f.name for f in dataclasses.fields(OrcaParams)]
    if "orca" in rest and not isinstance(rest["orca"], Mapping | OrcaParams):  # EnvConfig's refusal named
        raise SimulationError(  # OrcaParams only, which plain data cannot give
            f"config orca must be a mapping of OrcaParams' fields ({', '.join(names)}), "
            f"got {rest['orca']!r:.80}"
        )
    if isinstance(rest.get("orca"), Mapping):
        orca = dict(rest["orca"])
        if set(orca) - set(names):
            raise SimulationError(
                f"config orca has no field {sorted(set(orca) - set(names))[0]!r}; expected {', '.join(names)}"
            )
        rest["orca"] = OrcaParams(**orca)
    return dataclasses.replace(base, **rest)
