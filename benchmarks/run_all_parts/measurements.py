"""benchmarks/run_all.py's measurements: one controller, simulator or exported predictor timed at one size,
mostly through the sibling benchmark that measures it (orca_step.py, control_step.py, export.py, ...)."""

from __future__ import annotations

import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import sweep_floor

SCENARIOS = ("circle", "perpendicular")


def _stats(samples_s: Sequence[float]) -> dict[str, float]:
    ms = np.asarray(samples_s, dtype=float) * 1e3
    return {
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "mean_ms": float(ms.mean()),
        "steps": int(ms.size),
    }


def simulator_step(n_humans: int, n_robots: int, episodes: int) -> dict[str, float]:
    """CrowdEnv.step in real circle-crossing episodes with ORCA robots: benchmarks/orca_step.py's measure
    (each step timed on a copy of the environment, the fastest of 2 kept)."""
    import orca_step

    return orca_step.measure(n_humans, n_robots, episodes, "circle", repeats=2)


def mpc_step(spec: Any, n_humans: int, episodes: int, floor: bool = False) -> dict[str, Any]:
    """CMPC/DMPC with a registry predictor and 3 robots: benchmarks/control_step.py's closed_loop (whole
    circle-crossing episodes; with ``floor`` also the bare joint-NLP solve of the same steps)."""
    import control_step

    return control_step.closed_loop(spec, n_humans, episodes, floor=floor) | {"method": "control_step.py"}


def any_step(spec: Any, n_humans: int, n_robots: int, steps: int, episodes: int = 2) -> dict[str, Any]:
    """Any controller (the baselines, the ORCA oracle, any number of robots), which control_step.py does not
    cover: the step time over the first ``steps`` steps of ``episodes`` episodes, alternating scenarios."""
    from crowdsim.env import CrowdEnv
    from pipelines.loop.controllers import make_controller

    controller = make_controller(spec)
    env, times, iterations, solves = CrowdEnv(), [], [], []
    for k in range(episodes):
        obs = env.reset(k // 2, SCENARIOS[k % 2], n_humans, n_robots)
        controller.reset(obs)
        for _ in range(steps):
            out = controller.act(obs)
            times.append(out.solve_time_s)
            iterations.append(out.iterations)
            solves.append(out.extra.get("solves", 0))
            obs, done, _ = env.step(out.accelerations)
            if done:
                break
    return _stats(times) | {
        "iterations_mean": float(np.mean(iterations)),
        "solves_mean": float(np.mean(solves)),
        "method": f"run_all.py, first {steps} steps",
    }


def episodes_per_minute(spec: Any, n_humans: int, episodes: int) -> dict[str, float]:
    """Whole episodes in this process, alternating scenarios as a sweep does; controller built (and, when gcc
    is found, compiled, as sweep workers do) once, its NLPs built by a first episode that is not timed."""
    from pipelines.experiments.worker import jit_available
    from pipelines.loop.controllers import make_controller
    from pipelines.loop.episode import run_episode

    controller = make_controller(spec, jit=jit_available())
    run_episode(controller, seed=10_000, scenario=SCENARIOS[0], n_humans=n_humans)
    t0 = time.perf_counter()
    steps = 0
    for k in range(episodes):
        result = run_episode(controller, seed=k // 2, scenario=SCENARIOS[k % 2], n_humans=n_humans)
        steps += result.metrics.n_steps
    wall = time.perf_counter() - t0
    return {
        "episodes": episodes,
        "wall_s": wall,
        "episodes_per_minute": 60.0 * episodes / wall,
        "steps": steps,
    }


def sweep_rate(predictor: str, episodes_per_cell: int, workers: int) -> dict[str, float]:
    """A real ``run_sweep`` of Table II (CMPC and DMPC, 5-9 humans) with K process workers, compiled as
    ``crowdmpc sweep`` does by default. ``steady_cpu_s_per_episode`` leaves out each worker's first episode
    of a cell (it builds and compiles the NLPs): the cost per episode a long sweep approaches."""
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.log import EPISODES_FILE, EpisodeLog
    from pipelines.experiments.sweep import run_sweep
    from pipelines.experiments.sweep_config import SweepConfig
    from pipelines.experiments.worker import jit_available

    experiment = get_experiment("table2").with_predictor(predictor)
    with tempfile.TemporaryDirectory(prefix="crowdmpc-bench-") as out:
        config = SweepConfig(
            experiment,
            Path(out),
            episodes_per_cell,
            workers=workers,
            backend="process",
            progress=False,
            jit=jit_available(),
        )
        outcome = run_sweep(config)
        records = list(EpisodeLog(Path(out) / EPISODES_FILE).load(repair=False).values())
    built, steady_cpu = set(), []
    for record in records:
        first = (record["worker"], record["cell"]) not in built
        built.add((record["worker"], record["cell"]))
        if not first:
            steady_cpu.append(record["cpu_s"])
    cpu = float(np.mean(steady_cpu)) if steady_cpu else float("nan")
    steady = outcome.steady_episodes_per_minute
    full = sweep_floor.table2_episodes()
    return {
        "predictor": predictor,
        "jit": config.jit,
        "steady_cpu_s_per_episode": cpu,
        "projected_table2_hours_from_cpu": full * cpu / workers / 3600,
        "workers": workers,
        "episodes": outcome.ran,
        "wall_s": outcome.wall_s,
        "startup_s": outcome.startup_s,
        "episodes_per_minute": outcome.episodes_per_minute,
        "steady_episodes_per_minute": steady,
        "projected_table2_hours": full / steady / 60.0 if steady else float("nan"),
    }


def export_rows(model: str, n_humans: int, calls: int, closed_loop: bool) -> dict[str, dict[str, Any]]:
    """One zoo model exported to CasADi (and, for the Social-LSTM family, its hand-written twin):
    benchmarks/export.py's measure, keyed by twin ("exported", "hand-written")."""
    import export

    from predictors.zoo import zoo_names

    if model not in zoo_names():
        raise LookupError(f"{model} is not in the zoo")
    return {row["twin"]: row for row in export.measure(model, n_humans, calls, closed_loop)}


def robots_row(controller: str, n_robots: int, n_humans: int, episodes: int, variant: str) -> dict[str, Any]:
    """CMPC/DMPC (constant velocity) with ``n_robots`` robots in their formation (``auto``), paper profile,
    episodes alternating circle/perpendicular from seed 0: benchmarks/robot_scaling.py's run_row, as the
    paper (``variant`` "paper"), with docs/examples/many_robots.toml ("many"), or with those settings and
    the goals as slots of the formation ("slots", crowdsim/slots.py: a different task)."""
    import robot_scaling

    from crowdsim.slots import GoalAssignment

    scenarios = tuple(robot_scaling.SCENARIOS)
    cv = "constant_velocity"
    overrides, margins = robot_scaling.many_robots() if variant in ("many", "slots") else ((), None)
    goals: GoalAssignment = "slots" if variant == "slots" else "fixed"
    row = robot_scaling.run_row(
        controller, cv, n_robots, n_humans, episodes, 0, scenarios, "auto", overrides, margins, goals
    )
    return row | {"method": "robot_scaling.py, whole episodes", "mpc_overrides": dict(overrides)}


def dmpc_update_cell(n_robots: int, n_humans: int, rule: str, episodes: int) -> dict[str, Any]:
    """One DMPC rule (UPDATE:STOP) at ``n_robots`` robots, serial and threaded local solves on the same
    circle seeds: benchmarks/dmpc_scaling.py's closed_loop (gauss_seidel rules run serially only)."""
    import dmpc_scaling

    return dmpc_scaling.closed_loop(n_robots, n_humans, rule, ["serial", "threads"], episodes)
