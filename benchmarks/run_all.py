"""Every speed figure of the project in one run: a table, then the same numbers as JSON.

    nice -n 10 .venv/bin/python benchmarks/run_all.py            # everything (several minutes on 2 cores)
    nice -n 10 .venv/bin/python benchmarks/run_all.py --quick    # fewer sizes, shorter runs
    nice -n 10 .venv/bin/python benchmarks/run_all.py --json out.json --sections simulator,control

Sections
  simulator   one CrowdEnv.step (ORCA for every human + the robots' integration), humans 5..50, robots 3..12
              (benchmarks/orca_step.py's ``measure``)
  control     one control step (ControlOutput.solve_time_s: prediction + every solve) per controller, CMPC's
              floor (the joint NLP solved once with the prediction fixed), and CMPC per predictor (every one
              the registry has, the ORCA oracle among them) and per coupling (benchmarks/control_step.py's
              ``closed_loop`` for CMPC/DMPC, whole circle-crossing episodes)
  scaling     CMPC and DMPC control step against the number of humans (5..50, control_step.py) and of robots
              (3..12, here: control_step.py has 3 robots)
  dmpc        DMPC's local solves in a thread pool vs one after the other (mpc/dmpc.py): the speed-up
  episodes    episodes per minute of one process per controller (Table II's predictor, 7 humans), and of a
              real Table II sweep (5-9 humans) with K workers, with the projected time of the paper's full
              Table II (10 cells x 1000 episodes) from its rate and from its CPU time per episode; and
              the share of a Table II episode spent inside CasADi, with the table's time if the Python
              around it took none (benchmarks/sweep_floor.py; quick: 2 timed episodes a cell)
  export      the exported CasADi predictors against the hand-written twins (Social-LSTM family): export
              time, parity with torch (values, Jacobians), the IBR prediction call and the coupled-NLP control
              step over one circle episode (benchmarks/export.py's ``measure``; quick: one model, no episode)
  robots      CMPC and DMPC control step in whole paper-profile episodes with M robots in their formations
              (3..12, ``auto``), with success rate and fallbacks, as the paper and with the many-robot
              settings (docs/examples/many_robots.toml), and with those settings on the goal-slots task
              (``slots``: crowdsim/slots.py; benchmarks/robot_scaling.py's ``run_row``; quick: CMPC at 3 and
              6 robots, 1 episode)
  dmpc_updates  DMPC's update rules (UPDATE:STOP) x local solves serial/threads, circle episodes, 3..12 robots
              (benchmarks/dmpc_scaling.py's ``closed_loop``; quick: 3 and 6 robots, jacobi:regret and
              sequential_accept:no_improvement, 1 episode)
  ibr         CMPC's step against its floor, jit off and on (social_lstm_eth, 7 humans): the first solve (the
              floor), the later IBR solves, the predictor and the rest (benchmarks/ibr_solves.py; quick: 1
              episode)

Rows measured here rather than by control_step.py (the baselines, the oracle, robots != 3) time the first
``--steps`` control steps of episodes of both scenarios (export, robots and dmpc_updates time whole episodes).
Medians and 95th percentiles in milliseconds. The machine is shared: figures vary with the load, which is
printed.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipelines.experiments.cells import PAPER_PREDICTOR
from predictors.oracle import ORACLE_PREDICTOR
from predictors.registry import available

# The sibling benchmark modules (orca_step.py, control_step.py, export.py, robot_scaling.py, dmpc_scaling.py)
# are imported by name, however this is run.
sys.path.insert(0, str(Path(__file__).resolve().parent))

import sweep_floor  # noqa: E402
from bench_cli import json_text, output_file, run_main, write_text  # noqa: E402
from run_all_table import table  # noqa: E402

SECTIONS = ("simulator", "control", "scaling", "dmpc", "episodes", "export", "robots", "dmpc_updates", "ibr")
SCENARIOS = ("circle", "perpendicular")


def _stats(samples_s: Sequence[float]) -> dict[str, float]:
    ms = np.asarray(samples_s, dtype=float) * 1e3
    return {
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "mean_ms": float(ms.mean()),
        "steps": int(ms.size),
    }


# ----------------------------------------------------------------------------------------------------------
# Measurements
# ----------------------------------------------------------------------------------------------------------


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
    from pipelines.experiments.sweep import SweepConfig, run_sweep
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


# ----------------------------------------------------------------------------------------------------------
# The run
# ----------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Run:
    """What every section reads: the sizes (``--quick``), the steps timed, the sweep's workers, and the
    errors dict that ``timed`` fills."""

    quick: bool
    steps: int
    workers: int
    sweep_episodes: int | None
    errors: dict[str, str]

    @property
    def humans_scale(self) -> tuple[int, ...]:
        return (5, 20, 50) if self.quick else (5, 9, 20, 50)

    @property
    def robots_scale(self) -> tuple[int, ...]:
        return (3, 6) if self.quick else (3, 6, 12)

    def timed(self, label: str, fn: Callable[[], dict[str, Any]]) -> dict[str, Any] | None:
        """Run one measurement; a failure (a missing model, a broken build) is reported, not fatal."""
        t0 = time.perf_counter()
        try:
            result = fn()
        except Exception as exc:  # noqa: BLE001 - the benchmark reports what it could not measure
            self.errors[label] = f"{type(exc).__name__}: {exc}"
            print(f"  {label}: failed ({self.errors[label]})", file=sys.stderr)
            return None
        print(f"  {label}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        return result


CV = "constant_velocity"


def simulator_section(run: Run) -> dict[str, Any]:
    print("simulator step", file=sys.stderr)
    episodes = 1 if run.quick else 3
    sim: dict[str, Any] = {}
    for n in run.humans_scale:
        sim[f"h{n}_r3"] = run.timed(f"{n} humans, 3 robots", lambda n=n: simulator_step(n, 3, episodes))
    for m in run.robots_scale:
        sim[f"h7_r{m}"] = run.timed(f"7 humans, {m} robots", lambda m=m: simulator_step(7, m, episodes))
    return sim


def control_section(run: Run) -> dict[str, Any]:
    from pipelines.loop.controllers import ControllerSpec

    print("control step at 7 humans, 3 robots", file=sys.stderr)
    episodes, steps = (1 if run.quick else 2), run.steps
    control: dict[str, Any] = {}
    for name in ("straight", "orca"):
        control[name] = run.timed(name, lambda n=name: any_step(ControllerSpec(n), 7, 3, steps))
    cmpc = run.timed("cmpc + floor", lambda: mpc_step(ControllerSpec("cmpc", CV), 7, episodes, True))
    control["cmpc"] = cmpc
    control["floor (joint NLP, fixed prediction)"] = cmpc["floor"] if cmpc else None
    control["dmpc"] = run.timed("dmpc", lambda: mpc_step(ControllerSpec("dmpc", CV), 7, episodes))
    names = available()  # every predictor crowdmpc knows, the ORCA oracle among them
    for name in names:
        if name == CV:
            continue
        spec = ControllerSpec("cmpc", name)
        if name == ORACLE_PREDICTOR:  # not a registry predictor: control_step.py cannot build it
            control[f"cmpc/{name}"] = run.timed(name, lambda s=spec: any_step(s, 7, 3, steps))
        else:
            control[f"cmpc/{name}"] = run.timed(name, lambda s=spec: mpc_step(s, 7, episodes))
    coupled = "social_lstm_soft_eth" if "social_lstm_soft_eth" in names else CV
    for mode in ("exact", "first_order"):
        spec = ControllerSpec("cmpc", coupled, coupling="nlp", mpc_overrides=(("coupled_mode", mode),))
        label = f"cmpc/{coupled}/nlp-{mode}"
        control[label] = run.timed(label, lambda s=spec: mpc_step(s, 7, episodes))
    return control


def scaling_section(run: Run) -> dict[str, Any]:
    from pipelines.loop.controllers import ControllerSpec

    print("scaling (constant velocity)", file=sys.stderr)
    scale: dict[str, Any] = {}
    for controller in ("cmpc", "dmpc"):
        spec = ControllerSpec(controller, CV)
        for n in run.humans_scale:
            label = f"{controller} {n} humans, 3 robots"
            scale[f"{controller}_h{n}_r3"] = run.timed(label, lambda s=spec, n=n: mpc_step(s, n, 1))
        for m in run.robots_scale:
            label = f"{controller} 7 humans, {m} robots"
            scale[f"{controller}_h7_r{m}"] = run.timed(
                label, lambda s=spec, m=m: any_step(s, 7, m, run.steps, 2)
            )
    return scale


def dmpc_section(run: Run) -> dict[str, Any]:
    """The same measurement for every robot count (control_step.py's --dmpc-parallel has 3 robots only)."""
    from pipelines.loop.controllers import ControllerSpec

    print("DMPC: local solves in threads vs serial, 7 humans", file=sys.stderr)
    speedup: dict[str, Any] = {}
    for m in run.robots_scale:
        row = {}
        for mode in ("serial", "threads"):
            spec = ControllerSpec("dmpc", CV, mpc_overrides=(("dmpc_parallel", mode),))
            row[mode] = run.timed(f"{m} robots, {mode}", lambda s=spec, m=m: any_step(s, 7, m, run.steps, 2))
        if row["serial"] and row["threads"]:
            row["speedup_median"] = row["serial"]["median_ms"] / row["threads"]["median_ms"]
        speedup[f"r{m}"] = row
    return speedup


def episodes_section(run: Run) -> dict[str, Any]:
    """Table II's own predictor, so that the projections are of the table itself."""
    from pipelines.loop.controllers import ControllerSpec

    paper = PAPER_PREDICTOR if PAPER_PREDICTOR in available() else CV
    print(f"episodes per minute at 7 humans, {paper}", file=sys.stderr)
    n_episodes = 2 if run.quick else 4
    single = {}
    for name in ("straight", "orca", "cmpc", "dmpc"):
        spec = ControllerSpec(name, paper)
        single[name] = run.timed(f"{name}, 1 process", lambda s=spec: episodes_per_minute(s, 7, n_episodes))
    out: dict[str, Any] = {"one_process": single}
    if single["cmpc"] and single["dmpc"]:
        # Half of Table II is CMPC and half DMPC; K workers on K free cores run K episodes at once.
        minutes = (
            sweep_floor.table2_episodes()
            / 2
            * (1 / single["cmpc"]["episodes_per_minute"] + 1 / single["dmpc"]["episodes_per_minute"])
        )
        out["projected_table2_hours_from_one_process"] = minutes / run.workers / 60
    per_cell = run.sweep_episodes or (2 if run.quick else 6)
    out["sweep"] = run.timed(
        f"table2 sweep, 5-9 humans, {run.workers} workers", lambda: sweep_rate(paper, per_cell, run.workers)
    )
    out["casadi_floor"] = run.timed(
        "table2 episodes inline, time in CasADi",
        lambda: sweep_floor.summary(sweep_floor.measure(3 if run.quick else 11), run.workers),
    )
    return out


def export_section(run: Run) -> dict[str, Any]:
    print("exported predictors vs hand-written twins, 7 humans, 3 robots, H=4", file=sys.stderr)
    import export

    models = ("social_lstm_soft_eth",) if run.quick else export.DEFAULT_MODELS
    calls = 100 if run.quick else 300
    return {
        model: run.timed(model, lambda m=model: export_rows(m, 7, calls, not run.quick)) for model in models
    }


def robots_section(run: Run) -> dict[str, Any]:
    print("control step against robots in formation, 7 humans, paper profile", file=sys.stderr)
    controllers = ("cmpc",) if run.quick else ("cmpc", "dmpc")
    episodes = 1 if run.quick else 2
    robots: dict[str, Any] = {}
    for controller in controllers:
        for variant in ("paper", "many", "slots"):
            for m in run.robots_scale:
                robots[f"{controller}_{variant}_h7_r{m}"] = run.timed(
                    f"{controller} ({variant}), {m} robots",
                    lambda c=controller, m=m, v=variant: robots_row(c, m, 7, episodes, v),
                )
    return robots


def dmpc_updates_section(run: Run) -> dict[str, Any]:
    print("DMPC update rules x serial/threads, 7 humans, circle", file=sys.stderr)
    import dmpc_scaling

    rules = ("jacobi:regret", "sequential_accept:no_improvement") if run.quick else dmpc_scaling.RULES
    episodes = 1 if run.quick else 2
    updates: dict[str, Any] = {}
    for m in run.robots_scale:
        for rule in rules:
            cell = run.timed(f"{m} robots, {rule}", lambda m=m, r=rule: dmpc_update_cell(m, 7, r, episodes))
            if cell:
                rows = cell["rows"]
                if "serial" in rows and "threads" in rows:
                    cell["speedup_median"] = rows["serial"]["median_ms"] / rows["threads"]["median_ms"]
            updates[f"r{m} {rule}"] = cell
    return updates


def ibr_section(run: Run) -> dict[str, Any]:
    print("CMPC step against its floor, social_lstm_eth, 7 humans", file=sys.stderr)
    import ibr_solves

    episodes = 1 if run.quick else 4
    return {
        f"jit {jit}": run.timed(
            f"jit {jit}", lambda on=(jit == "on"): ibr_solves.measure(PAPER_PREDICTOR, 7, episodes, on)
        )
        for jit in ("off", "on")
    }


# Section name -> (its key in the report, what measures it), in the order they run.
SECTION_RUNS: dict[str, tuple[str, Callable[[Run], dict[str, Any]]]] = {
    "simulator": ("simulator_step", simulator_section),
    "control": ("control_step", control_section),
    "scaling": ("scaling", scaling_section),
    "dmpc": ("dmpc_parallel", dmpc_section),
    "episodes": ("episodes_per_minute", episodes_section),
    "export": ("export", export_section),
    "robots": ("robots", robots_section),
    "dmpc_updates": ("dmpc_updates", dmpc_updates_section),
    "ibr": ("ibr", ibr_section),
}
assert tuple(SECTION_RUNS) == SECTIONS


def run(args: argparse.Namespace) -> dict[str, Any]:
    quick = args.quick
    steps = args.steps or (8 if quick else 20)
    context = Run(quick, steps, args.workers, args.sweep_episodes, errors={})
    report: dict[str, Any] = {
        "machine": {
            "cpus": os.cpu_count(),
            "load_average": list(os.getloadavg()),
            "python": platform.python_version(),
            "platform": platform.platform(),
            "numpy": np.__version__,
        },
        "settings": {"steps": steps, "quick": quick, "workers": args.workers},
    }
    for name, (key, measure) in SECTION_RUNS.items():
        if name in args.sections:
            report[key] = measure(context)
    report["errors"] = context.errors
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="fewer steps and sizes")
    parser.add_argument("--steps", type=int, help="control steps timed per episode (default 20, quick 8)")
    parser.add_argument("--workers", type=int, default=2, help="workers of the sweep measurement (default 2)")
    parser.add_argument("--sweep-episodes", type=int, help="episodes per cell of the sweep measurement")
    parser.add_argument(
        "--sections",
        type=lambda s: tuple(part.strip() for part in s.split(",")),
        default=SECTIONS,
        metavar="NAME,NAME,...",
        help=f"comma-separated, from: {', '.join(SECTIONS)}",
    )
    parser.add_argument("--json", type=output_file, help="also write the JSON here")
    args = parser.parse_args(argv)
    if args.sweep_episodes is not None and args.sweep_episodes < 2:
        parser.error(f"--sweep-episodes must be >= 2 (a worker's first episode of a cell is not timed), got "
                     f"{args.sweep_episodes}")  # fmt: skip
    unknown = set(args.sections) - set(SECTIONS)
    if unknown:
        parser.error(f"unknown sections {sorted(unknown)}; choose from {list(SECTIONS)}")
    report = run(args)
    print(table(report))  # run_all_table.py
    text = json_text(report, indent=1)
    print(text)
    if args.json:
        write_text(args.json, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
