"""Controller plugins that fail as a sweep's episodes may: ``Dies`` ends its own worker process (as a
segfault in a library or the kernel's OOM killer would), ``RaisesOnCircles`` raises on the circle crossings
(every other episode of a cell, on every run), ``SetInDescribe`` describes itself with a set (no JSON);
``RaisesIn...`` raise in one method each, ``InterruptedInAct`` is Ctrl-C in act, ``HangsOnCircles`` never
returns from act on the circle crossings; ``InterruptsTheSweep`` sends its sweep's driver a Ctrl-C
(``InterruptsThenSleeps`` then runs a minute)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.env import Observation
from tests.plugins.toy_controller import StraightLine


class Dies(StraightLine):
    name = "dies"

    def reset(self, obs: Observation) -> None:
        os.kill(os.getpid(), signal.SIGKILL)


class RaisesOnCircles(StraightLine):
    name = "raises_on_circles"

    def reset(self, obs: Observation) -> None:
        if np.allclose(obs.human_goals, -obs.human_positions, rtol=0, atol=1e-9):  # the circle: goal = -start
            raise RuntimeError("solver crashed on this crowd")


class AlwaysRaises(StraightLine):
    name = "always_raises"

    def reset(self, obs: Observation) -> None:
        raise RuntimeError("broken build")


class SetInDescribe(StraightLine):
    name = "set_in_describe"

    def describe(self) -> dict[str, Any]:
        return {"predictor_sha256": None, "config": {"modes": {"a", "b"}}}


class RaisesInAct(StraightLine):
    name = "raises_in_act"

    def act(self, obs: Observation) -> Any:
        raise RuntimeError("boom in act")


class RaisesInDescribe(StraightLine):
    name = "raises_in_describe"

    def describe(self) -> dict[str, Any]:
        raise KeyError("version")


class RaisesInClose(StraightLine):
    name = "raises_in_close"

    def close(self) -> None:
        raise OSError("cannot release")


class InterruptedInAct(StraightLine):
    name = "interrupted_in_act"

    def act(self, obs: Observation) -> Any:
        raise KeyboardInterrupt


class NaNInThirdEpisode(StraightLine):
    """Returns a NaN acceleration at step 4 of the third episode it runs: research code that fails on one
    crowd of many."""

    name = "nan_in_third_episode"

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.episodes = 0

    def reset(self, obs: Observation) -> None:
        self.episodes += 1

    def act(self, obs: Observation) -> Any:
        out = super().act(obs)
        if self.episodes == 3 and obs.step == 4:
            out.accelerations[0, 0] = np.nan
        return out


class HangsOnCircles(StraightLine):
    """Never returns from ``act`` on a circle crossing, catching every Exception on the way (a plugin waiting
    on something that never comes); other crowds it crosses as StraightLine does."""

    name = "hangs_on_circles"

    def reset(self, obs: Observation) -> None:
        self.circle = bool(np.allclose(obs.human_goals, -obs.human_positions, rtol=0, atol=1e-9))

    def act(self, obs: Observation) -> Any:
        while self.circle:
            try:
                time.sleep(0.02)
            except Exception:  # noqa: S112 (the point: a catch-all that a time limit must get past)
                continue
        return super().act(obs)


class HangsInCloseToo(HangsOnCircles):
    """HangsOnCircles whose ``close`` waits for good too (a driver waiting on the device its act hung on)."""

    name = "hangs_in_close_too"

    def close(self) -> None:
        while True:
            try:
                time.sleep(0.02)
            except Exception:  # noqa: S112 (the point: a catch-all that a time limit must get past)
                continue


class RefusesWeights(StraightLine):
    """Refuses its episodes as a sweep's worker refuses weights replaced in the zoo since the driver checked
    them (pipelines.experiments.checked_weights): the sweep stops at the first."""

    name = "refuses_weights"

    def reset(self, obs: Observation) -> None:
        from pipelines.experiments.checked_weights import WeightsReplaced

        _wait_for_mark(TakesASecond.name)
        raise WeightsReplaced("predictor 'mine': the weights were replaced (a stand-in refusal)")


class TakesASecond(StraightLine):
    """StraightLine whose episodes each take a second more: on another worker, one still running when a
    refusal stops the sweep, and back within the stop's wait."""

    name = "takes_a_second"

    def reset(self, obs: Observation) -> None:
        _mark(self.name)
        time.sleep(1.0)
        super().reset(obs)


class SleepsInReset(StraightLine):
    """StraightLine whose episodes take a minute: one in flight that a stop's bounded wait cuts."""

    name = "sleeps_in_reset"

    def reset(self, obs: Observation) -> None:
        time.sleep(60.0)
        super().reset(obs)


class InterruptsTheSweep(StraightLine):
    """Sends the sweep's driver (``$CROWDMPC_TEST_DRIVER``, a pid: a Ray actor's parent is no driver) SIGINT,
    as a Ctrl-C in its terminal does (the workers ignore theirs), or the signal ``$CROWDMPC_TEST_SIGNAL``
    names (TERM: `kill`, `timeout`), then takes a second more: an episode near its end when the user stops
    the sweep, back within the stop's wait."""

    name = "interrupts_the_sweep"

    def reset(self, obs: Observation) -> None:
        _wait_for_mark(TakesASecond.name)
        sent = signal.Signals["SIG" + os.environ.get("CROWDMPC_TEST_SIGNAL", "INT")]
        os.kill(int(os.environ["CROWDMPC_TEST_DRIVER"]), sent)
        time.sleep(1.0)
        super().reset(obs)


class InterruptsTheSweepTwice(StraightLine):
    """Ctrl-C to the driver (as InterruptsTheSweep), a second one a second later (a user who will not wait),
    then a minute's run."""

    name = "interrupts_the_sweep_twice"

    def reset(self, obs: Observation) -> None:
        driver = int(os.environ["CROWDMPC_TEST_DRIVER"])
        os.kill(driver, signal.SIGINT)
        time.sleep(1.0)
        os.kill(driver, signal.SIGINT)
        time.sleep(60.0)
        super().reset(obs)


class InterruptsThenSleeps(StraightLine):
    """Ctrl-C to the sweep's driver (as InterruptsTheSweep), then a minute's run: the episode a stop's wait
    cuts, with the next one queued behind it on the same worker."""

    name = "interrupts_then_sleeps"

    def reset(self, obs: Observation) -> None:
        os.kill(int(os.environ["CROWDMPC_TEST_DRIVER"]), signal.SIGINT)
        time.sleep(60.0)
        super().reset(obs)


def _mark(name: str) -> None:
    """A file ``name`` in ``$CROWDMPC_TEST_STARTED`` (when set): the episode of ``name`` has started."""
    marks = os.environ.get("CROWDMPC_TEST_STARTED")
    if marks:
        Path(marks, name).touch()


def _wait_for_mark(name: str, bound_s: float = 60.0) -> None:
    """Until ``_mark(name)`` (when ``$CROWDMPC_TEST_STARTED`` is set, at most ``bound_s``): a worker of a
    loaded machine (CI's two test processes on two cores) may not have started its episode when the other's
    reset signals the sweep, and a stopping pool starts none (pipelines.experiments.pool_stop)."""
    marks = os.environ.get("CROWDMPC_TEST_STARTED")
    deadline = time.monotonic() + bound_s
    while marks and not Path(marks, name).exists() and time.monotonic() < deadline:
        time.sleep(0.02)


class MarksThenTakesThreeSeconds(StraightLine):
    """Leaves a file in ``$CROWDMPC_TEST_MARKS`` as its episode starts (a test then signals the sweep), then
    takes three seconds more: an episode back within a stop's wait."""

    name = "marks_then_takes_three_seconds"

    def reset(self, obs: Observation) -> None:
        marks = os.environ["CROWDMPC_TEST_MARKS"]
        Path(marks, f"{os.getpid()}-{time.monotonic_ns()}").touch()
        time.sleep(3.0)
        super().reset(obs)


class MarksThenTakesThreeSecondsToo(MarksThenTakesThreeSeconds):
    """Another controller of the same: a sweep runs each cell's first episode before any second one."""

    name = "marks_then_takes_three_seconds_too"
