"""benchmarks/run_all.py's sections: each runs its measurements over the sizes of the run (``--quick``) and
returns its part of the report; ``SECTION_RUNS`` lists them in the order they run."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import sweep_floor

from pipelines.experiments.methods import PAPER_PREDICTOR
from predictors.oracle import ORACLE_PREDICTOR
from predictors.registry import available
from run_all_parts.measurements import (
    any_step,
    dmpc_update_cell,
    episodes_per_minute,
    export_rows,
    mpc_step,
    robots_row,
    simulator_step,
    sweep_rate,
)


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

    from predictors.zoo import zoo_names

    models = ("social_lstm_soft_eth",) if run.quick else zoo_names()  # every zoo model, as export.py
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
            if cell and "speedup" in cell:  # dmpc_scaling.cell_report's, under the key run_all wrote before
                cell["speedup_median"] = cell["speedup"]["step_median"]
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
