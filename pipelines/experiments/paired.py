"""Paired comparisons: the exact McNemar test and how its p-value is printed (``mcnemar_exact``, ``p_text``),
which table.md's paired successes (pipelines.experiments.tables) and ``crowdmpc compare`` share; and one run
against the first on the episodes both hold (``crowdmpc compare``, pipelines.experiments.compare): each
episode's ``Outcome``, the paired counts of each flag with the McNemar test and Newcombe's interval
(``Paired``, ``paired_interval``), and the travel time's paired difference (``versus``); one run's own rates
(``side``). The statistics are described in pipelines.experiments.compare's docstring."""

from __future__ import annotations

import math
import operator
import statistics
from dataclasses import dataclass
from typing import Final

from pipelines.errors import PipelineError
from pipelines.experiments.summary import t95, wilson_interval

# The paper's per-episode outcomes (Section VI): discomfort too is "% of simulations" with the event, each
# episode's flag, so it pairs as the others do (McNemar, Newcombe), not as a mean of per-step frequencies.
FLAGS: Final[tuple[str, ...]] = ("success", "collision", "contact", "discomfort")


def mcnemar_exact(b: int, c: int) -> float:
    """Two-sided exact McNemar test: the p-value of ``b`` vs ``c`` discordant pairs under a fair coin."""
    # Python integers: numpy's int64 would overflow in the terms below and in 1 << n, silently.
    b, c = operator.index(b), operator.index(c)
    n = b + c
    if n == 0:
        return 1.0
    # C(n, k) for k <= min(b, c) built term by term: exact integers, linear in n (math.comb per term was
    # quadratic), and an integer ratio, which cannot overflow a float as 2.0**n did from n = 1024.
    term = tail = 1
    for k in range(min(b, c)):
        term = term * (n - k) // (k + 1)
        tail += term
    return min(1.0, 2 * tail / (1 << n))


# The levels a p-value is read against. At two significant digits McNemar's 0.0498 (+42 / −25) printed as
# 0.05 and 0.00997 (+74 / −45) as 0.01: significant, read as not.
SIGNIFICANCE_LEVELS: Final[tuple[float, ...]] = (0.05, 0.01, 0.001)


def p_text(p: float) -> str:
    """``p`` to two significant digits, or as many more as keep it on its own side of each of
    ``SIGNIFICANCE_LEVELS`` (17 give ``p`` itself)."""
    for digits in range(2, 17):
        text = f"{p:.{digits}g}"
        if all((float(text) < level) == (p < level) for level in SIGNIFICANCE_LEVELS):
            return text
    return f"{p:.17g}"


@dataclass(frozen=True, slots=True)  # one per episode: a million a run at 1000x Table II
class Outcome:
    """What one episode of a run is compared by. ``digest`` stands for every metric it recorded, ``core`` for
    those every record has (not crowdsim.metrics' ``ADDED_FIELDS``, which ``added`` names where present)."""

    success: bool
    collision: bool
    contact: bool
    discomfort: bool
    travel_time: float | None
    key: str
    digest: bytes
    core: bytes
    added: frozenset[str]

    def same_metrics(self, other: Outcome) -> bool:
        """Every metric equal; where one record predates some of ``ADDED_FIELDS``, every metric but those."""
        return self.digest == other.digest if self.added == other.added else self.core == other.core


@dataclass(frozen=True)
class Paired:
    """One flag, one run against the first, on the shared episodes: ``gained`` where only the run has it,
    ``lost`` where only the first has it, ``both`` and ``neither``."""

    gained: int
    lost: int
    both: int = 0
    neither: int = 0

    @property
    def p(self) -> float:
        return mcnemar_exact(self.gained, self.lost)

    @property
    def difference(self) -> float:
        """The run's rate minus the first's, as a fraction."""
        n = self.gained + self.lost + self.both + self.neither
        return (self.gained - self.lost) / n if n else math.nan

    @property
    def interval(self) -> tuple[float, float]:
        return paired_interval(self.both, self.gained, self.lost, self.neither)

    def text(self) -> str:
        return f"+{self.gained} / −{self.lost} (p = {p_text(self.p)})"


def paired_interval(both: int, gained: int, lost: int, neither: int) -> tuple[float, float]:
    """The 95 % interval, as fractions, of a run's rate minus the first run's on paired episodes (``both``
    with the outcome, ``gained`` in the run alone, ``lost`` in the first alone, ``neither``): Newcombe's
    square-and-add of the two Wilson intervals, with the correlation of the pairs (continuity-corrected
    phi; R. G. Newcombe, Statistics in Medicine 17, 2635-2650, 1998, method 10). (nan, nan) for no pair."""
    n = both + gained + lost + neither
    if n == 0:
        return math.nan, math.nan
    p1, p2 = (both + gained) / n, (both + lost) / n
    (l1, u1), (l2, u2) = wilson_interval(both + gained, n), wilson_interval(both + lost, n)
    product = (both + gained) * (lost + neither) * (both + lost) * (gained + neither)
    cross = both * neither - gained * lost
    phi = 0.0
    if product and cross > n / 2:
        phi = (cross - n / 2) / math.sqrt(product)
    elif product and cross < 0:
        phi = cross / math.sqrt(product)
    below = math.sqrt(max(0.0, (p1 - l1) ** 2 + (u2 - p2) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2)))
    above = math.sqrt(max(0.0, (u1 - p1) ** 2 + (p2 - l2) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2)))
    return max(-1.0, p1 - p2 - below), min(1.0, p1 - p2 + above)


@dataclass(frozen=True)
class Side:
    """One run's figures in one group: rates in %, mean travel time over its successes."""

    n: int
    rates: dict[str, float]
    travel: float | None


@dataclass(frozen=True)
class Versus:
    """One run against the first in one group."""

    flags: dict[str, Paired]
    travel_difference: float | None  # mean of (run - first) over the episodes both completed, s
    travel_half_width: float | None
    travel_n: int
    same: int  # episodes whose every metric equals the first run's

    def travel_text(self) -> str:
        if self.travel_difference is None:
            return "n/a"
        spread = "" if self.travel_half_width is None else f" ± {self.travel_half_width:.2f}"
        return f"{self.travel_difference:+.2f}{spread} ({self.travel_n})"


def side(outcomes: list[Outcome]) -> Side:
    travel = [o.travel_time for o in outcomes if o.success and o.travel_time is not None]
    rates = {name: 100.0 * sum(getattr(o, name) for o in outcomes) / len(outcomes) for name in FLAGS}
    mean = sum(travel) / len(travel) if travel else None
    if mean is not None and not math.isfinite(mean):
        _past_range("the mean travel time", outcomes)
    return Side(len(outcomes), rates, mean)


def versus(base: list[Outcome], other: list[Outcome]) -> Versus:
    """``other`` against ``base``, the same episodes in the same order."""
    pairs = list(zip(base, other, strict=True))
    flags = {
        name: Paired(
            sum(getattr(o, name) and not getattr(b, name) for b, o in pairs),
            sum(getattr(b, name) and not getattr(o, name) for b, o in pairs),
            sum(getattr(b, name) and getattr(o, name) for b, o in pairs),
            sum(not getattr(b, name) and not getattr(o, name) for b, o in pairs),
        )
        for name in FLAGS
    }
    differences = [
        o.travel_time - b.travel_time
        for b, o in pairs
        if b.success and o.success and b.travel_time is not None and o.travel_time is not None
    ]
    n = len(differences)
    try:  # statistics' errors at a float's end: fsum's OverflowError and ValueError (-inf + inf), stdev's
        # AttributeError (of an inf)
        mean = statistics.fmean(differences) if differences else None
        half = t95(n - 1) * statistics.stdev(differences) / math.sqrt(n) if n > 1 else None
    except (OverflowError, ValueError, AttributeError):
        mean = half = math.inf
    if not all(math.isfinite(x) for x in (mean or 0.0, half or 0.0, *differences)):
        _past_range("the travel times' paired difference", [*base, *other])
    same = sum(b.same_metrics(o) for b, o in pairs)
    return Versus(flags, mean, half, len(differences), same)


def _past_range(what: str, outcomes: list[Outcome]) -> None:
    """PipelineError for ``what``, past a float's range: only a hand-edited record holds such a travel time
    (the finite numbers a record may hold go to 1.8e308 s), and Python's statistics ended compare in a
    traceback on it. Names the episode of the longest travel time."""
    longest = max(outcomes, key=lambda o: -1.0 if o.travel_time is None else abs(o.travel_time))
    raise PipelineError(
        f"{what} is past a float's range: episode {longest.key} records a travel time of "
        f"{longest.travel_time!r} s, which no episode runs (a damaged record)"
    )
