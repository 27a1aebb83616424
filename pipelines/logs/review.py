"""Reviewing episode recordings as text: one run's summary, a table over runs, A/B comparison, schema check.

The summary takes the solver statistics from the per-step ``/mpc/solver`` messages rather than from
``/episode/metrics``, so that a truncated file (whose episode never ended) still reports them; the rates over
runs are crowdsim's own aggregate, over the runs whose episode ended. The check validates each message
against the schema stored in the file, not the one this version of crowdmpc would write.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np

from pipelines.errors import PipelineError
from pipelines.logs.jsonschema import unsupported_keywords, validate
from pipelines.logs.reader import Recording
from pipelines.logs.schemas import MESSAGE_ENCODING, SCHEMA_ENCODING
from pipelines.loop.episode import step_time_stats

# ------------------------------------------------------------------------------------------------------------
# summary
# ------------------------------------------------------------------------------------------------------------


def _solver_stats(rec: Recording) -> dict[str, Any]:
    """From the per-step solver messages, so that a truncated file (no /episode/metrics) still has them."""
    solver = rec.data("/mpc/solver")
    if not solver:
        return {"steps": 0}
    iterations = np.array([s["iterations"] for s in solver], dtype=float)
    potentials = [s["potential"] for s in solver if s["potential"] is not None]
    return {
        "steps": len(solver),
        **step_time_stats([s["solve_time_s"] for s in solver]),
        "mean_iterations": float(iterations.mean()),
        "max_iterations": int(iterations.max()),
        "statuses": dict(Counter(s["status"] for s in solver)),
        "fallbacks": dict(Counter(s["fallback"] for s in solver if s["fallback"] is not None)),
        "final_potential": potentials[-1] if potentials else None,
    }


def summarize(rec: Recording) -> dict[str, Any]:
    ep = rec.episode()
    metrics_messages = rec.data("/episode/metrics")
    robots = rec.data("/robots")
    return {
        "file": str(rec.path),
        "scenario": ep.get("scenario"),
        "seed": int(ep["seed"]) if "seed" in ep else None,
        "controller": ep.get("controller"),
        "predictor": ep.get("predictor") or None,
        "predictor_sha256": ep.get("predictor_sha256") or None,
        "n_robots": int(ep["n_robots"]) if "n_robots" in ep else None,
        "n_humans": int(ep["n_humans"]) if "n_humans" in ep else None,
        "crowdmpc_version": rec.metadata.get("crowdmpc", {}).get("version"),
        "states": len(robots),
        "sim_time_s": robots[-1]["time"] if robots else 0.0,
        "metrics": metrics_messages[-1]["metrics"] if metrics_messages else None,
        "solver": _solver_stats(rec),
        "messages": {topic: len(msgs) for topic, msgs in sorted(rec.messages.items())},
        "truncated": rec.truncated,
        "warning": rec.warning,
    }


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 1e4 else f"{value:.4g}"
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k} {v}" for k, v in value.items()) or "-"
    return str(value)


def format_summary(summary: dict[str, Any]) -> str:
    s = summary["solver"]
    rows: list[tuple[str, Any]] = [
        ("file", summary["file"]),
        ("scenario", f"{_fmt(summary['scenario'])} (seed {_fmt(summary['seed'])})"),
        ("agents", f"{_fmt(summary['n_robots'])} robots, {_fmt(summary['n_humans'])} humans"),
        ("controller", summary["controller"]),
        ("predictor", summary["predictor"]),
        ("predictor sha256", summary["predictor_sha256"]),
        ("crowdmpc", summary["crowdmpc_version"]),
        ("recorded", f"{summary['states']} states, {summary['sim_time_s']:.1f} s simulated"),
    ]
    metrics = summary["metrics"]
    if metrics is None:
        rows.append(("metrics", "missing (the episode did not end in this file)"))
    else:
        rows.extend((f"  {name}", value) for name, value in metrics.items())
    if s["steps"]:
        rows += [
            (
                "solve time",
                f"median {s['median_ms']:.1f} ms, p95 {s['p95_ms']:.1f} ms, max {s['max_ms']:.1f} ms",
            ),
            ("IBR iterations", f"mean {s['mean_iterations']:.2f}, max {s['max_iterations']}"),
            ("statuses", s["statuses"]),
            ("fallbacks", s["fallbacks"] or "none"),
            ("final potential", s["final_potential"]),
        ]
    rows.append(("messages", summary["messages"]))
    # the full warning goes to stderr (crowdmpc review); the summary says it in a word
    rows.append(("truncated", "YES: read up to its last complete chunk" if summary["truncated"] else "no"))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k.ljust(width)}  {_fmt(v)}" for k, v in rows)


def _table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    cells = [list(header)] + [[_fmt(v) for v in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip() for row in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


_RUN_COLUMNS: Final = ("success", "collision", "timeout", "travel_time", "min_distance")


def aggregate_table(recordings: list[Recording]) -> tuple[str, dict[str, Any]]:
    """One row per run, then crowdsim's rates over the runs whose episode ended, and the control-step costs
    pooled over every recorded step."""
    summaries = [summarize(rec) for rec in recordings]
    header = [
        "file",
        "controller",
        "predictor",
        *_RUN_COLUMNS,
        "median ms",
        "p95 ms",
        "fallbacks",
        "truncated",
    ]
    rows = [
        [
            Path(s["file"]).name,
            s["controller"],
            s["predictor"],
            *((s["metrics"] or {}).get(c) for c in _RUN_COLUMNS),
            s["solver"].get("median_ms"),
            s["solver"].get("p95_ms"),
            sum(s["solver"].get("fallbacks", {}).values()),
            s["truncated"],
        ]
        for s in summaries
    ]
    ended = [s["metrics"] for s in summaries if s["metrics"] is not None]
    totals: dict[str, Any] = {"runs": len(summaries), "ended": len(ended)}
    if ended:
        totals.update(_aggregate_metrics(ended))
    solver = [m for rec in recordings for m in rec.data("/mpc/solver")]
    if solver:
        times = step_time_stats([m["solve_time_s"] for m in solver])
        totals.update({f"solve_time_{k}": v for k, v in times.items()})
        totals.update(
            control_steps=len(solver), fallback_steps=sum(m["fallback"] is not None for m in solver)
        )
    return _table(header, rows) + "\n\n" + _format_totals(totals), totals


def _format_totals(t: dict[str, Any]) -> str:
    lines = [
        f"{t['runs']} runs"
        + (f", {t['runs'] - t['ended']} truncated (no metrics)" if t["ended"] < t["runs"] else "")
    ]
    if t["ended"]:
        n = t["episodes"]
        rates = ", ".join(
            f"{name} {t[f'{name}_rate']:.1f} % ({t[f'{name}_count']}/{n})"
            for name in ("success", "collision", "contact", "discomfort", "timeout")
        )
        lines += [
            rates,
            f"travel time {_fmt(t['travel_time_mean'])} s mean over successes "
            f"(std {_fmt(t['travel_time_std'])} s); path length {_fmt(t['path_length_mean'])} m per robot",
            f"min robot-human distance {_fmt(t['min_distance_mean'])} m mean, "
            f"{_fmt(t['min_distance_min'])} m min",
        ]
    if "control_steps" in t:
        lines.append(
            f"solve time per control step: median {t['solve_time_median_ms']:.1f} ms, p95 "
            f"{t['solve_time_p95_ms']:.1f} ms, max {t['solve_time_max_ms']:.1f} ms over {t['control_steps']} "
            f"steps; fallback steps {t['fallback_steps']}"
        )
    return "\n".join(lines)


def _aggregate_metrics(recorded: list[dict[str, Any]]) -> dict[str, Any]:
    """crowdsim's own aggregate over EpisodeMetrics rebuilt from the recorded dicts (null was NaN or inf;
    recordings from before the per-step counts still aggregate, their frequencies reading n/a)."""
    from crowdsim.errors import SimulationError
    from crowdsim.metrics import EpisodeMetrics, aggregate

    try:
        rebuilt = [EpisodeMetrics.from_dict(m) for m in recorded]
    except SimulationError as exc:
        raise PipelineError(f"recorded metrics: {exc}: written by another crowdmpc version?") from None
    return {
        k: (None if isinstance(v, float) and not math.isfinite(v) else v)
        for k, v in aggregate(rebuilt).items()
    }


def compare_table(a: Recording, b: Recording) -> str:
    sa, sb = summarize(a), summarize(b)
    ma, mb = sa["metrics"] or {}, sb["metrics"] or {}
    rows: list[list[Any]] = [
        ["controller", sa["controller"], sb["controller"]],
        ["predictor", sa["predictor"], sb["predictor"]],
        ["scenario", f"{sa['scenario']} {sa['seed']}", f"{sb['scenario']} {sb['seed']}"],
    ]
    rows += [[name, ma.get(name), mb.get(name)] for name in dict.fromkeys([*ma, *mb])]
    for key in ("median_ms", "p95_ms", "max_ms", "mean_iterations"):
        rows.append([key, sa["solver"].get(key), sb["solver"].get(key)])
    rows.append(["fallbacks", sa["solver"].get("fallbacks"), sb["solver"].get("fallbacks")])
    rows.append(["truncated", sa["truncated"], sb["truncated"]])
    return _table(["", f"A: {a.path.name}", f"B: {b.path.name}"], rows)


# ------------------------------------------------------------------------------------------------------------
# schema check
# ------------------------------------------------------------------------------------------------------------


def check_recording(rec: Recording) -> tuple[int, list[str]]:
    """Validate every message against its channel's schema as stored in the file: (checked, errors)."""
    errors = list(rec.decode_errors)
    checked = 0
    for topic, channel in rec.channels.items():
        if channel.message_encoding != MESSAGE_ENCODING or channel.schema_encoding != SCHEMA_ENCODING:
            errors.append(
                f"{topic}: encoding {channel.message_encoding!r} / schema {channel.schema_encoding!r}, "
                f"expected {MESSAGE_ENCODING!r} / {SCHEMA_ENCODING!r}"
            )
            continue
        try:
            schema = json.loads(channel.schema_data)
        except ValueError as exc:
            errors.append(f"{topic}: schema {channel.schema_name!r} is not JSON ({exc})")
            continue
        unchecked = unsupported_keywords(schema)
        if unchecked:
            errors.append(
                f"{topic}: schema {channel.schema_name!r} uses keywords not checked here: {unchecked}"
            )
            continue
        for message in rec.messages[topic]:
            if message.data is None:
                continue
            checked += 1
            for problem in validate(message.data, schema):
                errors.append(
                    f"{topic} @ {message.log_time_ns / 1e9:.3f} s ({channel.schema_name}): {problem}"
                )
    return checked, errors
