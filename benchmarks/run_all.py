"""Every speed figure of the project in one run: a table, then the same numbers as JSON.

    nice -n 10 .venv/bin/python benchmarks/run_all.py            # everything (several minutes on 2 cores)
    nice -n 10 .venv/bin/python benchmarks/run_all.py --quick    # fewer sizes, shorter runs
    nice -n 10 .venv/bin/python benchmarks/run_all.py --json out.json --sections simulator,control

Sections
  simulator   one CrowdEnv.step (ORCA for every human + the robots' integration), humans 5..50, robots 3..12
              (benchmarks/orca_step.py's ``measure``)
  control     one control step (ControlOutput.solve_time_s: prediction + every solve) per controller, CMPC's
              floor (the joint NLP solved once with the prediction fixed), and CMPC per predictor (every one
              the registry has, plus the ORCA oracle) and per coupling (benchmarks/control_step.py's
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
import json
import os
import platform
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

# The sibling benchmark modules (orca_step.py, control_step.py, export.py, robot_scaling.py, dmpc_scaling.py)
# are imported by name, however this is run.
sys.path.insert(0, str(Path(__file__).resolve().parent))

SECTIONS = ("simulator", "control", "scaling", "dmpc", "episodes", "export", "robots", "dmpc_updates", "ibr")
SCENARIOS = ("circle", "perpendicular")
ORACLE_PREDICTOR = "orca_oracle"  # pipelines.experiments.ORACLE_PREDICTOR
TABLE2_EPISODES = 10 * 1000  # the paper: 5 crowd sizes x 2 methods, 500 + 500 episodes per cell
PAPER_PREDICTOR = "social_lstm_eth"  # pipelines.experiments.PAPER_PREDICTOR


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
    return {
        "predictor": predictor,
        "jit": config.jit,
        "steady_cpu_s_per_episode": cpu,
        "projected_table2_hours_from_cpu": TABLE2_EPISODES * cpu / workers / 3600,
        "workers": workers,
        "episodes": outcome.ran,
        "wall_s": outcome.wall_s,
        "startup_s": outcome.startup_s,
        "episodes_per_minute": outcome.episodes_per_minute,
        "steady_episodes_per_minute": steady,
        "projected_table2_hours": TABLE2_EPISODES / steady / 60.0 if steady else float("nan"),
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


def _predictors() -> list[str]:
    from predictors.registry import available

    return [*available(), ORACLE_PREDICTOR]


def _timed(label: str, fn: Callable[[], dict[str, Any]], errors: dict[str, str]) -> dict[str, Any] | None:
    """Run one measurement; a failure (a missing model, a broken build) is reported, not fatal."""
    t0 = time.perf_counter()
    try:
        result = fn()
    except Exception as exc:  # noqa: BLE001 - the benchmark reports what it could not measure
        errors[label] = f"{type(exc).__name__}: {exc}"
        print(f"  {label}: failed ({errors[label]})", file=sys.stderr)
        return None
    print(f"  {label}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return result


def run(args: argparse.Namespace) -> dict[str, Any]:
    from pipelines.loop.controllers import ControllerSpec

    quick = args.quick
    steps = args.steps or (8 if quick else 20)
    humans_scale = (5, 20, 50) if quick else (5, 9, 20, 50)
    robots_scale = (3, 6) if quick else (3, 6, 12)
    errors: dict[str, str] = {}
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
    sections = args.sections
    cv = "constant_velocity"

    if "simulator" in sections:
        print("simulator step", file=sys.stderr)
        episodes = 1 if quick else 3
        sim: dict[str, Any] = {}
        for n in humans_scale:
            sim[f"h{n}_r3"] = _timed(
                f"{n} humans, 3 robots", lambda n=n: simulator_step(n, 3, episodes), errors
            )
        for m in robots_scale:
            sim[f"h7_r{m}"] = _timed(
                f"7 humans, {m} robots", lambda m=m: simulator_step(7, m, episodes), errors
            )
        report["simulator_step"] = sim

    if "control" in sections:
        print("control step at 7 humans, 3 robots", file=sys.stderr)
        episodes = 1 if quick else 2
        control: dict[str, Any] = {}
        for name in ("straight", "orca"):
            control[name] = _timed(name, lambda n=name: any_step(ControllerSpec(n), 7, 3, steps), errors)
        cmpc = _timed("cmpc + floor", lambda: mpc_step(ControllerSpec("cmpc", cv), 7, episodes, True), errors)
        control["cmpc"] = cmpc
        control["floor (joint NLP, fixed prediction)"] = cmpc["floor"] if cmpc else None
        control["dmpc"] = _timed("dmpc", lambda: mpc_step(ControllerSpec("dmpc", cv), 7, episodes), errors)
        for name in _predictors():
            if name == cv:
                continue
            spec = ControllerSpec("cmpc", name)
            if name == ORACLE_PREDICTOR:  # not a registry predictor: control_step.py cannot build it
                control[f"cmpc/{name}"] = _timed(name, lambda s=spec: any_step(s, 7, 3, steps), errors)
            else:
                control[f"cmpc/{name}"] = _timed(name, lambda s=spec: mpc_step(s, 7, episodes), errors)
        coupled = "social_lstm_soft_eth" if "social_lstm_soft_eth" in _predictors() else cv
        for mode in ("exact", "first_order"):
            spec = ControllerSpec("cmpc", coupled, coupling="nlp", mpc_overrides=(("coupled_mode", mode),))
            label = f"cmpc/{coupled}/nlp-{mode}"
            control[label] = _timed(label, lambda s=spec: mpc_step(s, 7, episodes), errors)
        report["control_step"] = control

    if "scaling" in sections:
        print("scaling (constant velocity)", file=sys.stderr)
        scale: dict[str, Any] = {}
        for controller in ("cmpc", "dmpc"):
            spec = ControllerSpec(controller, cv)
            for n in humans_scale:
                label = f"{controller} {n} humans, 3 robots"
                scale[f"{controller}_h{n}_r3"] = _timed(label, lambda s=spec, n=n: mpc_step(s, n, 1), errors)
            for m in robots_scale:
                label = f"{controller} 7 humans, {m} robots"
                scale[f"{controller}_h7_r{m}"] = _timed(
                    label, lambda s=spec, m=m: any_step(s, 7, m, steps, 2), errors
                )
        report["scaling"] = scale

    if "dmpc" in sections:
        # The same measurement for every robot count (control_step.py's --dmpc-parallel has 3 robots only).
        print("DMPC: local solves in threads vs serial, 7 humans", file=sys.stderr)
        speedup: dict[str, Any] = {}
        for m in robots_scale:
            row = {}
            for mode in ("serial", "threads"):
                spec = ControllerSpec("dmpc", cv, mpc_overrides=(("dmpc_parallel", mode),))
                row[mode] = _timed(
                    f"{m} robots, {mode}", lambda s=spec, m=m: any_step(s, 7, m, steps, 2), errors
                )
            if row["serial"] and row["threads"]:
                row["speedup_median"] = row["serial"]["median_ms"] / row["threads"]["median_ms"]
            speedup[f"r{m}"] = row
        report["dmpc_parallel"] = speedup

    if "episodes" in sections:
        # Table II's own predictor, so that the projection is of the table itself.
        paper = PAPER_PREDICTOR if PAPER_PREDICTOR in _predictors() else cv
        print(f"episodes per minute at 7 humans, {paper}", file=sys.stderr)
        n_episodes = 2 if quick else 4
        single = {}
        for name in ("straight", "orca", "cmpc", "dmpc"):
            spec = ControllerSpec(name, paper)
            single[name] = _timed(
                f"{name}, 1 process", lambda s=spec: episodes_per_minute(s, 7, n_episodes), errors
            )
        report["episodes_per_minute"] = {"one_process": single}
        if single["cmpc"] and single["dmpc"]:
            # Half of Table II is CMPC and half DMPC; K workers on K free cores run K episodes at once.
            minutes = (
                TABLE2_EPISODES
                / 2
                * (1 / single["cmpc"]["episodes_per_minute"] + 1 / single["dmpc"]["episodes_per_minute"])
            )
            report["episodes_per_minute"]["projected_table2_hours_from_one_process"] = (
                minutes / args.workers / 60
            )
        per_cell = args.sweep_episodes or (2 if quick else 6)
        report["episodes_per_minute"]["sweep"] = _timed(
            f"table2 sweep, 5-9 humans, {args.workers} workers",
            lambda: sweep_rate(paper, per_cell, args.workers),
            errors,
        )
        import sweep_floor

        report["episodes_per_minute"]["casadi_floor"] = _timed(
            "table2 episodes inline, time in CasADi",
            lambda: sweep_floor.summary(sweep_floor.measure(3 if quick else 11), args.workers),
            errors,
        )

    if "export" in sections:
        print("exported predictors vs hand-written twins, 7 humans, 3 robots, H=4", file=sys.stderr)
        import export

        models = ("social_lstm_soft_eth",) if quick else export.DEFAULT_MODELS
        calls = 100 if quick else 300
        report["export"] = {
            model: _timed(model, lambda m=model: export_rows(m, 7, calls, not quick), errors)
            for model in models
        }

    if "robots" in sections:
        print("control step against robots in formation, 7 humans, paper profile", file=sys.stderr)
        controllers = ("cmpc",) if quick else ("cmpc", "dmpc")
        episodes = 1 if quick else 2
        robots: dict[str, Any] = {}
        for controller in controllers:
            for variant in ("paper", "many", "slots"):
                for m in robots_scale:
                    robots[f"{controller}_{variant}_h7_r{m}"] = _timed(
                        f"{controller} ({variant}), {m} robots",
                        lambda c=controller, m=m, v=variant: robots_row(c, m, 7, episodes, v),
                        errors,
                    )
        report["robots"] = robots

    if "dmpc_updates" in sections:
        print("DMPC update rules x serial/threads, 7 humans, circle", file=sys.stderr)
        import dmpc_scaling

        rules = ("jacobi:regret", "sequential_accept:no_improvement") if quick else dmpc_scaling.RULES
        episodes = 1 if quick else 2
        updates: dict[str, Any] = {}
        for m in robots_scale:
            for rule in rules:
                cell = _timed(
                    f"{m} robots, {rule}", lambda m=m, r=rule: dmpc_update_cell(m, 7, r, episodes), errors
                )
                if cell:
                    rows = cell["rows"]
                    if "serial" in rows and "threads" in rows:
                        cell["speedup_median"] = rows["serial"]["median_ms"] / rows["threads"]["median_ms"]
                updates[f"r{m} {rule}"] = cell
        report["dmpc_updates"] = updates

    if "ibr" in sections:
        print("CMPC step against its floor, social_lstm_eth, 7 humans", file=sys.stderr)
        import ibr_solves

        episodes = 1 if quick else 4
        report["ibr"] = {
            f"jit {jit}": _timed(
                f"jit {jit}",
                lambda on=(jit == "on"): ibr_solves.measure(PAPER_PREDICTOR, 7, episodes, on),
                errors,
            )
            for jit in ("off", "on")
        }
    report["errors"] = errors
    return report


# ----------------------------------------------------------------------------------------------------------
# Printing
# ----------------------------------------------------------------------------------------------------------


def _row(label: str, stats: dict[str, Any] | None) -> str:
    if not stats:
        return f"| {label} | failed | | |"
    extra = f"{stats['iterations_mean']:.2f}" if "iterations_mean" in stats else ""
    return f"| {label} | {stats['median_ms']:.2f} | {stats['p95_ms']:.2f} | {extra} |"


def table(report: dict[str, Any]) -> str:
    lines = [
        f"machine: {report['machine']['cpus']} CPUs, load {report['machine']['load_average']}, "
        f"python {report['machine']['python']}",
        "",
        "| what | median ms | p95 ms | IBR iterations |",
        "|---|---|---|---|",
    ]
    for key, stats in report.get("simulator_step", {}).items():
        lines.append(_row(f"simulator step {key}", stats))
    for key, stats in report.get("control_step", {}).items():
        lines.append(_row(f"control step {key} (7 humans)", stats))
    for key, stats in report.get("scaling", {}).items():
        lines.append(_row(f"control step {key}", stats))
    for key, row in report.get("dmpc_parallel", {}).items():
        for mode in ("serial", "threads"):
            lines.append(_row(f"dmpc {key} {mode}", row.get(mode)))
        if "speedup_median" in row:
            lines.append(f"| dmpc {key} threads speed-up (median) | x{row['speedup_median']:.2f} | | |")
    for key, row in report.get("robots", {}).items():
        label = f"control step robots {key}"
        if row:
            label += (
                f" ({row['formation']}, {row['episodes']} ep, success {row['success_rate']:.0f}%, "
                f"collision {row['collision_rate']:.0f}%, fallbacks {row['fallback_steps']}/{row['steps']})"
            )
        lines.append(_row(label, row))
    for key, cell in report.get("dmpc_updates", {}).items():
        if not cell:
            lines.append(_row(f"dmpc {key}", None))
            continue
        for mode, stats in cell["rows"].items():
            lines.append(_row(f"dmpc {key} {mode}", stats))
        if "speedup_median" in cell:
            lines.append(
                f"| dmpc {key} threads speed-up (median; same trajectories: {cell['same']}) | "
                f"x{cell['speedup_median']:.2f} | | |"
            )
    for key, row in report.get("ibr", {}).items():
        if not row:
            lines.append(_row(f"cmpc step split, {key}", None))
            continue
        lines.append(
            f"| cmpc step, {key}: first solve {row['first_solve_ms']:.2f} ms, later solves "
            f"{row['later_solves_ms']:.2f} ms, predictor {row['encode_ms'] + row['twin_ms']:.2f} ms, step / "
            f"first solve {row['step_over_first']:.2f} ({row['bound_over_first']:.2f} without bookkeeping) "
            f"| {row['step_ms']:.2f} | | |"
        )
    exported = report.get("export")
    if exported:
        lines += [
            "",
            "| exported predictor (7 humans, 3 robots, H=4) | export s | value err | jac err | IBR ms/call "
            "| NLP step median ms |",
            "|---|---|---|---|---|---|",
        ]
        for model, rows in exported.items():
            if not rows:
                lines.append(f"| {model} | failed | | | | |")
                continue
            for twin, r in rows.items():
                lines.append(
                    f"| {model} {twin} | {r['export_s']:.3f} | {r['value_err']:.1e} | {r['jac_err']:.1e} | "
                    f"{r['ibr_ms']:.3f} | {r['nlp_ms']:.2f} |"
                )
            if "exported" in rows and "hand-written" in rows:
                e, h = rows["exported"], rows["hand-written"]
                lines.append(
                    f"| {model} ratio exported / hand-written (target <= 1.5) | | | | "
                    f"{e['ibr_ms'] / h['ibr_ms']:.2f} | {e['nlp_ms'] / h['nlp_ms']:.2f} |"
                )
    episodes = report.get("episodes_per_minute")
    if episodes:
        lines += ["", "| episodes per minute (one process: 7 humans; sweep: 5-9) | value |", "|---|---|"]
        for name, stats in episodes["one_process"].items():
            value = f"{stats['episodes_per_minute']:.1f}" if stats else "failed"
            lines.append(f"| {name}, one process | {value} |")
        sweep = episodes.get("sweep")
        if sweep:
            lines.append(
                f"| table2 sweep, {sweep['workers']} workers (CMPC+DMPC) | "
                f"{sweep['steady_episodes_per_minute']:.1f} "
                f"({sweep['episodes_per_minute']:.1f} with {sweep['startup_s']:.1f} s start-up) |"
            )
            lines.append(
                f"| projected full Table II (10 x 1000 episodes) from the sweep's rate (in a short sweep, "
                f"mostly the one-off jit builds) | "
                f"{sweep['projected_table2_hours']:.2f} h |"
            )
            lines.append(
                f"| table2 sweep, CPU per episode once the NLPs are built (jit {sweep['jit']}) | "
                f"{sweep['steady_cpu_s_per_episode']:.3f} s |"
            )
            lines.append(
                f"| projected full Table II from that CPU time, {sweep['workers']} workers | "
                f"{sweep['projected_table2_hours_from_cpu']:.2f} h |"
            )
        floor = episodes.get("casadi_floor")
        if floor:
            lines.append(
                f"| table2 episode inline (sweep_floor.py), {floor['episode_ms']:.0f} ms: share in CasADi "
                f"(solves, predictor, statistics) | {100 * floor['casadi_share']:.1f} % |"
            )
            lines.append(
                f"| projected full Table II with no Python at all, {floor['workers']} workers (at this "
                f"rate: {floor['table2_min']:.1f} min) | {floor['table2_min_without_python'] / 60:.2f} h |"
            )
        projected = episodes.get("projected_table2_hours_from_one_process")
        if projected is not None:
            lines.append(
                f"| projected full Table II from the one-process rates, {report['settings']['workers']} "
                f"workers | {projected:.2f} h |"
            )
    if report["errors"]:
        lines += ["", "not measured: " + "; ".join(f"{k}: {v}" for k, v in report["errors"].items())]
    return "\n".join(lines)


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
        type=lambda s: tuple(s.split(",")),
        default=SECTIONS,
        help=f"subset of {','.join(SECTIONS)}",
    )
    parser.add_argument("--json", type=Path, help="also write the JSON here")
    args = parser.parse_args(argv)
    unknown = set(args.sections) - set(SECTIONS)
    if unknown:
        parser.error(f"unknown sections {sorted(unknown)}; choose from {list(SECTIONS)}")
    report = run(args)
    print(table(report))
    text = json.dumps(report, indent=1)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
