"""Where a CMPC control step's time goes against its floor: the first solve, the later IBR solves, the rest.

Algorithm 1 stops when ``|F^(j) - F^(j-1)| <= xi`` with ``F^(0) = inf``: every step predicts at least
twice and, unless the second prediction repeats the first bit for bit, solves twice. Issue 16's floor is one
bare solve from the shifted previous plan, i.e. the first of them. This splits each step of seeded circle
episodes (3 robots) into that first solve, the later solves (warm-started from the first) and everything else
(encoding the past, the twin's predictions, the IBR bookkeeping), and prints medians, the solver iterations
of the first and second solves, and the step / first-solve ratio. The machine is shared: the load is printed.

    nice -n 5 .venv/bin/python benchmarks/ibr_solves.py
    nice -n 5 .venv/bin/python benchmarks/ibr_solves.py --jit --episodes 8 --humans 9
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from crowdsim.env import CrowdEnv
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.mpc import MPCController


def measure(predictor: str, n_humans: int, episodes: int, jit: bool) -> dict[str, float]:
    controller = MPCController(ControllerSpec("cmpc", predictor), distributed=False, jit=jit)
    env = CrowdEnv()
    obs = env.reset(0, "circle", n_humans, 3)
    controller.reset(obs)
    nlp = controller.solver(3, n_humans).nlp
    solve = nlp.solve_multi_start
    solves: list[tuple[float, int]] = []

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        result = solve(*args, **kwargs)
        solves.append((time.perf_counter() - t0, result[2]))  # (seconds, solver iterations)
        return result

    nlp.solve_multi_start = timed  # type: ignore[method-assign]
    steps = []
    for seed in range(episodes):
        obs = env.reset(seed, "circle", n_humans, 3)
        controller.reset(obs)
        done = False
        while not done:
            solves.clear()
            out = controller.act(obs)
            if solves:
                steps.append((out.solve_time_s, list(solves)))
            obs, done, _ = env.step(out.accelerations)
    total = np.array([t for t, _ in steps])
    first = np.array([s[0][0] for _, s in steps])
    later = np.array([sum(x[0] for x in s[1:]) for _, s in steps])
    return {
        "steps": len(steps),
        "step_ms": 1e3 * float(np.median(total)),
        "first_solve_ms": 1e3 * float(np.median(first)),
        "later_solves_ms": 1e3 * float(np.median(later)),
        "solves_per_step": float(np.mean([len(s) for _, s in steps])),
        "first_iterations": float(np.median([s[0][1] for _, s in steps])),
        "second_iterations": float(np.median([s[1][1] for _, s in steps if len(s) > 1])),
        "step_over_first": float(np.median(total / first)),
        "non_solve_share": 1.0 - float((first + later).sum() / total.sum()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--predictor", default="social_lstm_eth")
    parser.add_argument("--humans", type=int, default=7)
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--jit", action="store_true", help="compile the NLP (cached, mpc/compile_cache.py)")
    args = parser.parse_args(argv)
    load = os.getloadavg()[0]
    row = measure(args.predictor, args.humans, args.episodes, args.jit)
    setting = f"{args.predictor}, {args.humans} humans, {args.episodes} episodes, jit {args.jit}"
    print(f"{setting}, load {load:.2f}")
    print(
        f"step {row['step_ms']:.2f} ms median: first solve {row['first_solve_ms']:.2f}, later solves "
        f"{row['later_solves_ms']:.2f} ({row['solves_per_step']:.2f} solves a step; solver iterations "
        f"{row['first_iterations']:.1f} then {row['second_iterations']:.1f}); step / first solve "
        f"{row['step_over_first']:.2f}; outside the solves {100 * row['non_solve_share']:.0f} %"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
