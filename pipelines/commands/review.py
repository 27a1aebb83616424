"""``crowdmpc review``: read MCAP recordings of closed-loop runs back (summary, plots, animation, check)."""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final

from pipelines.commands import check_writable, comma_items, path_arg, write_output
from pipelines.commands.output_paths import file_output_arg
from pipelines.commands.review_folder import recordings_or_none, review_folder
from pipelines.commands.review_notes import (
    warn,
    warn_different_crowds,
)
from pipelines.commands.standard_output import is_stdout, json_on_stdout, json_path, shown
from pipelines.errors import PipelineError, print_note
from pipelines.plain_json import plain

if TYPE_CHECKING:
    from pipelines.logs.digest import RunDigest

EPILOG = """examples:
  crowdmpc review runs/demo/                              # one row per episode, then rates over them
  crowdmpc review runs/demo/circle_seed000000.mcap --plot runs/p.png --times 0,4,8 \\
      --animate runs/a.gif
  crowdmpc review runs/a.mcap --compare other/a.mcap --plot runs/overlay.png
  crowdmpc review runs/demo/ --check --json runs/review.json   # validate every message against its schema
  crowdmpc review runs/                                   # runs/cmpc/ and runs/dmpc/: a table each
  crowdmpc review SWEEP/                                  # a sweep's recordings (SWEEP/mcap/CELL/)

The folders are those `make demo`, `crowdmpc simulate --record DIR` and `crowdmpc sweep --record` write; a
folder means the .mcap files directly in it or, when it holds none, those one and two levels below it (a
folder of runs' folders, a sweep's DIR or DIR/mcap; a warning counts the subfolders' recordings that a
folder's own files leave unread). Runs of different set-ups (controller, predictor,
numbers of robots and humans, or any simulator or controller setting the recordings' "config" metadata holds:
profile, visibility, formation, MPC settings, margins...) get one table and aggregate each, named by what
differs, their files by their paths below the folder, then a row each side by side. --json writes "groups",
one per set-up with its "totals" (and "totals" at the top too when the folder holds one set-up). Copies of
one episode (same set-up, scenario, seed and code) count once, with a warning. A sweep recorded with --record
failures kept its failed episodes only: a warning says that its rates here are over those, and its table.md
has the sweep's.

A file whose run was killed reads up to its last complete chunk, with a warning. A bad chunk (its CRC or
compression fails) or a message that is not what the review reads is left out, with a warning; --check lists
every one, with the schema violations, a truncated file and the file's own problems on lines apart from its
messages' count, and checks --compare's file too.

In a folder, every readable file is reviewed; each unreadable one (empty, not MCAP, another program's MCAP
file, cut before its first metadata record or holding none and no message, a folder named *.mcap) gets one
line on stderr, and each unfinished NAME.mcap.part (a recording still being written, or whose run was
killed: review it by name to read what it holds) a warning line.

Exit code: 0 when the review ran, even with files left out of a folder (a sweep killed half-way must still
review what it finished); 2 when nothing could be read (one file, or a folder without one readable recording);
with --check, 1 when any file is truncated or unreadable, or has a bad chunk, a corrupt record, a bad message
or a schema violation.
"""

MAX_ERRORS_SHOWN = 20
# The units of the episode metrics (crowdsim.metrics.EpisodeMetrics), printed after their names.
METRIC_UNITS: Final[Mapping[str, str]] = {
    "travel_time": "s",
    "min_distance": "m",
    "min_distance_robots": "m",
    "min_distance_humans": "m",
    "min_distance_between_steps": "m",
    "path_length": "m",
    "reach_times": "s",
}


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "review",
        help="summarize, plot, animate, compare and check MCAP recordings",
        description="Review closed-loop runs recorded with `crowdmpc simulate --record DIR`.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("path", type=path_arg, help="an .mcap file, or a folder of them (aggregate table)")
    parser.add_argument(
        "--plot", type=file_output_arg, metavar="PNG", help="draw paths and plans (overlay with --compare)"
    )
    parser.add_argument(
        "--times",
        type=_times,
        metavar="T1,T2,..",
        help="simulated times (s) of the plans drawn by --plot (not with --compare)",
    )
    parser.add_argument(
        "--animate",
        type=file_output_arg,
        metavar="GIF|MP4",
        help="the episode as an animation at simulated speed; a frame is shown 0.02 s (GIF; MP4 0.001 s) "
        "to 655.35 s (a GIF's longest), so an episode of steps beyond plays faster or slower, as the output "
        "line says",
    )
    parser.add_argument(
        "--compare",
        type=path_arg,
        metavar="OTHER.mcap",
        help="side-by-side metrics with this run, and each setting in which the two differ",
    )
    parser.add_argument("--check", action="store_true", help="validate every message against its schema")
    parser.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar of a folder's files or an animation's frames (drawn on a terminal only)",
    )
    parser.add_argument(
        "--json", type=json_path, metavar="FILE", help="also write the summary as JSON (-: standard output)"
    )
    parser.set_defaults(func=run)


def _times(text: str) -> list[float]:
    try:
        times = [float(t) for t in comma_items(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected seconds separated by commas, e.g. 0,4,8; got {text!r}"
        ) from None
    if not times or not all(math.isfinite(t) and t >= 0 for t in times):  # float() takes "nan" and "inf"
        raise argparse.ArgumentTypeError(f"expected non-negative seconds, e.g. 0,4,8; got {text!r}")
    return times


def _check(runs: list[RunDigest], report: dict[str, Any]) -> int:
    """Each file's check: a line for a truncated file and one for the file's own problems (a bad chunk, a
    corrupt record), apart from its messages' count, then the messages' errors; how many files failed."""
    from pipelines.logs.review import count

    failed = 0
    for run in runs:
        assert run.check is not None  # digested with check=True
        checked, errors = run.check
        truncated = bool(run.summary["truncated"])
        report.setdefault("check", {})[run.file] = {
            "messages": checked,
            "errors": errors,
            "file_problems": run.file_problems,
            "truncated": truncated,
        }
        if truncated:
            read = sum(run.summary["messages"].values())
            why = run.stopped_at or "no closing magic"
            print(f"check {run.file}: {read} messages read, truncated: {why}; the rest of the file is lost")
        if run.file_problems:
            print(f"check {run.file}: the file itself: {count(len(run.file_problems), 'problem')}")
            _listed(run.file_problems)
        # the verdict, last: "ok" only for a file that passes (a truncated one read "ok" after its cut line)
        fails = [
            why for why, bad in (("truncated", truncated), ("its own problems", run.file_problems)) if bad
        ]
        verdict = f"{len(errors)} invalid" if errors else "each valid" if fails else "ok"
        print(
            f"check {run.file}: {checked} messages, {verdict}"
            + (f"; fails: {', '.join(fails)}" if fails else "")
        )
        _listed(errors)
        failed += bool(errors or run.file_problems or truncated)
    return failed


def _listed(lines: list[str]) -> None:
    for line in lines[:MAX_ERRORS_SHOWN]:
        print(f"  {line}")
    if len(lines) > MAX_ERRORS_SHOWN:
        print(f"  ... and {len(lines) - MAX_ERRORS_SHOWN} more")


def _with_units(summary: dict[str, Any]) -> dict[str, Any]:
    """``summary`` for printing: each metric with a unit named with it ("travel_time (s)")."""
    metrics = summary["metrics"]
    if metrics is None:
        return summary
    named = {f"{k} ({METRIC_UNITS[k]})" if k in METRIC_UNITS else k: v for k, v in metrics.items()}
    return summary | {"metrics": named}


def _check_distinct_outputs(args: argparse.Namespace) -> None:
    """Each output its own file: written one after the other, the last (--json) replaced the figure."""
    outputs = [(f"--{name}", getattr(args, name)) for name in ("plot", "animate", "json")]
    given = [(option, path) for option, path in outputs if path is not None and not is_stdout(path)]
    for i, (option, path) in enumerate(given):
        for other, other_path in given[i + 1 :]:
            if path.resolve() == other_path.resolve():
                raise PipelineError(f"{option} and {other} name the same file {path}; give each its own")


def _check_outputs(args: argparse.Namespace) -> None:
    """Every output checked before any file is read: the options go together, each output's format, then
    that it can be written without overwriting an input."""
    from pipelines.logs.reader import FOLDER_LEVELS

    if args.times and not args.plot:
        raise PipelineError("--times chooses the plans drawn by --plot; add --plot FILE.png")
    if args.times and args.compare:  # the overlay draws both runs' paths, no plan: the times went unused
        raise PipelineError("--times chooses the plans drawn by --plot, and --compare's overlay draws none")
    if args.animate and args.compare:  # it animated A alone, unsaid
        raise PipelineError("--animate animates one run, not --compare's two; animate each on its own")
    if args.plot:
        from crowdsim.plotting import check_figure_path

        check_figure_path(args.plot, "--plot")
    if args.animate:
        from pipelines.logs.animation import check_animation_path

        check_animation_path(args.animate, "--animate")
    inputs = [args.path]
    if args.path.is_dir():  # every file a folder's review may read, finished or not
        below = [pattern + "*" for level in FOLDER_LEVELS for pattern in level]
        inputs += [p for pattern in below for p in args.path.glob(pattern)]
    inputs += [args.compare] if args.compare else []
    # the figures' temporaries (whole_files.save_figure) have names of their own length: no room
    check_writable(args.plot, "--plot", inputs=inputs, room=0)
    check_writable(args.animate, "--animate", inputs=inputs, room=0)
    check_writable(args.json, "--json", inputs=inputs, json_only=True)
    _check_distinct_outputs(args)


def run(args: argparse.Namespace) -> int:
    with json_on_stdout(args.json):  # --json -: the JSON alone on stdout, the rest on stderr
        return _review(args)


def _review(args: argparse.Namespace) -> int:
    from pipelines.logs.animation import animate_recording
    from pipelines.logs.digest import digest
    from pipelines.logs.identity import differing_settings
    from pipelines.logs.plots import plot_compare, plot_recording
    from pipelines.logs.reader import read_recording
    from pipelines.logs.review import compare_table, format_summary

    _check_outputs(args)
    show = False if args.no_progress else None  # None: a bar on a terminal only
    report: dict[str, Any] = {}
    n_unreadable = 0
    other_run = None
    if args.path.is_dir():
        single_file_only = [
            f"--{name}" for name in ("plot", "times", "animate", "compare") if getattr(args, name)
        ]
        if single_file_only:
            files = [p for p in recordings_or_none(args.path) if p.is_file()]  # a folder named *.mcap is none
            example = f"; give one of its files, e.g. {files[0]}" if files else ""
            verb = "needs" if len(single_file_only) == 1 else "need"
            raise PipelineError(
                f"{', '.join(single_file_only)} {verb} one .mcap file, not the folder {args.path}{example}"
            )
        runs, n_unreadable = review_folder(args.path, report, args.check, show)
    else:
        rec = read_recording(args.path)
        # read before anything is printed: a --compare file that cannot be read is the one line, alone
        other = read_recording(args.compare) if args.compare else None
        runs = [digest(rec, args.check)]
        print(format_summary(_with_units(runs[0].summary)))
        report["summary"] = runs[0].summary
        other_run = digest(other, args.check) if other is not None else None
    for run in runs:
        if run.warning:
            print_note(f"crowdmpc review: warning: {run.warning}")
        if run.problems_warning and not args.check:  # --check lists them all
            print_note(f"crowdmpc review: warning: {run.problems_warning}")

    checked = runs if args.path.is_dir() or other_run is None else [*runs, other_run]  # --compare's too
    failed = _check(checked, report) + n_unreadable if args.check else 0

    for out in (args.plot, args.animate, args.json):
        # checked writable above, as other commands' outputs: its folder made here
        if out is not None and not is_stdout(out):
            out.parent.mkdir(parents=True, exist_ok=True)
    if not args.path.is_dir():
        if other is not None and other_run is not None:
            print()
            print(compare_table(rec, other))
            differ = [{"setting": k, "a": va, "b": vb} for k, va, vb in differing_settings(rec, other)]
            report["compare"] = other_run.summary | {"differing_settings": differ}
            warn_different_crowds(runs[0].summary, other_run.summary)
            for warning in (other.warning, None if args.check else other.problems_warning):
                if warning:
                    warn(warning)
        if args.plot:
            if other is not None:
                plot_compare(rec, other, args.plot)
                print(f"overlay plot: {args.plot}")
            else:
                print(f"plot: {args.plot} ({plot_recording(rec, args.plot, args.times)})")
        if args.animate:
            facts = animate_recording(rec, args.animate, progress=show)
            thinned = f", one state in {facts.every}" if facts.every > 1 else ""
            pace = f"; {facts.pace_note}" if facts.pace_note else ""
            print(f"animation: {args.animate} ({facts.frames} frames{thinned}{pace})")

    if args.json:
        # plain: a hostile or foreign file's NaN metrics would make the report invalid JSON
        write_output(args.json, json.dumps(plain(report), indent=2, allow_nan=False) + "\n", "--json")
        if not is_stdout(args.json):
            print(f"json: {shown(args.json)}")
    return 1 if failed else 0
