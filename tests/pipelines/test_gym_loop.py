"""The closed loop through gymnasium's API: CMPC and the ORCA baseline drive crowdmpc/CrowdNav-v0 to the
episodes, metrics and observer calls of ``run_episode``; any policy's episodes are recorded to MCAP; the
docs example runs."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import crowdsim
from crowdsim.env_config import EnvConfig
from crowdsim.errors import SimulationError
from crowdsim.gym_env import CrowdNavEnv
from crowdsim.gym_wrappers import VelocityControl
from pipelines.errors import PipelineError
from pipelines.logs.reader import read_recording
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.logs.schema_check import check_recording
from pipelines.logs.view import episode_view
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode, run_episodes
from pipelines.loop.gym_loop import ObserveEpisodes, run_gym_episode
from tests.same_metrics import same_metrics

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "gym_velocity_policy.py"


class Calls:
    """An EpisodeObserver that keeps what it is given."""

    def __init__(self) -> None:
        self.meta: dict[str, Any] = {}
        self.steps: list[tuple[Any, Any, Any]] = []
        self.result: Any = None

    def on_reset(self, obs, meta) -> None:
        self.meta = dict(meta)

    def on_step(self, obs, out, next_obs) -> None:
        self.steps.append((obs, out, next_obs))

    def on_end(self, result) -> None:
        self.result = result


@pytest.mark.parametrize("name", ["orca", "cmpc"])
def test_a_controller_through_the_gym_env_is_run_episode(name):
    """The same seed gives the same episode, bit for bit: trajectories, metrics, solver statuses and what the
    observers see (CMPC with the constant-velocity predictor, as `crowdmpc simulate --controller cmpc`)."""
    spec = ControllerSpec(name, "constant_velocity")
    seen, gym_seen = Calls(), Calls()
    direct = run_episode(make_controller(spec), seed=4, scenario="circle", n_humans=5, observers=[seen])
    env = gym.make(crowdsim.ENV_ID, n_humans=5)
    through = run_gym_episode(make_controller(spec), env, seed=4, observers=[gym_seen])

    np.testing.assert_array_equal(through.robot_positions, direct.robot_positions)
    np.testing.assert_array_equal(through.human_positions, direct.human_positions)
    assert through.metrics.as_dict() == direct.metrics.as_dict()
    assert (through.statuses, through.fallbacks) == (direct.statuses, direct.fallbacks)
    np.testing.assert_array_equal(through.iterations, direct.iterations)
    record, direct_record = through.record().to_dict(), direct.record().to_dict()
    for r in (record, direct_record):
        r["solver"] = {k: v for k, v in r["solver"].items() if not k.endswith("_ms")}  # wall times
    assert record == direct_record
    assert gym_seen.meta == seen.meta and len(gym_seen.steps) == len(seen.steps) == direct.metrics.n_steps
    assert gym_seen.result is through
    for (obs, out, nxt), (obs2, out2, nxt2) in zip(gym_seen.steps, seen.steps, strict=True):
        assert obs == obs2 and nxt == nxt2  # ComparableObservation against the loop's own
        np.testing.assert_array_equal(out.accelerations, out2.accelerations)


def test_run_gym_episode_takes_reset_options_and_refuses_velocity_actions():
    env = CrowdNavEnv(n_humans=4, max_robots=4, config=EnvConfig(time_limit=2.0, timeout_margin=0.0))
    result = run_gym_episode(
        make_controller(ControllerSpec("straight")), env, seed=1, options={"n_humans": 2, "n_robots": 2}
    )
    assert (result.n_humans, result.n_robots, result.metrics.n_steps) == (2, 2, 5)
    assert result.robot_positions.shape == (6, 2, 2)
    with pytest.raises(PipelineError, match="pass it without VelocityControl"):
        run_gym_episode(make_controller(ControllerSpec("straight")), VelocityControl(env), seed=1)
    with pytest.raises(PipelineError, match="expected a crowdmpc/CrowdNav-v0 environment, got CartPoleEnv"):
        ObserveEpisodes(gym.make("CartPole-v1"), [])


def test_a_policys_episodes_are_recorded_to_mcap(tmp_path):
    with McapEpisodeRecorder(tmp_path) as recorder:
        base = CrowdNavEnv(n_humans=3, config=EnvConfig(time_limit=3.2, timeout_margin=0.0))
        env = VelocityControl(ObserveEpisodes(base, [recorder], controller="still", meta={"note": "test"}))
        for seed in (5, 6):
            env.reset(seed=seed)
            done = False
            while not done:
                *_, terminated, truncated, info = env.step(np.zeros((3, 2)))
                done = terminated or truncated
    results = env.env.results  # ObserveEpisodes's
    assert [r.seed for r in results] == [5, 6] and all(r.controller == "still" for r in results)
    assert results[1].metrics == info["episode_metrics"] and results[1].metrics.n_steps == 8
    assert [p.name for p in recorder.paths] == ["circle_seed000005.mcap", "circle_seed000006.mcap"]
    rec = read_recording(recorder.paths[1])
    _, errors = check_recording(rec)
    assert not errors and not rec.truncated
    assert rec.episode()["controller"] == "still" and rec.config()["env"]["time_limit"] == 3.2
    view = episode_view(rec)
    np.testing.assert_allclose(view.robot_positions, results[1].robot_positions)
    assert len(rec.data("/episode/metrics")) == 1


def test_each_episode_of_a_seed_reset_again_keeps_its_own_file(tmp_path):
    """A gym loop may reset to one seed several times with other actions (or another crowd): each episode
    took the seed's one file, the earlier ones silently replaced, ``paths`` naming it each time, and one of
    another crowd was refused as another run's after the environment had reset. The same loop run again (a
    new recorder: the next process) replaces its own files."""

    def loop() -> tuple[McapEpisodeRecorder, ObserveEpisodes]:
        with McapEpisodeRecorder(tmp_path) as recorder:
            base = CrowdNavEnv(n_humans=3, n_robots=2, max_humans=5, config=EnvConfig(time_limit=1.6))
            env = ObserveEpisodes(base, [recorder], controller="constant")
            for action, options in ((1.0, None), (-1.0, None), (0.5, {"n_humans": 5})):
                env.reset(seed=5, options=options)
                done = False
                while not done:
                    *_, terminated, truncated, _ = env.step(np.full((2, 2), action))
                    done = terminated or truncated
        return recorder, env

    recorder, env = loop()
    names = ["circle_seed000005.mcap", "circle_seed000005_1.mcap", "circle_seed000005_2.mcap"]
    assert [p.name for p in recorder.paths] == names == sorted(p.name for p in tmp_path.iterdir())
    recordings = [read_recording(p) for p in recorder.paths]
    for rec, result in zip(recordings, env.results, strict=True):
        np.testing.assert_allclose(episode_view(rec).robot_positions, result.robot_positions)
    assert [rec.episode()["n_humans"] for rec in recordings] == ["3", "3", "5"]
    again, _ = loop()
    assert [p.name for p in again.paths] == names == sorted(p.name for p in tmp_path.iterdir())


def test_episodes_from_a_layout_are_recorded_without_a_seed(tmp_path):
    """No seed draws a hand-built scene: its file is numbered, its record says seed null, it reads back."""
    from crowdsim.scenarios import Layout
    from pipelines.loop.record import EpisodeRecord

    layout = Layout(
        np.array([[0.0, -2.0]]), np.array([[0.0, 2.0]]), np.array([[3.0, 0.0]]), np.array([[-3.0, 0.0]])
    )
    with McapEpisodeRecorder(tmp_path) as recorder:
        base = CrowdNavEnv(n_humans=1, n_robots=1, config=EnvConfig(time_limit=2.0, timeout_margin=0.0))
        env = ObserveEpisodes(base, [recorder], controller="still")
        for seed in (None, 3, None):
            env.reset(seed=seed, options={"layout": layout} if seed is None else None)
            done = False
            while not done:
                *_, terminated, truncated, _ = env.step(np.zeros((1, 2)))
                done = terminated or truncated
    assert [r.seed for r in env.results] == [None, 3, None]
    assert [p.name for p in recorder.paths] == [
        "layout_000000.mcap",
        "circle_seed000003.mcap",
        "layout_000001.mcap",
    ]
    rec = read_recording(recorder.paths[2])
    _, errors = check_recording(rec)
    assert not errors and "seed" not in rec.episode() and rec.episode()["scenario"] == "layout"
    assert EpisodeRecord.from_dict(rec.data("/episode/metrics")[0]).seed is None


def test_an_episode_from_a_layout_never_replaces_a_file(tmp_path):
    """Its number names no scene: a second recorder into the folder numbers on from the highest file there
    (an unfinished one too), where layout_000000 would have replaced the first run's scene."""
    from crowdsim.scenarios import Layout

    layout = Layout(
        np.array([[0.0, -2.0]]), np.array([[0.0, 2.0]]), np.array([[3.0, 0.0]]), np.array([[-3.0, 0.0]])
    )

    def record(episodes: int) -> list[str]:
        with McapEpisodeRecorder(tmp_path) as recorder:
            base = CrowdNavEnv(n_humans=1, n_robots=1, config=EnvConfig(time_limit=0.8, timeout_margin=0.0))
            env = ObserveEpisodes(base, [recorder], controller="still")
            for _ in range(episodes):
                env.reset(options={"layout": layout})
                done = False
                while not done:
                    *_, terminated, truncated, _ = env.step(np.zeros((1, 2)))
                    done = terminated or truncated
        return [p.name for p in recorder.paths]

    assert record(2) == ["layout_000000.mcap", "layout_000001.mcap"]
    first = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert record(1) == ["layout_000002.mcap"]
    assert all((tmp_path / name).read_bytes() == data for name, data in first.items())
    (tmp_path / "layout_000005.mcap.part").write_bytes(b"")  # a killed run's
    (tmp_path / "other_000009.mcap").write_bytes(b"")  # another scenario's numbers are its own
    assert record(2) == ["layout_000006.mcap", "layout_000007.mcap"]


def test_the_docs_example_runs_and_records(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("gym_velocity_policy", EXAMPLE)
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    example.main(episodes=2, out_dir=str(tmp_path / "runs"), n_humans=3)
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("seed 0: return ") and out[1].startswith("seed 1: return ")
    assert out[-1] == f"wrote 2 MCAP files to {tmp_path / 'runs'}"
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == [
        "circle_seed000000.mcap",
        "circle_seed000001.mcap",
    ]


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["runs/g"], "argument EPISODES: invalid int value: 'runs/g'"),
        (["1", "runs/g", "eth_tset"], "'eth_tset'"),
    ],
)
def test_the_docs_examples_command_line_refuses_a_bad_argument_in_one_line(
    tmp_path, monkeypatch, capsys, argv, named
):
    """`python docs/examples/gym_velocity_policy.py runs/g` (OUT_DIR alone) ended in a TypeError traceback
    from range('runs/g'), a mistyped CROWD in EnvConfig's; argparse names the argument now, exit 2."""
    import runpy

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.argv", [str(EXAMPLE), *argv])
    with pytest.raises(SystemExit) as stopped:
        runpy.run_path(str(EXAMPLE), run_name="__main__")
    err = capsys.readouterr().err
    assert stopped.value.code == 2 and named in err and "Traceback" not in err
    assert not (tmp_path / "runs").exists()
    monkeypatch.setattr("sys.argv", [str(EXAMPLE), "1", "runs/g"])  # the documented form still runs
    runpy.run_path(str(EXAMPLE), run_name="__main__")
    assert capsys.readouterr().out.splitlines()[-1] == "wrote 1 MCAP file to runs/g"


def test_an_episode_ended_by_gymnasiums_time_limit_is_recorded_whole(tmp_path):
    """gym.make's max_episode_steps wraps the environment in TimeLimit, which truncates before the environment
    ends the episode itself, so the last info has no episode_metrics: the record takes the metrics of the
    trajectory so far (it was a KeyError, and the MCAP file was left without its metrics)."""
    from gymnasium.utils.env_checker import check_env

    from crowdsim.metrics import episode_metrics

    with McapEpisodeRecorder(tmp_path) as recorder:
        limited = gym.make(crowdsim.ENV_ID, n_humans=3, n_robots=2, max_episode_steps=5)
        env = ObserveEpisodes(limited, [recorder])
        env.reset(seed=0)
        ends = [env.step(np.zeros((2, 2)))[2:4] for _ in range(5)]
    assert ends == [(False, False)] * 4 + [(False, True)]
    (result,) = env.results
    assert same_metrics(result.metrics, episode_metrics(env.unwrapped.simulator.trajectory()))
    assert result.metrics.n_steps == 5 and not result.metrics.success
    rec = read_recording(recorder.paths[0])
    assert not check_recording(rec)[1] and len(rec.data("/episode/metrics")) == 1
    # and the wrapper keeps its arguments, as gymnasium's own do: check_env takes it, env.spec rebuilds it
    with pytest.warns(UserWarning, match="different from the unwrapped version"):  # gymnasium's advice
        check_env(ObserveEpisodes(gym.make(crowdsim.ENV_ID), []), skip_render_check=True)
    rebuilt = gym.make(VelocityControl(ObserveEpisodes(gym.make(crowdsim.ENV_ID), [], controller="p")).spec)
    assert isinstance(rebuilt.env, ObserveEpisodes) and rebuilt.env.controller == "p"


def test_an_episode_a_time_limit_outside_the_wrapper_cut_is_ended_at_the_next_reset_or_close(tmp_path):
    """TimeLimit put around ObserveEpisodes truncates where the wrapper cannot see: each recording lacked its
    metrics and last state (`crowdmpc review`: "whose episode did not end") and results stayed empty. They
    are now those of TimeLimit put inside, as gym.make(..., max_episode_steps=5) puts it."""

    def recorded(folder: Path, outside: bool) -> tuple[list[Any], list[dict[str, int]]]:
        with McapEpisodeRecorder(folder) as recorder:
            if outside:
                env: Any = gym.make(crowdsim.ENV_ID, n_humans=3, n_robots=2)
                env = gym.wrappers.TimeLimit(ObserveEpisodes(env, [recorder]), 5)
            else:
                env = ObserveEpisodes(
                    gym.make(crowdsim.ENV_ID, n_humans=3, n_robots=2, max_episode_steps=5), [recorder]
                )
            for seed in (0, 1):
                env.reset(seed=seed)
                assert [env.step(np.zeros((2, 2)))[3] for _ in range(5)][-1]  # truncated
            env.close()
            results = env.get_wrapper_attr("results")
        counts = [
            {topic: len(read_recording(p).data(topic)) for topic in ("/robots", "/episode/metrics")}
            for p in recorder.paths
        ]
        return results, counts

    inside, inside_counts = recorded(tmp_path / "inside", outside=False)
    outside, outside_counts = recorded(tmp_path / "outside", outside=True)
    assert outside_counts == inside_counts == [{"/robots": 6, "/episode/metrics": 1}] * 2
    assert [r.seed for r in outside] == [0, 1]
    for a, b in zip(inside, outside, strict=True):
        assert same_metrics(a.metrics, b.metrics)
        assert np.array_equal(a.robot_positions, b.robot_positions)


def test_a_cut_episode_whose_observer_fails_to_take_it_is_ended_once_and_the_env_still_closes():
    """An observer raising in on_end (a full disk, a recorder closed before the env) had the next reset end
    the same episode again, and close() left the environments beneath it open."""

    class FailsOnce:
        ends: list[int] = []

        def on_reset(self, obs: Any, meta: Any) -> None:
            pass

        def on_step(self, before: Any, out: Any, after: Any) -> None:
            pass

        def on_end(self, result: Any) -> None:
            FailsOnce.ends.append(result.seed)
            if len(FailsOnce.ends) == 1:
                raise OSError(28, "No space left on device")

    observed = ObserveEpisodes(gym.make(crowdsim.ENV_ID, n_humans=2, n_robots=2), [FailsOnce()])
    env = gym.wrappers.TimeLimit(observed, 3)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros((2, 2)))
    with pytest.raises(OSError, match="No space left"):
        env.reset(seed=1)
    env.reset(seed=1)
    assert [r.seed for r in observed.results] == [0] and FailsOnce.ends == [0]
    closed = []
    observed.env.close = lambda: closed.append(True)  # type: ignore[method-assign]
    env.step(np.zeros((2, 2)))
    FailsOnce.ends.clear()  # the next on_end raises again
    with pytest.raises(OSError):
        env.close()
    assert closed == [True] and [r.seed for r in observed.results] == [0, 1]


def test_a_recorder_closed_before_the_env_leaves_the_cut_episode_cut_short_and_the_close_quiet(tmp_path):
    """`with McapEpisodeRecorder(...)` ending before env.close() had the close raise the recorder's "called
    before on_reset" for the episode a TimeLimit outside had cut: its file is finished, without metrics."""
    with McapEpisodeRecorder(tmp_path) as recorder:
        observed = ObserveEpisodes(gym.make(crowdsim.ENV_ID, n_humans=2, n_robots=2), [recorder])
        env = gym.wrappers.TimeLimit(observed, 3)
        env.reset(seed=0)
        for _ in range(3):
            env.step(np.zeros((2, 2)))
    env.close()
    assert [r.seed for r in observed.results] == [0]
    rec = read_recording(recorder.paths[0])
    assert len(rec.data("/robots")) == 3 and not rec.data("/episode/metrics")
    # a step into the file closed is refused, naming the close
    with McapEpisodeRecorder(tmp_path / "stepped") as recorder:
        env = ObserveEpisodes(gym.make(crowdsim.ENV_ID, n_humans=2, n_robots=2), [recorder])
        env.reset(seed=0)
        env.step(np.zeros((2, 2)))
    with pytest.raises(PipelineError, match=r"on_step after close\(\), which finished .*seed000000"):
        env.step(np.zeros((2, 2)))


def test_a_controller_whose_act_returns_no_control_output_is_named_through_gym_too():
    from tests.plugins.broken_controllers import ArrayAct

    env = gym.make(crowdsim.ENV_ID, n_humans=2)
    with pytest.raises(PipelineError, match=r"controller 'array_act' \(ArrayAct\): act\(\) must return"):
        run_gym_episode(ArrayAct(None, None), env, seed=0)


@pytest.mark.parametrize(
    "name, max_robots, got",
    [
        ("TooFewRows", None, (2, 2)),  # was padded with zeros: the last robot never moved
        ("ExtraRow", 4, (4, 2)),  # was cut to the episode's robots: its extra row dropped unseen
        ("ExtraRow", None, (4, 2)),  # was numpy's ValueError (broadcast)
    ],
)
def test_accelerations_of_the_wrong_rows_are_refused_through_gym_as_by_run_episode(name, max_robots, got):
    from tests.plugins import broken_controllers

    controller = getattr(broken_controllers, name)(None, None)
    message = (
        f"controller '{controller.name}' ({name}): act() must return accelerations of shape (3, 2), "
        f"a row per robot, got shape {got}"
    )
    with pytest.raises(PipelineError) as caught:
        run_gym_episode(controller, CrowdNavEnv(n_humans=2, max_robots=max_robots), seed=0)
    assert str(caught.value) == message
    with pytest.raises(PipelineError) as caught:
        run_episode(controller, seed=0, scenario="circle", n_humans=2)
    assert str(caught.value) == message


def test_observe_episodes_refuses_meta_that_would_relabel_its_episodes(tmp_path):
    """A meta seed named every episode's recording: three episodes wrote one file over and over."""
    clash = r"ObserveEpisodes: meta must not set \['seed', 'scenario'\]: the episode sets seed, scenario"
    with pytest.raises(PipelineError, match=clash):
        ObserveEpisodes(CrowdNavEnv(n_humans=2), [], meta={"scenario": "mine", "seed": 0, "note": "fine"})
    with pytest.raises(PipelineError, match=r"run_gym_episode: meta must not set \['controller'\]"):
        run_gym_episode(
            make_controller(ControllerSpec("straight")), CrowdNavEnv(), seed=0, meta={"controller": 1}
        )
    seen = Calls()
    with McapEpisodeRecorder(tmp_path) as recorder:
        base = CrowdNavEnv(n_humans=2, config=EnvConfig(time_limit=0.8, timeout_margin=0.0))
        env = ObserveEpisodes(base, [recorder, seen], meta={"experiment": "demo"})
        for seed in (10, 11):
            env.reset(seed=seed)
            while not any(env.step(np.zeros((3, 2)))[2:4]):
                pass
    assert [p.name for p in recorder.paths] == ["circle_seed000010.mcap", "circle_seed000011.mcap"]
    assert (seen.meta["seed"], seen.meta["experiment"]) == (11, "demo")


def test_observe_episodes_refuses_velocity_control_inside_it():
    """Underneath, the actions it saw were velocities, recorded as accelerations."""
    with pytest.raises(
        PipelineError, match=r"wrap VelocityControl around it, VelocityControl\(ObserveEpisodes"
    ):
        ObserveEpisodes(VelocityControl(CrowdNavEnv(n_humans=2)), [])
    assert isinstance(VelocityControl(ObserveEpisodes(CrowdNavEnv(n_humans=2), [])).env, ObserveEpisodes)
    # with a_max = v_max the two action spaces are equal: the order is what tells
    even = CrowdNavEnv(n_humans=2, config=EnvConfig(a_max=1.0, v_max=1.0))
    assert VelocityControl(even).action_space == even.action_space
    with pytest.raises(PipelineError, match=r"wrap VelocityControl around it"):
        ObserveEpisodes(VelocityControl(even), [])
    with pytest.raises(PipelineError, match=r"pass it without VelocityControl"):
        run_gym_episode(make_controller(ControllerSpec("straight")), VelocityControl(even), seed=0)


def test_a_wrapper_that_changes_the_actions_is_named_as_it_is_refused():
    """ClipAction (actions in Box(-inf, inf)) was refused as if it were VelocityControl: 'pass it without
    VelocityControl', 'wrap VelocityControl around it', with none there. The message names the wrapper."""
    for wrapper in (gym.wrappers.ClipAction, lambda e: gym.wrappers.RescaleAction(e, -1.0, 1.0)):
        env = wrapper(gym.make(crowdsim.ENV_ID, n_humans=2))
        name = type(env).__name__
        with pytest.raises(PipelineError, match=rf"pass it without {name}, which changes the actions$"):
            run_gym_episode(make_controller(ControllerSpec("straight")), env, seed=0)
        with pytest.raises(PipelineError, match=rf"wrap {name} around it, {name}\(ObserveEpisodes\(env"):
            ObserveEpisodes(env, [])


def test_run_gym_episode_names_a_spec_or_a_name_given_for_the_controller():
    """run_episode refuses a ControllerSpec or a name in place of the controller in one line; the same slip in
    run_gym_episode ended in "AttributeError: 'ControllerSpec' object has no attribute 'name'"."""
    with pytest.raises(PipelineError, match=r"^run_gym_episode takes a controller built by make_controller"):
        run_gym_episode(ControllerSpec("orca"), CrowdNavEnv(), seed=0)
    with pytest.raises(PipelineError, match=r"^run_gym_episode: .orca. is no controller: it has no reset"):
        run_gym_episode("orca", CrowdNavEnv(), seed=0)  # type: ignore[arg-type]


def test_the_own_layout_example_runs_two_controllers_that_review_compares(tmp_path, capsys):
    """docs/examples/own_layout.py: a hand-made corridor (one human standing) through the gymnasium
    environment, each controller's episodes recorded in a folder of its own, which `crowdmpc review` sets
    side by side."""
    from pipelines.cli import main

    path = EXAMPLE.parent / "own_layout.py"
    spec = importlib.util.spec_from_file_location("own_layout", path)
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    out = tmp_path / "runs"
    example.main(str(out), ("cmpc", "orca"))
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(",")[0] for line in lines[:6]] == ["cmpc"] * 3 + ["orca"] * 3
    assert all("success True" in line for line in lines[:6])  # the corridor is passable, by both
    assert lines[-1] == f"wrote {out}: crowdmpc review {out}"
    for name in ("cmpc", "orca"):
        assert sorted(p.name for p in (out / name).iterdir()) == [f"layout_00000{i}.mcap" for i in range(3)]
    assert main(["review", str(out)]) == 0
    table = capsys.readouterr().out.split("== 2 set-ups side by side ==\n")[1].splitlines()
    assert [row.split("  ")[0] for row in table[2:4]] == [
        "cmpc, predictor constant_velocity",
        "orca, predictor none",
    ]


def test_observers_that_are_none_one_recorder_or_no_observer_are_one_line(tmp_path):
    """run_episode names bad observers; through gym they ended in "TypeError: 'McapEpisodeRecorder' object is
    not iterable" (one recorder, not a list of it) or an AttributeError for on_reset after the reset."""
    recorder = McapEpisodeRecorder(tmp_path)
    straight = make_controller(ControllerSpec("straight"))
    for bad, shown in ((None, "None"), (recorder, "McapEpisodeRecorder"), ([object()], "object")):
        with pytest.raises(PipelineError, match=rf"^ObserveEpisodes: observer.*{shown}"):
            ObserveEpisodes(CrowdNavEnv(n_humans=2), bad)  # type: ignore[arg-type]
        with pytest.raises(PipelineError, match=rf"^run_gym_episode: observer.*{shown}"):
            run_gym_episode(straight, CrowdNavEnv(n_humans=2), seed=0, observers=bad)  # type: ignore[arg-type]
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("bad", ["a", None, object()])
def test_an_action_of_no_numbers_through_observe_episodes_is_the_environments_one_line(bad):
    """It was numpy's own "ValueError: could not convert string to float: 'a'" (or an IndexError for None),
    raised by the wrapper's record of the action before the environment could name it."""
    env = ObserveEpisodes(CrowdNavEnv(n_humans=2), [])
    env.reset(seed=0)
    with pytest.raises(SimulationError, match=r"^action must be"):
        env.step(bad)
    env.step(np.zeros((3, 2)))  # nothing of the refused step was recorded
    assert len(env._steps.solve_times) == 1


@pytest.mark.parametrize("meta", ["demo", ["experiment", "demo"], 5])
def test_meta_that_is_no_mapping_is_one_line_naming_it(meta):
    """meta="demo" for meta={"experiment": "demo"} ended in dict()'s "ValueError: dictionary update sequence
    element #0 has length 1; 2 is required" (a TypeError for 5), naming neither meta nor the call."""
    with pytest.raises(PipelineError, match=r"^ObserveEpisodes: meta must be a dict of fields to add, got"):
        ObserveEpisodes(CrowdNavEnv(n_humans=2), [], meta=meta)
    with pytest.raises(PipelineError, match=r"^run_gym_episode: meta must be a dict"):
        run_gym_episode(make_controller(ControllerSpec("straight")), CrowdNavEnv(), seed=0, meta=meta)
    with pytest.raises(PipelineError, match=r"^run_episode: meta must be a dict"):
        run_episode(
            make_controller(ControllerSpec("straight")), seed=0, scenario="circle", n_humans=2, meta=meta
        )
    with pytest.raises(PipelineError, match=r"^run_episodes: meta must be a dict"):
        run_episodes(ControllerSpec("straight"), episodes=1, seed=0, scenario="circle", n_humans=2, meta=meta)


def test_meta_refused_by_run_gym_episode_leaves_the_env_unreset(tmp_path):
    """It was checked after env.reset: a recorder inside the env (ObserveEpisodes) had opened its file."""
    env = ObserveEpisodes(CrowdNavEnv(n_humans=2), [McapEpisodeRecorder(tmp_path)])
    for meta in ("demo", {"seed": 3}):
        with pytest.raises(PipelineError, match=r"^run_gym_episode: meta"):
            run_gym_episode(make_controller(ControllerSpec("straight")), env, seed=0, meta=meta)
    assert env.unwrapped.episode == {} and not list(tmp_path.iterdir())


@pytest.mark.parametrize("name", [lambda obs: np.zeros((3, 2)), None, ""])
def test_observe_episodes_names_a_policy_given_for_its_name(name):
    """controller=policy (the function, for its name) was recorded as "<function <lambda> at 0x...>", another
    name each run, so the same episodes recorded again were refused as another run's."""
    with pytest.raises(PipelineError, match=r"^ObserveEpisodes: controller is the name the records give"):
        ObserveEpisodes(CrowdNavEnv(n_humans=2), [], controller=name)


def test_meta_refused_by_run_episode_is_refused_before_the_controllers_reset():
    """It was checked after the reset, where an MPC builds its NLPs (minutes at twelve robots)."""
    controller = make_controller(ControllerSpec("straight"))
    resets = []
    controller.reset = resets.append  # type: ignore[method-assign]
    with pytest.raises(PipelineError, match=r"^run_episode: meta"):
        run_episode(controller, seed=0, scenario="circle", n_humans=2, meta={"seed": 3})
    assert resets == []
