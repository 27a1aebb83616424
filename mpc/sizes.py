"""The sizes of the MPC's work: how far each number of ``MPCConfig`` that sets how much a control step builds,
iterates and waits may go. ``MPCConfig`` refuses beyond them, and the CLI's config schema reads them from here
(``pipelines.config.keys.MOST``), so that Python and a config file refuse the same values. Far above any
sensible value: a typo of a few zeros would otherwise run for hours before anything said so.

Unlike ``mpc.config.MPC_BOUNDS``, which the NLP checks as it is built so that a sweep folder that ran beyond a
bound added since reads back, these refuse every ``MPCConfig``: the config schema has refused the same values
since sweeps recorded their configs, so no recorded folder holds one. ``check_team``: the team an NLP is built
for, a count of robots and of humans."""

from __future__ import annotations

import operator
from typing import Any, Final

from mpc.errors import MPCConfigError

# steps: one CasADi call builds the NLP, and 100 among 50 humans took minutes; a config file, export and
# Python all stop here (pipelines.commands.export too)
MAX_HORIZON: Final[int] = 100
MOST_IBR_ITERATIONS: Final[int] = 1000  # j_max (Table I: 10): each one solves the joint or M local NLPs
# solver_max_iter (100 by default). The solvers take it as a C int, which this stays far below: 2**31 made
# IPOPT refuse its options (a RuntimeError when the NLP was built), 2**32 wrapped to 0 and every solve failed.
MOST_SOLVER_ITER: Final[int] = 100_000
MOST_STEP_TIME: Final[float] = 3600.0  # s, time_limit_s (1 s by default): an hour for one control step
# s, time_limit_s's least value (mpc.config.MPC_LEAST: checked as the NLP is built, not by every MPCConfig):
# a nanosecond, the resolution of the clock the steps measure it with (time.perf_counter); 5e-324 passed
# "> 0" and is no time that clock or IPOPT's max_wall_time tells from 1e-9, the tests' budget cut at once.
LEAST_STEP_TIME: Final[float] = 1e-9
# The team an NLP is built for (``check_team``): crowdsim runs at most 12 robots among 50 humans. The joint
# NLP's pairs grow as the square of the robots (50 took 6 s to build, 1000 would take hours) and its
# constraints as the humans (100,000 among 3 robots took a minute): past these a count is a typo, which
# CasADi met with std::bad_alloc (10**12 humans) or its overloads of SX.sym (10**30 robots).
MOST_TEAM_ROBOTS: Final[int] = 1000
MOST_TEAM_HUMANS: Final[int] = 100_000
# The counts: field -> (least, most)
COUNTS: Final[dict[str, tuple[int, int]]] = {
    "horizon": (1, MAX_HORIZON),
    "j_max": (1, MOST_IBR_ITERATIONS),
    "solver_max_iter": (0, MOST_SOLVER_ITER),
}


def check_counts(cfg: Any) -> None:
    """``cfg``'s ``COUNTS``: plain ints within their ranges."""
    for name, (least, most) in COUNTS.items():
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise MPCConfigError(f"{name} must be an integer >= {least}, got {value!r}")
        if value > most:
            raise MPCConfigError(f"{name} must be an integer in [{least}, {most}], got {value!r}")


def check_step_time(seconds: float) -> None:
    """``time_limit_s``, already a finite number > 0, within ``MOST_STEP_TIME``."""
    if seconds > MOST_STEP_TIME:
        raise MPCConfigError(f"time_limit_s must be in (0, {MOST_STEP_TIME:g}] s, got {seconds!r}")


def check_team(n_robots: Any, n_humans: Any, least_robots: int = 0) -> tuple[int, int]:
    """The team an NLP is built for as plain ints (numpy's too), ``n_robots`` >= ``least_robots`` and
    ``n_humans`` >= 0, each at most its ``MOST_TEAM_*``, else a ValueError naming the one that is not: CasADi
    refused them in its own words ("Dimensions must be non-negative, got -8-by-1", or its overloads of
    ``SX.sym`` for 2.5 robots)."""
    counts = []
    team = (
        ("n_robots", n_robots, least_robots, MOST_TEAM_ROBOTS),
        ("n_humans", n_humans, 0, MOST_TEAM_HUMANS),
    )
    for name, value, least, most in team:
        try:
            count = None if isinstance(value, bool) else operator.index(value)
        except TypeError:
            count = None
        if count is None or count < least:
            why = " (a local NLP is one robot's)" if name == "n_robots" and least > 0 else ""
            raise ValueError(f"{name} must be an integer >= {least}{why}, got {value!r}")
        if count > most:
            raise ValueError(f"{name} must be an integer in [{least}, {most}], got {value!r}")
        counts.append(count)
    return counts[0], counts[1]
