"""The comment of every key that a dataclass field backs ([world], [env.orca], [env], [mpc]), as ``crowdmpc
config show`` writes it beside the key: unit, meaning, allowed values. pipelines/config/schema.py builds the
keys from the dataclasses and these notes (a field without a note fails at import there).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Final

WORLD_NOTES: Final[Mapping[str, str]] = {
    "dt": "tau, s: simulation step = control period = the predictors' sampling time (Table I: 0.4 s)",
    "obs_len": "L, observed steps the simulator keeps for the predictors: at least each predictor's own "
    "(Table I: 8; the zoo's models read 9)",
    "radius": "m, every robot and human (CrowdNav)",
    "v_pref": "m/s, the humans' preferred speed = their ORCA max speed (CrowdNav)",
    "v_max": "v_max, m/s, robot velocity bound per component, Eq. 6 (Table I: 1.0 m/s)",
    "a_max": "a_max, m/s^2, robot acceleration bound per component, Eq. 6 (Table I: 2.0 m/s^2)",
}

ORCA_NOTES: Final[Mapping[str, str]] = {
    "neighbor_dist": "m, 1e-06 to 1e+06 or inf: only agents strictly closer than this are neighbours "
    "(CrowdNav's ORCA)",
    "max_neighbors": "the nearest this many neighbours get a half-plane",
    "time_horizon": "s, velocity obstacles are truncated at this horizon",
}

ENV_NOTES: Final[Mapping[str, str]] = {
    "time_limit": "s, the episode's time limit",
    "timeout_margin": "s, no step starts at or after time_limit - timeout_margin",
    "spawn_separation": "m added to the two radii between sampled humans",
    "crossing": "how the humans' starts and goals are sampled: paper | v1",
    "success_rule": "simultaneous (every robot at its goal at once) | first_reach (each reached it once)",
    "orca_radius_margin": "m added to the radius given to ORCA (CrowdNav's 'for safety')",
}

MPC_NOTES: Final[Mapping[str, str]] = {
    "horizon": "H, control and prediction horizon, steps (Table I: 4)",
    "w_goal": "omega^goal, reference tracking weight, Eqs. 7 and 13 (Table I: 10.0)",
    "w_acce": "omega^acce, acceleration weight, Eqs. 9 and 13 (Table I: 1e-1)",
    "w_jerk": "omega^jerk, jerk weight, Eqs. 10 and 13 (Table I: 1e-1)",
    "w_coll": "omega^coll, robot-human (Eq. 11) and robot-robot (Eq. 12) penalty weight (Table I: 1e7)",
    "w_floc": "omega^floc, flocking weight, Eqs. 14 and 15 (Table I: 10; 0 disables flocking)",
    "rho": "rho, s^2, speed-dependent growth of the robot-human safety distance, Eq. 11 (Table I: 0.5)",
    "d_min": (
        "d_min, m, minimum allowed centre distance, Eqs. 11 and 12, at least 2 x [world] radius "
        "(Table I: 0.8 m; the collision rate counts 0.8 m whatever it is)"
    ),
    "mu": "mu, 1/m^2, sharpness of smax(z) = log(exp(mu z) + 1) / mu, penalty of Eqs. 11-12 (Table I: 30)",
    "j_max": "j_max, maximum IBR iterations, Algorithms 1 and 2 (Table I: 10)",
    "xi": "xi, CMPC convergence threshold on |F^(j) - F^(j-1)|, Algorithm 1 (Table I: 1e-3)",
    "epsilon": "epsilon, DMPC improvement and epsilon-Nash threshold, Algorithm 2 (Table I: 1e-3)",
    "d_flock": "d_ij, m, desired robot-robot distance in the flock, Eq. 15 (not in the paper: mpc/config.py)",
    "delta": "delta, goal-normalisation offset (Eq. 7) and norm smoothing (Eq. 15) (not in the paper)",
    "on_goal": "a robot on its goal: track (stays in the optimisation, holds its place) | brake | yield "
    "(track, holding its goal no harder than the farthest teammate on its way pulls to its own)",
    "cost_scale": "the solver minimises cost_scale * F",
    "solver": "fatrop | ipopt: the interior-point solver of the NLPs with fixed predictions",
    "solver_tol": "the solver's tolerance (Fatrop: KKT error; IPOPT: scaled NLP error)",
    "solver_max_iter": "iterations per solve; hitting it counts as a failure (fallback)",
    "time_limit_s": "s, wall-time budget of one control step (a safety net, far above the normal step time)",
    "warm_start": "IPOPT (the solver, or Fatrop's fallback) also starts from the shifted previous solution's "
    "multipliers (every solve starts from the shifted plan, the IBR loops' u^(0), either way)",
    "multi_start": "solve again from braking when the first solution pays more than restart_penalty",
    "restart_penalty": "collision penalty above which multi_start solves again",
    "jit": "compile the NLPs with gcc (simulate; a sweep compiles by [sweep] jit)",
    "dmpc_parallel": "serial | threads: how DMPC runs its local solves",
    "dmpc_update": "jacobi (Algorithm 2) | gauss_seidel | relaxed | sequential_accept: DMPC's update",
    "dmpc_relaxation": "in (0, 1]: the step towards the best response of dmpc_update relaxed",
    "dmpc_stop": "regret (Algorithm 2, lines 12-16) | no_improvement: when DMPC's iterations end",
    "dmpc_order": "index | nearest_first (to its target): the order of gauss_seidel's best responses",
    "dmpc_pairs": "a stalled robot re-plans with the teammate in its way (needs stall_release_s)",
    "dmpc_conflicts": "robots whose plans come within d_min of each other re-plan together",
    "dmpc_start": "DMPC's u^(0): shifted (previous plan, else braking) | heading (not braking if F lower)",
    "guidance": "none (the paper: Eq. 8 heads for the goal) | standing: around rows of humans standing still",
    "flocking_weight": "per_pair (the paper: w_floc on every pair) | per_robot: w_floc * 2 / (M - 1)",
    "flock_distance": "uniform (the paper's runs: d_flock for every pair) | goals: max(d_flock, the pair's "
    "goals' distance)",
    "flock_range": "m; > 0: a pair flocks only if its goals lie within it (robots bound apart); 0: every "
    "pair (the paper)",
    "guidance_clearance": "margin (d_min + margin) | penalty (where Eq. 11's penalty falls to w_goal)",
    "stall_release_s": "s without 0.25 m of progress before a robot stops flocking (mpc/stall.py); 0: never",
    "coupled_mode": "coupling nlp: auto | exact (the predictor inside the NLP) | first_order",
}
