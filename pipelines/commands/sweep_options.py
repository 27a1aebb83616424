"""``crowdmpc sweep``'s options beyond the experiment and its sizes (pipelines.commands.sweep): what replaces
the experiment's own choices for every method, where the sweep goes and how it runs, the argparse types of
the --predictors and --controllers lists, and which options set a config key (pipelines/config)."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from pipelines.commands import comma_items, path_arg

if TYPE_CHECKING:
    from pipelines.config import Option


# The options that set a config key when given (their defaults are the config's: pipelines/config).
def config_options() -> tuple[Option, ...]:
    from pipelines.config import Option

    return (
        Option("experiment", "sweep", "experiment", "--experiment"),
        Option("out", "sweep", "out", "--out"),
        Option("episodes_per_cell", "sweep", "episodes_per_cell", "--episodes-per-cell"),
        Option("humans", "sweep", "humans", "--humans"),
        Option("seed", "sweep", "seed", "--seed"),
        Option("workers", "sweep", "workers", "--workers"),
        Option("backend", "sweep", "backend", "--backend"),
        Option("ray_address", "sweep", "ray_address", "--ray-address"),
        Option("record", "sweep", "record", "--record"),
        Option("jit", "sweep", "jit", "--jit"),
        Option("episode_timeout", "sweep", "episode_timeout_s", "--episode-timeout"),
        Option("predictors", "sweep", "predictors", "--predictors"),
        Option("controllers", "sweep", "controllers", "--controllers"),
        Option("robots", "scenario", "robots", "--robots"),
        Option("predictor", "controller", "predictor", "--predictor"),
        Option("margins", "controller", "margins", "--margins"),
        Option("profile", "env", "profile", "--profile"),
        Option("visibility", "env", "robots_visible", "--visibility", lambda v: v == "visible"),
        Option("crowd", "env", "crowd", "--crowd"),
        Option("sensor_range", "simulate", "sensor_range", "--sensor-range"),
        Option("no_sensor_tracks", "simulate", "sensor_tracks", "--no-sensor-tracks", lambda v: not v),
        Option("vary", "sweep", "vary", "--vary", ";".join),
    )


def controller_list(text: str) -> tuple[str, ...]:
    """An argparse type: ``a,b,c`` -> ("a", "b", "c"); whether each is registered is checked with the
    experiment (``Experiment.with_controllers``)."""
    from pipelines.config.settings import MAX_SWAP_PREDICTORS

    names = tuple(comma_items(text))
    if not names or len(names) > MAX_SWAP_PREDICTORS:
        raise argparse.ArgumentTypeError(
            f"expected 1 to {MAX_SWAP_PREDICTORS} names like cmpc,orca, got {text[:64]!r}"
        )
    return names


def predictor_list(text: str) -> tuple[str, ...]:
    """An argparse type: ``a,b,c`` -> ("a", "b", "c"), each a well-formed predictor name."""
    from pipelines.config.settings import MAX_SWAP_PREDICTORS
    from predictors.checkpoint import NAME_PATTERN

    names = tuple(comma_items(text))
    if not names:
        raise argparse.ArgumentTypeError(
            f"expected names like constant_velocity,social_lstm_eth, got {text!r}"
        )
    if len(names) > MAX_SWAP_PREDICTORS:
        raise argparse.ArgumentTypeError(f"at most {MAX_SWAP_PREDICTORS} names, got {len(names)}")
    bad = [name for name in names if NAME_PATTERN.fullmatch(name) is None]
    if bad:
        raise argparse.ArgumentTypeError(f"{bad[0][:64]!r} is not a predictor name")
    return names


def add_method_options(p: argparse.ArgumentParser) -> None:
    """What replaces the experiment's own choices for every method."""
    from crowdsim.profiles import PROFILES, VISIBILITY
    from crowdsim.replay import CROWDS
    from pipelines.experiments.methods import SHIPPED_CONTROLLERS
    from pipelines.loop.replay_data import CROWD_HELP

    p.add_argument(
        "--predictor",
        metavar="NAME",
        help="replace the predictor of every method (table2/table3 default to social_lstm_eth, as the paper)",
    )
    p.add_argument(
        "--predictors",
        type=predictor_list,
        metavar="A,B,C",
        help="the predictors experiment's list, one column each (default: the shipped swap table, with "
        "social_gru_eth and social_attention_eth when the zoo has them)",
    )
    p.add_argument(
        "--controllers",
        type=controller_list,
        metavar="A,B,C",
        help="the controllers experiment's list, one column each (default: "
        f"{','.join(SHIPPED_CONTROLLERS)}; a plugin's module:Class after `crowdmpc --plugin module:Class`)",
    )
    p.add_argument(
        "--margins",
        metavar="SPEC",
        help="safety margins of every method: none (the paper), conformal[:ALPHA[:closed-loop|real]], "
        "conformal-motion[:ALPHA], conformal-shortfall[:ALPHA], fixed:M1,..,MH (default: the experiment's "
        "own, none for table2/table3/predictors/coupling)",
    )
    p.add_argument(
        "--profile",
        choices=sorted(PROFILES),
        help="simulation conventions (default paper: the authors' CrowdNav fork; v1: this project's first)",
    )
    p.add_argument(
        "--visibility",
        choices=VISIBILITY,
        help="whether the humans' ORCA sees the robots (default visible, as the authors' fork)",
    )
    p.add_argument("--crowd", choices=CROWDS, help=CROWD_HELP)
    p.add_argument(
        "--vary",
        action="append",
        metavar="mpc.KEY=V1,V2",
        help="a column per value of an [mpc] setting (or controller.margins=M1,M2) beside each method that "
        "plans, on the same crowds, or of scenario.robots=M1,M2, a simulator setting (env.KEY=V1,V2, "
        "env.orca.KEY=V1,V2; not the profile, visibility or crowd, which --profile, --visibility and --crowd "
        "set for the whole sweep) or simulate.sensor_range=R1,R2 beside every method (Table I's value is a "
        "plain sweep's cell); again: every combination",
    )
    p.add_argument(
        "--sensor-range",
        type=float,
        metavar="M",
        help="every method's controller sees only the humans within M metres of some robot, as a tracker "
        "gives them ([simulate] sensor_range; default: every human; the sensing experiment compares ranges)",
    )
    p.add_argument(
        "--no-sensor-tracks",
        action="store_true",
        default=None,
        help="with --sensor-range: the tracker reports no track lengths",
    )


def add_execution_options(p: argparse.ArgumentParser) -> None:
    """Where the sweep goes, what it keeps, and how it runs."""
    from pipelines.config.settings import JIT_CHOICES
    from pipelines.experiments.worker import RECORD_POLICIES

    p.add_argument(
        "--record",
        choices=RECORD_POLICIES,
        help="keep MCAP logs: of failed episodes (not all robots arrived, or a collision), all, or none",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        help="sweep directory, created; resumed (required, here or in --config)",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="write the table and plots from DIR; run nothing (without --config, every setting not typed "
        "is the one DIR's last run recorded, --experiment too)",
    )
    p.add_argument(
        "--reuse",
        type=path_arg,
        metavar="OTHER",
        help="take the episodes sweep OTHER ran of this plan's cells first, with their runs' code (Table "
        "III's F cells are Table II's CMPC cells), then run the rest",
    )
    p.add_argument("--dry-run", action="store_true", help="print the cells and episode count; run nothing")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (drawn on a terminal only)")
    p.add_argument(
        "--episode-timeout",
        type=float,
        metavar="S",
        help="stop an episode after S s of wall-clock time (a controller that hangs), record it in "
        "errors.jsonl and go on ([sweep] episode_timeout_s; default: no limit)",
    )
    p.add_argument(
        "--jit",
        choices=JIT_CHOICES,
        help="compile the MPC NLPs with gcc, once per machine ($CROWDMPC_CACHE/compiled, `crowdmpc cache "
        "info`): 2-8 s a first compile; solves ~2x faster, ~0.1 s CPU saved a CMPC episode, ~0.2 s a DMPC "
        "one. auto (the default): on when gcc is found, the cache's disk has 64 MB free and the episodes "
        "repay compiling each NLP (8 s CPU joint, 2.3 s local, per distinct cell settings; from 12 episodes "
        "a cell for the 7-predictor swap, 36 for table2); a warm cache is not consulted",
    )
