"""Tables over runs of recordings: one row per run with crowdsim's rates over the runs whose episode ended
and the control step's costs pooled over every recorded step (``aggregate_table``), and one row per set-up
of a folder (``setups_table``). One run's summary and the A/B comparison are pipelines.logs.review."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np

from pipelines.logs.ending import ends_count, ends_text
from pipelines.logs.review import count, fmt, text_table
from pipelines.loop.record import step_time_stats

_RUN_COLUMNS: Final = ("success", "collision", "timeout", "travel_time", "min_distance")
# Each column's header: the metric's name, then its unit as the table's "median ms" and table.md's
# "Average travel time (s)" give theirs; the flags are yes or no.
_RUN_HEADERS: Final = ("success", "collision", "timeout", "travel_time s", "min_distance m")


def aggregate_table(
    summaries: Sequence[dict[str, Any]], solve_times_s: Sequence[np.ndarray], root: Path | None = None
) -> tuple[str, dict[str, Any]]:
    """One row per run, then crowdsim's rates over the runs whose episode ended, and the control-step costs
    pooled over every recorded step: ``summaries`` are the runs' ``summarize``, ``solve_times_s`` their
    steps' times (``pipelines.logs.digest``). Runs are named by their path below ``root`` (a sweep's cells
    hold files of the same names), else by their file's name."""
    header = [
        "file",
        "controller",
        "predictor",
        *_RUN_HEADERS,
        "ended",  # what ended it: the timeout column is the metric, not success
        "median ms",
        "p95 ms",
        "fallbacks",
        "truncated",
    ]
    rows = [
        [
            str(Path(s["file"]).relative_to(root)) if root is not None else Path(s["file"]).name,
            s["controller"],
            s["predictor"],
            *((s["metrics"] or {}).get(c) for c in _RUN_COLUMNS),
            s.get("ended_by"),
            s["solver"].get("median_ms"),
            s["solver"].get("p95_ms"),
            sum(s["solver"].get("fallbacks", {}).values()),
            s["truncated"],
        ]
        for s in summaries
    ]
    ended = [s for s in summaries if s["metrics"] is not None]
    totals: dict[str, Any] = {"runs": len(summaries), "ended": len(ended)}
    if ended:
        rates, unusable = _aggregate_metrics([s["metrics"] for s in ended])
        totals.update(rates)
        if unusable:
            totals["unusable_metrics"] = [ended[i]["file"] for i in unusable]
        if "episodes" in totals:  # the rates' episodes: what ended those that the timeout rate counts
            totals["ends"] = ends_count([s for i, s in enumerate(ended) if i not in unusable])
    times = np.concatenate([np.zeros(0), *solve_times_s])
    if times.size:
        totals.update({f"solve_time_{k}": v for k, v in step_time_stats(times).items()})
        # a summary counts its fallbacks by kind over the same /mpc/solver messages
        fallbacks = sum(sum(s["solver"].get("fallbacks", {}).values()) for s in summaries)
        totals.update(control_steps=len(times), fallback_steps=fallbacks)
    return text_table(header, rows) + "\n\n" + _format_totals(totals), totals


def setups_table(names: Sequence[str], totals: Sequence[dict[str, Any]]) -> str:
    """One row per set-up of a folder: its runs, the rates over those whose episode ended (robot contact is
    two robots touching, not in the paper), travel time and the closest approach to a human, and the
    control step's median and p95; "-" where a set-up has none."""

    def rate(t: dict[str, Any], name: str) -> str:
        if "episodes" not in t:
            return "-"
        if t.get(f"{name}_rate") is None:  # a figure added later, which some run's metrics predate
            return "n/a"
        return f"{t[f'{name}_rate']:.1f} ({t[f'{name}_count']}/{t['episodes']})"

    # "smallest", "all steps": table.md gives the median of the episodes' minima and of their medians
    header = [
        "set-up",
        "runs",
        "success %",
        "collision %",
        "contact %",
        "robot contact %",
        "mean travel time s",
    ]
    header += ["smallest distance m", *(f"step {k} ms (all steps)" for k in ("median", "p95"))]
    rows = [
        [
            name,
            t["runs"],
            *(rate(t, k) for k in ("success", "collision", "contact", "robot_contact")),
            t.get("travel_time_mean"),
            t.get("min_distance_min"),
            *(
                None if "control_steps" not in t else t[f"solve_time_{k}_ms"]  # the table rounds
                for k in ("median", "p95")
            ),
        ]
        for name, t in zip(names, totals, strict=True)
    ]
    return text_table(header, rows)


def _format_totals(t: dict[str, Any]) -> str:
    lines = [
        count(t["runs"], "run")
        + (
            f", {t['runs'] - t['ended']} whose episode did not end (no metrics)"
            if t["ended"] < t["runs"]
            else ""
        )
        + (
            f", {len(t['unusable_metrics'])} with metrics of another format (left out of the rates)"
            if t.get("unusable_metrics")
            else ""
        )
    ]
    if "episodes" in t:
        n = t["episodes"]
        rates = ", ".join(
            f"{name} {t[f'{name}_rate']:.1f} % ({t[f'{name}_count']}/{n})"
            for name in ("success", "collision", "contact", "discomfort", "timeout")
        )
        lines += [
            rates,
            ends_text(t["ends"]),
            "between steps (straight motion within each step): "
            + ", ".join(_between_steps_rate(t, name, n) for name in ("collision", "contact")),
            _robot_contact(t, n),
            f"travel time {fmt(t['travel_time_mean'])} s mean over successes "
            f"(std {fmt(t['travel_time_std'])} s); path length {fmt(t['path_length_mean'])} m per robot",
            f"min robot-human distance {fmt(t['min_distance_mean'])} m mean, "
            f"{fmt(t['min_distance_min'])} m min",
        ]
    if "control_steps" in t:
        lines.append(
            f"solve time per control step: median {t['solve_time_median_ms']:.1f} ms, p95 "
            f"{t['solve_time_p95_ms']:.1f} ms, max {t['solve_time_max_ms']:.1f} ms over "
            f"{count(t['control_steps'], 'step')}; fallback steps {t['fallback_steps']}"
        )
    return "\n".join(lines)


def _between_steps_rate(t: dict[str, Any], name: str, n: int) -> str:
    """``collision 5.0 % (1/20)``; n/a when some run's metrics predate the between-step fields."""
    rate, hits = t.get(f"{name}_between_steps_rate"), t.get(f"{name}_between_steps_count")
    if rate is None or hits is None:
        return f"{name} n/a (metrics recorded before the between-step figures)"
    return f"{name} {rate:.1f} % ({hits}/{n})"


def _robot_contact(t: dict[str, Any], n: int) -> str:
    """Robots touching each other (crowdsim.metrics' ``robot_contact``, not a metric of the paper): episodes
    and states, then episodes between steps; n/a when some run's metrics predate the field."""
    rate, hits, states = (t.get(f"robot_contact_{k}") for k in ("rate", "count", "step_freq"))
    figures = (
        "n/a (metrics recorded before it)" if rate is None or hits is None else f"{rate:.1f} % ({hits}/{n})"
    )
    if states is not None:
        figures += f", {states:.2f} % of states"
    rate, hits = (t.get(f"robot_contact_between_steps_{k}") for k in ("rate", "count"))
    if rate is not None and hits is not None:  # absent before the figure existed: nothing to add
        figures += f"; between steps {rate:.1f} % ({hits}/{n})"
    return f"robot-robot contact (two robots touching, not in the paper): {figures}"


def _aggregate_metrics(recorded: list[dict[str, Any]]) -> tuple[dict[str, Any], list[int]]:
    """crowdsim's own aggregate over EpisodeMetrics rebuilt from the recorded dicts (null was NaN or inf;
    recordings from before the per-step counts still aggregate, their frequencies reading n/a), and the
    indices of the records that do not rebuild (written by another version, or not by crowdmpc at all)."""
    from crowdsim.errors import SimulationError
    from crowdsim.metrics import EpisodeMetrics, aggregate

    rebuilt, unusable = [], []
    for i, record in enumerate(recorded):
        try:
            metrics = EpisodeMetrics.from_dict(record)
            aggregate([metrics])  # its values are of the types the aggregate adds up
        except (SimulationError, TypeError, ValueError, AttributeError):
            unusable.append(i)
        else:
            rebuilt.append(metrics)
    if not rebuilt:
        return {}, unusable
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in aggregate(rebuilt).items()
    }, unusable
