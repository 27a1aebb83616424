"""Figure of benchmarks/robot_scaling.py's results: success and control-step time against the number of robots
M and of humans N, one line per controller and task (fixed goals, slots).

    .venv/bin/python benchmarks/plot_scaling.py RUN.json [RUN.json ...] --out docs/robot_scaling.png

Each RUN.json is what ``robot_scaling.py --json`` wrote. Rows that share controller, goals and humans make a
line against M; rows that share controller, goals and M but differ in humans make a line against N (the
N rows of docs/results.md at 3 robots, with the 7-human row of the M runs among them). Success is drawn with
its 95% Wilson interval (from each row's episodes; a report without them gets none) and the collision rate
(episodes within 0.8 m of a human) dotted beside it; step times as the median with the p99
dashed above it, on a log axis, beside the 0.4 s control period that every step must stay under.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable
from pathlib import Path
from typing import Any, NamedTuple, cast

from pipelines.commands import check_writable
from pipelines.commands.output_paths import without_missing_parents
from pipelines.errors import PipelineError
from predictors.text_table import counted

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cli import check_input_files, check_not_input, run_main  # noqa: E402

RUN_FILE = "a robot_scaling.py --json file"  # what each of the runs is, as a refusal names it

CONTROL_PERIOD_MS = 400.0  # the paper's dt = 0.4 s: a step slower than this misses its period
EMPTY_WHAT = {"robots": "robots M", "humans": "humans N"}  # a panel's axis, as its note names it


class Point(NamedTuple):
    controller: str
    goals: str
    robots: int
    humans: int
    success: float  # %
    collision: float  # % of episodes within 0.8 m of a human
    median_ms: float
    p99_ms: float
    episodes: int | None = None  # the row's episodes (older reports lack it: no interval drawn)


def points(reports: Iterable[tuple[str, dict[str, Any]]]) -> list[Point]:
    """Every row of every report as a point; the same (controller, goals, robots, humans) twice is an error
    naming both files, since a figure cannot show two measurements as one."""
    seen: dict[tuple[str, str, int, int], str] = {}
    out = []
    for name, report in reports:
        try:
            humans = int(report["args"]["humans"])
            new = [
                Point(
                    str(row["controller"]),
                    str(row["goals"]),
                    int(row["robots"]),
                    humans,
                    float(row["success_rate"]),
                    float(row["collision_rate"]),
                    float(row["median_ms"]),
                    float(row["p99_ms"]),
                    int(row["episodes"]) if "episodes" in row else None,
                )
                for row in report["rows"]
            ]
        except (KeyError, TypeError, ValueError) as exc:
            reason = f"no {exc}" if isinstance(exc, KeyError) else str(exc)
            raise ValueError(f"{name} is not robot_scaling.py --json output ({reason})") from None
        for point in new:
            key = point[:4]
            if key in seen:
                raise ValueError(f"{name} and {seen[key]} both hold {key}: give one of them")
            seen[key] = name
            out.append(point)
    return out


def series(pts: list[Point], along: str) -> dict[tuple[str, str, int], list[Point]]:
    """Lines along ``"robots"`` (keyed by controller, goals, humans) or ``"humans"`` (controller, goals,
    robots), each sorted along its axis; a group with a single value along the axis is no line."""
    fixed = "humans" if along == "robots" else "robots"
    groups: dict[tuple[str, str, int], list[Point]] = {}
    for p in pts:
        groups.setdefault((p.controller, p.goals, getattr(p, fixed)), []).append(p)
    return {
        key: sorted(group, key=lambda p: getattr(p, along))
        for key, group in sorted(groups.items())
        if len({getattr(p, along) for p in group}) > 1
    }


def undrawn(pts: list[Point]) -> list[Point]:
    """The points on no line: alone along both axes (e.g. the single row of a run for one M and one N)."""
    drawn = {p for along in ("robots", "humans") for line in series(pts, along).values() for p in line}
    return [p for p in pts if p not in drawn]


def success_errors(line: list[Point]) -> list[list[float]] | None:
    """The 95% Wilson interval of each point's success rate as (below, above) distances in %, or None when
    a row does not give its episodes: a rate of 50 episodes was drawn bare, so that 94 % and 100 % looked
    apart when their intervals overlap."""
    from pipelines.experiments.summary import wilson_interval

    if any(p.episodes is None for p in line):
        return None
    below, above = [], []
    for p in line:
        n = cast(int, p.episodes)
        lo, hi = wilson_interval(round(p.success * n / 100.0), n)
        below.append(max(0.0, p.success - 100.0 * lo))
        above.append(max(0.0, 100.0 * hi - p.success))
    return [below, above]


def plot(pts: list[Point], out: Path) -> None:
    fig = figure(pts)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    import matplotlib.pyplot as plt

    plt.close(fig)


def controller_looks(pts: list[Point]) -> dict[str, dict[str, Any]]:
    """Each controller's colour, line width, marker size and drawing order. Where two controllers measure the
    same (both 100 % success, both 0 % collisions) the later line lay exactly on the earlier and only one
    showed; so the k-th controller's line is drawn narrower and above the (k-1)-th's, which stays visible as
    a wider band of its colour round it, and no plotted value is moved."""
    colours = {"cmpc": "tab:blue", "dmpc": "tab:orange"}
    controllers = sorted({p.controller for p in pts})
    looks = {}
    for rank, controller in enumerate(controllers):
        below = len(controllers) - 1 - rank  # how many controllers are drawn above this one
        looks[controller] = {
            "color": colours.get(controller),
            "linewidth": 1.5 + 2.5 * below,
            "markersize": 6.0 + 4.0 * below,
            "zorder": 2.0 + rank,
        }
    return looks


def figure(pts: list[Point]) -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(2, 2, figsize=(11, 7.5), sharex="col")
    looks = controller_looks(pts)
    for col, along in enumerate(("robots", "humans")):
        lines = series(pts, along)
        for (controller, goals, other), line in lines.items():
            x = [getattr(p, along) for p in line]
            style = {**looks[controller], "marker": "o" if goals == "fixed" else "s"}
            task = "fixed goals" if goals == "fixed" else goals
            label = f"{controller.upper()}, {task}, {other} {'humans' if along == 'robots' else 'robots'}"
            axes[0, col].errorbar(
                x, [p.success for p in line], yerr=success_errors(line), capsize=3, label=label, **style
            )
            axes[0, col].plot(x, [p.collision for p in line], linestyle=":", alpha=0.6, **style)
            axes[1, col].plot(x, [p.median_ms for p in line], label=f"{label}: median", **style)
            axes[1, col].plot(x, [p.p99_ms for p in line], linestyle="--", alpha=0.6, **style)
        axes[0, col].set_ylabel("success % (95% Wilson interval)\ncollision % dotted")
        axes[0, col].set_ylim(0, 102)
        axes[1, col].set_yscale("log")
        axes[1, col].axhline(CONTROL_PERIOD_MS, color="grey", linewidth=1)
        axes[1, col].text(axes[1, col].get_xlim()[0], CONTROL_PERIOD_MS * 1.08, " control period 0.4 s")
        axes[1, col].set_ylabel("control step ms (median, p99 dashed)")
        axes[1, col].set_xlabel("robots M" if along == "robots" else "humans N")
        axes[1, col].xaxis.set_major_locator(MaxNLocator(integer=True))  # counts: no 3.5 robots
        if lines:
            axes[0, col].legend(fontsize=8)
        else:  # said on the terminal only, the figure showed bare axes from 0 to 1 robot or human
            for ax in axes[:, col]:
                ax.text(0.5, 0.5, f"no two rows differ in {EMPTY_WHAT[along]} alone", transform=ax.transAxes,
                        ha="center", va="center", color="0.4")  # fmt: skip
        for ax in axes[:, col]:
            ax.grid(alpha=0.3)
    axes[0, 0].set_title("against the number of robots")
    axes[0, 1].set_title("against the number of humans")
    fig.tight_layout()
    return fig


def figure_file(text: str) -> Path:
    """An argparse ``type``: the figure's file, its format named by its suffix as matplotlib reads it. A name
    without one gets ``.png`` here, as matplotlib would have added it (so the path printed is the one
    written); a suffix matplotlib cannot write (``fig.pdfx``), a folder or a place without write access is
    refused now, not by a traceback after the runs are read."""
    from crowdsim.plotting import figure_refusal

    path = without_missing_parents(Path(text))  # nothing made to follow a ".."
    if not path.suffix[1:] and path.name.strip("."):
        path = path.with_name(path.name.rstrip(".") + ".png")
    refusal = figure_refusal(path)
    if refusal is not None:
        raise argparse.ArgumentTypeError(f"{text}: {refusal}")
    try:
        check_writable(path, "--out")
    except PipelineError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", type=Path, help="robot_scaling.py --json files")
    parser.add_argument(
        "--out",
        type=figure_file,
        required=True,
        help="the figure to write, in the format its suffix names (none: .png is added)",
    )
    args = parser.parse_args(argv)
    check_input_files(parser, "runs", args.runs, RUN_FILE)
    check_not_input(parser, "--out", args.out, args.runs)
    try:
        reports = [(str(path), json.loads(path.read_text(encoding="utf-8"))) for path in args.runs]
        pts = points(reports)
    except OSError as exc:  # found by the parser but unreadable (no permission): named as a missing one is
        raise PipelineError(
            f"runs: cannot read {exc.filename} ({exc.strerror}); expected {RUN_FILE}"
        ) from None
    except ValueError as exc:  # json.JSONDecodeError is a ValueError
        raise PipelineError(str(exc)) from None
    plot(pts, args.out)
    alone = undrawn(pts)
    print(f"wrote {args.out} ({len(pts) - len(alone)} of {counted(len(pts), 'row')} drawn)")
    for p in alone:
        print(
            f"  not drawn (no row to make a line with): {p.controller} {p.goals} goals, M={p.robots}, "
            f"N={p.humans}"
        )
    for along, what in EMPTY_WHAT.items():
        if not series(pts, along):
            print(f"  the panels against {what} are empty: no two rows differ in {what} alone")
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main))
