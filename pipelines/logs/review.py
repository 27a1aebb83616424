"""Reviewing episode recordings as text: one run's summary and A/B comparison (the tables over runs and over
a folder's set-ups: pipelines.logs.run_tables).

The summary takes the solver statistics from the per-step ``/mpc/solver`` messages rather than from
``/episode/metrics``, so that a truncated file (whose episode never ended) still reports them; the rates over
runs are crowdsim's own aggregate, over the runs whose episode ended. The schema check of a recording
(``--check``) is pipelines.logs.schema_check.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Iterable, Sequence
from datetime import UTC, datetime
from typing import Any

import numpy as np

from pipelines.logs.ending import ended_by, metric_rows, metric_shown
from pipelines.logs.identity import differing_settings, null_none, recorded_plugins, shown
from pipelines.logs.reader import Recording
from pipelines.loop.record import step_time_stats
from pipelines.version import dirty_text


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
    code = rec.metadata.get("crowdmpc", {})
    metrics_messages = rec.data("/episode/metrics")
    metrics = metrics_messages[-1]["metrics"] if metrics_messages else None
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
        "crowdmpc_version": code.get("version"),
        # the commit that recorded it ("null" for a copy without git history; absent in older recordings)
        "crowdmpc_commit": code.get("commit"),
        # recorded from a tree with uncommitted changes: the commit alone does not name its code
        "crowdmpc_dirty": {"true": True, "false": False}.get(code.get("dirty", "")),
        # which uncommitted changes (the sha256 of their diff; "null" when clean, absent in older recordings)
        "crowdmpc_diff_sha256": null_none(code.get("diff_sha256")),
        # the plugins' code (module:Class -> its file's sha256); None without plugins and in older recordings
        "crowdmpc_plugins": recorded_plugins(code.get("plugins")),
        "states": len(robots),
        "sim_time_s": robots[-1]["time"] if robots else 0.0,
        "started": _wall_clock(rec.start_time_ns),
        "metrics": metrics,
        # what ended it (pipelines.logs.ending): the metrics' timeout is "not success", whatever ended it
        "ended_by": ended_by(rec, metrics),
        "solver": _solver_stats(rec),
        "messages": {topic: len(msgs) for topic, msgs in sorted(rec.messages.items())},
        "truncated": rec.truncated,
        "warning": rec.warning,
        "problems": rec.problems + rec.message_problems(),
    }


def _wall_clock(ns: int) -> str | None:
    """ISO 8601 UTC time of a wall-clock log time; None for 0 (files whose log times start at 0)."""
    if ns <= 0:
        return None
    return datetime.fromtimestamp(ns / 1e9, UTC).isoformat(timespec="seconds")


def fmt(value: Any) -> str:
    """A value as the summary and the tables print it: "-" for None, yes or no, floats to three digits."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return _fmt_float(value)
    if isinstance(value, list):
        return "[" + ", ".join(fmt(v) for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k} {v}" for k, v in value.items()) or "-"
    return str(value)


def _fmt_float(value: float) -> str:
    """Three significant digits in fixed point, trailing zeros kept: "1.00" m, "16.0" s, "0.992" m, "1234" ms
    (``:.3g`` printed a robot 1.004 m away as "1" m, a 16.0 s travel as "16" and 1234 ms as "1.23e+03")."""
    if not math.isfinite(value) or abs(value) < 1e-3:  # inf, nan, 0 and the tiny as :.3g says them
        return f"{value:.3g}"
    return f"{value:.{max(0, 2 - math.floor(math.log10(abs(value))))}f}"


def count(n: Any, noun: str) -> str:
    """``n noun`` with the noun plural unless n is 1 ("1 run", "2 runs"; "-" for an unknown n)."""
    return f"{fmt(n)} {noun}" + ("" if str(n) == "1" else "s")


def commit_shown(summary: dict[str, Any]) -> str | None:
    """The recording's commit as ``crowdmpc compare`` names code ("c28989d46c28+dirty": recorded from a tree
    with uncommitted changes, which the commit alone does not name); None where it names none."""
    commit = summary.get("crowdmpc_commit")
    if commit in (None, "", "null"):
        return None
    return str(commit)[:12] + dirty_text(summary.get("crowdmpc_dirty"), summary.get("crowdmpc_diff_sha256"))


def plugins_shown(summary: dict[str, Any]) -> str:
    """The recorded plugins' code: "module:Class 0123456789ab, ..." (their files' sha256), "" for none."""
    return ", ".join(
        f"{spec} {str(sha)[:12]}" for spec, sha in (summary.get("crowdmpc_plugins") or {}).items()
    )


def _code(summary: dict[str, Any]) -> str:
    """The version, the commit when the recording names one, and the plugins' files."""
    named, plugins = commit_shown(summary), plugins_shown(summary)
    shown = f"{fmt(summary['crowdmpc_version'])}" + (f" (commit {named})" if named else "")
    return shown + (f", plugins {plugins}" if plugins else "")


def format_summary(summary: dict[str, Any]) -> str:
    s = summary["solver"]
    rows: list[tuple[str, Any]] = [
        ("file", summary["file"]),
        ("scenario", f"{fmt(summary['scenario'])} (seed {fmt(summary['seed'])})"),
        ("agents", f"{count(summary['n_robots'], 'robot')}, {count(summary['n_humans'], 'human')}"),
        ("controller", summary["controller"]),
        ("predictor", summary["predictor"]),
        ("predictor sha256", summary["predictor_sha256"]),
        ("crowdmpc", _code(summary)),
        ("recorded", f"{summary['states']} states, {summary['sim_time_s']:.1f} s simulated"),
        ("started", summary["started"]),
    ]
    metrics = summary["metrics"]
    if metrics is None:
        rows.append(("metrics", "missing (the episode did not end in this file)"))
    else:
        rows += metric_rows(summary)
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
    if summary["problems"]:
        rows.append(
            ("problems", f"{len(summary['problems'])}, left out of this summary (--check lists them)")
        )
    # the full warning goes to stderr (crowdmpc review); the summary says it in a word
    rows.append(("truncated", "YES: read up to its last complete chunk" if summary["truncated"] else "no"))
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k.ljust(width)}  {fmt(v)}" for k, v in rows)


def text_table(header: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    from predictors.text_table import aligned_lines

    return "\n".join(aligned_lines(header, [[fmt(v) for v in row] for row in rows], numbers_right=False))


def compare_table(a: Recording, b: Recording) -> str:
    sa, sb = summarize(a), summarize(b)
    ma, mb = sa["metrics"] or {}, sb["metrics"] or {}
    rows: list[list[Any]] = [
        ["controller", sa["controller"], sb["controller"]],
        ["predictor", sa["predictor"], sb["predictor"]],
        ["scenario", f"{sa['scenario']} {sa['seed']}", f"{sb['scenario']} {sb['seed']}"],
        ["crowdmpc", _code(sa), _code(sb)],  # a run before an upgrade beside one after it: which is which
    ]
    rows += [[key, shown(va), shown(vb)] for key, va, vb in differing_settings(a, b)]
    rows.append(["ended", sa["ended_by"], sb["ended_by"]])
    for k in dict.fromkeys([*ma, *mb]):  # a contact's timeout worded as the single summary words it
        rows.append(
            [k, metric_shown(k, ma.get(k), sa["ended_by"]), metric_shown(k, mb.get(k), sb["ended_by"])]
        )
    for key in ("median_ms", "p95_ms", "max_ms", "mean_iterations"):
        rows.append([key, sa["solver"].get(key), sb["solver"].get(key)])
    rows.append(["fallbacks", sa["solver"].get("fallbacks"), sb["solver"].get("fallbacks")])
    rows.append(["truncated", sa["truncated"], sb["truncated"]])
    name_a, name_b = compare_names(a, b)
    return text_table(["", f"A: {name_a}", f"B: {name_b}"], rows)


def compare_names(a: Recording, b: Recording) -> tuple[str, str]:
    """The two files by name, or, where the names are the same (one scene and seed recorded by two runs into
    two folders, the usual comparison), by their paths from the folder they share: both columns read
    "A: circle_seed000000.mcap" and "B: circle_seed000000.mcap" before."""
    if a.path.name != b.path.name:
        return a.path.name, b.path.name
    pa, pb = a.path.resolve(), b.path.resolve()
    shared = len(os.path.commonpath([pa, pb]).rstrip(os.sep)) + 1 if pa.anchor == pb.anchor else 0
    return str(pa)[shared:] or str(a.path), str(pb)[shared:] or str(b.path)
