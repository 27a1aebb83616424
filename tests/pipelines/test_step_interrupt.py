"""Ctrl-C during an episode is raised where the step in progress ends (pipelines/loop/interrupt.py): CasADi's
own check inside a solve wrote "KeyboardInterrupt" (or IPOPT's warning) on stderr above the CLI's one line."""

from __future__ import annotations

import os
import signal

import gymnasium as gym
import pytest

import crowdsim
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode
from pipelines.loop.gym_loop import run_gym_episode


@pytest.fixture(autouse=True)
def python_default_sigint():
    """Python's own SIGINT handler, as a program run from a terminal has it; a test run started in the
    background (`make test &`, nohup, some CI runners) inherits SIGINT ignored, which the loop keeps."""
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, saved)


class _Steps:
    def __init__(self) -> None:
        self.steps = 0

    def on_reset(self, obs, meta) -> None:
        pass

    def on_step(self, obs, out, next_obs) -> None:
        self.steps += 1

    def on_end(self, result) -> None:
        pass


def _signalled(name: str, at_step: int, signals: int = 1):
    """A shipped controller whose ``act`` sends itself ``signals`` SIGINTs at step ``at_step`` and then does
    its work (a solve, for cmpc): ``acts`` says how far each call got."""
    controller = make_controller(ControllerSpec(name))
    act = controller.act
    acts: list[str] = []

    def signalled_act(obs):
        acts.append("started")
        if len(acts) == at_step:
            for _ in range(signals):
                os.kill(os.getpid(), signal.SIGINT)
        out = act(obs)
        acts[-1] = "finished"
        return out

    controller.act = signalled_act  # type: ignore[method-assign]
    return controller, acts


def _episode(controller, observer, gym_loop: bool):
    if gym_loop:
        env = gym.make(crowdsim.ENV_ID, n_humans=2)
        return run_gym_episode(controller, env, seed=0, observers=[observer])
    return run_episode(controller, seed=0, scenario="circle", n_humans=2, observers=[observer])


@pytest.mark.parametrize("gym_loop", [False, True], ids=["run_episode", "run_gym_episode"])
@pytest.mark.parametrize("name", ["straight", "cmpc"])
def test_ctrl_c_is_raised_when_the_step_in_progress_ends(name, gym_loop):
    controller, acts = _signalled(name, at_step=3)
    observer = _Steps()
    with pytest.raises(KeyboardInterrupt):
        _episode(controller, observer, gym_loop)
    assert acts == ["finished"] * 3  # the third step's solve ran to its end, and no fourth began
    assert observer.steps == 3
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_second_ctrl_c_is_raised_at_once():
    controller, acts = _signalled("straight", at_step=2, signals=2)
    with pytest.raises(KeyboardInterrupt):
        _episode(controller, _Steps(), gym_loop=False)
    assert acts == ["finished", "started"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_episode_without_ctrl_c_restores_the_default_handler():
    controller, acts = _signalled("straight", at_step=10**9)
    result = _episode(controller, _Steps(), gym_loop=False)
    assert result.metrics.success and set(acts) == {"finished"}
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_handler_of_the_callers_own_is_kept():
    """A program (or a sweep worker) that set its own SIGINT handler gets the signal as before."""
    seen: list[int] = []
    saved = signal.signal(signal.SIGINT, lambda signum, frame: seen.append(signum))
    try:
        controller, acts = _signalled("straight", at_step=2)
        result = _episode(controller, _Steps(), gym_loop=False)
        assert seen == [signal.SIGINT] and result.metrics.success
        assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, saved)


def test_sigint_ignored_by_the_caller_stays_ignored():
    """A background job (`cmd &` in a script, nohup) starts with SIGINT ignored: the loop leaves it so."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    controller, acts = _signalled("straight", at_step=2)
    result = _episode(controller, _Steps(), gym_loop=False)
    assert result.metrics.success and set(acts) == {"finished"}
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
