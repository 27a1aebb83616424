"""A sweep's episode time limit (pipelines/experiments/deadline.py): a controller that never returns is
stopped as an episode error, its worker goes on, and the limit is checked where it is given."""

from __future__ import annotations

import json
import math
import re
import signal
import threading
import time

import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.experiments.deadline import MOST_TIMER_S, EpisodeTimeout, check_timeout, deadline
from tests.cli_calls import one_line, parser_error
from tests.cli_calls import run_cli as run
from tests.plugins.toy_controller import StraightLine

HANGS = "tests.plugins.failing_controllers:HangsOnCircles"


def test_the_deadline_stops_a_loop_that_catches_every_exception_and_leaves_no_timer():
    before = signal.getsignal(signal.SIGALRM)
    started = time.perf_counter()
    with pytest.raises(EpisodeTimeout), deadline(0.2):
        while True:
            try:
                time.sleep(0.01)
            except Exception:  # noqa: S112 (what a plugin may do: the limit is no Exception)
                continue
    assert 0.2 <= time.perf_counter() - started < 2.0
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    assert signal.getsignal(signal.SIGALRM) is before
    with deadline(5.0):  # a block that ends in time: nothing raised, the timer cleared
        pass
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_a_limit_whose_raise_c_code_swallowed_is_raised_when_the_block_ends():
    """CasADi's SWIG layer clears the errors of the conversions it tries: the limit fired inside one while an
    NLP was built, and its episode finished far past a 1 ms limit (1 to 2 of 4 episodes)."""
    started = time.perf_counter()
    with pytest.raises(EpisodeTimeout), deadline(0.05):
        try:
            time.sleep(0.5)
        except EpisodeTimeout:  # what the C layer did with it
            pass
        finished = time.perf_counter()
    assert finished - started < 0.4  # the sleep was cut, and the block ended without the raise
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_a_limit_met_during_a_step_is_raised_where_the_step_ends_unless_the_step_hangs():
    """Raised inside a CasADi solve, the limit made CasADi print its interrupt lines and IPOPT take it for a
    user's stop (the raise lost, the episode run to its end). A step that outlasts the limit once more is a
    hang, stopped inside it."""
    from pipelines.loop.interrupt import interrupts_between_steps

    ended = []
    with pytest.raises(EpisodeTimeout), deadline(0.2):
        with interrupts_between_steps() as step:
            time.sleep(0.3)  # the step, past the limit: nothing raised inside it
            ended.append(True)
            step.check()  # where the loop ends each step
    assert ended == [True]
    started = time.perf_counter()
    with pytest.raises(EpisodeTimeout), deadline(0.2):
        with interrupts_between_steps():
            while True:
                time.sleep(0.01)
    assert 0.4 <= time.perf_counter() - started < 2.0
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


class _SwallowsTheLimitInReset(StraightLine):
    """A reset in a long C call that clears the limit's raise, as CasADi's SWIG conversions did while a
    predictor's exported encoder ran in MPCController.reset (table2's CMPC at 5 humans, a 1 ms limit: 2 of
    6 episodes ran to their end, 20 times the stopped ones' time)."""

    name = "swallows_the_limit_in_reset"

    def __init__(self) -> None:
        super().__init__(None, None)
        self.acts = 0

    def reset(self, obs):
        ends = time.perf_counter() + 0.3
        while time.perf_counter() < ends:
            try:
                time.sleep(0.01)
            except EpisodeTimeout:  # what the C layer did with it
                pass

    def act(self, obs):
        self.acts += 1
        return super().act(obs)


def test_a_limit_whose_raise_c_code_swallowed_before_the_steps_ends_the_episode_at_the_first_step():
    """The swallowed raise was raised again only where the episode ended, every step run past the limit."""
    from pipelines.loop.episode import run_episode

    controller = _SwallowsTheLimitInReset()
    with pytest.raises(EpisodeTimeout) as raised, deadline(0.05):
        run_episode(controller, seed=0, scenario="circle", n_humans=2)
    assert controller.acts == 1
    assert raised.traceback[-1].name == "check"  # the step's end, not the limit's block
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    controller.acts = 0
    run_episode(controller, seed=0, scenario="circle", n_humans=2)  # the next, limited no more: nothing due
    assert controller.acts > 10


def test_a_limited_sweep_builds_its_nlp_outside_the_limit_and_runs_the_same_episodes(monkeypatch):
    """The limit counts the episode, not the build of its cell's NLP, which the first episode's reset did
    inside the limit (a limit of 1 ms stopped it there, a first episode's jit compile counted)."""
    import contextlib

    import mpc.cmpc
    import pipelines.experiments.worker as worker_module
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.worker import EpisodeWorker

    task = get_experiment("table2").with_predictor("constant_velocity").tasks(1, humans=(3,))[0]
    assert task.cell.spec.controller == "cmpc"
    free = EpisodeWorker().run(task).record
    inside: list[bool] = []
    builds: list[bool] = []
    timed = worker_module.deadline

    @contextlib.contextmanager
    def watched(seconds):
        inside.append(True)
        with timed(seconds):
            yield
        inside.clear()

    built = mpc.cmpc.CMPC.__init__

    def build(self, *args, **kwargs):
        builds.append(bool(inside))
        built(self, *args, **kwargs)

    monkeypatch.setattr(worker_module, "deadline", watched)
    monkeypatch.setattr(mpc.cmpc.CMPC, "__init__", build)
    limited = EpisodeWorker(timeout_s=60.0).run(task).record
    assert builds == [False]  # built once, before the limit started
    assert free is not None and limited is not None and limited["metrics"] == free["metrics"]


def test_the_deadline_needs_the_main_thread():
    raised: list[BaseException] = []

    def in_thread() -> None:
        try:
            with deadline(1.0):
                pass
        except PipelineError as exc:
            raised.append(exc)

    thread = threading.Thread(target=in_thread)
    thread.start()
    thread.join()
    assert raised and "main thread" in str(raised[0])
    with deadline(None):  # no limit: no timer, any thread
        pass


@pytest.mark.parametrize("bad", [0, -1.0, math.nan, math.inf, True, "10"])
def test_a_limit_is_a_positive_finite_number(bad):
    with pytest.raises(PipelineError, match="episode_timeout_s must be a number of seconds > 0"):
        check_timeout(bad)
    assert check_timeout(None) is None and check_timeout(3) == 3.0


def test_a_limit_longer_than_a_timer_takes_is_no_timer(tmp_path, capsys):
    """setitimer refuses more than about 9.2e9 s: `--episode-timeout 1e10` passed the checks and every
    episode failed with OverflowError into errors.jsonl; it now runs its episodes, as no limit does."""
    with deadline(MOST_TIMER_S):
        assert signal.getitimer(signal.ITIMER_REAL)[0] > 0
    with deadline(1e10):
        assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "baselines", "--humans", "1", "--episodes-per-cell", "1"]
    argv += ["--backend", "inline", "--no-progress", "--episode-timeout", "1e10", "--out", str(out)]
    code, _, err = run(capsys, *argv)
    assert code == 0, err
    assert not (out / "errors.jsonl").exists()
    assert len((out / "episodes.jsonl").read_text().splitlines()) == 2


def _sweep(capsys, out, backend: str, *extra: str) -> tuple[int, str, str]:
    argv = ["--plugin", HANGS, "sweep", "--experiment", "controllers", "--controllers", f"straight,{HANGS}"]
    argv += ["--humans", "2", "--episodes-per-cell", "4", "--workers", "1", "--backend", backend]
    return run(capsys, *argv, "--jit", "off", "--no-progress", "--out", str(out), *extra)


@pytest.mark.parametrize("backend", ["inline", "process"])
def test_a_hanging_controller_is_an_episode_error_and_its_worker_goes_on(backend, tmp_path, capsys):
    """HangsOnCircles never returns on the circle crossings (seeds 0 and 1 of its cell): each is stopped
    after the limit into errors.jsonl, naming the limit and the line it hung on, and the same worker runs the
    rest, the plugin's perpendicular crossings with a controller built again."""
    out = tmp_path / "sweep"
    started = time.perf_counter()
    code, _, err = _sweep(capsys, out, backend, "--episode-timeout", "1")
    assert time.perf_counter() - started < 60
    assert code == 1, err  # some episodes raised
    errors = [json.loads(line) for line in (out / "errors.jsonl").read_text().splitlines()]
    assert sorted(e["key"].rsplit("/", 2)[1:] for e in errors) == [["circle", "0"], ["circle", "1"]]
    assert all(e["key"].startswith(HANGS) for e in errors), errors
    message = errors[0]["error"]
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d", errors[0]["time"])  # ISO 8601
    assert message.startswith("the episode ran past the sweep's episode_timeout_s = 1 s of wall-clock time")
    assert "failing_controllers.py" in message and "time.sleep(0.02)" in message
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert sorted((r["controller"], r["scenario"]) for r in records) == [
        ("hangs_on_circles", "perpendicular"),
        ("hangs_on_circles", "perpendicular"),
        *[("straight", s) for s in ("circle", "circle", "perpendicular", "perpendicular")],
    ]
    assert len({r["worker"] for r in records}) == 1  # one worker throughout: not killed, not replaced
    run_line = json.loads((out / "sweep.json").read_text())["runs"][0]
    assert run_line["config"]["sweep"]["episode_timeout_s"] == 1.0
    # the table's rates are of the episodes that finished: said under it (they had vanished without a word)
    table = (out / "table.md").read_text()
    assert (
        f"Not counted, planned episodes not recorded: {HANGS} at 2 humans 2 of 4 (each raised or ran" in table
    )


def test_the_worker_builds_a_timed_out_cells_controller_again(tmp_path):
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.worker import EpisodeWorker
    from pipelines.plugins import register_plugins

    register_plugins([HANGS])
    tasks = get_experiment("controllers").with_controllers((HANGS,)).tasks(2, humans=(2,))
    worker = EpisodeWorker(timeout_s=0.5)
    circle, perpendicular = tasks
    assert circle.scenario == "circle" and "episode_timeout_s = 0.5 s" in (worker.run(circle).error or "")
    assert worker.run(perpendicular).record is not None
    assert worker.builds == 2  # the cell's controller, stopped mid-act, was not used again


def test_a_bad_limit_is_one_line(tmp_path, capsys):
    out = tmp_path / "sweep"
    for given, label in (
        (["--episode-timeout", "0"], "--episode-timeout"),
        (["--episode-timeout", "nan"], "--episode-timeout"),
        (["--set", "sweep.episode_timeout_s=-5"], "--set sweep.episode_timeout_s:"),
    ):
        argv = ["sweep", "--experiment", "baselines", "--episodes-per-cell", "1", "--out", str(out)]
        code, _, err = run(capsys, *argv, *given)
        assert code == 2 and f"{label} must be a number of seconds > 0" in one_line(err), err
    assert not out.exists()
    assert "invalid float value" in parser_error(capsys, "sweep", "--episode-timeout", "soon")


@pytest.mark.parametrize("backend", ["inline", "process"])
def test_a_close_that_hangs_neither_holds_the_worker_nor_follows_a_timeout(backend, tmp_path, capfd):
    """The controller a limit stopped is dropped unclosed (its close may wait on what its act hung on: the
    sweep hung there); the one built again is closed at the end within the limit, and said so."""
    hangs = "tests.plugins.failing_controllers:HangsInCloseToo"
    argv = [
        "--plugin",
        hangs,
        "sweep",
        "--experiment",
        "controllers",
        "--controllers",
        hangs,
        "--humans",
        "2",
    ]
    argv += ["--episodes-per-cell", "4", "--workers", "1", "--backend", backend, "--jit", "off"]
    started = time.perf_counter()
    code = main([*argv, "--no-progress", "--episode-timeout", "1", "--out", str(tmp_path / "sweep")])
    assert time.perf_counter() - started < 60
    assert code == 1  # the circles' episodes raised
    err = capfd.readouterr().err
    assert err.count("note: controller 'hangs_in_close_too''s close() did not return in 1 s") == 1, err
