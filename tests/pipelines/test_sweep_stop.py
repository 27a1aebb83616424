"""A sweep that stops part way (a worker's refusal of replaced weights, a lost Ray cluster, Ctrl-C or `kill`)
keeps the episodes its other workers finish: the driver stopped at once and closed the backend, and those
episodes ended unrecorded, for a rerun to run again (pipelines.experiments.sweep_stop)."""

from __future__ import annotations

import os
import signal
import time
import types
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.experiments import sweep_stop
from pipelines.experiments.log import EPISODES_FILE, ERRORS_FILE, EpisodeLog
from tests.pipelines.test_sweep import plugins  # noqa: F401 (a fixture)


def _sweep(out: Path, controllers: list[str], backend: str) -> list[str]:
    """Two workers, an episode of each controller: the first one's worker refuses at once."""
    return ["sweep", "--experiment", "controllers", "--controllers", ",".join(controllers), "--humans", "1",
            "--episodes-per-cell", "1", "--workers", "2", "--backend", backend, "--jit", "off",
            "--no-progress", "--out", str(out)]  # fmt: skip


def _stopped_at(out: Path, recorded: str) -> str:
    return (
        "crowdmpc sweep: error: predictor 'mine': the weights were replaced (a stand-in refusal) (the sweep "
        f"stopped at the first episode that loaded them, {recorded})"
    )


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_a_stopped_sweep_records_the_episode_another_worker_finishes(
    backend,
    tmp_path,
    tmp_path_factory,
    plugins,  # noqa: F811
    capsys,
    monkeypatch,
):
    """`--workers 2`, weights replaced in the zoo while the other worker ran an episode of a cell it had built
    (on the weights checked): the refusal stopped the sweep and closed the backend at once, and that episode,
    back a moment later, was lost (met in a Table II sweep: 3 episodes in flight came back within 5 s)."""
    if backend == "ray":
        pytest.importorskip("ray")  # the [cluster] extra
    if backend == "process":  # the refusal waits for the other episode to start: under load a worker may
        # not have begun it, and a stopping pool starts none (pool_stop); a Ray actor runs the two in turn
        monkeypatch.setenv("CROWDMPC_TEST_STARTED", str(tmp_path_factory.mktemp("started")))
    refuses, slow = plugins("RefusesWeights", "TakesASecond")
    assert main(_sweep(tmp_path, [refuses, slow], backend)) == 2
    err = capsys.readouterr().err
    assert err.strip().splitlines()[-1] == _stopped_at(tmp_path, f"the 1 episode recorded in {tmp_path} kept")
    records = EpisodeLog(tmp_path / EPISODES_FILE).load()
    assert [r["controller"] for r in records.values()] == ["takes_a_second"]
    assert not (tmp_path / ERRORS_FILE).exists()  # a refusal is no episode error
    assert "CPU per episode" in err and (tmp_path / "table.md").exists()  # the report has it


def test_a_stop_waits_a_bounded_time_and_says_how_many_episodes_it_cut(
    tmp_path,
    plugins,  # noqa: F811
    capsys,
    monkeypatch,
):
    """An episode still running when the stop's wait ends is cut, unrecorded, and the stop's line says so:
    "rerun to resume" alone did not say that the episodes in flight were lost with the stop."""
    monkeypatch.setattr(sweep_stop, "STOP_WAIT_S", 0.5)
    refuses, sleeps = plugins("RefusesWeights", "SleepsInReset")  # a minute an episode
    start = time.monotonic()
    assert main(_sweep(tmp_path, [refuses, sleeps], "process")) == 2
    assert time.monotonic() - start < 45  # the pool's start, the wait, and its end: not the minute
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err == _stopped_at(tmp_path, f"no episode of it is recorded in {tmp_path} yet") + (
        "; 1 episode in flight on the workers was cut unrecorded (a resume runs it)"
    )
    log = tmp_path / EPISODES_FILE
    assert not log.exists() or not log.read_text()


@pytest.fixture
def ctrl_c():
    """Python's Ctrl-C handler in this process for the test: a process started in the background (a CI job,
    `make test &`) inherits SIGINT ignored, as a shell's background job does, and the driver then never saw
    the interrupt the test sends it (the sweep ran to its end, exit 0)."""
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, saved)


@pytest.mark.parametrize("backend", ["process", "ray"])
@pytest.mark.parametrize(("sent", "status"), [("INT", 130), ("TERM", 143)])
def test_an_interrupted_sweep_records_the_episodes_its_workers_finish(
    backend,
    sent,
    status,
    tmp_path,
    tmp_path_factory,
    plugins,  # noqa: F811
    capsys,
    monkeypatch,
    ctrl_c,
):
    """`--workers 2`, Ctrl-C (or `kill`) while both workers ran an episode a second from its end: the driver
    closed the backend at once and both were lost (a Table II sweep's two, each about a second from its end).
    Now they are recorded, and a worker that frees up does not start the minute's episode, queued behind
    them (pool_stop, ray_stop; a Ray actor holds two, so there it is the first actor's second), nor is it
    counted as cut."""
    if backend == "ray":
        pytest.importorskip("ray")  # the [cluster] extra
    monkeypatch.setenv("CROWDMPC_TEST_DRIVER", str(os.getpid()))
    monkeypatch.setenv("CROWDMPC_TEST_SIGNAL", sent)
    if backend == "process":  # the interrupt waits for the second's episode to start (under load a worker
        # may not have begun it, and a stopping pool starts none); Ray's actors take theirs as they are handed
        monkeypatch.setenv("CROWDMPC_TEST_STARTED", str(tmp_path_factory.mktemp("started")))
    interrupts, slow, sleeps = plugins("InterruptsTheSweep", "TakesASecond", "SleepsInReset")
    start = time.monotonic()
    controllers = [interrupts, slow, sleeps] if backend == "process" else [interrupts, sleeps, slow]
    assert main(_sweep(tmp_path, controllers, backend)) == status
    assert time.monotonic() - start < 45  # the workers' start, the wait, and their end: not the minute
    err = capsys.readouterr().err.strip().splitlines()
    records = EpisodeLog(tmp_path / EPISODES_FILE).load()
    assert sorted(r["controller"] for r in records.values()) == ["interrupts_the_sweep", "takes_a_second"]
    said = (
        "interrupted: recording the episodes the workers finish within 5 s; interrupt again to stop at once"
    )
    assert said in err
    assert "interrupted: rerun the same command to resume" in err  # nothing cut
    assert (tmp_path / "table.md").exists()  # the report of what it recorded


def test_a_second_interrupt_ends_the_wait_at_once(tmp_path, plugins, capsys, monkeypatch, ctrl_c):  # noqa: F811
    """The wait for the workers' episodes is the first interrupt's: a second one stops the sweep at once, as
    the docs promise, whatever is still running."""
    monkeypatch.setattr(sweep_stop, "STOP_WAIT_S", 300.0)
    monkeypatch.setenv("CROWDMPC_TEST_DRIVER", str(os.getpid()))
    twice, sleeps = plugins("InterruptsTheSweepTwice", "SleepsInReset")
    start = time.monotonic()
    assert main(_sweep(tmp_path, [twice, sleeps], "process")) == 130
    assert time.monotonic() - start < 45  # not the wait's 300 s, nor the episodes' minute
    err = capsys.readouterr().err
    assert "within 300 s; interrupt again to stop at once" in err
    assert "interrupted: rerun the same command to resume" in err
    log = tmp_path / EPISODES_FILE
    assert not log.exists() or not log.read_text()


class _Refs:
    """A stand-in ``ray`` for RayBackend.finished: ``done`` the refs back, ``died`` those whose actor died,
    ``unstarted`` those an actor handed back unstarted (None) after the stop."""

    def __init__(self, done: set[str], died: set[str], unstarted: set[str]):
        self.done, self.died, self.unstarted, self.timeouts = done, died, unstarted, []
        self.exceptions = types.SimpleNamespace(RayActorError=RuntimeError)

    def wait(self, refs, num_returns, timeout):
        self.timeouts.append(timeout)
        return [r for r in refs if r in self.done], [r for r in refs if r not in self.done]

    def get(self, ref, timeout):
        if ref in self.died:
            raise RuntimeError("The actor died unexpectedly before finishing this task.")
        return None if ref in self.unstarted else f"outcome of {ref}"


class _Flag:
    """A stand-in StopFlag actor's handle: ``said`` once the stop was said."""

    def __init__(self):
        self.said = False
        self.stop = types.SimpleNamespace(remote=self._stop)

    def _stop(self):
        self.said = True
        return "set"


@pytest.mark.parametrize("gcs_gone", [False, True])
def test_the_ray_backend_gives_back_what_its_actors_finished_and_counts_the_rest(gcs_gone):
    """Without Ray: the episodes back are given; the one a dead actor ran and the one still running are cut,
    and of an actor's episodes not back only the one it runs: another of its own, still out or handed back
    unstarted, never started. Once the cluster's GCS is gone (nothing came back for GCS_GONE_S) it takes only
    those back already, waiting for none and saying nothing to the actors."""
    from pipelines.experiments.backends import RayBackend

    backend = RayBackend.__new__(RayBackend)  # its state alone: no Ray started
    backend._ray = _Refs(done={"a", "b", "b2", "e"}, died={"b", "b2"}, unstarted={"e"})
    backend._gcs_gone = gcs_gone
    backend._flag = _Flag()
    one, two, three, four = object(), object(), object(), object()
    backend._owner = {
        "a": (0, one, None),
        "b": (1, two, None),  # its actor died: b2 never started
        "b2": (1, two, None),
        "c": (2, three, None),  # still running: d queued behind it
        "d": (2, three, None),
        "e": (3, four, None),
    }
    assert backend.finished(7.0) == (["outcome of a"], 2)
    assert backend._ray.timeouts == [0.0 if gcs_gone else 7.0]
    assert backend._flag.said is not gcs_gone
    assert backend.finished(7.0) == ([], 0)  # given once


@pytest.mark.parametrize("sent", ["INT", "TERM"])
def test_an_interrupt_while_an_outcome_is_written_is_held_until_its_record_is(
    sent,
    tmp_path,
    monkeypatch,
    ctrl_c,
):
    """Ctrl-C (or `kill`) as the driver wrote an episode's MCAP log was raised there, before the record that
    vouches for it: the episode, which had run, was lost and a rerun ran it again. The interrupt is held until
    the record is written and counted, then raised."""
    from pipelines.experiments import outcome_write
    from pipelines.experiments.sweep import SweepOutcome
    from pipelines.experiments.worker import EpisodeOutcome
    from pipelines.loop.interrupt import terminate_as_interrupt
    from tests.pipelines.test_sweep import _controllers

    (task,) = _controllers(tmp_path, 1, ["straight"]).tasks()
    written = outcome_write.write_atomic

    def interrupted_write(path, data):  # the signal comes as the MCAP log is written
        os.kill(os.getpid(), signal.Signals["SIG" + sent])
        written(path, data)

    monkeypatch.setattr(outcome_write, "write_atomic", interrupted_write)
    outcome = SweepOutcome(planned=1, already_done=0)
    bar = types.SimpleNamespace(update=lambda n: None, set_postfix=lambda **kw: None)
    log = EpisodeLog(tmp_path / EPISODES_FILE)
    keep = outcome_write.OutcomeWriter(log, outcome, {task.key: task}, 1, None, bar, "process")
    with pytest.raises(KeyboardInterrupt), terminate_as_interrupt():
        keep(EpisodeOutcome(task.key, record={"key": task.key}, mcap=b"recording"))
    assert [record["key"] for record in log.load().values()] == [task.key]
    assert outcome.ran == 1


class _StopsAnsweringForAStray:
    """A backend of one's own that stops (``stop``: SweepStopped or an interrupt) with an episode in flight
    and, at the stop, hands back one it was not given: writing it raises."""

    name = "stray"
    workers = 2

    def __init__(self, stop: BaseException):
        self.stop = stop

    def run(self, tasks):
        yield from ()
        raise self.stop

    def finished(self, wait_s):
        from pipelines.experiments.worker import EpisodeOutcome

        return [EpisodeOutcome("not-planned", record={"key": "not-planned"})], 1

    def close(self):
        pass


_UNKEPT = (
    "; 1 episode in flight on the workers was cut unrecorded (a resume runs it); 1 episode the workers "
    "finished was not recorded (a resume runs it): stray backend returned episode 'not-planned', which it "
    "was not given"
)


def test_a_write_that_fails_at_a_stop_joins_the_stop_line(tmp_path):
    """A write of the episodes back at a stop that raised replaced the stop's line: the user read that the
    backend answered for another episode, not that (nor why) the sweep had stopped."""
    from pipelines.errors import SweepStopped
    from pipelines.experiments.sweep import run_sweep
    from tests.pipelines.test_sweep import _controllers

    backend = _StopsAnsweringForAStray(SweepStopped("the Ray cluster stopped answering"))
    with pytest.raises(SweepStopped) as stopped:
        run_sweep(_controllers(tmp_path, 1, ["straight"]), backend_factory=lambda config, scratch: backend)
    assert str(stopped.value) == "the Ray cluster stopped answering" + _UNKEPT


def test_a_write_that_fails_at_an_interrupt_joins_the_interrupted_line(tmp_path, monkeypatch, capsys):
    """The same at an interrupt: the write's error replaced the KeyboardInterrupt, so the sweep ended with
    that error and without its "interrupted: rerun ..." line and status."""
    import functools

    from pipelines.commands.sweep_run import INTERRUPTED, run_cells
    from pipelines.experiments import sweep
    from tests.pipelines.test_sweep import _controllers

    backend = _StopsAnsweringForAStray(KeyboardInterrupt())
    factory = functools.partial(sweep.run_sweep, backend_factory=lambda config, scratch: backend)
    monkeypatch.setattr(sweep, "run_sweep", factory)
    assert run_cells(_controllers(tmp_path, 1, ["straight"]))[0] == INTERRUPTED
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "interrupted: rerun the same command to resume" + _UNKEPT


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_a_stop_counts_as_cut_only_the_episodes_that_were_running(
    backend,
    tmp_path,
    plugins,  # noqa: F811
    capsys,
    monkeypatch,
    ctrl_c,
):
    """`--workers 1`, Ctrl-C in its first episode: the process pool had taken the second one into its call
    queue, where it counts as running and no cancel reaches it (a Ray actor holds it queued behind the
    first), and the stop's line said "2 episodes in flight on the workers were cut", one of which never
    started."""
    if backend == "ray":
        pytest.importorskip("ray")  # the [cluster] extra
    monkeypatch.setattr(sweep_stop, "STOP_WAIT_S", 0.5)
    monkeypatch.setenv("CROWDMPC_TEST_DRIVER", str(os.getpid()))
    interrupts, queued = plugins("InterruptsThenSleeps", "TakesASecond")
    argv = _sweep(tmp_path, [interrupts, queued], backend)
    argv[argv.index("--workers") + 1] = "1"
    assert main(argv) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        "interrupted: rerun the same command to resume; 1 episode in flight on the workers was cut "
        "unrecorded (a resume runs it)"
    ) in err
    log = tmp_path / EPISODES_FILE
    assert not log.exists() or not log.read_text()


def _stop_signals_by_default() -> None:
    """In the sweep's process before it starts: SIGTERM and SIGHUP at their default action, as in a terminal.
    `nohup make test` (or a CI runner started so) hands its children SIGHUP ignored, and the sweep, rightly
    leaving an ignored signal ignored, ran on past the test's SIGHUP."""
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_DFL)


@pytest.mark.parametrize("backend", ["process", "ray"])
def test_a_worker_that_frees_up_at_a_stop_starts_no_queued_episode(
    backend,
    tmp_path,
    plugins,  # noqa: F811
    capsys,
    monkeypatch,
    ctrl_c,
):
    """`--workers 1`, Ctrl-C in its first episode, which ends a second later, within the stop's wait: the Ray
    actor then started the episode queued behind it (it left its mark), which a resume runs all the same.
    Now the first is recorded and the queued one never starts, nor is it counted as cut."""
    if backend == "ray":
        pytest.importorskip("ray")  # the [cluster] extra
    marks = tmp_path / "marks"
    marks.mkdir()
    monkeypatch.setenv("CROWDMPC_TEST_MARKS", str(marks))
    monkeypatch.setenv("CROWDMPC_TEST_DRIVER", str(os.getpid()))
    interrupts, queued = plugins("InterruptsTheSweep", "MarksThenTakesThreeSeconds")
    out = tmp_path / "sweep"
    argv = _sweep(out, [interrupts, queued], backend)
    argv[argv.index("--workers") + 1] = "1"
    assert main(argv) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert "interrupted: rerun the same command to resume" in err  # nothing cut
    records = EpisodeLog(out / EPISODES_FILE).load()
    assert [r["controller"] for r in records.values()] == ["interrupts_the_sweep"]
    assert list(marks.iterdir()) == []


@pytest.mark.parametrize(("sent", "status"), [("TERM", 143), ("HUP", 129)])
def test_a_signal_to_the_sweeps_process_group_lets_the_workers_finish(sent, status, tmp_path):
    """`timeout 30 crowdmpc sweep ...` or a closed terminal signals every process of the sweep's group: the
    process pool's workers, whose default action ended them at once, cut the episodes they ran, where a
    signal to the driver alone let them finish within the stop's wait. Now both episodes are recorded, the
    minute's episode queued behind them never starts, and the sweep ends in the wait's bound."""
    import subprocess
    import sys

    marks = tmp_path / "marks"
    marks.mkdir()
    out = tmp_path / "out"
    names = ("MarksThenTakesThreeSeconds", "MarksThenTakesThreeSecondsToo", "SleepsInReset")
    controllers = [f"tests.plugins.failing_controllers:{name}" for name in names]
    env = os.environ | {"CROWDMPC_TEST_MARKS": str(marks), "CROWDMPC_CONTROLLERS": ",".join(controllers)}
    argv = _sweep(out, controllers, "process")
    start = time.monotonic()
    sweep = subprocess.Popen(
        [sys.executable, "-m", "pipelines.cli", *argv],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # a process group of its own, as a terminal's job has
        preexec_fn=_stop_signals_by_default,
    )
    try:
        while len(list(marks.iterdir())) < 2 and time.monotonic() - start < 120:
            assert sweep.poll() is None, sweep.stderr.read() if sweep.stderr else ""
            time.sleep(0.05)
        os.killpg(sweep.pid, signal.Signals["SIG" + sent])
        _, err = sweep.communicate(timeout=60)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
            sweep.wait()
    assert sweep.returncode == status, err
    assert time.monotonic() - start < 120  # not the minute's episodes
    records = EpisodeLog(out / EPISODES_FILE).load()
    assert sorted(r["controller"] for r in records.values()) == [
        "marks_then_takes_three_seconds",
        "marks_then_takes_three_seconds_too",
    ], err
    assert "interrupted: rerun the same command to resume" in err.splitlines(), err


def test_a_signal_to_the_process_group_with_a_worker_idle_keeps_the_running_episode(tmp_path):
    """The sweep's last episodes, a worker idle beside one running an episode (`--workers 2`, two episodes,
    one of them back at once): a SIGTERM to the group ended the idle worker at once, which broke the pool,
    and the pool's break failed the running episode's future: the episode, held to finish, was lost."""
    import subprocess
    import sys

    marks = tmp_path / "marks"
    marks.mkdir()
    out = tmp_path / "out"
    names = (
        "tests.plugins.toy_controller:StraightLine",
        "tests.plugins.failing_controllers:MarksThenTakesThreeSeconds",
    )
    env = os.environ | {"CROWDMPC_TEST_MARKS": str(marks), "CROWDMPC_CONTROLLERS": ",".join(names)}
    start = time.monotonic()
    sweep = subprocess.Popen(
        [sys.executable, "-m", "pipelines.cli", *_sweep(out, list(names), "process")],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # a process group of its own, as a terminal's job has
        preexec_fn=_stop_signals_by_default,
    )
    log = out / EPISODES_FILE

    def idle() -> bool:  # the straight line's episode recorded, the other's begun
        return any(marks.iterdir()) and log.exists() and "straight_line" in log.read_text()

    try:
        while not idle() and time.monotonic() - start < 120:
            assert sweep.poll() is None, sweep.stderr.read() if sweep.stderr else ""
            time.sleep(0.05)
        os.killpg(sweep.pid, signal.SIGTERM)
        _, err = sweep.communicate(timeout=60)
    finally:
        if sweep.poll() is None:
            os.killpg(sweep.pid, signal.SIGKILL)
            sweep.wait()
    assert sweep.returncode == 143, err
    records = EpisodeLog(out / EPISODES_FILE).load()
    assert sorted(r["controller"] for r in records.values()) == [
        "marks_then_takes_three_seconds",
        "straight_line",
    ], err
