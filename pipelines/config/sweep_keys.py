"""The [sweep] section's keys (``crowdmpc sweep``'s run), apart from pipelines.config.schema, which lists
every section: the experiment, its size, where it goes and how it runs."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pipelines.config.keys import Key
from pipelines.config.settings import SweepSettings, available_cpus


def sweep_keys() -> tuple[Key, ...]:
    """The [sweep] keys, in the order ``crowdmpc config show`` writes them."""
    return (*_experiment_keys(), *_running_keys(), *_column_keys())


def _experiment_keys() -> tuple[Key, ...]:
    """Which experiment, where it goes and its size."""
    from pipelines.experiments.cells import EXPERIMENTS, PAPER_EPISODES_PER_CELL

    return (
        Key(
            "experiment",
            "str",
            None,
            f"{' | '.join(sorted(EXPERIMENTS))} (--experiment; sweep needs one)",
            "table2",
        ),
        Key(
            "out",
            "str",
            None,
            "the sweep directory, created and resumed (--out; sweep needs one; a leading ~ is the home "
            "directory)",
            "runs/x",
        ),
        Key(
            "episodes_per_cell",
            "int",
            PAPER_EPISODES_PER_CELL,
            "episodes per cell, circle and perpendicular crossings in turn, the circle first (even: half of "
            "each; the paper's 1000; --episodes-per-cell)",
        ),
        Key("humans", "ints", None, "crowd sizes (--humans); unset: the experiment's own", [5, 6, 7, 8, 9]),
        Key("seed", "int", 0, "base scenario seed: episode i is seed + i // 2 (--seed)"),
    )


def _running_keys() -> tuple[Key, ...]:
    """How and where its episodes run."""
    return (
        Key(
            "workers",
            "int",
            None,
            "parallel workers (--workers); unset: the CPUs this process may use",
            available_cpus(),
        ),
        Key(
            "backend",
            "str",
            "auto",
            "auto (Ray when installed, else processes) | ray | process | inline (--backend)",
        ),
        Key("ray_address", "str", None, "run on this Ray cluster (--ray-address)", "ray://head:10001"),
        Key("record", "str", "none", "keep MCAP logs: none | failures | all (--record)"),
        Key(
            "jit",
            "str",
            "auto",
            "compile the MPC NLPs (once per machine, cached): auto (when it pays back) | on | off (--jit)",
        ),
        Key(
            "episode_timeout_s",
            "float",
            None,
            "s of wall-clock time after which a worker stops an episode (a controller that hangs) and "
            "records it in errors.jsonl (--episode-timeout); unset: no limit",
            600.0,
        ),
    )


def _column_keys() -> tuple[Key, ...]:
    """The columns of the experiments whose columns a user chooses."""
    from pipelines.experiments.methods import SHIPPED_CONTROLLERS

    return (
        Key(
            "predictors",
            "strs",
            None,
            "the predictors experiment's columns (--predictors); unset: the shipped swap table",
            ["constant_velocity", "social_lstm_eth"],
        ),
        Key(
            "controllers",
            "strs",
            None,
            f"the controllers experiment's columns (--controllers); unset: {', '.join(SHIPPED_CONTROLLERS)}",
            ["cmpc", "orca"],
        ),
        Key(
            "vary",
            "str",
            None,
            "a column per value of one [mpc] setting, or controller.margins, beside each method that plans, "
            "or of scenario.robots, a simulator setting (env.KEY, env.orca.KEY) or simulate.sensor_range "
            "beside every method (--vary); several separated by ';': a column per combination; unset: none",
            "mpc.d_min=0.8,0.9,1.0",
        ),
    )


def build_sweep(values: dict[str, Any], built: Mapping[str, Any]) -> SweepSettings:
    return SweepSettings(**values)
