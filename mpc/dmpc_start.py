"""DMPC's initial strategy u^(0) (``MPCConfig.dmpc_start``): the shifted previous plan, else braking, or with
"heading" every robot heading for its target where that lowers F.

Apart from mpc/dmpc.py (Algorithm 2's loop, its update and stop rules), as mpc/dmpc_keep.py and
mpc/dmpc_pairs.py are: the start is chosen once a step, before the loop, and has measurements of its own.

Algorithm 2 starts from "an initial guess" u^(0): here the shifted previous plan,
else braking. From rest a flock of many robots barely leaves braking: a robot stepping forward alone
stretches its M - 1 flocking terms, so each best response moves it a little. With 12 robots (7 humans, the
many_robots.toml settings) the flock covered 0.2-1 m in its first 4 s where CMPC covered 2.3 m. ``"heading"``
starts a step that would start from braking (an episode's first, or one after failures) from every robot
heading straight for its target instead (``mpc.fallback.heading_plan``), when that plan has the lower F. After
the first step the two are nearly level in F (2974 from braking, 3012 from heading at 12 robots: the flocking
terms of the wedge dominate), but the flock leaves moving and its shifted plans keep it moving.
benchmarks/robot_scaling.py (docs/results.md, "More robots, more humans"), shifted -> heading, same crowds: 12
robots 18 -> 44 % (fixed goals), 52 -> 82 % (slots), but 2-3 of the 50 episodes within 0.8 m of a human (none
before); 3, 5, 6 robots within 6 points either way; 50 episodes a row. At 3 robots the heading start picks
the slower formation (middle robot ahead, F 26.4 against 23.3 from braking: mpc/solvers.py ``_Solver``),
travel 1.4-2.1 s longer. Comparing the two starts by F at the end of the first step instead keeps braking
every time (20 of 20 episodes at 12 robots), so it is not offered. All of this with the paper's per-pair
flocking weight; with ``flocking_weight="per_robot"`` (many_robots.toml now) the flock's pull is that of a
team of 3, and the heading start still helps at 12 robots: 80 -> 92 % (fixed), 90 -> 94 % (slots).
"""

from __future__ import annotations

import numpy as np

from mpc.cmpc import PredictFn, finite_prediction
from mpc.config import MPCConfig
from mpc.dynamics import rollout_numpy
from mpc.fallback import Start, heading_plan
from mpc.nlp import JointNLP, StepData


def initial_strategy(
    cfg: MPCConfig, joint: JointNLP, data: StepData, predict: PredictFn, start: Start, moving: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None]:
    """u^(0) (``cfg.dmpc_start``) and the humans predicted for it when already known; ``joint`` is the DMPC's
    joint NLP (its F and its number of humans), ``moving`` the indices of the robots that play.

    With "heading", a step that starts from braking gives the moving robots ``heading_plan`` instead if
    that lowers F under the humans predicted for braking. The potential-lowering updates only ever lower
    F from u^(0), and from a flock at rest a robot's best response moves it little (a step alone
    stretches M - 1 flocking terms): without a start that already moves, the flock creeps off over many
    steps (module docstring). ``start`` itself, the fallback of a step that cannot solve, is unchanged.
    """
    accels = start.accels.copy()
    if cfg.dmpc_start == "shifted" or start.kind != "brake" or len(moving) == 0:
        return accels, None
    positions = rollout_numpy(data.states, accels, cfg.dt)[0]
    prediction = finite_prediction(predict(positions.transpose(1, 0, 2)), (cfg.horizon, joint.n_humans, 2))
    if prediction is None:
        return accels, None  # the loop's own prediction reports it
    heading = accels.copy()
    heading[moving] = heading_plan(data, cfg)[moving]
    if joint.potential(heading, data, prediction) < joint.potential(accels, data, prediction):
        return heading, None
    return accels, prediction
