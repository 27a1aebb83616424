"""The MPC's parameters: Table I of the paper, the two values it omits, and the solver's knobs.

Every formulation (joint NLP, local NLPs, coupled NLP) reads the same frozen ``MPCConfig``. Symbols are the
paper's (Le et al., "Multi-robot cooperative navigation in crowds: a game-theoretic learning-based model
predictive control approach"); equation numbers are the design notes', which README.md maps to the paper's.

The facts the MPC shares with the simulator and the predictors (``tau``, ``v_max``, ``a_max``) default to
``crowdsim.world``, their one source; so do ``d_min`` and ``d_flock``, which the robots' start and goal
formations (``crowdsim.scenarios``) are spaced with. Table I's ``L`` (observed steps) is not here: it belongs
to the predictor (``Predictor.obs_len``, 9 for every zoo model), and the simulator keeps
``crowdsim.world.OBS_LEN`` rows of history for it; the closed loop checks that they agree
(``pipelines.loop.mpc_setup.check_world``).

The two values the paper uses without giving them:

* ``d_flock`` (``d_ij`` in Eq. 15) = 1.2 m. The robot-robot penalty of Eq. 12 goes through
  ``omega_coll * smax(d_min^2 - d^2)`` with ``omega_coll = 1e7`` and ``mu = 30``: at 1.0 m it still costs
  about 7 per step, at 1.1 m 0.01, at 1.2 m 1e-5. 1.2 m is the tightest spacing at which the flocking term
  (weight 10) does not fight the collision penalty, so the flock stays as compact as the safety distance
  allows (1.2 m between centres leaves 0.6 m between the 0.3 m bodies).
* ``delta`` (``delta`` in Eqs. 7 and 15) = 1e-3. In Eq. 7 (metres) it keeps the goal normalisation finite at
  the goal, where the weight becomes ``omega_goal / delta``; in the smoothed norm
  ``||z|| ~ sqrt(z^T z + delta)`` (square metres) it biases a 1.2 m flocking distance by 0.4 mm and bounds
  the curvature of the norm at ``z = 0`` by ``1 / sqrt(delta) ~ 32``, which IPOPT handles without trouble.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Final, Literal, get_args

import numpy as np

from crowdsim import world
from crowdsim.world import PAPER_ROBOTS as PAPER_ROBOTS  # Table I's weights were set for it; named here too
from crowdsim.world import WorldFacts
from mpc.errors import MPCConfigError
from mpc.sizes import LEAST_STEP_TIME, check_counts, check_step_time
from mpc.sizes import MAX_HORIZON as MAX_HORIZON  # its importers' name for it since before mpc.sizes

# Option types as Literals (values stay plain strings in JSON and MCAP metadata); the tuples are their values.
Solver = Literal["fatrop", "ipopt"]
ParallelMode = Literal["serial", "threads"]  # how DMPC runs the robots' local solves (see mpc/dmpc.py)
# how a DMPC iteration turns the robots' best responses into the new plans (see mpc/dmpc.py)
DMPCUpdate = Literal["jacobi", "gauss_seidel", "relaxed", "sequential_accept"]
DMPCStop = Literal["regret", "no_improvement"]  # when DMPC's iterations end (MPCConfig.dmpc_stop)
DMPCOrder = Literal["index", "nearest_first"]  # Gauss-Seidel's order of the robots (MPCConfig.dmpc_order)
DMPCStart = Literal["shifted", "heading"]  # DMPC's initial strategy u^(0) (MPCConfig.dmpc_start)
# coupling="nlp": the predictor itself inside the NLP, its linearisation, or whichever suits (mpc/coupled.py)
CoupledMode = Literal["auto", "exact", "first_order"]
OnGoal = Literal["brake", "track", "yield"]  # what a robot that has reached its goal does (MPCConfig.on_goal)
FlockingWeight = Literal["per_pair", "per_robot"]  # how w_floc weighs each pair (MPCConfig.flocking_weight)
FlockDistance = Literal["uniform", "goals"]  # each pair's d_ij in Eq. 15 (MPCConfig.flock_distance)
SOLVERS: Final[tuple[Solver, ...]] = get_args(Solver)
PARALLEL_MODES: Final[tuple[ParallelMode, ...]] = get_args(ParallelMode)
DMPC_UPDATES: Final[tuple[DMPCUpdate, ...]] = get_args(DMPCUpdate)
DMPC_STOPS: Final[tuple[DMPCStop, ...]] = get_args(DMPCStop)
DMPC_STARTS: Final[tuple[DMPCStart, ...]] = get_args(DMPCStart)
DMPC_ORDERS: Final[tuple[DMPCOrder, ...]] = get_args(DMPCOrder)
FLOCKING_WEIGHTS: Final[tuple[FlockingWeight, ...]] = get_args(FlockingWeight)
FLOCK_DISTANCES: Final[tuple[FlockDistance, ...]] = get_args(FlockDistance)
Guidance = Literal["none", "standing"]
GUIDANCE_MODES: Final[tuple[Guidance, ...]] = get_args(Guidance)
# the radius of guidance's discs around standing humans (MPCConfig.guidance_clearance)
GuidanceClearance = Literal["margin", "penalty"]
GUIDANCE_CLEARANCES: Final[tuple[GuidanceClearance, ...]] = get_args(GuidanceClearance)
COUPLED_MODES: Final[tuple[CoupledMode, ...]] = get_args(CoupledMode)
ON_GOAL_MODES: Final[tuple[OnGoal, ...]] = get_args(OnGoal)
_CHOICES: Final[dict[str, tuple[str, ...]]] = {  # each option of MPCConfig that names one of a few choices
    "solver": SOLVERS,
    "dmpc_parallel": PARALLEL_MODES,
    "dmpc_update": DMPC_UPDATES,
    "dmpc_stop": DMPC_STOPS,
    "dmpc_order": DMPC_ORDERS,
    "dmpc_start": DMPC_STARTS,
    "flocking_weight": FLOCKING_WEIGHTS,
    "flock_distance": FLOCK_DISTANCES,
    "on_goal": ON_GOAL_MODES,
    "guidance": GUIDANCE_MODES,
    "guidance_clearance": GUIDANCE_CLEARANCES,
    "coupled_mode": COUPLED_MODES,
}

# Upper bounds of the numbers that enter the NLP: far above any sensible value, low enough that its cost,
# gradient and exact Hessian stay finite with all of them at their bounds together (rho = 1e300 made the
# Hessian Inf, and a Fatrop solve, which has no wall-time limit, ran on for minutes). Measured there (3
# robots, 2 humans, accelerations up to 10 a_max, positions up to 100 m): |F| up to 2e45, the Hessian 5e36;
# a short closed loop of CMPC and DMPC took at most 0.1 s a solve. The thresholds that never enter the NLP
# (xi, epsilon, restart_penalty, stall_release_s) are only compared with: any finite value does. They guard
# the solver, so an NLP checks them as it is built (mpc.nlp.check_solvable), and a run as it starts: not
# every MPCConfig, so that a sweep folder that ran beyond a bound added since (rho = 2000) reads back.
MAX_WEIGHT: Final[float] = 1e12  # Table I's largest weight is w_coll = 1e7
MPC_BOUNDS: Final[dict[str, tuple[float, str]]] = {
    **{name: (MAX_WEIGHT, "") for name in ("w_goal", "w_acce", "w_jerk", "w_coll", "w_floc")},
    "rho": (1e3, " s^2"),  # Table I: 0.5
    "mu": (1e4, " 1/m^2"),  # Table I: 30; at 1e4 smax is max(z, 0) to within 7e-5 m^2
    "d_min": (1e3, " m"),  # Table I: 0.8; the scenarios are 10 m across
    "d_flock": (1e3, " m"),  # 1.2
    "flock_range": (1e3, " m"),  # 0: every pair flocks
    "delta": (1e3, ""),  # 1e-3 (m in Eq. 7, m^2 in Eq. 15)
    "cost_scale": (1e3, ""),  # 1; docs/examples/many_robots.toml scales F down, by 0.01
    # 1e-6; it never enters the NLP, but a loose one passes any iterate: at 100 and 1e300 every step was
    # "ok" and no robots reached their goals (CMPC, 4 episodes of 4 humans; at 1 and 10 all four did)
    "solver_tol": (1.0, ""),
    # the world's facts, as the simulator bounds them (dt: by its time limit)
    "dt": (world.MOST_TIME, " s"),
    "v_max": (world.MOST_SPEED, " m/s"),
    "a_max": (world.MOST_ACCEL, " m/s^2"),
}
# Lower bounds beyond "> 0": smax(z) = log(exp(mu z) + 1) / mu is log(2) / mu at z = 0, so a sharpness near
# zero makes every pair's penalty w_coll log(2) / mu wherever the agents are (mu = 1e-300 overflowed the cost
# to inf and every solve failed); at 1e-3 it is 693 w_coll per pair, finite at every weight's bound. Eq. 7
# weighs a robot on its goal by w_goal / delta: delta = 1e-300 overflowed it (a NaN gradient; Fatrop hung).
# At 1e-40 the NLP stays far from overflow (mpc/step_data.py); so does guidance's penalty disc, which divides
# by mu w_goal (w_goal = 5e-324 with mu = 1e-3 made it zero). Checked as MPC_BOUNDS are (see there).
# time_limit_s never enters the NLP; it is IPOPT's max_wall_time (mpc.sizes.LEAST_STEP_TIME has its least).
# tau, v_max and a_max are the world's facts: a run takes them from the world, which refuses less
# (crowdsim.world.LEAST), and an MPCConfig built in Python is held to the same least values: "> 0" let
# through an MPC that never moved and called every step "ok" (tau = 1e-300 planned a horizon of 4e-300 s,
# and 5e-324 overflowed the plan's clipping, (v_max - v) / tau, to inf; v_max = 5e-324 gave a reference
# speed of 0; a_max = 1e-300 left two converging robots unable to part, Eq. 12 costing 6.9e6 each step).
# d_flock is no fact of the world's, but a length like them: Eq. 15's smoothed norm is never below
# sqrt(delta), so no least value changes what it does, and a millionth of a metre, the world's least
# length, keeps subnormals (5e-324 ran as 1e-300 did) out of the runs and their records.
MPC_LEAST: Final = {
    "mu": (1e-3, " 1/m^2"),
    "delta": (1e-40, ""),
    "w_goal": (1e-40, ""),
    "time_limit_s": (LEAST_STEP_TIME, " s"),
    **{name: (world.LEAST[name][0], f" {world.LEAST[name][1]}") for name in ("dt", "v_max", "a_max")},
    "d_flock": (world.LEAST["radius"][0], " m"),
}


@dataclass(frozen=True)
class MPCConfig:
    # --- Table I ---------------------------------------------------------------------------------------
    horizon: int = world.HORIZON  # H, control and prediction horizon (steps)
    dt: float = world.DT  # tau, s, sampling time of the double integrator, Eq. 2
    w_goal: float = 10.0  # omega^goal, reference tracking weight, Eqs. 7 and 13
    w_acce: float = 0.1  # omega^acce, acceleration weight, Eqs. 9 and 13
    w_jerk: float = 0.1  # omega^jerk, jerk weight, Eqs. 10 and 13
    w_coll: float = 1e7  # omega^coll, robot-human (Eq. 11, 13) and robot-robot (Eq. 12, 14) penalty weight
    w_floc: float = 10.0  # omega^floc, flocking weight, Eqs. 14 and 15 (0 disables flocking, Table III "NF")
    # v_max, m/s, bound on each velocity component, Eq. 6; reference speed in Eq. 8
    v_max: float = world.V_MAX
    a_max: float = world.A_MAX  # a_max, m/s^2, bound on each acceleration component, Eq. 6
    # rho, s^2 (Table I prints s; rho |v|^2 is added to d_min^2, an area), speed-dependent growth of the
    # robot-human safety distance, Eq. 11
    rho: float = 0.5
    d_min: float = world.D_MIN  # d_min, m, minimum allowed distance, Eqs. 11 and 12
    mu: float = 30.0  # mu, 1/m^2, sharpness of smax(z) = log(exp(mu z) + 1) / mu, the penalty of Eqs. 11-12
    j_max: int = 10  # j_max, maximum IBR iterations, Algorithms 1 and 2
    xi: float = 1e-3  # xi, CMPC convergence threshold on |F^(j) - F^(j-1)|, Algorithm 1
    epsilon: float = 1e-3  # epsilon, DMPC improvement and epsilon-Nash threshold, Algorithm 2
    # --- omitted by the paper (see the module docstring) ------------------------------------------------
    d_flock: float = world.D_FLOCK  # d_ij, m, desired distance between two robots of the flock, Eq. 15
    delta: float = 1e-3  # delta, goal-normalisation offset (Eq. 7) and norm smoothing (Eq. 15)
    # --- more robots than the paper's 3 --------------------------------------------------------------------
    # Eq. 15 gives every pair the weight w_floc, so a robot's flocking terms grow with its M - 1 teammates
    # while its goal term (Eq. 7) stays one: at 12 robots the flock pulls 5.5x harder against the goal than
    # in the paper's team of 3, for which Table I was tuned. "per_pair": w_floc on every pair (the paper);
    # "per_robot": w_floc * 2 / (M - 1) on every pair, so each robot's flocking weighs what it weighs in a
    # team of 3 whatever M (the same weights at M = 3; a symmetric weight, so Lemma 1's potential game holds).
    flocking_weight: FlockingWeight = "per_pair"
    # Eq. 15 writes d_ij per pair; the paper gives one value. "uniform": d_flock for every pair (as Table I is
    # run). "goals": max(d_flock, ||g_i - g_j||), so a flock arrives in the shape of its goals: under one
    # d_flock the outer pair of a row of 3 spaced 1.5 m (3 m apart at their goals) is pulled towards 1.2 m,
    # and with nobody about the outer robots parked 0.39 m short of their goals every episode. Among 7 humans
    # the wider flock collided more (docs/extending.md), so "uniform" stays the default.
    flock_distance: FlockDistance = "uniform"
    # Which pairs flock. Eq. 15 holds every pair near d_ij, which suits a team bound for one place (the
    # paper's row of 3 with goals 1 m apart) and holds robots bound for separate places together: two robots
    # swapping places passed each other and then stood 1.42 m apart until the time limit (docs/extending.md).
    # > 0: a pair flocks only while its goals lie within flock_range m of each other (w_floc_ij = 0 beyond,
    # symmetric, so Lemma 1 holds); 0: every pair (the paper). flocking_weight "per_robot" still divides by
    # M - 1 teammates, so a robot with fewer flocking partners feels less of Eq. 15's pull.
    flock_range: float = 0.0
    # --- robots on their goals (the paper does not say what one that has arrived does meanwhile) ---------
    # "track": a robot that has reached its goal stays in the optimisation with its goal term (the reference
    # is then the goal itself, weighted omega_goal / (||s - goal|| + delta) = 1e4 on the goal), so it holds
    # its place unless a human or another robot needs the room; flocking with it is off. "brake": its
    # controls are pinned to braking: it stays exactly where it stopped and can neither dodge a human nor let
    # a teammate through to a goal closer than ~1.03 m, the distance the Eq. 12 penalty keeps free. "yield":
    # "track", but it holds its goal no harder than the farthest teammate still on its way pulls towards its
    # own: Eq. 7's weight w_goal / (max(||s - goal||, D) + delta), D that teammate's distance to its goal
    # (pipelines/loop/mpc.py, goal_slack). Robots parked 1.2 m apart otherwise wall off a goal between them
    # (passing needs 2 x 1.03 m) and hold it with weight 1e4 against the teammate's 10 / D.
    on_goal: OnGoal = "track"
    # --- solver -------------------------------------------------------------------------------------------
    # The solver minimises cost_scale * F. IPOPT's own gradient-based scaling already tames the 1e7 penalty
    # (measured with IPOPT: no speed-up from scaling F by 1e-2 or 1e-4; only looser solutions, since tol
    # applies to the scaled problem). Fatrop does not scale, and with margins and several robots the active
    # penalties leave it short of solver_max_iter, retried with IPOPT: `benchmarks/cost_scale.py --config
    # docs/examples/safe_crossing.toml --robots 3 12 --episodes 4` gives 9.7 % of Fatrop solves failing at 3
    # robots and 21.0 % at 12 with F, 1.1 % and 1.3 % with F / 100 (p95 step at 12 robots 288 -> 114 ms, load
    # 0.9-1.0; docs/results.md, "Fatrop and cost_scale", measured since that file sets guidance_clearance =
    # "penalty"). The paper's method (no --config) fails on 2 of 306 solves at 3 robots and 9 of 780 at 12
    # with F, none with F / 100: so few that the default leaves F as it is and reproduces it exactly;
    # docs/examples/many_robots.toml sets 0.01.
    cost_scale: float = 1.0
    # "fatrop" or "ipopt": the interior-point solver of every NLP built from fixed predictions (joint and
    # local). Fatrop with a dense single stage solves these small NLPs (8 or 24 accelerations) 2-4x faster
    # than IPOPT, whose MUMPS factorisation costs ~0.3 ms an iteration here, and finds the same solutions:
    # `benchmarks/solvers.py` on 2250 recorded DMPC local problems (3 robots, 7 humans) gives 0.76 vs 2.9 ms
    # a solve, the cost within 1e-3 of IPOPT's on 2248; on 277 joint ones 3.3 vs 7.7 ms, 270 the same. A
    # Fatrop solve that fails is retried with IPOPT, and a step that starts from braking asks both
    # (mpc/solvers.py, _Solver, has why). The coupled NLP with a network inside always uses IPOPT (it needs
    # IPOPT's L-BFGS Hessian, mpc/coupled.py).
    solver: Solver = "fatrop"
    solver_tol: float = 1e-6  # the solver's tol (Fatrop: KKT error; IPOPT: scaled NLP error)
    solver_max_iter: int = 100  # iterations per solve; hitting it counts as a failure (fallback)
    # Wall-time budget of one control step: no new IBR iteration starts once the step has used it, and
    # IPOPT's max_wall_time for each solve (exceeding it is a failure; a Fatrop solve is bounded by
    # solver_max_iter, a few ms). A safety net, far above the normal step time, so that results do not depend
    # on the machine's load.
    time_limit_s: float = 1.0
    # IPOPT (the solver, or Fatrop's fallback) starts from the multipliers of the shifted previous solution
    # too, with a small barrier parameter. The primal start is the shifted previous plan either way: it is the
    # IBR loops' u^(0) (Algorithms 1-2); Fatrop takes no multipliers, so only its fallback solves change.
    warm_start: bool = True
    # The collision penalties make F non-convex, and the shifted previous plan can sit in a basin that has
    # become poor (a gap closing). multi_start: when the first solution of a step still pays more than
    # restart_penalty of collision penalty, solve again from braking and keep the lower cost (CMPC: F;
    # DMPC: each robot's C_i). Measured on recorded steps: braking found a much lower F in ~1.5 % of steps.
    multi_start: bool = True
    restart_penalty: float = 1.0
    # Compile the NLP's functions with the system C compiler (gcc): with Fatrop a local solve 0.76 -> 0.48 ms
    # and a joint one 3.3 -> 1.4 ms, for 4.1 and 9.1 s of build (benchmarks/solvers.py, load 2.5). Worth it
    # for sweeps (`crowdmpc sweep --jit auto`, the default), not for one episode.
    jit: bool = False
    # "serial" or "threads": how DMPC runs its M local solves per iteration
    dmpc_parallel: ParallelMode = "serial"
    # DMPC's update (mpc/dmpc.py has the measurements). "jacobi": Algorithm 2 as printed, every robot
    # best-responds to the others' plans of iteration j-1 and keeps its own improvement; "gauss_seidel":
    # the robots solve one after the other, each against the latest plans; "relaxed": Jacobi, each robot
    # moving only dmpc_relaxation of the way to its best response; "sequential_accept": Jacobi's solves
    # (parallel), then the improvements are accepted one robot at a time, largest first, each re-checked
    # against the plans accepted before it (every accepted plan lowers the potential F by >= epsilon).
    dmpc_update: DMPCUpdate = "jacobi"
    dmpc_relaxation: float = 0.5  # in (0, 1], the step towards the best response of dmpc_update="relaxed"
    # When DMPC's iterations end (before j_max). "regret": Algorithm 2's lines 12-16, no robot's new plan is
    # worse by epsilon than its old one against the others' new plans; "no_improvement": an iteration in
    # which no robot keeps a new plan, i.e. no best response to the current plans improves by epsilon (the
    # epsilon-Nash definition itself, at u^(j-1)).
    dmpc_stop: DMPCStop = "regret"
    # DMPC's initial strategy u^(0) (Algorithm 2 leaves it open). "shifted": the previous plan shifted, else
    # braking; "heading": a step that would start from braking (an episode's first, or one after failures)
    # starts instead from every robot heading straight for its Eq. 8 target (mpc.fallback.heading_plan) when
    # that has the lower potential F (mpc/dmpc_start.py has the measurements).
    dmpc_start: DMPCStart = "shifted"
    # The order of dmpc_update="gauss_seidel"'s best responses in each round: "index" (robot 0 first) or
    # "nearest_first" (by distance to the Eq. 8 target at the step, nearest first; mpc/dmpc.py).
    dmpc_order: DMPCOrder = "index"
    # DMPC: after the step's IBR loop, each stalled robot (stall_release_s) and the teammate in its way solve
    # the joint NLP over their two plans, the others' fixed, kept when F drops by epsilon (mpc/dmpc_pairs.py:
    # a late robot in front of a parked teammate is an equilibrium no single best response leaves).
    dmpc_pairs: bool = False
    # DMPC: after the loop (and the pair moves), robots whose plans come within d_min of each other (joined
    # where they share a robot) solve the same joint NLP over their plans, kept when F drops by epsilon: the
    # loop can stop on plans that run robots into each other (mpc/dmpc_pairs.py).
    dmpc_conflicts: bool = False
    # coupling="nlp": "exact" (the predictor inside the NLP), "first_order" (its value and Jacobian at the
    # current plan, re-linearised until F settles) or "auto": exact for a predictor small enough to expand
    # into the NLP's scalar graph, first-order for a network (mpc/coupled.py has the measurements).
    coupled_mode: CoupledMode = "auto"
    # --- safety under prediction error (beyond the paper) --------------------------------------------------
    # m_k, m, added to d_min in the robot-human constraint of Eq. 11 at horizon step k = 1..H:
    # smax((d_min + m_k)^2 + rho ||v||^2 - ||s - s_j||^2). () (the default) is exactly the paper's Eq. 11.
    # The closed loop fills it from the predictor's conformal calibration (pipelines/loop/margins.py): if the
    # realised human position lies within m_k of the prediction, keeping d_min + m_k from the prediction
    # keeps d_min from the human. Robot-robot (Eq. 12) is unchanged: robots know each other's plans.
    human_margins: tuple[float, ...] = ()
    # Where Eq. 8's reference heads. "none": the goal (the paper). "standing": around humans standing still,
    # discs (guidance_clearance, below), when they block the straight line to the goal (mpc/guidance.py:
    # the local minimum behind a row of standing humans; the closed loop says who stands).
    guidance: Guidance = "none"
    # The radius of guidance's discs. "margin": d_min plus the human's margin, the distance Eq. 11 asks for.
    # "penalty": the distance Eq. 11's soft penalty keeps in practice, where one step's penalty
    # w_coll * smax(z) has fallen to w_goal (z = (d_min + m)^2 - d^2, smax ~ exp(mu z) / mu there):
    # sqrt((d_min + m)^2 + ln(w_coll / (mu w_goal)) / mu), 1.02 m for m = 0.03 with Table I's weights. A
    # robot between two standing humans 1.7 m apart holds about 1.05 m from each (the penalty's tail), while
    # "margin"'s 0.83 m discs leave the gap open, so guidance keeps heading it into the gap
    # (docs/results.md, "More robots, more humans": the 12-robot runs' stuck robots).
    guidance_clearance: GuidanceClearance = "margin"
    # Seconds without 0.25 m of progress towards its goal after which a robot stops flocking until it moves
    # again (mpc/stall.py: a boxed-in robot otherwise holds the whole flock). 0: never (the paper).
    stall_release_s: float = 0.0

    def __post_init__(self):
        self._plain_scalars()
        self._check_numbers()
        for name in ("warm_start", "multi_start", "jit", "dmpc_pairs", "dmpc_conflicts"):
            if not isinstance(getattr(self, name), bool):
                raise MPCConfigError(f"{name} must be True or False, got {getattr(self, name)!r}")
        for name, choices in _CHOICES.items():
            if getattr(self, name) not in choices:
                raise MPCConfigError(f"{name} must be one of {choices}, got {getattr(self, name)!r}")
        if self.dmpc_order != "index" and self.dmpc_update != "gauss_seidel":
            raise MPCConfigError(
                f"dmpc_order {self.dmpc_order!r} orders gauss_seidel's rounds; dmpc_update is "
                f"{self.dmpc_update!r}"
            )
        if self.dmpc_pairs and not self.stall_release_s:
            raise MPCConfigError(
                "dmpc_pairs moves stalled robots, and stall_release_s = 0 marks none stalled: set "
                "stall_release_s > 0"
            )
        if not 0 < self.dmpc_relaxation <= 1:
            raise MPCConfigError(f"dmpc_relaxation must be in (0, 1], got {self.dmpc_relaxation!r}")
        self._check_margins()

    def _check_numbers(self) -> None:
        """The counts, weights, lengths and tolerances: finite, of the right sign, the sizes of the work
        within mpc.sizes (``MPC_BOUNDS`` and ``MPC_LEAST`` guard the solver: mpc.nlp.check_solvable)."""
        check_counts(self)
        positive: tuple[str, ...] = ("dt", "w_goal", "w_coll", "v_max", "a_max", "d_min", "mu", "xi")
        positive += ("epsilon", "delta")
        positive += ("d_flock", "cost_scale", "solver_tol", "time_limit_s", "dmpc_relaxation")
        non_negative: tuple[str, ...] = ("w_acce", "w_jerk", "w_floc", "rho", "restart_penalty")
        non_negative += ("stall_release_s", "flock_range")
        for name in positive + non_negative:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise MPCConfigError(f"{name} must be a finite number, got {value!r}")
            if name in positive and value <= 0:
                raise MPCConfigError(f"{name} must be > 0, got {value!r}")
            if name in non_negative and value < 0:
                raise MPCConfigError(f"{name} must be >= 0, got {value!r}")
        check_step_time(self.time_limit_s)

    def _plain_scalars(self) -> None:
        """numpy's scalars stored as Python's, as EnvConfig stores them: values from numpy (a sweep over
        ``np.linspace``) were refused as if wrong ("horizon must be an integer >= 1, got np.int64(4)"), and
        a run's JSON record takes Python's alone."""
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.generic):
                object.__setattr__(self, f.name, value.item())
            elif (
                f.name == "human_margins"
                and isinstance(value, tuple | list | np.ndarray)
                and np.ndim(value) == 1
            ):
                # an array too: "must be a sequence of 4 numbers, got array([0.1, 0.1, 0.1, 0.1])" refused one
                plain = [m.item() if isinstance(m, np.generic) else m for m in value]
                object.__setattr__(self, f.name, list(plain) if isinstance(value, list) else tuple(plain))

    def _check_margins(self) -> None:
        margins = self.human_margins
        if not isinstance(margins, tuple | list):
            raise MPCConfigError(
                f"human_margins must be a sequence of {self.horizon} numbers, got {margins!r}"
            )
        if margins and len(margins) != self.horizon:
            raise MPCConfigError(
                f"human_margins needs one margin per horizon step ({self.horizon}), got {len(margins)}"
            )
        for m in margins:
            if isinstance(m, bool) or not isinstance(m, int | float) or not math.isfinite(m) or m < 0:
                raise MPCConfigError(f"human_margins must be finite numbers >= 0 m, got {list(margins)}")
        # JSON round trips give lists: keep the frozen config hashable and comparable.
        object.__setattr__(self, "human_margins", tuple(float(m) for m in margins))

    def human_margin(self, k: int) -> float:
        """m_k of horizon step ``k`` (0-based), 0 without margins (the paper's Eq. 11)."""
        return self.human_margins[k] if self.human_margins else 0.0

    def pair_floc_weight(self, n_robots: int) -> float:
        """Eq. 15's weight of one pair of flocking robots in a team of ``n_robots`` (``flocking_weight``)."""
        if self.flocking_weight == "per_pair" or n_robots < 2:
            return self.w_floc
        return self.w_floc * (PAPER_ROBOTS - 1) / (n_robots - 1)

    def standing_clearance(self, margin: float) -> float:
        """Guidance's disc radius, m, around a standing human with margin ``margin`` (guidance_clearance)."""
        radius = self.d_min + margin
        if self.guidance_clearance == "margin":
            return radius
        tail = math.log(self.w_coll / (self.mu * self.w_goal)) / self.mu  # m^2; <= 0: no tail to add
        return math.sqrt(radius * radius + max(tail, 0.0))

    @classmethod
    def from_world(cls, world: WorldFacts, **settings: Any) -> MPCConfig:
        """Table I's MPC in ``world``: its tau and robot bounds, with ``settings`` for the rest."""
        return cls(dt=world.dt, v_max=world.v_max, a_max=world.a_max, **settings)

    def replace(self, **changes: Any) -> MPCConfig:
        """A copy with ``changes`` applied (validated); unknown names raise ``MPCConfigError``."""
        names = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise MPCConfigError(f"unknown MPC config field(s) {unknown}; choose from {sorted(names)}")
        return MPCConfig(**{**asdict(self), **changes})

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)
