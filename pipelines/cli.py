"""The ``crowdmpc`` command line. Each subcommand lives in ``pipelines/commands/<name>.py``."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import os
import sys
from typing import NoReturn

from pipelines.errors import (
    EPISODES_RAISED,
    CloseFailed,
    EpisodeFailed,
    PipelineError,
    RecordingRefused,
    interrupt_behind,
    one_line,
    storage_refusal,
    warnings_as_notes,
)
from pipelines.lightning_names import lightning_hint

# The order in which subcommands are listed by --help.
COMMANDS = (
    "data",
    "evaluate",
    "train",
    "export",
    "zoo",
    "calibrate",
    "simulate",
    "sweep",
    "compare",
    "review",
    "cache",
    "config",
)


def user_errors() -> tuple[type[BaseException], ...]:
    """Errors a user can cause: printed as one line, exit code 2, no traceback. Anything else is a bug and
    keeps its traceback. Imported when asked for, not with this module: the packages of the other errors
    import numpy and gymnasium (a third of a second, more from a cold disk), which ran before ``main`` could
    catch a Ctrl-C, and a Ctrl-C then printed a library's KeyboardInterrupt traceback, or numpy's "Importing
    the numpy C-extensions failed" advice with exit 1."""
    from crowdsim.errors import SimulationError
    from mpc.errors import MPCConfigError
    from predictors.errors import PredictorError

    return (
        PredictorError,
        SimulationError,
        MPCConfigError,
        PipelineError,
        FileNotFoundError,
        NotADirectoryError,
        IsADirectoryError,
        PermissionError,
    )


def __getattr__(name: str) -> object:
    """``USER_ERRORS``, the tuple of ``user_errors()``, made when first read (``benchmarks/bench_cli.py``)."""
    if name == "USER_ERRORS":
        return user_errors()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


EPILOG = """examples:
  crowdmpc data prepare --raw ../shared/data/raw_ewap --out data/prepared
  crowdmpc evaluate --predictor constant_velocity --dataset biwi_eth --split test
  crowdmpc simulate --controller cmpc --predictor constant_velocity --scenario circle --humans 7 --episodes 5
  crowdmpc --config docs/examples/demo.toml --set mpc.w_coll=1e6 simulate --humans 5 \\
      --record runs/demo-w6-h5 --plot runs/demo-w6-h5/episode.png
  crowdmpc --plugin my_predictor:MyNet train --model my_predictor:MyNet --data-dir ../shared/data

Plugins: --plugin module:Class (before the command; repeatable) registers, for every command and the
sweep's workers, a predictor net of your own (a torch.nn.Module with the step contract of
predictors/nets/contract.py) as the model kind "module:Class", or a robot controller of your own (a class
with name, predictor, reset, act, describe and close: docs/extending.md, section 6) as the controller
"module:Class" (simulate --controller module:Class). The module is imported from the installed packages or
the current directory. $CROWDMPC_PLUGINS and $CROWDMPC_CONTROLLERS (comma-separated) do the same; installed
packages may declare entry points in the groups "crowdmpc.predictors" (nets) and "crowdmpc.controllers"
(controllers). `crowdmpc train` writes a run into its --out; `crowdmpc zoo add` puts the model into the user
zoo, $CROWDMPC_ZOO (default $XDG_DATA_HOME/crowdmpc/zoo or ~/.local/share/crowdmpc/zoo); the shipped zoo
(checkpoints/) is read-only.
"""


class PluginAction(argparse.Action):
    """``--plugin module:NetClass``: registered as soon as it is parsed (``predictors.models``), so that the
    options after it (``train --model module:NetClass``) can name it, and recorded in ``$CROWDMPC_PLUGINS``
    for the processes the command starts. A plugin that does not load is a one-line parser error naming
    --plugin."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        from pipelines.plugins import register_plugins
        from predictors.errors import PredictorError

        try:
            register_plugins([str(values)])
        except PredictorError as exc:
            raise argparse.ArgumentError(self, str(exc)) from None
        items = list(getattr(namespace, self.dest, None) or [])
        setattr(namespace, self.dest, [*items, values])


class OneLineParser(argparse.ArgumentParser):
    """An argparse parser whose errors are one line and a pointer to ``--help``, exit code 2, instead of the
    usage block (which for a long option list is many lines before the one that matters). Subparsers are of
    the class of their parent (argparse's ``add_subparsers`` default), so every level errs the same way."""

    given: list[str] = []  # the command line being parsed (main's argv), for the hint below

    def error(self, message: str) -> NoReturn:
        after = _plugin_after_command(self.prog, OneLineParser.given)
        if (message.startswith("unrecognized arguments:") and "--plugin" in message.split()) or (
            after and "is a plugin that is not registered" in message
        ):
            # `crowdmpc evaluate --plugin m:C ...`: an option of crowdmpc itself, given after the command (a
            # --model naming the plugin was refused first, as not registered, without the hint)
            if message.startswith("unrecognized arguments:"):
                message = _plugin_as_given(message, OneLineParser.given)
            message += " (--plugin goes before COMMAND: crowdmpc --plugin MODULE:CLASS COMMAND ...)"
        message += _train_hint(self, message, OneLineParser.given)
        prog = self.prog
        if message.startswith("unrecognized arguments:") and "--plugin goes" not in message:
            # argparse's top level says it for every command, and --plugin's hint points at the top's help
            prog = " ".join([prog, *_command(self, OneLineParser.given)])
        self.exit(2, f"{prog}: error: {one_line(message)}; see '{prog} --help'\n")


def _command(parser: argparse.ArgumentParser, given: list[str]) -> list[str]:
    """The command of ``given`` that ``parser``'s subcommands know, and its own ("zoo", "list"): `crowdmpc
    calibrate --robots 1` was refused as "crowdmpc: error", pointing at the top level's help."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for k, arg in enumerate(given):
                if arg in action.choices:
                    return [arg, *_command(action.choices[arg], given[k + 1 :])]
    return []


def _train_hint(parser: argparse.ArgumentParser, message: str, given: list[str]) -> str:
    """``lightning_hint`` of ``given`` for an error of `crowdmpc train`'s arguments (refused by the top level
    as unrecognized, or by train's own parser: "--model is required"), else ""."""
    command = _command(parser, given)
    if parser.prog.split()[1:] + command != ["train"]:
        return ""
    if command and not message.startswith("unrecognized arguments:"):
        return ""  # the top level's own (a --plugin that does not import), of no train option
    for name in command:  # the top level's: down to train's own parser, whose options are not hinted
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    words = given[given.index("train") + 1 :] if "train" in given else given
    return lightning_hint(words, parser._option_string_actions)


def _command_run(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[str]:
    """The command parsed into ``args`` with the action of its group ("data", "stats"), read from the
    namespace: an error of `crowdmpc data stats` said "crowdmpc data:", as if of every data action, while
    the parser's own errors name "crowdmpc data stats"."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            name = getattr(args, action.dest, None)
            if name in action.choices:
                return [name, *_command_run(action.choices[name], args)]
    return []


def _plugin_as_given(message: str, given: list[str]) -> str:
    """argparse's "unrecognized arguments: --plugin X" with X the value given after the last --plugin (one
    before the command was taken): before a command's positional argument (`export --plugin m:C NAME`) that
    positional took m:C, and the line named NAME as --plugin's value."""
    words = message.split(" ")
    at = len(given) - 1 - given[::-1].index("--plugin") if "--plugin" in given else len(given)
    if "--plugin" not in words[:-1] or at + 1 >= len(given):
        return message
    words[words.index("--plugin") + 1] = given[at + 1]
    return " ".join(words)


def _plugin_after_command(prog: str, given: list[str]) -> bool:
    """Whether ``--plugin`` comes after the command of subparser ``prog`` ("crowdmpc train") in ``given``."""
    command = prog.split()[-1]
    if command not in given or "--plugin" not in given:
        return False
    return given.index("--plugin") > given.index(command)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="crowdmpc",
        description="Multi-robot navigation in crowds with learned predictors and game-theoretic MPC.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    from pipelines.version import crowdmpc_version  # importlib.metadata: not before main catches a Ctrl-C

    parser.add_argument("--version", action="version", version=f"crowdmpc {crowdmpc_version()}")
    parser.add_argument(
        "--plugin",
        action=PluginAction,
        default=[],
        metavar="MODULE:CLASS",
        help="register a predictor net (model kind MODULE:CLASS) or a robot controller (controller "
        "MODULE:CLASS) of your own (repeatable; before COMMAND)",
    )
    # Config files (pipelines/config): also accepted after simulate, sweep and config show.
    # Appended, not stored: a second --config is refused, not dropped
    # (pipelines.config.command_line.config_arguments).
    parser.add_argument(
        "--config",
        dest="config_file",
        action="append",
        metavar="FILE",
        help="a TOML config file (see `crowdmpc config show`), or a pipe: --config <(...)",
    )
    parser.add_argument(
        "--set",
        dest="config_set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="override one config value, e.g. mpc.w_coll=1e6; =null unsets it (repeatable)",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        module_name = f"pipelines.commands.{name}"
        if importlib.util.find_spec(module_name) is None:
            continue
        importlib.import_module(module_name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The ``crowdmpc`` command: its status, whatever stopped it."""
    from pipelines.commands.standard_output import hold_standard_descriptors

    hold_standard_descriptors()
    if (gone := _no_working_directory()) is not None:
        print(f"crowdmpc: error: {gone}", file=sys.stderr)
        return 2
    if sys.stdout is not None and hasattr(sys.stdout, "reconfigure"):
        # under a locale without "—" or "±" (ASCII, Latin-1) a table printed them as escapes, where it had
        # raised a UnicodeEncodeError once the work was done (stderr does so by Python's default)
        sys.stdout.reconfigure(errors="backslashreplace")
    from pipelines.loop.interrupt import forget_handled_interrupts

    try:
        return _stopped_in_order(argv)
    finally:
        forget_handled_interrupts()  # the status returned is the process's, 128 + a signal included


def _stopped_in_order(argv: list[str] | None) -> int:
    """``main``'s command, an interrupt ended in one line and its status. Its output flushed here, so that a
    reader that left (``crowdmpc review ... | head``) ends the command quietly, with the status of a SIGPIPE,
    instead of a BrokenPipeError traceback."""
    from pipelines.commands import quit_closed_stdout, stdout_reader_left
    from pipelines.loop.interrupt import stop_status, terminate_as_interrupt

    try:
        # from the start: a `kill` while the commands are imported ended the process silently, by the default
        # action, where Ctrl-C printed the line below
        with terminate_as_interrupt():
            try:
                return _main(argv)
            finally:
                if sys.stdout is not None:  # None: started with standard output closed (`>&-`)
                    sys.stdout.flush()
    except BrokenPipeError:
        if not stdout_reader_left():  # another pipe (a worker's): a real error
            raise
        return quit_closed_stdout()
    except KeyboardInterrupt:  # Ctrl-C or kill before a command runs (importing the commands takes a second)
        print(f"{_early_prog(argv)}: interrupted", file=sys.stderr)
        return stop_status()
    except ImportError as exc:  # that Ctrl-C inside an extension's import (scipy: "initialization failed")
        if interrupt_behind(exc) is None:
            raise
        print(f"{_early_prog(argv)}: interrupted", file=sys.stderr)
        return stop_status()


# crowdmpc's own options that take a value (an abbreviation, "--conf F", is one too)
_VALUED: tuple[str, ...] = ("--plugin", "--config", "--set")


def _early_prog(argv: list[str] | None) -> str:
    """The "crowdmpc COMMAND" of a command line stopped before it was parsed, the command read off the words
    without the parser (which is what was being imported): a Ctrl-C in the first second said "crowdmpc:
    interrupted" where a later one names the command. "crowdmpc" where no word before the command's own
    options names one (``--help``, a typo, a value of --config)."""
    words = iter(sys.argv[1:] if argv is None else argv)
    for word in words:
        if word == "--":
            break
        if len(word) > 2 and "=" not in word and any(o.startswith(word) for o in _VALUED):
            next(words, None)  # its value, which may be a command's name ("--config review")
        elif not word.startswith("-"):
            return f"crowdmpc {word}" if word in COMMANDS else "crowdmpc"
    return "crowdmpc"


def _no_working_directory() -> str | None:
    """Why the command cannot run where it was started: a current directory removed while a shell sat in it
    (``rmdir`` from another terminal, a job's scratch folder cleaned). torch then failed to load with Intel
    oneMKL's "FATAL ERROR: Cannot load libtorch_cpu.so" and exit 2, and a relative path names nothing."""
    try:
        os.getcwd()
    except FileNotFoundError:
        return "the current directory no longer exists (removed since the shell entered it); cd to another"
    return None


def _main(argv: list[str] | None) -> int:
    from pipelines.plugins import PluginError, load_environment_plugins

    warnings_as_notes()

    try:  # before parsing: an option that names a plugin would otherwise report a broken one as its own
        load_environment_plugins()
    except PluginError as exc:
        print(f"crowdmpc: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    parser = build_parser()
    OneLineParser.given = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    if getattr(args, "func", None) is None:  # usage, as a missing argument is: on stderr, not stdout
        parser.print_help(sys.stderr)
        print("crowdmpc: error: give a COMMAND (above)", file=sys.stderr)
        return 2
    if (args.config_file or args.config_set) and args.command not in ("simulate", "sweep", "config"):
        parser.error(f"--config and --set apply to simulate, sweep and config, not {args.command}")
    from pipelines.loop.interrupt import stop_status, terminate_as_interrupt

    command = " ".join(_command_run(parser, args))
    try:
        with terminate_as_interrupt():  # `kill`, `timeout`: what Ctrl-C keeps is kept (finished episodes)
            return int(args.func(args) or 0)
    except KeyboardInterrupt:  # first: the clause below may import its errors' packages
        print(f"crowdmpc {command}: interrupted", file=sys.stderr)
        return stop_status()
    except (EpisodeFailed, CloseFailed) as exc:  # before the user errors they are among
        # a refusal of the --record folder is one of the user's input, told alone: the file it names is the
        # episode refused, where the seed of the episode that met it is the first's (which checks every
        # planned file) and no episode to rerun
        refused = isinstance(exc.__cause__, RecordingRefused)
        print(
            f"crowdmpc {command}: error: {one_line(str(exc.__cause__ if refused else exc))}", file=sys.stderr
        )
        return 2 if refused else EPISODES_RAISED
    except user_errors() as exc:
        print(f"crowdmpc {command}: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except OSError as exc:
        if (refusal := storage_refusal(exc)) is None:  # not a full disk: a bug, with its traceback
            raise
        print(f"crowdmpc {command}: error: {one_line(refusal)}", file=sys.stderr)
        return 2
    except Exception as exc:
        if interrupt_behind(exc) is None:  # a bug: its traceback
            raise
        # Ctrl-C inside a CasADi call outside any solve, handed back as a SystemError caused by it
        print(f"crowdmpc {command}: interrupted", file=sys.stderr)
        return stop_status()


if __name__ == "__main__":
    sys.exit(main())
