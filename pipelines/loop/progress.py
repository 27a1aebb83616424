"""The progress a closed loop shows while an episode runs (``run_episodes``' bar of episodes)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from crowdsim.control import ControlOutput
    from crowdsim.env import Observation


class StepShown:
    """The running episode's step beside a bar of episodes: a long horizon's episode takes minutes, and the
    bar sat at 0 of 1 as if hung. Drawn at most every ``every`` seconds (and the bar's ``mininterval``): a
    bar written to a log file (simulate draws one there too) grows by a line's worth each time."""

    every = 0.5

    def __init__(self, bar: Any) -> None:
        self.bar, self.drawn = bar, 0.0
        self.success: str | None = None

    def on_reset(self, obs: Observation, meta: Mapping[str, Any]) -> None: ...

    def on_step(self, obs: Observation, out: ControlOutput, next_obs: Observation) -> None:
        shown = [] if self.success is None else [self.success]
        self.bar.set_postfix_str(", ".join([*shown, f"step={next_obs.step}"]), refresh=False)
        now = time.monotonic()
        if now - self.drawn >= max(self.every, self.bar.mininterval):  # update(0) stops once miniters > 0
            self.bar.refresh()
            self.drawn = now

    def on_end(self, result: Any) -> None: ...  # an EpisodeResult (pipelines.loop.episode imports this)
