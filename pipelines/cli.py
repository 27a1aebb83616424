"""The ``crowdmpc`` command line. Each subcommand lives in ``pipelines/commands/<name>.py``."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
from typing import NoReturn

from crowdsim.errors import SimulationError
from mpc.errors import MPCConfigError
from pipelines.errors import PipelineError
from pipelines.version import crowdmpc_version
from predictors.errors import PredictorError

# The order in which subcommands are listed by --help.
COMMANDS = ("data", "evaluate", "train", "export", "zoo", "calibrate", "simulate", "sweep", "review")

# Errors a user can cause: printed as one line, exit code 2, no traceback. Anything else is a bug and keeps
# its traceback.
USER_ERRORS: tuple[type[BaseException], ...] = (
    PredictorError,
    SimulationError,
    MPCConfigError,
    PipelineError,
    FileNotFoundError,
    NotADirectoryError,
    IsADirectoryError,
    PermissionError,
)

EPILOG = """examples:
  crowdmpc data prepare --raw ../shared/data/raw_ewap --out data/prepared
  crowdmpc evaluate --predictor constant_velocity --dataset biwi_eth --split test
  crowdmpc simulate --controller cmpc --predictor constant_velocity --scenario circle --humans 7 --episodes 5
"""


class OneLineParser(argparse.ArgumentParser):
    """An argparse parser whose errors are one line and a pointer to ``--help``, exit code 2, instead of the
    usage block (which for a long option list is many lines before the one that matters). Subparsers are of
    the class of their parent (argparse's ``add_subparsers`` default), so every level errs the same way."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}; see '{self.prog} --help'\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="crowdmpc",
        description="Multi-robot navigation in crowds with learned predictors and game-theoretic MPC.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"crowdmpc {crowdmpc_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module_name = f"pipelines.commands.{name}"
        if importlib.util.find_spec(module_name) is None:
            continue
        importlib.import_module(module_name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except USER_ERRORS as exc:
        print(f"crowdmpc {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"crowdmpc {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
