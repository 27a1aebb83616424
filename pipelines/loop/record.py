"""One finished episode as data: the record that simulate's JSON, the MCAP ``/episode/metrics`` message
and the sweep's ``episodes.jsonl`` lines all serialise (each adds what only it knows: a sweep its cell).

Solve times are per control step, in ms: median, p95 and max through ``step_time_stats``, the one function
every report states them with.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from crowdsim.metrics import EpisodeMetrics, aggregate
from pipelines.errors import PipelineError
from pipelines.plain_json import plain


def step_time_stats(seconds: Sequence[float] | np.ndarray) -> dict[str, float | None]:
    """Median, 95th percentile and maximum of control-step wall times in ms (None when there are none)."""
    ms = np.asarray(seconds, dtype=float) * 1e3
    if ms.size == 0:
        return {"median_ms": None, "p95_ms": None, "max_ms": None}
    return {
        "median_ms": float(np.median(ms)),
        "p95_ms": float(np.percentile(ms, 95)),
        "max_ms": float(ms.max()),
    }


@dataclass(frozen=True)
class SolverStats:
    """What the episode's control steps cost and how they ended."""

    steps: int
    total_ms: float
    median_ms: float | None
    p95_ms: float | None
    max_ms: float | None
    mean_iterations: float | None  # IBR iterations per control step
    max_iterations: int | None
    fallback_steps: int
    statuses: Mapping[str, int] = field(default_factory=dict)  # solver status -> steps
    fallbacks: Mapping[str, int] = field(default_factory=dict)  # fallback used -> steps

    @classmethod
    def of_steps(
        cls,
        solve_times_s: Sequence[float] | np.ndarray,
        iterations: Sequence[int] | np.ndarray,
        statuses: Iterable[str],
        fallbacks: Iterable[str | None],
    ) -> SolverStats:
        times = np.asarray(solve_times_s, dtype=float)
        its = np.asarray(iterations, dtype=float)
        used = [str(f) for f in fallbacks if f is not None]
        return cls(
            steps=int(times.size),
            total_ms=float(times.sum() * 1e3),
            **step_time_stats(times),
            mean_iterations=float(its.mean()) if its.size else None,
            max_iterations=int(its.max()) if its.size else None,
            fallback_steps=len(used),
            statuses=dict(Counter(str(s) for s in statuses)),
            fallbacks=dict(Counter(used)),
        )


@dataclass(frozen=True)
class EpisodeRecord:
    """Who drove, in which episode, what happened and what it cost (no trajectories)."""

    seed: int | None  # None: no seed drew the episode (a gym episode started from a layout)
    scenario: str
    n_humans: int
    n_robots: int
    controller: str
    predictor: str | None
    predictor_sha256: str | None
    metrics: EpisodeMetrics
    solver: SolverStats

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN and inf become null)."""
        out = {name: getattr(self, name) for name in self.__dataclass_fields__}
        out["metrics"] = self.metrics.as_dict()
        return plain(out)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> EpisodeRecord:
        """Rebuild from ``to_dict``'s output (a sweep's record line, an MCAP ``/episode/metrics`` message)."""
        try:
            known = SolverStats.__dataclass_fields__
            return cls(
                seed=None if data["seed"] is None else int(data["seed"]),
                scenario=str(data["scenario"]),
                n_humans=int(data["n_humans"]),
                n_robots=int(data["n_robots"]),
                controller=str(data["controller"]),
                predictor=data.get("predictor"),
                predictor_sha256=data.get("predictor_sha256"),
                metrics=EpisodeMetrics.from_dict(data["metrics"]),
                solver=SolverStats(**{k: v for k, v in data["solver"].items() if k in known}),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise PipelineError(f"not an episode record ({type(exc).__name__}: {exc})") from None


class EpisodeConfigs:
    """An observer keeping each episode's effective config, in the order the episodes start: the "config"
    its recording's metadata and a sweep's line hold (``contract.episode_config``: the simulator's settings,
    the MPC's config, the margins in metres). ``run``'s "config" is the config file's form, which names the
    margins as given (``conformal:0.1``), not the metres the zoo's calibration gave them, which
    recalibrating changes."""

    def __init__(self) -> None:
        self.configs: list[dict[str, Any]] = []

    def on_reset(self, obs: Any, meta: Mapping[str, Any]) -> None:
        config = plain(meta["config"])
        # the same config as the last episode's is held once: a run's episodes mostly share one
        self.configs.append(self.configs[-1] if self.configs and self.configs[-1] == config else config)

    def on_step(self, obs: Any, out: Any, next_obs: Any) -> None:
        pass

    def on_end(self, result: Any) -> None:
        pass


class SteppedEpisode(Protocol):
    """What ``summarize`` reads of an episode (``pipelines.loop.episode.EpisodeResult``, which imports this
    module)."""

    @property
    def metrics(self) -> EpisodeMetrics: ...
    @property
    def solve_times_s(self) -> np.ndarray: ...
    @property
    def iterations(self) -> np.ndarray: ...
    @property
    def statuses(self) -> tuple[str, ...]: ...
    @property
    def fallbacks(self) -> tuple[str | None, ...]: ...


def summarize(results: Sequence[SteppedEpisode]) -> dict[str, Any]:
    """Episode metrics (``crowdsim.metrics.aggregate``: the rates sampled at the steps, and the collision and
    contact rates between steps) and control-step costs over all steps of all episodes.

    Solve times in ms per control step: median, p95, max; IBR iterations: mean and max; fallback steps.
    """
    out: dict[str, Any] = dict(aggregate([r.metrics for r in results]))
    times = np.concatenate([r.solve_times_s for r in results])
    its = np.concatenate([r.iterations for r in results])
    has = times.size > 0
    out["control_steps"] = int(times.size)
    out.update({f"solve_time_{k}": v for k, v in step_time_stats(times).items()})
    out["iterations_mean"] = float(its.mean()) if has else math.nan
    out["iterations_max"] = int(its.max()) if has else 0
    out["fallback_steps"] = int(sum(f is not None for r in results for f in r.fallbacks))
    out["statuses"] = dict(Counter(s for r in results for s in r.statuses))
    return out
