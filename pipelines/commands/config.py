"""``crowdmpc config show``: the defaults, or the effective config of a file and ``--set`` items, as TOML."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

from pipelines.commands import examples
from pipelines.errors import PipelineError, print_note

if TYPE_CHECKING:
    from pipelines.config import RunConfig

EPILOG = """examples:
  crowdmpc config show > run.toml            # every setting with its default and what it means
  crowdmpc config show --config run.toml --set mpc.w_coll=1e6 --set scenario.humans=5
  crowdmpc --config run.toml simulate --controller cmpc   # or: crowdmpc simulate --config run.toml ...
  crowdmpc --config run.toml --set controller.predictor=social_lstm_eth sweep --experiment table2 \\
      --out runs/table2
  crowdmpc config show --from-sweep runs/table2 > rerun.toml   # what that sweep ran, with its commit
  crowdmpc --config rerun.toml sweep --out runs/table2-again

Sections: [world] (tau, L, radius, speeds: shared by the simulator and the MPC), [env] and [env.orca] (the
simulator), [scenario], [controller], [mpc] (Table I and the solver), [simulate], [sweep]. Precedence, lowest
first: defaults < the --config file < --set SECTION.KEY=VALUE (in order; VALUE is a TOML value, a bare word a
string) < a command's explicit options. TOML has no null: --set SECTION.KEY=null unsets a key, back to its
default (--set simulate.plot=null draws no figure whatever the file says). The output of `config show` is
itself a config file.
"""


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--set SECTION.KEY=VALUE`` after the command (also accepted before it)."""
    parser.add_argument(
        "--config",
        dest="sub_config_file",
        action="append",  # two are refused (config_arguments), not the last one silently kept
        metavar="FILE",
        help="a TOML config file (see `crowdmpc config show`), or a pipe; options given here override it",
    )
    parser.add_argument(
        "--set",
        dest="sub_config_set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override one config value, e.g. mpc.w_coll=1e6; =null unsets it, e.g. a file's simulate.plot "
        "(repeatable; over the file, under options)",
    )


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "config",
        help="show the configuration (defaults, or a config file's effective values) as TOML",
        description="Print every setting as an annotated TOML config file: the defaults (the paper's "
        "Table I), or the effective values of a --config file with --set overrides.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    actions = parser.add_subparsers(dest="config_command", metavar="ACTION", required=True)
    show = actions.add_parser(
        "show",
        help="print the defaults, or the effective config, as TOML",
        description="Print the configuration as a TOML file that loads back to the same configuration.",
        **examples(
            "crowdmpc config show > run.toml",
            "crowdmpc config show --config run.toml --set mpc.w_coll=1e6 --set scenario.humans=5",
            "crowdmpc config show --from-sweep runs/table2 > rerun.toml",
        ),
    )
    add_config_options(show)
    show.add_argument(
        "--from-sweep",
        metavar="DIR",
        help="the config a sweep directory recorded (its sweep.json), to rerun it",
    )
    show.add_argument(
        "--run",
        type=int,
        default=None,
        metavar="K",
        help="with --from-sweep: the K-th run (default: the last)",
    )
    show.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pipelines.commands.simulate_checks import check_mpc_solvable, check_predictors_known
    from pipelines.config import command_config, render

    if args.from_sweep is not None:
        return _show_recorded(args)
    if args.run is not None:
        raise PipelineError("--run goes with --from-sweep DIR")
    config = command_config(args)
    # what it shows is a run's config: refused as simulate and sweep refuse it (not a sweep's record, which
    # shows what ran: a predictor a plugin registered then, or a zoo held, is named by a rerun's refusal)
    check_mpc_solvable(config)
    check_predictors_known(config, ("controller", "predictor"), ("sweep", "predictors"))
    print(render(config), end="")
    _note_refused(config)
    return 0


def _note_refused(config: RunConfig) -> None:
    """A note for a configuration that simulate and sweep refuse before running: its values each pass their
    own checks here, but an MPC d_min below the contact distance, or fixed margins of another length than
    the horizon, is a fact of two sections together, which `config show` printed without a word and
    simulate then refused."""
    from pipelines.loop.margins import parse_margins
    from pipelines.loop.mpc_setup import check_contact_distance

    if config.controller.controller not in (None, "cmpc", "dmpc"):  # a sweep's experiment runs the MPCs
        return
    refused = "note: simulate and sweep refuse this configuration:"
    try:
        check_contact_distance(config.world, config.mpc)
    except PipelineError as exc:
        print_note(f"{refused} {exc}")
    margins = parse_margins(config.controller.margins or "none")
    if margins.mode == "fixed" and len(margins.values) != config.mpc.horizon:
        print_note(
            f"{refused} fixed margins need one value per horizon step ({config.mpc.horizon}), got "
            f"{len(margins.values)}"
        )


def _show_recorded(args: argparse.Namespace) -> int:
    """The TOML of what a sweep ran (``pipelines.config.recorded``); a config file or --set beside it would
    make it another run, so they are refused (edit the printed file instead)."""
    from pipelines.config import render
    from pipelines.config.command_line import config_arguments
    from pipelines.config.recorded import (
        comment,
        last_own_run,
        machine_note,
        provenance,
        recorded_config,
        recorded_runs,
    )
    from pipelines.experiments.zoo_changes import zoo_note

    path, sets = config_arguments(args)
    if path is not None or sets:
        raise PipelineError("--from-sweep prints what the sweep ran: no --config or --set beside it")
    sweep_file, runs = recorded_runs(args.from_sweep)
    index = last_own_run(runs) if args.run is None else args.run  # not a run --reuse took episodes of
    if not 1 <= index <= len(runs):
        raise PipelineError(f"--run {args.run}: {sweep_file} records runs 1..{len(runs)}")
    run_line = runs[index - 1]
    config = recorded_config(sweep_file, run_line, index)
    changed = zoo_note(args.from_sweep, _cell_keys(run_line))  # the printed run's cells: what a rerun plans
    if changed:  # on stderr too: a file piped into a rerun shows its comments to no one
        print_note(f"note: {changed}")
    notes = machine_note(config) + comment(changed)
    print(provenance(sweep_file, run_line, index, len(runs)) + notes + render(config), end="")
    return 0


def _cell_keys(run_line: dict[str, Any]) -> set[str] | None:
    """The keys of the cells a run line planned (None: a line from before they were recorded, whose note
    takes every record)."""
    cells = run_line.get("cells")
    if not isinstance(cells, list):
        return None
    return {str(c.get("key")) for c in cells if isinstance(c, dict)}
