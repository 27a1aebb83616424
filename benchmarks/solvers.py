"""IPOPT vs Fatrop (and jit) on the NLPs the closed loop really solves.

    nice -n 10 .venv/bin/python benchmarks/solvers.py                 # 4 episodes per controller, 7 humans
    nice -n 10 .venv/bin/python benchmarks/solvers.py --episodes 8 --humans 9 --json solvers.json

Records every local (DMPC) and joint (CMPC) solve of a few closed-loop episodes driven with the default
solver (constant-velocity predictions unless ``--predictor``), then solves each recorded
problem again, from the same initial guess (and, for warm-started IPOPT, the same multipliers), with each
solver: IPOPT as the loop calls it, Fatrop, and both with ``jit`` when gcc is found. Prints, per NLP and
solver, the CPU time per solve, iterations, failures, and how the cost compares with IPOPT's on the same
problem (the NLPs are non-convex: two solvers may stop in different local minima). Build times are
printed separately (the jit build dominates them): the jit builds compile in a private, initially empty
``$CROWDMPC_CACHE``, removed after (the user's cache is not touched; a warm one made the column a load,
0.0 s).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mpc import nlp as nlp_module  # noqa: E402
from mpc.config import MPCConfig  # noqa: E402
from predictors.text_table import counted  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import (  # noqa: E402
    episode_count,
    human_count,
    json_on_stdout,
    output_file,
    predictor_name,
    private_cache,
    run_main,
    write_json,
)

SCENARIOS = ("circle", "perpendicular")


def record_problems(n_humans: int, episodes: int, predictor: str) -> dict[str, list[dict[str, Any]]]:
    """Every local and joint solve of ``episodes`` DMPC and CMPC episodes: inputs and the loop's cost."""
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.episode import run_episode

    problems: dict[str, list[dict[str, Any]]] = {"local": [], "joint": []}
    local_solve, joint_solve = nlp_module.LocalNLP.solve, nlp_module.JointNLP.solve

    def local(self, i, params, accels0, lam_x0=None, lam_g0=None, explore=False):
        sol = local_solve(self, i, params, accels0, lam_x0, lam_g0, explore)
        lbx, ubx = -self.cfg.a_max, self.cfg.a_max
        x0 = np.clip(np.ravel(accels0), lbx, ubx)
        problems["local"].append(dict(x0=x0, p=params.copy(), lbx=lbx, ubx=ubx, lam_x0=lam_x0, lam_g0=lam_g0))
        return sol

    def joint(self, data, extra, accels0, lam_x0=None, lam_g0=None, explore=False):
        sol = joint_solve(self, data, extra, accels0, lam_x0, lam_g0, explore)
        lbx, ubx = self.bounds(data)
        x0 = np.clip(np.ravel(accels0), lbx, ubx)
        p = self.params(data, extra)
        problems["joint"].append(dict(x0=x0, p=p, lbx=lbx, ubx=ubx, lam_x0=lam_x0, lam_g0=lam_g0))
        return sol

    nlp_module.LocalNLP.solve, nlp_module.JointNLP.solve = local, joint
    try:
        for controller in ("dmpc", "cmpc"):
            c = make_controller(ControllerSpec(controller, predictor))
            for k in range(episodes):
                run_episode(c, seed=k // 2, scenario=SCENARIOS[k % 2], n_humans=n_humans)
    finally:
        nlp_module.LocalNLP.solve, nlp_module.JointNLP.solve = local_solve, joint_solve
    return problems


class _Keep(nlp_module._Solver):
    """A _Solver that also keeps the NLP it was given, to rebuild it with other settings."""

    last_nlp: dict | None = None

    def __init__(self, name, nlp, cfg, ipopt_extra=None):
        _Keep.last_nlp = nlp
        super().__init__(name, nlp, cfg, ipopt_extra)


def nlp_of(kind: str, n_humans: int) -> dict:
    saved = nlp_module._Solver
    nlp_module._Solver = _Keep
    try:
        cfg = MPCConfig()
        (nlp_module.LocalNLP if kind == "local" else nlp_module.JointNLP)(cfg, 3, n_humans)
    finally:
        nlp_module._Solver = saved
    assert _Keep.last_nlp is not None
    return _Keep.last_nlp


def replay(nlp: dict, cfg: MPCConfig, problems: list[dict[str, Any]]) -> dict[str, Any]:
    t0 = time.perf_counter()
    solver = nlp_module._Solver("bench", nlp, cfg)
    build_s = time.perf_counter() - t0
    v = cfg.v_max
    costs, iterations, failures, used = [], [], 0, {"fatrop": 0, "ipopt": 0}
    cpu0 = time.process_time()
    for pr in problems:
        out, stats = solver.solve(pr["x0"], pr["p"], pr["lbx"], pr["ubx"], -v, v, pr["lam_x0"], pr["lam_g0"])
        costs.append(float(np.asarray(out["f"]).item()))  # BufferedFunction returns (1, 1) arrays
        iterations.append(stats["iterations"])
        failures += stats["status"] not in nlp_module.SOLVED
        used[stats["solver"]] += 1
    cpu = time.process_time() - cpu0
    return {
        "ms_per_solve": 1e3 * cpu / len(problems),
        "iterations_mean": float(np.mean(iterations)),
        "failures": failures,
        "ipopt_retries": used["ipopt"] if cfg.solver == "fatrop" else None,
        "build_s": build_s,
        "costs": costs,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--humans", type=human_count, default=7)
    parser.add_argument("--episodes", type=episode_count, default=4, help="episodes per controller to record")
    parser.add_argument(
        "--predictor",
        type=predictor_name,
        default="constant_velocity",
        help="the predictor of the recorded loop",
    )
    parser.add_argument("--json", type=output_file, help="also write the figures here")
    args = parser.parse_args(argv)
    # --json -: the JSON alone on stdout, the rest on stderr
    with json_on_stdout(args.json), private_cache("solvers-bench-"):
        print(
            f"recording {args.episodes} DMPC + {args.episodes} CMPC episodes, "
            f"{counted(args.humans, 'human')}",
            file=sys.stderr,
        )
        problems = record_problems(args.humans, args.episodes, args.predictor)
        variants = [("ipopt", False), ("fatrop", False)]
        if shutil.which("gcc"):
            variants += [("ipopt", True), ("fatrop", True)]
        report: dict[str, Any] = {"humans": args.humans, "episodes": args.episodes, "results": {}}
        lines = [
            "| NLP | solver | problems | ms / solve | iterations | failures | IPOPT retries | "
            "cost vs IPOPT: within 1e-3 / lower / higher | build s |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for kind in ("local", "joint"):
            nlp = nlp_of(kind, args.humans)
            reference = None
            for solver, jit in variants:
                label = solver + (" + jit" if jit else "")
                print(f"{kind}: {label}", file=sys.stderr)
                result = replay(nlp, MPCConfig(solver=solver, jit=jit), problems[kind])
                costs = np.asarray(result.pop("costs"))
                if reference is None:
                    reference = costs
                diff = costs - reference
                scale = np.maximum(1.0, np.abs(reference))
                result["same"] = int(np.sum(np.abs(diff) <= 1e-3 * scale))
                result["lower"] = int(np.sum(diff < -1e-3 * scale))
                result["higher"] = int(np.sum(diff > 1e-3 * scale))
                report["results"][f"{kind}/{label}"] = result
                retries = "-" if result["ipopt_retries"] is None else str(result["ipopt_retries"])
                lines.append(
                    f"| {kind} | {label} | {len(costs)} | {result['ms_per_solve']:.3f} | "
                    f"{result['iterations_mean']:.1f} | {result['failures']} | {retries} | "
                    f"{result['same']} / {result['lower']} / {result['higher']} | {result['build_s']:.1f} |"
                )
        print("\n".join(lines))
        if args.json:
            write_json(args.json, report, indent=1)
        return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
