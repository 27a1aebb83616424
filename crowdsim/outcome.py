"""How an episode ended, in the words of every figure's title: simulate's and review's (pipelines) and the
gymnasium environment's frames, from one function so that the three say it alike."""

from __future__ import annotations

import math
from typing import Final

from crowdsim.env_config import EnvConfig
from crowdsim.metrics import EpisodeMetrics

SUCCESS: Final[str] = "success"
TIME_LIMIT: Final[str] = "time_limit"
CONTACT: Final[str] = "contact"  # a robot touched a human in the last step, before the time limit
CUT_SHORT: Final[str] = "cut_short"  # stopped before the time limit by whoever stepped it


def outcome_text(end: str | None, end_s: float, limit_s: float | None, travel_s: float | None = None) -> str:
    """How an episode ended, as simulate's, review's and the gym frames' titles say it: "success in 12.2 s",
    "timeout at 5.2 s (time limit 6 s)". A title once said "timeout" alone: not after how long, nor that the
    paper's profile starts no step within timeout_margin of the limit: a 6 s limit ends its run at 5.2 s."""
    at = f"at {end_s:g} s"
    limit = "" if limit_s is None else f" (time limit {limit_s:g} s)"
    if end == SUCCESS:
        return f"success in {end_s if travel_s is None else travel_s:g} s"
    if end == TIME_LIMIT:
        return f"timeout {at}{limit}"
    if end == CONTACT:
        return f"robot-human contact {at}{limit}"
    if end == CUT_SHORT:
        return f"stopped {at} by its loop{limit}"
    return f"no success, ended {at}{limit}"  # what ended it is not recorded


def ended_text(metrics: EpisodeMetrics, contact_ended: bool, config: EnvConfig) -> str:
    """``outcome_text`` of a gymnasium episode that the environment ended: a success, a contact under
    ``end_on_collision`` (whose metrics say timeout, not success), else the time limit's truncation. The
    frame's title once gave the time alone, so that a last frame read as any other."""
    end = CONTACT if contact_ended else SUCCESS if metrics.success else TIME_LIMIT
    travel = None if math.isnan(metrics.travel_time) else metrics.travel_time
    return outcome_text(end, metrics.n_steps * config.dt, config.time_limit, travel)
