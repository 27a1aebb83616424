"""benchmarks/run_all.py's report as Markdown tables: step times, then the exported predictors, then the
episode rates and Table II projections, then what could not be measured."""

from __future__ import annotations

import math
from typing import Any


def table(report: dict[str, Any]) -> str:
    lines = [
        f"machine: {report['machine']['cpus']} CPUs, load {report['machine']['load_average']}, "
        f"python {report['machine']['python']}",
    ]
    steps = _step_rows(report) + _formation_rows(report)
    if steps:  # none when only the export or episode sections ran
        lines += ["", "| what | median ms | p95 ms | IBR iterations |", "|---|---|---|---|", *steps]
    if report.get("export"):
        lines += _export_rows(report["export"])
    if report.get("episodes_per_minute"):
        lines += _episode_rows(report["episodes_per_minute"], report["settings"]["workers"])
    if report["errors"]:
        lines += ["", "not measured: " + "; ".join(f"{k}: {v}" for k, v in report["errors"].items())]
    return "\n".join(lines)


def _row(label: str, stats: dict[str, Any] | None) -> str:
    if not stats:
        return f"| {label} | failed | | |"
    extra = f"{stats['iterations_mean']:.2f}" if "iterations_mean" in stats else ""
    return f"| {label} | {stats['median_ms']:.2f} | {stats['p95_ms']:.2f} | {extra} |"


def _step_rows(report: dict[str, Any]) -> list[str]:
    """The simulator's and the controllers' step times, and DMPC's local solves serial and in threads."""
    lines = []
    for key, stats in report.get("simulator_step", {}).items():
        lines.append(_row(f"simulator step {key}", stats))
    for key, stats in report.get("control_step", {}).items():
        # the baselines' and the oracle's rows time the first --steps steps of each episode from rest, the
        # others whole episodes: as in the scaling rows, the count tells the two measurements apart
        steps = f", {stats['steps']} steps" if stats and "steps" in stats else ""
        lines.append(_row(f"control step {key} (7 humans{steps})", stats))
    for key, stats in report.get("scaling", {}).items():
        # the humans' rows time whole episodes, the robots' their first --steps steps from rest: the count
        # tells two rows measured differently apart (46.8 ms over 2 steps beside 3.8 ms over 38)
        steps = f" ({stats['steps']} steps)" if stats and "steps" in stats else ""
        lines.append(_row(f"control step {key}{steps}", stats))
    for key, row in report.get("dmpc_parallel", {}).items():
        for mode in ("serial", "threads"):
            lines.append(_row(f"dmpc {key} {mode}", row.get(mode)))
        if "speedup_median" in row:
            lines.append(f"| dmpc {key} threads speed-up (median) | x{row['speedup_median']:.2f} | | |")
    return lines


def _formation_rows(report: dict[str, Any]) -> list[str]:
    """Robots in formation, DMPC's update rules, and CMPC's step against its floor."""
    lines = []
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
            # dmpc_scaling.same_before_limit compared these episodes only up to a step past the time limit
            cut = f", {cell['cut']} episodes up to a step past the time limit" if cell.get("cut") else ""
            lines.append(
                f"| dmpc {key} threads speed-up (median; same trajectories: {cell['same']}{cut}) | "
                f"x{cell['speedup_median']:.2f} | | |"
            )
    for key, row in report.get("ibr", {}).items():
        if not row:
            lines.append(_row(f"cmpc step split, {key}", None))
            continue
        lines.append(
            f"| cmpc step, {key}: first solve {row['first_solve_ms']:.2f} ms, later solves "
            f"{row['later_solves_ms']:.2f} ms, predictor {row['encode_ms'] + row['twin_ms']:.2f} ms; median "
            f"step / median first solve {row['step_median_over_first_median']:.2f}; median of per-step (step "
            f"/ first solve) {row['step_over_first']:.2f} ({row['bound_over_first']:.2f} without "
            f"bookkeeping) | {row['step_ms']:.2f} | | |"
        )
    return lines


def _ms(value: float, spec: str) -> str:
    """A figure, or why there is none: --quick runs no closed-loop episode of the coupled NLP."""
    return format(value, spec) if math.isfinite(value) else "not run (--quick)"


def _checked(error: float) -> str:
    """A parity error, or "-" where none is checked (the hand-written twins' Jacobians)."""
    return f"{error:.1e}" if math.isfinite(error) else "-"


def _export_rows(exported: dict[str, Any]) -> list[str]:
    lines = [
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
                f"| {model} {twin} | {r['export_s']:.3f} | {r['value_err']:.1e} | {_checked(r['jac_err'])} | "
                f"{r['ibr_ms']:.3f} | {_ms(r['nlp_ms'], '.2f')} |"
            )
        if "exported" in rows and "hand-written" in rows:
            e, h = rows["exported"], rows["hand-written"]
            lines.append(
                f"| {model} ratio exported / hand-written (target <= 1.5) | | | | "
                f"{e['ibr_ms'] / h['ibr_ms']:.2f} | {_ms(e['nlp_ms'] / h['nlp_ms'], '.2f')} |"
            )
    return lines


def _episode_rows(episodes: dict[str, Any], workers: int) -> list[str]:
    """Episodes per minute, and the full Table II projected from each measurement."""
    lines = ["", "| episodes per minute (one process: 7 humans; sweep: 5-9) | value |", "|---|---|"]
    for name, stats in episodes["one_process"].items():
        value = f"{stats['episodes_per_minute']:.1f}" if stats else "failed"
        lines.append(f"| {name}, one process | {value} |")
    sweep = episodes.get("sweep")
    if sweep:
        lines += [
            f"| table2 sweep, {sweep['workers']} workers (CMPC+DMPC) | "
            f"{sweep['steady_episodes_per_minute']:.1f} "
            f"({sweep['episodes_per_minute']:.1f} with {sweep['startup_s']:.1f} s start-up) |",
            f"| projected full Table II (10 x 1000 episodes) from the sweep's rate (in a short sweep, "
            f"mostly the one-off jit builds) | {sweep['projected_table2_hours']:.2f} h |",
        ]
        if math.isfinite(sweep["steady_cpu_s_per_episode"]):
            lines += [
                f"| table2 sweep, CPU per episode once the NLPs are built (jit {sweep['jit']}) | "
                f"{sweep['steady_cpu_s_per_episode']:.3f} s |",
                f"| projected full Table II from that CPU time, {sweep['workers']} workers | "
                f"{sweep['projected_table2_hours_from_cpu']:.2f} h |",
            ]
        else:  # each worker's first episode of a cell builds the NLPs and is left out
            lines.append(
                "| table2 sweep, CPU per episode once the NLPs are built | not measured: each episode was "
                "its worker's first of a cell (more --sweep-episodes) |"
            )
    floor = episodes.get("casadi_floor")
    if floor:
        lines += [
            f"| table2 episode inline (sweep_floor.py), {floor['episode_ms']:.0f} ms: share in CasADi "
            f"(solves, predictor, statistics) | {100 * floor['casadi_share']:.1f} % |",
            f"| projected full Table II with no Python at all, {floor['workers']} workers (at this "
            f"rate: {floor['table2_min']:.1f} min) | {floor['table2_min_without_python'] / 60:.2f} h |",
        ]
    projected = episodes.get("projected_table2_hours_from_one_process")
    if projected is not None:
        lines.append(
            f"| projected full Table II from the one-process rates, {workers} workers | {projected:.2f} h |"
        )
    return lines


if __name__ == "__main__":
    raise SystemExit("run_all_table.py holds benchmarks/run_all.py's tables; run benchmarks/run_all.py")
