"""``crowdmpc compare``: runs side by side on the crowds they share, each against the first, episode by
episode (pipelines.experiments.compare)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

from pipelines.commands import check_writable, write_output
from pipelines.commands.output_paths import file_output_arg
from pipelines.commands.standard_output import is_stdout, json_on_stdout, json_path, shown
from pipelines.errors import PipelineError, print_note
from pipelines.plain_json import plain
from pipelines.whole_files import save_figure
from predictors.text_table import counted

if TYPE_CHECKING:
    from pipelines.experiments.compare import Identity, Run
    from pipelines.experiments.paired import Paired, Versus

EPILOG = """examples:
  crowdmpc compare runs/table2 runs/table2-cp
  crowdmpc compare paper=runs/table2 cp0.1=runs/table2-cp safe=runs/t2-safe --json runs/compare.json
  crowdmpc compare paper=runs/table2 safe=runs/t2-safe --plot runs/safe_vs_paper.png
  crowdmpc compare before=runs/t2-main after=runs/t2-branch --expect-identical
  crowdmpc compare runs/table2 runs/t2-dmin --by-cell --expect-identical   # --vary mpc.d_min=0.8,1.0's 0.8
  crowdmpc compare cv=runs/cmpc-cv lstm=runs/cmpc-lstm    # `simulate --record` folders of the same seeds

Each RUN is a `crowdmpc sweep --out` folder, a `crowdmpc simulate --json` file, or recordings: an .mcap file
or a folder of them as `crowdmpc review` finds them (`simulate --record DIR`, `make demo`'s runs/demo; a file
that cannot be read or whose episode did not finish is left out with a warning); the episodes of the last two
are the method named by their controller. Each is named by LABEL= or by its name. Episodes pair where two runs
faced the same crowd: the same scenario, seed, humans and robots, the crowd made alike (ORCA's humans or the
same recording, the same placement rules and formation), and the same method (case ignored; with --by-cell,
sweeps' episodes the same cell, whatever their columns' labels: `--vary mpc.d_min=0.8,1.0`'s 0.8 column is
Table II's cell). Only episodes every run holds are compared. First each run's folder, episodes and code (the
commits it names, each with its plugins' files; code of no git commit, an installed wheel's, by its versions
as table.md names it: "no git commit, crowdmpc 0.1.0, Python ..."); then, for each method and crowd size,
every run's success, collision, contact and discomfort rates (%) and mean travel time over its successes (s),
and for each run after the first, against it: +k / −j, the episodes where the run has the outcome and the
first run not, and the reverse, with the exact McNemar p; the mean travel-time difference over the episodes
both completed, ± Student's t 95 % half-width, their number in brackets; and how many episodes have every
metric equal.
Last, the settings the compared groups' episodes ran with where they differ from the first run's. --plot
draws each change with its 95 % interval (the rates' by Newcombe's square-and-add for paired proportions;
--json holds them too).
--expect-identical exits 1 unless every episode of every run is in every other with every metric equal: a
change that must not move a result (`--jit on` against off, a refactoring).
"""
MAX_SETTINGS_SHOWN: Final = 12  # per run; the rest counted (--json has them all)
VALUE_WIDTH: Final = 60  # characters of a setting's values shown
MAX_CELLS_NAMED: Final = 2  # per run, in the line saying that runs share no cell


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "compare",
        help="runs side by side on the crowds they share, paired episode by episode",
        description="Compare runs' episodes on the crowds they share: rates per method and crowd size, "
        "paired changes against the first run (exact McNemar), and the settings that differ.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "runs",
        nargs="+",
        metavar="[LABEL=]RUN",
        help="two or more sweep folders, simulate --json files or recordings (.mcap files or folders)",
    )
    parser.add_argument(
        "--json",
        type=json_path,
        metavar="FILE",
        help="also write the comparison as JSON (-: standard output)",
    )
    parser.add_argument(
        "--plot",
        type=file_output_arg,
        metavar="PNG",
        help="draw each run's change against the first per method and crowd size, with 95 %% intervals",
    )
    parser.add_argument(
        "--by-cell",
        action="store_true",
        help="pair sweeps' episodes by their cell (its key) rather than their method's label: a --vary "
        "column with the plain sweep's column of that cell, one experiment's column with another's",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar while reading the runs")
    parser.add_argument(
        "--expect-identical",
        action="store_true",
        help="exit 1 unless the runs hold the same episodes with every metric equal",
    )
    parser.set_defaults(func=run)


def labelled(items: list[str]) -> list[tuple[str, Path]]:
    """``(label, path)`` of each ``[LABEL=]RUN``: an existing path is taken whole (its name may hold "="),
    else LABEL=RUN names it; the label defaults to the folder's name (a file's, less its suffix). A label
    given twice, or one the table cannot show (a newline, a "|"), is refused."""
    from pipelines.experiments.compare import SOURCES
    from pipelines.experiments.log import EPISODES_FILE

    runs: list[tuple[str, Path]] = []
    for item in items:
        label, sep, folder = item.partition("=")
        if sep and not Path(item).exists():
            if not (label and folder):
                raise PipelineError(f"expected [LABEL=]RUN, {SOURCES}, got {item!r}")
        elif item:
            whole = Path(item).resolve()
            if whole.name == EPISODES_FILE and whole.is_file():  # a sweep's log: named by its folder
                whole = whole.parent
            label, folder = (whole.stem if whole.is_file() else whole.name) or item, item
        else:
            raise PipelineError(f"expected [LABEL=]RUN, {SOURCES}, got ''")
        if not label.isprintable() or "|" in label:  # a newline or "|" broke the table's rows
            raise PipelineError(
                f"label {label!r} must be printable text without '|' (it names the run in the table's rows); "
                "name the run LABEL=RUN"
            )
        if any(label == seen for seen, _ in runs):
            raise PipelineError(f"label {label!r} is given twice; name each run once (LABEL=RUN)")
        runs.append((label, Path(folder)))
    if len(runs) < 2:
        raise PipelineError(f"give at least two runs to compare, each {SOURCES}")
    return runs


def run(args: argparse.Namespace) -> int:
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        return _compare(args)


def _compare(args: argparse.Namespace) -> int:
    from pipelines.experiments.compare import load_run, shared_identities
    from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE

    named = labelled(args.runs)
    inputs = [p for _, path in named for p in (path, path / EPISODES_FILE, path / SWEEP_FILE)]
    check_writable(args.json, "--json", inputs=inputs, json_only=True)
    if args.plot is not None:
        from crowdsim.plotting import check_figure_path

        check_figure_path(args.plot, "--plot")
        check_writable(args.plot, "--plot", inputs=inputs, room=0)
        if not is_stdout(args.json) and args.json is not None and args.json.resolve() == args.plot.resolve():
            raise PipelineError(f"--json and --plot name the same file {args.plot}; give each its own")
    show = False if args.no_progress else None
    runs = [load_run(label, path, progress=show, by_cell=args.by_cell) for label, path in named]
    shared = shared_identities(runs)
    if not shared:
        raise PipelineError(_nothing_shared(runs))
    report = _report(runs, shared)
    print(_text(report))
    if args.plot is not None:
        from pipelines.experiments.compare_plot import compare_figure

        args.plot.parent.mkdir(parents=True, exist_ok=True)
        figure = compare_figure(report)
        save_figure(args.plot, lambda name: figure.savefig(name, dpi=120))
        print(f"plot: {args.plot}")
    if args.json:
        write_output(args.json, json.dumps(plain(report), indent=2, allow_nan=False) + "\n", "--json")
        if not is_stdout(args.json):
            print(f"json: {shown(args.json)}")
    if args.expect_identical:
        return _identical(report)
    return 0


def _nothing_shared(runs: list[Run]) -> str:
    """Why ``runs`` share no episode: their methods' labels where the crowds are shared (a --vary column is
    labelled with its value, "CMPC orca.time_horizon=5.0", and was said to draw other crowds), or with
    --by-cell their cells (the labels, "CMPC" in both runs, read as if shared), else the crowds."""
    crowds = [{identity[1:] for identity in run.outcomes} for run in runs]
    if set.intersection(*crowds) and all(run.cells for run in runs):
        cells = "; ".join(f"{run.label}: {_some(set(run.cells.values()), 'cell')}" for run in runs)
        return (
            "the runs share no cell on the same crowds (--by-cell pairs sweeps' episodes by their cell's "
            f"key, which names its predictor, margins and settings; without it they pair by method): {cells}"
        )
    if set.intersection(*crowds):
        methods = "; ".join(f"{run.label}: {', '.join(sorted(set(run.methods.values())))}" for run in runs)
        return (
            f"the runs share no method on the same crowds (episodes pair by their method's label, humans and "
            f"robots; a --vary column's label names its value, and --by-cell pairs sweeps by cell): {methods}"
        )
    return (
        "the runs share no episode (the same method, humans, robots, scenario, seed and crowd: another "
        "crowd, profile, team or formation draws other people from the same seeds)"
    )


def _some(names: set[str], noun: str, most: int = MAX_CELLS_NAMED) -> str:
    """The first ``most`` of ``names`` (sorted), then how many more: a sweep's keys are long, and Table II
    has ten."""
    shown = sorted(names)
    more = f" and {counted(len(shown) - most, f'more {noun}')}" if len(shown) > most else ""
    return ", ".join(shown[:most]) + more


def _report(runs: list[Run], shared: list[Identity]) -> dict[str, Any]:
    from pipelines.experiments.compare import groups_of, settings_differ
    from pipelines.experiments.paired import side, versus

    base = runs[0]
    groups = []
    grouped = groups_of(shared)
    # a sweep's plan first, then the order its episodes came in: a method it did not plan after those it did
    seen = dict.fromkeys(g[0] for g in grouped)
    order = {method: (base.plan.get(method, len(base.plan)), i) for i, method in enumerate(seen)}
    for group in sorted(grouped, key=lambda g: (order[g[0]], g[2], g[1])):
        identities = grouped[group]
        sides = {run.label: side([run.outcomes[k] for k in identities]) for run in runs}
        against = {
            run.label: versus([base.outcomes[k] for k in identities], [run.outcomes[k] for k in identities])
            for run in runs[1:]
        }
        groups.append(
            {
                "method": base.methods[group],
                "humans": group[1],
                "robots": group[2],
                "episodes": len(identities),
                "runs": {label: {"rates": s.rates, "travel_time": s.travel} for label, s in sides.items()},
                "versus_first": {label: _versus_json(v) for label, v in against.items()},
            }
        )
    held = set(shared)
    return {
        "shared_episodes": len(shared),
        "runs": [
            {
                "label": run.label,
                "path": str(run.path),
                "episodes": len(run.outcomes),
                "code": run.commits,
                "unshared": sorted(o.key for k, o in run.outcomes.items() if k not in held)[:20],
            }
            for run in runs
        ],
        "groups": groups,
        "settings_differ": {
            run.label: [
                {"setting": k, "first": a, "this": b} for k, a, b in settings_differ(base, run, grouped)
            ]
            for run in runs[1:]
        },
    }


def _versus_json(v: Versus) -> dict[str, Any]:
    return {
        **{name: _flag_json(p) for name, p in v.flags.items()},
        "travel_difference": {
            "mean": v.travel_difference,
            "half_width_95": v.travel_half_width,
            "n": v.travel_n,
        },
        "same_metrics": v.same,
        "text": {**{name: p.text() for name, p in v.flags.items()}, "travel": v.travel_text()},
    }


def _flag_json(p: Paired) -> dict[str, Any]:
    low, high = p.interval
    pp = 100.0 * p.difference
    return {
        "gained": p.gained,
        "lost": p.lost,
        "p": p.p,
        "difference_pp": pp,
        "interval_pp": [100 * low, 100 * high],
    }


def _text(report: dict[str, Any]) -> str:
    from pipelines.experiments.paired import FLAGS
    from pipelines.logs.review import count

    first = report["runs"][0]["label"]
    lines = [f"Compared on the {count(report['shared_episodes'], 'episode')} every run holds:"]
    for r in report["runs"]:
        code = ", ".join(r["code"]) or "not recorded"
        lines.append(f"  {r['label']}: {r['path']}, {count(r['episodes'], 'episode')}, code {code}")
    lines += [
        "",
        f"success / collision / contact / discomfort %, travel s (mean over successes); against {first}: "
        "+k / −j episodes with the outcome only in this run / only in the first (exact McNemar p), travel "
        "difference over the episodes both completed (mean ± 95 %, their number), episodes with every metric "
        "equal",
        "",
        "| method | humans | robots | run | episodes | success % | collision % | contact % | discomfort % | "
        "travel s | success | collision | contact | discomfort | travel Δ s | same |",
        "|---" * 16 + "|",
    ]
    for g in report["groups"]:
        for label, s in g["runs"].items():
            rates = [f"{s['rates'][name]:.1f}" for name in FLAGS]
            travel = "n/a" if s["travel_time"] is None else f"{s['travel_time']:.1f}"
            v = g["versus_first"].get(label)
            paired = (
                [""] * (len(FLAGS) + 2)
                if v is None
                else [
                    *(v["text"][name] for name in FLAGS),
                    v["text"]["travel"],
                    f"{v['same_metrics']} of {g['episodes']}",
                ]
            )
            cells = [
                g["method"],
                str(g["humans"]),
                str(g["robots"]),
                label,
                str(g["episodes"]),
                *rates,
                travel,
            ]
            lines.append("| " + " | ".join(cells + paired) + " |")
    lines += _settings_lines(report, first)
    return "\n".join(lines)


def _settings_lines(report: dict[str, Any], first: str) -> list[str]:
    lines = []
    for label, rows in report["settings_differ"].items():
        if not rows:
            lines.append(f"\n{label} ran with the settings of {first}.")
            continue
        lines.append(f"\nSettings {label}'s episodes ran with where they differ from {first}'s:")
        for row in rows[:MAX_SETTINGS_SHOWN]:
            lines.append(f"  {row['setting']}: {_short(row['first'])} -> {_short(row['this'])}")
        if len(rows) > MAX_SETTINGS_SHOWN:
            lines.append(f"  and {len(rows) - MAX_SETTINGS_SHOWN} more (--json lists them all)")
    return lines


def _short(text: str) -> str:
    return text if len(text) <= VALUE_WIDTH else text[: VALUE_WIDTH - 3] + "..."


def _identical(report: dict[str, Any]) -> int:
    """0 when every run holds the shared episodes alone and each has every metric of the first's, else 1
    with a line saying what differs."""
    from pipelines.logs.review import count

    problems = []
    for r in report["runs"]:
        if r["episodes"] != report["shared_episodes"]:
            extra = r["episodes"] - report["shared_episodes"]
            problems.append(
                f"{r['label']} holds {count(extra, 'episode')} not in every run (e.g. {r['unshared'][0]})"
            )
    for label in [r["label"] for r in report["runs"][1:]]:
        differ = sum(g["episodes"] - g["versus_first"][label]["same_metrics"] for g in report["groups"])
        if differ:
            problems.append(
                f"{differ} of {report['shared_episodes']} episodes of {label} differ from the first run's"
            )
    if problems:
        print_note(f"crowdmpc compare: not identical: {'; '.join(problems)}")
        return 1
    print(f"identical: {report['shared_episodes']} episodes, every metric equal")
    return 0
