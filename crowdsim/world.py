"""The world facts every package shares: time step, observed history, agent size and robot bounds.

One source, so that the simulator, the MPC and the predictors cannot drift apart; they import these names
rather than repeating the numbers. The crowd geometry (circle radius, square width) is the same in every
simulation profile (``crowdsim.profiles``) and lives here too.
"""

from __future__ import annotations

from typing import Final

DT: Final[float] = 0.4  # s, tau: simulation step = control period (Table I; TrajNet++ samples at 2.5 Hz)
# L: observed steps every zoo predictor reads. TrajNet++ observes 9 steps; the paper's Table I says 8, but
# our models are trained on 9, so the simulator keeps 9 rows of history and feeds them exactly their length.
OBS_LEN: Final[int] = 9
RADIUS: Final[float] = 0.3  # m, every robot and human (Table I; CrowdNav's env config)
V_PREF: Final[float] = 1.0  # m/s, humans' preferred speed = their ORCA max speed (CrowdNav's env config)
V_MAX: Final[float] = 1.0  # m/s, robot velocity bound per component, Eq. (6)
A_MAX: Final[float] = 2.0  # m/s^2, robot acceleration bound per component, Eq. (6)

CIRCLE_RADIUS: Final[float] = 5.0  # m, circle crossing (the paper's fork, env_m.config; CrowdNav's is 4 m)
SQUARE_WIDTH: Final[float] = 10.0  # m, side of the perpendicular-crossing square (env_m.config)
