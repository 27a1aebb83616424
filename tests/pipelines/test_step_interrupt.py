"""Ctrl-C during an episode is raised where the step in progress ends (pipelines/loop/interrupt.py): CasADi's
own check inside a solve wrote "KeyboardInterrupt" (or IPOPT's warning) on stderr above the CLI's one line.
SIGTERM and SIGHUP, under terminate_as_interrupt (every CLI command), are taken the same way."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import gymnasium as gym
import pytest

import crowdsim
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode
from pipelines.loop.gym_loop import run_gym_episode
from pipelines.loop.interrupt import STEP_GRACE_S, stop_status, terminate_as_interrupt

REPO = Path(__file__).resolve().parents[2]


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


def _signalled(name: str, at_step: int, signals: int = 1, sig: int = signal.SIGINT):
    """A shipped controller whose ``act`` sends itself ``signals`` ``sig`` at step ``at_step`` and then does
    its work (a solve, for cmpc): ``acts`` says how far each call got."""
    controller = make_controller(ControllerSpec(name))
    act = controller.act
    acts: list[str] = []

    def signalled_act(obs):
        acts.append("started")
        if len(acts) == at_step:
            for _ in range(signals):
                os.kill(os.getpid(), sig)
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


class _SignalledAtEnd(_Steps):
    """An observer that is sent ``sig`` as it ends the episode, as a recorder finishing its file may be."""

    def __init__(self, sig: int) -> None:
        super().__init__()
        self.sig = sig
        self.ended = False

    def on_end(self, result) -> None:
        os.kill(os.getpid(), self.sig)
        self.ended = True  # a recorder's rename, after its footer


@pytest.mark.parametrize("gym_loop", [False, True], ids=["run_episode", "run_gym_episode"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl_c", "terminate"])
def test_an_interrupt_as_the_observers_end_is_raised_once_they_have_ended(sig, gym_loop, default_terminate):
    """The observers' ends ran outside the loop's hold: a `kill` of simulate while the recorder finished an
    episode's file (footer written and synced, not yet renamed) left it as a .part (a fresh clone's suite
    failed test_a_terminated_simulate_keeps_the_episodes_that_finished so, under load)."""
    observer = _SignalledAtEnd(sig)
    with terminate_as_interrupt(), pytest.raises(KeyboardInterrupt):
        _episode(make_controller(ControllerSpec("straight")), observer, gym_loop)
    assert observer.ended


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


@pytest.fixture
def default_terminate():
    """SIGTERM and SIGHUP with their default actions, as a program run from a terminal has them; a test run
    under `nohup` inherits SIGHUP ignored."""
    saved = {s: signal.signal(s, signal.SIG_DFL) for s in (signal.SIGTERM, signal.SIGHUP)}
    yield
    for s, handler in saved.items():
        signal.signal(s, handler)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_a_terminate_is_raised_when_the_step_in_progress_ends(sig, default_terminate):
    controller, acts = _signalled("cmpc", at_step=3, sig=sig)
    observer = _Steps()
    with terminate_as_interrupt(), pytest.raises(KeyboardInterrupt):
        _episode(controller, observer, gym_loop=False)
    assert acts == ["finished"] * 3 and observer.steps == 3
    assert signal.getsignal(sig) is signal.SIG_DFL  # the caller's handler back


def test_a_terminate_with_sigint_ignored_is_raised_when_the_step_in_progress_ends(default_terminate):
    """`crowdmpc simulate ... &` in a script starts with SIGINT ignored, so the loop installs no note of its
    own; a `kill` then raised KeyboardInterrupt inside CasADi's solve, which printed "KeyboardInterrupt" of
    its own above the CLI's line."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    controller, acts = _signalled("cmpc", at_step=3, sig=signal.SIGTERM)
    with terminate_as_interrupt(), pytest.raises(KeyboardInterrupt):
        _episode(controller, _Steps(), gym_loop=False)
    assert acts == ["finished"] * 3  # the third step's solve ran to its end
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_a_hangup_the_caller_ignores_stays_ignored(default_terminate):
    """`nohup crowdmpc sweep ...` starts with SIGHUP ignored, to outlive its terminal: the sweep had taken
    the hangup as a Ctrl-C all the same."""
    signal.signal(signal.SIGHUP, signal.SIG_IGN)
    controller, acts = _signalled("straight", at_step=2, sig=signal.SIGHUP)
    with terminate_as_interrupt():
        try:
            result = _episode(controller, _Steps(), gym_loop=False)
        except KeyboardInterrupt:  # what would otherwise stop pytest itself
            pytest.fail("the hangup the caller ignores was raised as a Ctrl-C")
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    assert result.metrics.success and set(acts) == {"finished"}


def test_a_terminate_outside_an_episode_is_raised_at_once(default_terminate):
    with terminate_as_interrupt(), pytest.raises(KeyboardInterrupt, match="SIGTERM"):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the handler runs in the main thread before the sleep's end


@pytest.mark.parametrize(
    ("sig", "status"), [(signal.SIGTERM, 143), (signal.SIGHUP, 129)], ids=["TERM", "HUP"]
)
def test_the_exit_status_names_the_signal_as_a_shell_does(default_terminate, sig, status):
    """Every stop gave 130, Ctrl-C's: a batch script could not tell a scheduler's SIGTERM from a user."""
    with terminate_as_interrupt(), pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), sig)
        time.sleep(5)
    assert stop_status() == status
    with terminate_as_interrupt():  # the next command's own: a Ctrl-C is 130 again
        assert stop_status() == 130
    with terminate_as_interrupt(), pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), sig)
        time.sleep(5)
    seen = []

    def command() -> None:  # a command run in a thread (a notebook's): none of the signal before is its
        with terminate_as_interrupt():
            seen.append(stop_status())

    worker = threading.Thread(target=command)
    worker.start()
    worker.join()
    assert seen == [130]


@pytest.mark.slow
def test_a_terminated_simulate_keeps_the_episodes_that_finished(tmp_path):
    """`kill` or `timeout` ended simulate at once: no line, the episodes it had finished lost (no --json
    written) and the episode in progress left as an MCAP ``.part``. It now ends as a Ctrl-C does."""
    record, report = tmp_path / "rec", tmp_path / "run.json"
    command = [sys.executable, "-m", "pipelines.cli", "simulate", "--controller", "straight", "--humans", "2"]
    command += ["--episodes", "1000", "--record", str(record), "--json", str(report), "--no-progress"]
    proc = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not list(record.glob("*.mcap")):
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "no episode finished"
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 143 and err.endswith("crowdmpc simulate: interrupted\n"), err
    payload = json.loads(report.read_text())
    assert payload["interrupted"] and payload["episodes_finished"] >= 1
    assert payload["episodes_finished"] == len(payload["episodes"]) and "| interrupted: " in out
    assert not list(record.glob("*.part"))


def test_one_terminate_stops_a_step_that_hangs(tmp_path):
    """The interrupt waits for the step in progress to end: a plugin's step that never returned kept one
    SIGTERM (what `timeout` and schedulers send) from stopping simulate, which ran on for minutes. After
    STEP_GRACE_S the step is interrupted where it hangs."""
    marker = tmp_path / "stepping"
    toy = "tests.plugins.toy_controller:Hang"
    command = [sys.executable, "-m", "pipelines.cli", "--plugin", toy, "simulate", "--controller", toy]
    command += ["--humans", "1", "--robots", "1", "--no-progress"]
    env = {**os.environ, "CROWDMPC_TEST_HANG": str(marker)}
    proc = subprocess.Popen(
        command, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.monotonic() + 60
        while not marker.exists():
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, "no step began"
            time.sleep(0.02)
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        waited = time.monotonic() - sent
    finally:
        proc.kill()
    assert proc.returncode == 143 and err.endswith("crowdmpc simulate: interrupted\n"), err
    assert STEP_GRACE_S - 0.5 < waited < STEP_GRACE_S + 20  # held for the grace, then stopped


class _SignalledStart(_Steps):
    """An observer that is sent SIGINT while it starts (a recorder opening its file) and then finishes."""

    def __init__(self) -> None:
        super().__init__()
        self.started = False

    def on_reset(self, obs, meta) -> None:
        signal.raise_signal(signal.SIGINT)
        self.started = True  # a file opened here would be the observer's to finish, not left half-made


@pytest.mark.parametrize("gym_loop", [False, True], ids=["run_episode", "run_gym_episode"])
def test_a_ctrl_c_while_an_observer_starts_is_raised_after_the_first_step(gym_loop):
    """The recorder opens the episode's .part in on_reset, which ran before the block that notes Ctrl-C:
    SIGTERM there (simulate's test sends it as the first file is finished) raised inside the recorder's
    constructor, before it held the file, and the .part was left behind."""
    observer = _SignalledStart()
    with pytest.raises(KeyboardInterrupt):
        _episode(make_controller(ControllerSpec("straight")), observer, gym_loop)
    assert observer.started and observer.steps == 1
