"""The safety side of a sweep's report: per-step frequencies, how close each episode came, what margins cost.

The paper's rates are per episode: an episode counts as a collision when a robot came within d_min = 0.8 m
of a human at any step, so a brush and a long intrusion weigh the same. CrowdNav reports how often the
condition holds per evaluated state as well (crowdsim.metrics.aggregate); both are given, the per-step
frequencies as ``100 sum(x_steps) / sum(n_steps + 1)`` over a cell's episodes. Records written before the
step counts existed still report, with NaN (printed "—") for what they lack.

Those rates sample distances at the steps (every 0.4 s), as the paper's table is compared; CrowdNav takes the
closest approach within each step. ``added_flag_count`` counts a cell's episodes whose closest approach
with linear motion between steps is below d_min (crowdsim.metrics ``collision_between_steps``), cells.csv's
``collision_between_steps_*`` columns; empty when some record predates the field. The same goes
for robots touching each other (``robot_contact``, not a metric of the paper): cells.csv's
``robot_contact_*`` columns and ``robot_contact_step_freq``.

Two plots: the histogram of each episode's minimum robot-human distance, with the contact (0.6 m) and
personal-space (0.8 m) thresholds drawn, shows whether collisions are near misses or deep intrusions; the
success / collision trade-off places each method (for the ``safety`` experiment: conformal margins at
decreasing alpha) against the collision target, its mean travel time written beside it (in the legend past
four methods). pipelines.experiments.safety_plots draws them.

It reads a cell's summary through ``SafetyColumn`` (``pipelines.experiments.summary.CellSummary`` is one)
and imports
nothing from the report that builds on it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, Final, Protocol, cast

import numpy as np

from crowdsim.metrics import ADDED_FLAGS
from crowdsim.reaction import reacts
from crowdsim.world import RADIUS

if TYPE_CHECKING:
    from pipelines.experiments.tasks import Cell


class _Rate(Protocol):
    @property
    def percent(self) -> float: ...

    @property
    def interval(self) -> tuple[float, float]: ...


class SafetyColumn(Protocol):
    """What the safety plots and the histogram read of one cell's summary."""

    @property
    def cell(self) -> Cell: ...

    @property
    def episodes(self) -> int: ...

    @property
    def success(self) -> _Rate: ...

    @property
    def collision(self) -> _Rate: ...

    @property
    def travel_time_mean(self) -> float: ...

    @property
    def min_distances(self) -> tuple[float, ...]: ...


MIN_DISTANCE_HIST_PNG: Final[str] = "min_distance_hist.png"
MIN_DISTANCE_HIST_CSV: Final[str] = "min_distance_hist.csv"
SAFETY_TRADEOFF_PNG: Final[str] = "safety_tradeoff.png"

# each a metrics "<name>_steps"; robot_contact is robots touching each other, not a metric of the paper
STEP_COUNTS: Final[tuple[str, ...]] = ("collision", "contact", "discomfort", "robot_contact")
CONTACT_DISTANCE: Final[float] = 2.0 * RADIUS  # m, the radii touch: crowdsim.metrics' contact
# The collision rate the trade-off plot measures methods against: the paper's Table II stays below it at
# every crowd size (at most 1.9 %; Table III's NF column reaches 2.4 % at 9 humans).
COLLISION_TARGET: Final[float] = 2.0  # %
HIST_BIN_WIDTH: Final[float] = 0.05  # m
HIST_MAX: Final[float] = 3.0  # m; farther minima (and episodes without humans) share one overflow bin
# Rounded so that the CSV reads 0.05, 0.1, ... rather than accumulated floating-point sums.
HIST_EDGES: Final[np.ndarray] = np.round(np.arange(0.0, HIST_MAX + HIST_BIN_WIDTH / 2, HIST_BIN_WIDTH), 6)


# ----------------------------------------------------------------------------------------------------------
# Numbers
# ----------------------------------------------------------------------------------------------------------


def step_frequency(metrics: Sequence[Mapping[str, Any]], name: str) -> float:
    """% of evaluated states (rows 0..T of every episode) at which ``name`` held; NaN when some episode
    lacks the count (an older record) or there are no episodes, rather than a rate over part of the cell."""
    counts = [m.get(f"{name}_steps") for m in metrics]
    steps = [m.get("n_steps") for m in metrics]
    if not metrics or any(c is None for c in counts) or any(n is None for n in steps):
        return math.nan
    # No None left (checked above).
    return 100.0 * sum(cast("list[float]", counts)) / sum(n + 1 for n in cast("list[float]", steps))


def added_flag_count(metrics: Sequence[Mapping[str, Any]], name: str) -> int | None:
    """The episodes in which ``name`` (a crowdsim.metrics flag added after the first records: a
    ``*_between_steps`` flag, ``robot_contact``) held; None when some episode lacks it (an older record) or
    there are no episodes."""
    flags = [m.get(name) for m in metrics]
    if not flags or any(f is None for f in flags):
        return None
    return sum(bool(f) for f in flags)


def min_distances(metrics: Sequence[Mapping[str, Any]]) -> tuple[float, ...]:
    """Each episode's minimum robot-human distance (m); null (as_dict's inf: no human) is inf."""
    return tuple(math.inf if m.get("min_distance") is None else float(m["min_distance"]) for m in metrics)


def safety_figures(metrics: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """A cell summary's safety fields from the cell's metrics dicts."""
    distances = min_distances(metrics)
    finite = [d for d in distances if math.isfinite(d)]
    return {f"{name}_step_freq": step_frequency(metrics, name) for name in STEP_COUNTS} | {
        "min_distance_median": float(np.median(finite)) if finite else math.nan,
        "min_distances": distances,
        # the flags added after the first records, counted per cell like the paper's rates
        "added_flag_counts": {name: added_flag_count(metrics, name) for name in ADDED_FLAGS},
    }


def world_columns(cell: Cell) -> dict[str, str]:
    """The conventions a cell ran under, as cells.csv and the histogram CSV name them."""
    return {
        "margins": cell.spec.margins.label,
        "profile": cell.world.profile,
        "visibility": cell.world.visibility,
        "sensing": cell.world.sensing_label,
    }


def _world_names(cells: Sequence[Cell]) -> tuple[str, ...]:
    """The ``world_columns`` the table names; sensing only where some column senses, so that the tables of
    full observation read as before sensing existed."""
    sensed = any(c.world.sensor_range is not None for c in cells)
    return ("margins", "profile", "visibility") + (("sensing",) if sensed else ())


def world_row_label(cells: Sequence[Cell]) -> str:
    """The table's row of each column's conventions: "Margins / profile / visibility[ / sensing]"."""
    return " / ".join(_world_names(cells)).capitalize()


def world_note(cells: Sequence[Cell]) -> tuple[str, list[str] | None]:
    """The table notes' line on margins, profile, visibility (and sensing, where some column senses), and,
    when they differ across the columns, each column's "margins / profile / visibility" for a row of its
    own (``world_row_label``; else None)."""
    names = _world_names(cells)
    worlds = [tuple(world_columns(c)[name] for name in names) for c in cells]
    margins, profiles, visibilities, *sensings = (sorted(set(values)) for values in zip(*worlds, strict=True))
    parts = [
        f"Margins: {margins[0]}" if len(margins) == 1 else "Margins: per column",
        f"profile {profiles[0]}" if len(profiles) == 1 else "profile per column",
        f"robots {visibilities[0]} to the humans"
        if len(visibilities) == 1
        else "robot visibility per column",
    ]
    for sensing in sensings:
        parts.append(f"sensor range {sensing[0]}" if len(sensing) == 1 else "sensing per column")
    crowds = sorted({c.world.crowd for c in cells})
    if crowds != ["orca"] and not any(map(reacts, crowds)):  # they see no robot: the visibility does nothing
        parts[2] = f"humans replayed from BIWI {', '.join(crowds)} (reacting to no one)"
    elif crowds != ["orca"]:  # the reactive replays yield to the robots they see, as ORCA's humans do
        parts.insert(2, f"humans replayed from BIWI {', '.join(crowds)} (yielding to visible robots)")
    line = f"{parts[0]}; " + ", ".join(parts[1:]) + "."
    per_column = None
    if len(set(worlds)) > 1:
        line = line[:-1] + f" (row '{world_row_label(cells)}')."
        per_column = [" / ".join(w) for w in worlds]
    # Settings every column shares beside Table I's (a config file's guidance, stall release, ...): without
    # them a safe-crossing sweep's table read the same as one with the margins alone.
    shared = set.intersection(*(set(c.spec.mpc_overrides) for c in cells)) if cells else set()
    if shared:
        line += " MPC settings: " + ", ".join(f"{k}={v}" for k, v in sorted(shared)) + "."
    for controller, own in _controller_settings(cells, shared).items():
        line += f" {controller}'s: " + ", ".join(f"{k}={v}" for k, v in own) + "."
    # a sweep's [env], [env.orca] (every column's); a --vary env.KEY column's value is in its label: listed
    # here, time_limit=3.0 of one column read as every column's beside one of 40
    simulator = sorted(set.intersection(*(set(c.world.env_settings) for c in cells))) if cells else []
    if simulator:
        line += " Simulator settings over the profile's: " + ", ".join(f"{k}={v}" for k, v in simulator) + "."
    return line, per_column


def _controller_settings(cells: Sequence[Cell], shared: set[tuple[str, Any]]) -> dict[str, list[Any]]:
    """The settings beside ``shared`` that every column of one controller shares, by controller ("DMPC"):
    safe_crossing.toml's Gauss-Seidel update is DMPC's alone, and Table II's table read as the paper's Jacobi.
    A setting some of a controller's columns lack (a --vary column's, in its label) is not one of them."""
    by_controller: dict[str, list[set[tuple[str, Any]]]] = {}
    for cell in cells:
        by_controller.setdefault(cell.spec.controller, []).append(set(cell.spec.mpc_overrides) - shared)
    named = {"cmpc": "CMPC", "dmpc": "DMPC"}
    return {
        named.get(controller, controller): sorted(common)
        for controller, settings in by_controller.items()
        if (common := set.intersection(*settings))
    }


def min_distance_counts(distances: Sequence[float]) -> np.ndarray:
    """Episodes per HIST_EDGES bin, then one overflow count for minima of HIST_MAX or more, so that every
    episode is counted once: len(HIST_EDGES) counts."""
    d = np.asarray(distances, dtype=float)
    inside = np.histogram(d[d < HIST_MAX], bins=HIST_EDGES)[0]
    return np.append(inside, int((d >= HIST_MAX).sum()))


def min_distance_hist_rows(summaries: Sequence[SafetyColumn]) -> list[dict[str, Any]]:
    """min_distance_hist.csv: a row per cell and bin (the last bin, up to inf, is the overflow)."""
    upper = np.append(HIST_EDGES[1:], math.inf)
    rows = []
    for s in summaries:
        cell = {"cell": s.cell.key, "method": s.cell.method, "n_humans": s.cell.n_humans} | world_columns(
            s.cell
        )
        for lo, hi, count in zip(HIST_EDGES, upper, min_distance_counts(s.min_distances), strict=True):
            rows.append(cell | {"bin_lo_m": float(lo), "bin_hi_m": float(hi), "episodes": int(count)})
    return rows
