"""Reading episode recordings back: summary, plots, animation, comparison and schema check.

Files are read with ``NonSeekingReader(...).iter_messages(log_time_order=False)``, the one way mcap 1.6 reads
a file whose writer was killed: it walks the records front to back and stops where the bytes stop, so a
truncated file yields everything up to its last complete chunk. The seeking reader needs the footer, and
log-time ordering sorts (so reads everything) before yielding anything. A file is truncated when it does not
end with MCAP's magic.
"""

from __future__ import annotations

import json
import math
import shutil
import struct
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader
from mcap.records import Metadata
from mcap.stream_reader import StreamReader

from pipelines.errors import PipelineError
from pipelines.logs.schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, unsupported_keywords, validate
from pipelines.loop.episode import step_time_stats

MAGIC: Final[bytes] = b"\x89MCAP0\r\n"


@dataclass(frozen=True)
class Channel:
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes


@dataclass(frozen=True)
class LoggedMessage:
    log_time_ns: int
    data: Any  # the decoded JSON (None when it did not decode; see Recording.decode_errors)


@dataclass(frozen=True)
class Recording:
    """Everything read from one file."""

    path: Path
    metadata: dict[str, dict[str, str]]  # name -> record (the last one when a name repeats)
    channels: dict[str, Channel]  # topic -> channel
    messages: dict[str, list[LoggedMessage]]  # topic -> messages in file order
    truncated: bool  # the file does not end with MCAP's closing magic
    stopped_at: str | None = None  # what ended reading early (truncated files)
    decode_errors: list[str] = field(default_factory=list)

    @property
    def warning(self) -> str | None:
        if not self.truncated:
            return None
        n = sum(len(v) for v in self.messages.values())
        last = max((m[-1].log_time_ns for m in self.messages.values() if m), default=0) / 1e9
        return (
            f"{self.path} is truncated (the run was killed or is still writing): read {n} messages up to "
            f"t = {last:.1f} s, the last complete chunk; the rest is lost ({self.stopped_at or 'no footer'})"
        )

    def episode(self) -> dict[str, str]:
        return self.metadata.get("episode", {})

    def config(self) -> dict[str, Any]:
        return _decoded(self.metadata.get("config", {}))

    def run_meta(self) -> dict[str, Any]:
        return _decoded(self.metadata.get("run", {}))

    def data(self, topic: str) -> list[Any]:
        return [m.data for m in self.messages.get(topic, ()) if m.data is not None]

    @property
    def label(self) -> str:
        ep = self.episode()
        parts = [ep.get("controller"), ep.get("predictor"), ep.get("scenario"), f"seed {ep.get('seed', '?')}"]
        return " / ".join(p for p in parts if p)


def _decoded(record: dict[str, str]) -> dict[str, Any]:
    """Metadata values are JSON text (pipelines.logs.recording); a value that is not stays a string."""
    out: dict[str, Any] = {}
    for key, text in record.items():
        try:
            out[key] = json.loads(text)
        except ValueError:
            out[key] = text
    return out


# ------------------------------------------------------------------------------------------------------------
# reading
# ------------------------------------------------------------------------------------------------------------


def _ends_with_magic(path: Path) -> bool:
    size = path.stat().st_size
    if size < 2 * len(MAGIC):
        return False
    with open(path, "rb") as f:
        f.seek(size - len(MAGIC))
        return f.read() == MAGIC


def _check_header(path: Path) -> None:
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
    if head != MAGIC:
        raise PipelineError(f"{path} is not an MCAP file (it does not start with MCAP's magic bytes)")


def _stop_reason(exc: BaseException) -> str:
    if isinstance(exc, EndOfFile | struct.error):
        return "the file ends inside a record"
    return f"{type(exc).__name__}: {exc}".rstrip(": ")


def read_recording(path: str | Path) -> Recording:
    """Read every message and metadata record of ``path``; a truncated file reads up to its last chunk."""
    path = Path(path)
    if not path.is_file():
        raise PipelineError(f"{path}: no such recording")
    _check_header(path)
    complete = _ends_with_magic(path)
    stopped_at = None

    metadata: dict[str, dict[str, str]] = {}
    with open(path, "rb") as f:
        # emit_chunks: walk over chunks without decompressing them; metadata records sit between chunks.
        try:
            for record in StreamReader(f, emit_chunks=True).records:
                if isinstance(record, Metadata):
                    metadata[record.name] = dict(record.metadata)
        except Exception as exc:  # noqa: BLE001 (any parse error past a cut; a finished file re-raises)
            if complete:
                raise PipelineError(f"{path} is corrupt: {_stop_reason(exc)}") from exc
            stopped_at = _stop_reason(exc)

    channels: dict[str, Channel] = {}
    messages: dict[str, list[LoggedMessage]] = {}
    decode_errors: list[str] = []
    with open(path, "rb") as f:
        try:
            for schema, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                topic = channel.topic
                if topic not in channels:
                    channels[topic] = Channel(
                        topic,
                        channel.message_encoding,
                        schema.name if schema else "",
                        schema.encoding if schema else "",
                        schema.data if schema else b"",
                    )
                    messages[topic] = []
                try:
                    data = json.loads(message.data)
                except ValueError as exc:
                    data = None
                    decode_errors.append(f"{topic} @ {message.log_time / 1e9:.3f} s: not JSON ({exc})")
                messages[topic].append(LoggedMessage(message.log_time, data))
        except Exception as exc:  # noqa: BLE001 (see above)
            if complete:
                raise PipelineError(f"{path} is corrupt: {_stop_reason(exc)}") from exc
            stopped_at = _stop_reason(exc)
    return Recording(path, metadata, channels, messages, not complete, stopped_at, decode_errors)


def find_recordings(directory: str | Path) -> list[Path]:
    directory = Path(directory)
    paths = sorted(directory.glob("*.mcap"))
    if not paths:
        raise PipelineError(f"no .mcap files in {directory}")
    return paths


# ------------------------------------------------------------------------------------------------------------
# the episode as arrays
# ------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EpisodeView:
    """The recorded states and plans as arrays (state rows are the steps that made it into the file)."""

    times: np.ndarray  # (T,) s
    steps: np.ndarray  # (T,) int
    robot_positions: np.ndarray  # (T, M, 2) m
    human_positions: np.ndarray  # (T, N, 2) m
    robot_goals: np.ndarray  # (M, 2) m
    human_goals: np.ndarray  # (N, 2) m
    plans: dict[int, np.ndarray]  # step -> (M, H, 2) m
    predictions: dict[int, np.ndarray]  # step -> (H, N, 2) m
    dt: float  # s
    radius: float  # m

    def row_at(self, t: float) -> int:
        """Index of the recorded state nearest to time ``t`` (s)."""
        return int(np.argmin(np.abs(self.times - t)))


def _points(rows: list[Any], n: int) -> np.ndarray:
    return np.asarray(rows, dtype=float).reshape(n, 2)


def episode_view(rec: Recording) -> EpisodeView:
    humans = rec.data("/humans")
    by_step = {h["step"]: h for h in humans}
    robots = [r for r in rec.data("/robots") if r["step"] in by_step]  # a cut can fall between the two
    if not robots:
        raise PipelineError(f"{rec.path} holds no complete state (/robots and /humans) to draw")
    steps = [r["step"] for r in robots]
    m, n = len(robots[0]["positions"]), len(humans[0]["positions"])
    ep = rec.episode()
    times = np.array([r["time"] for r in robots], dtype=float)
    dt = float(ep["dt"]) if "dt" in ep else float(np.median(np.diff(times))) if len(times) > 1 else 0.4
    return EpisodeView(
        times=times,
        steps=np.array(steps, dtype=int),
        robot_positions=np.array([_points(r["positions"], m) for r in robots]),
        human_positions=np.array([_points(by_step[s]["positions"], n) for s in steps]).reshape(
            len(steps), n, 2
        ),
        robot_goals=_points(robots[0]["goals"], m),
        human_goals=_points(humans[0]["goals"], n),
        plans={p["step"]: np.asarray(p["positions"], dtype=float) for p in rec.data("/mpc/plan")},
        predictions={
            p["step"]: np.asarray(p["positions"], dtype=float).reshape(-1, n, 2)
            for p in rec.data("/mpc/prediction")
        },
        dt=dt,
        radius=float(ep.get("radius", 0.3)),
    )


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


# ------------------------------------------------------------------------------------------------------------
# pictures
# ------------------------------------------------------------------------------------------------------------


def _robot_color(i: int) -> str:
    from crowdsim.plotting import ROBOT_COLORS

    return ROBOT_COLORS[i % len(ROBOT_COLORS)]


GOAL_COLOR: Final = "red"  # as crowdsim.plotting draws them
HUMAN_COLOR: Final = "0.35"


def default_times(view: EpisodeView, count: int = 3) -> list[float]:
    return [float(t) for t in np.linspace(view.times[0], view.times[-1], count + 1)[:-1]]


def _draw_plans(ax: Any, view: EpisodeView, row: int, *, label: bool) -> None:
    """Robot i's plan at state ``row`` from its position, one marker per planned step, above the agents
    (a plan that is followed would otherwise hide under the trajectory); predictions dotted grey."""
    step = int(view.steps[row])
    plan = view.plans.get(step)
    if plan is not None:
        for i, track in enumerate(plan):
            pts = np.vstack([view.robot_positions[row, i], track])
            ax.plot(pts[:, 0], pts[:, 1], "--o", color=_robot_color(i), lw=1.2, ms=3, mfc="white", mew=0.8,
                    zorder=6, label="plan" if label and i == 0 else None)  # fmt: skip
    prediction = view.predictions.get(step)
    if prediction is not None:
        for j in range(prediction.shape[1]):
            pts = np.vstack([view.human_positions[row, j], prediction[:, j]])
            ax.plot(pts[:, 0], pts[:, 1], ":.", color=HUMAN_COLOR, lw=1.0, ms=3, zorder=6,
                    label="prediction" if label and j == 0 else None)  # fmt: skip


def plot_recording(rec: Recording, out: str | Path, times: Sequence[float] | None = None) -> list[float]:
    """Trajectories (crowdsim.plotting.plot_episode) with the plans and predictions made at ``times`` (s).

    Returns the times actually drawn (the nearest recorded states).
    """
    from crowdsim.plotting import plot_episode

    view = episode_view(rec)
    rows = sorted({view.row_at(t) for t in (times if times else default_times(view))})
    fig = plot_episode(
        view.robot_positions,
        view.human_positions,
        view.robot_goals,
        snapshot_steps=rows,
        radius=view.radius,
        dt=view.dt,
    )
    ax = fig.axes[0]
    for k, row in enumerate(rows):
        _draw_plans(ax, view, row, label=k == 0)
    drawn = [float(view.times[r]) for r in rows]
    ax.set_title(f"{rec.label}\nplans and predictions at t = {', '.join(f'{t:g}' for t in drawn)} s")
    if rec.truncated:
        ax.text(0.01, 0.01, "TRUNCATED FILE", transform=ax.transAxes, color="red", fontsize=9)
    _dedupe_legend(ax)
    fig.savefig(out, dpi=120, bbox_inches="tight")
    return drawn


def _dedupe_legend(ax: Any, *, below: bool = False) -> None:
    handles, labels = ax.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    if unique and below:  # under the axes: nothing drawn is hidden
        ax.legend(
            unique.values(), unique.keys(), loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=7
        )
    elif unique:
        ax.legend(unique.values(), unique.keys(), loc="best", fontsize=7)


def plot_compare(a: Recording, b: Recording, out: str | Path) -> None:
    """Both runs' trajectories on one axes: A solid, B dashed, robots in the same colours."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 7))
    ax = fig.add_subplot()
    for rec, style, alpha in ((a, "-", 1.0), (b, "--", 0.8)):
        view = episode_view(rec)
        tag = "A" if rec is a else "B"
        for j in range(view.human_positions.shape[1]):
            ax.plot(*view.human_positions[:, j].T, style, color="0.6", lw=0.8, alpha=0.6,
                    label=f"{tag} humans" if j == 0 else None)  # fmt: skip
        for i in range(view.robot_positions.shape[1]):
            ax.plot(*view.robot_positions[:, i].T, style, color=_robot_color(i), lw=2.0, alpha=alpha,
                    label=f"{tag}: {rec.label}" if i == 0 else None)  # fmt: skip
        ax.plot(*view.robot_goals.T, "*", color=GOAL_COLOR, mec="k", mew=0.5, ms=14)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.set_title("A solid, B dashed")
    _dedupe_legend(ax, below=True)
    fig.savefig(out, dpi=120, bbox_inches="tight")


def animate_recording(rec: Recording, out: str | Path, *, speed: float = 1.0) -> int:
    """The episode as a GIF (Pillow) or, for a ``.mp4`` name, an MP4 (needs ffmpeg). Returns the frame count.

    One frame per recorded state, played at ``speed`` times simulated time.
    """
    from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from crowdsim.plotting import frame_axes

    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise PipelineError(f"--animate writes .gif or .mp4, got {out.name!r}")
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise PipelineError("an .mp4 needs ffmpeg, which is not installed here; ask for a .gif instead")
    view = episode_view(rec)
    fps = speed / view.dt
    m, n = view.robot_positions.shape[1], view.human_positions.shape[1]

    fig = Figure(figsize=(6, 6), layout="constrained")
    ax = fig.add_subplot()
    frame_axes(ax, view.robot_positions, view.human_positions, view.robot_goals)
    ax.set_title(rec.label, fontsize=9)
    ax.plot(*view.robot_goals.T, "*", color=GOAL_COLOR, mec="k", mew=0.5, ms=14, zorder=1)
    robots = [Circle((0, 0), view.radius, fc=_robot_color(i), ec="k", lw=0.5, zorder=3) for i in range(m)]
    humans = [Circle((0, 0), view.radius, fill=False, ec=HUMAN_COLOR, lw=1.2, zorder=3) for _ in range(n)]
    for patch in robots + humans:
        ax.add_patch(patch)
    trails = [ax.plot([], [], "-", color=_robot_color(i), lw=1.0, alpha=0.6)[0] for i in range(m)]
    plans = [ax.plot([], [], "--", color=_robot_color(i), lw=1.2)[0] for i in range(m)]
    predictions = [ax.plot([], [], ":", color=HUMAN_COLOR, lw=1.0)[0] for _ in range(n)]
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=9)

    def draw(row: int) -> list[Any]:
        step = int(view.steps[row])
        for i, patch in enumerate(robots):
            patch.center = view.robot_positions[row, i]
            trails[i].set_data(view.robot_positions[: row + 1, i, 0], view.robot_positions[: row + 1, i, 1])
        for j, patch in enumerate(humans):
            patch.center = view.human_positions[row, j]
        plan = view.plans.get(step)
        for i, line in enumerate(plans):
            pts = np.vstack([view.robot_positions[row, i], plan[i]]) if plan is not None else np.empty((0, 2))
            line.set_data(pts[:, 0], pts[:, 1])
        prediction = view.predictions.get(step)
        for j, line in enumerate(predictions):
            pts = (
                np.vstack([view.human_positions[row, j], prediction[:, j]])
                if prediction is not None
                else np.empty((0, 2))
            )
            line.set_data(pts[:, 0], pts[:, 1])
        clock.set_text(f"t = {view.times[row]:.1f} s" + ("   (truncated file)" if rec.truncated else ""))
        return [*robots, *humans, *trails, *plans, *predictions, clock]

    frames = len(view.times)
    animation = FuncAnimation(fig, draw, frames=frames, blit=False)
    writer = PillowWriter(fps=fps) if suffix == ".gif" else FFMpegWriter(fps=fps)
    animation.save(out, writer=writer, dpi=80)
    return frames
