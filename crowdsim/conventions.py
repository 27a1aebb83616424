"""The numbers in which the simulation profiles differ (``crowdsim.profiles`` names the combinations).

"paper" follows the paper authors' public CrowdNav fork (vaishnavtvHRI/CrowdNav: ``crowd_nav/configs/
env_m.config`` and ``crowd_sim/envs/crowd_sim.py``); "v1" is this project's first simulator, kept so that
earlier results stay reproducible bit for bit.
"""

from __future__ import annotations

from typing import Final, Literal

Crossing = Literal["paper", "v1"]  # how the humans' starts and goals are sampled (crowdsim.scenarios)
SuccessRule = Literal["simultaneous", "first_reach"]  # when the robots have succeeded (crowdsim.metrics)
CROSSINGS: Final[tuple[str, ...]] = ("paper", "v1")
SUCCESS_RULES: Final[tuple[str, ...]] = ("simultaneous", "first_reach")

PAPER_TIME_LIMIT: Final[float] = 40.0  # s, env_m.config [env] time_limit
# s, crowd_sim.py step(): `if self.global_time >= self.time_limit - 1` is a timeout, checked before the step
PAPER_TIMEOUT_MARGIN: Final[float] = 1.0
PAPER_DISCOMFORT_DIST: Final[float] = 0.4  # m, env_m.config [reward] discomfort_dist
# m added to the two radii when spawning: crowd_sim.py generate_*_human use `discomfort_dist + 0.1`
PAPER_SPAWN_SEPARATION: Final[float] = PAPER_DISCOMFORT_DIST + 0.1

V1_TIME_LIMIT: Final[float] = 30.0  # s, upstream CrowdNav's env.config time_limit
V1_TIMEOUT_MARGIN: Final[float] = 0.0  # s, v1 ran until round(time_limit / dt) steps
V1_SPAWN_SEPARATION: Final[float] = 0.2  # m, upstream CrowdNav's discomfort_dist (no extra 0.1)

SPAWN_SEPARATION: Final[dict[str, float]] = {"paper": PAPER_SPAWN_SEPARATION, "v1": V1_SPAWN_SEPARATION}
