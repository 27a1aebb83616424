"""``crowdmpc config show``: the defaults, or the effective config of a file and ``--set`` items, as TOML."""

from __future__ import annotations

import argparse

EPILOG = """examples:
  crowdmpc config show > run.toml            # every setting with its default and what it means
  crowdmpc config show --config run.toml --set mpc.w_coll=1e6 --set scenario.humans=5
  crowdmpc --config run.toml simulate --controller cmpc   # or: crowdmpc simulate --config run.toml ...
  crowdmpc --config run.toml --set controller.predictor=social_lstm_eth sweep --experiment table2 \\
      --out runs/table2

Sections: [world] (tau, L, radius, speeds: shared by the simulator and the MPC), [env] and [env.orca] (the
simulator), [scenario], [controller], [mpc] (Table I and the solver), [simulate], [sweep]. Precedence, lowest
first: defaults < the --config file < --set SECTION.KEY=VALUE (in order; VALUE is a TOML value, a bare word a
string) < a command's explicit options. The output of `config show` is itself a config file.
"""


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--set SECTION.KEY=VALUE`` after the command (also accepted before it)."""
    parser.add_argument(
        "--config",
        dest="sub_config_file",
        action="append",  # two are refused (config_arguments), not the last one silently kept
        metavar="FILE",
        help="a TOML config file (see `crowdmpc config show`); options given here override it",
    )
    parser.add_argument(
        "--set",
        dest="sub_config_set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override one config value, e.g. mpc.w_coll=1e6 (repeatable; over the file, under options)",
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
    )
    add_config_options(show)
    show.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pipelines.config import command_config, render

    print(render(command_config(args)), end="")
    return 0
