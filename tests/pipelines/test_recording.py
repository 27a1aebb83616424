"""McapEpisodeRecorder: every channel reads back with the values the closed loop had; metadata is complete."""

from __future__ import annotations

import dataclasses
import json
import platform
import re
import subprocess
import time
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from pipelines.errors import PipelineError
from pipelines.logs.reader import read_recording
from pipelines.logs.recording import (
    FORMAT,
    McapEpisodeRecorder,
    episode_filename,
    next_unseeded,
    seconds_to_ns,
)
from pipelines.logs.scene import ROBOT_RGB, array_json
from pipelines.logs.schema_check import check_recording
from pipelines.loop.record import EpisodeRecord
from tests.pipelines.mcap_episode import HORIZON, control_output, record_episode

REPO = Path(__file__).resolve().parents[2]

NS = 1_000_000_000


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    return record_episode(tmp_path_factory.mktemp("runs"), record_iterations=True)


@pytest.fixture(scope="module")
def recording(episode):
    return read_recording(episode.path)


def test_scene_colours_are_the_plots_colours():
    from crowdsim.plotting import ROBOT_COLORS

    for rgb, hex_color in zip(ROBOT_RGB, ROBOT_COLORS, strict=True):
        assert rgb == pytest.approx([int(hex_color[k : k + 2], 16) / 255 for k in (1, 3, 5)], abs=6e-4)


def test_one_file_per_episode_named_by_scenario_and_seed(episode):
    assert episode.path.name == "circle_seed000007.mcap" == episode_filename("circle", 7)


def test_robots_and_humans_round_trip(episode, recording):
    robots, humans = recording.messages["/robots"], recording.messages["/humans"]
    states = episode.observations
    assert len(robots) == len(humans) == len(states) == 6  # 5 steps + the terminal state
    for k, (r, h, obs) in enumerate(zip(robots, humans, states, strict=True)):
        # log time: the wall-clock start + simulation time (ns); the simulation time is in the message too
        assert r.log_time_ns == h.log_time_ns == recording.start_time_ns + k * 400_000_000
        assert r.data["step"] == k and r.data["time"] == pytest.approx(0.4 * k)
        np.testing.assert_array_equal(r.data["positions"], obs.robot_positions)
        np.testing.assert_array_equal(r.data["velocities"], obs.robot_velocities)
        np.testing.assert_array_equal(r.data["goals"], obs.robot_goals)
        assert r.data["reached"] == obs.robot_reached.tolist()
        np.testing.assert_array_equal(h.data["positions"], obs.human_positions)
        np.testing.assert_array_equal(h.data["velocities"], obs.human_velocities)
        np.testing.assert_array_equal(h.data["goals"], obs.human_goals)
    for r, out, after in zip(robots[:-1], episode.outputs, states[1:], strict=True):
        np.testing.assert_array_equal(r.data["commanded"], out.accelerations)
        np.testing.assert_array_equal(r.data["actions"], after.robot_last_actions)  # applied = clipped
    assert not np.array_equal(robots[0].data["actions"], robots[0].data["commanded"])  # 3 m/s^2 > a_max
    assert robots[-1].data["actions"] is None and robots[-1].data["commanded"] is None


def test_plan_prediction_and_solver_round_trip(episode, recording):
    plans, predictions = recording.messages["/mpc/plan"], recording.messages["/mpc/prediction"]
    solver = recording.data("/mpc/solver")
    assert len(plans) == len(predictions) == len(solver) == len(episode.outputs) == 5
    for k, out in enumerate(episode.outputs):
        assert plans[k].log_time_ns == predictions[k].log_time_ns == recording.start_time_ns + k * 400_000_000
        # plans and predictions are recorded to 1e-6 m (PLAN_DECIMALS): within 5e-7 m of the values
        np.testing.assert_allclose(plans[k].data["positions"], out.plan, rtol=0, atol=5.1e-7)
        assert np.shape(plans[k].data["positions"]) == (3, HORIZON, 2)
        np.testing.assert_allclose(predictions[k].data["positions"], out.prediction, rtol=0, atol=5.1e-7)
        np.testing.assert_allclose(
            predictions[k].data["iterations"], np.stack(out.iteration_predictions), rtol=0, atol=5.1e-7
        )
        assert solver[k]["solve_time_s"] == out.solve_time_s
        assert (solver[k]["status"], solver[k]["iterations"], solver[k]["fallback"]) == (
            out.status,
            out.iterations,
            out.fallback,
        )
        assert solver[k]["extra"] == {"lp3": k, "gap": 0.25}
    assert [s["potential"] for s in solver] == [0.5, None, 2.5, 3.5, 4.5]  # NaN is recorded as null
    assert [s["fallback"] for s in solver] == [None, None, "shifted", None, None]


def test_scene_update_draws_agents_goals_plans_and_predictions(episode, recording):
    scenes = recording.messages["/scene"]
    assert len(scenes) == 6
    first = scenes[1].data  # step 1: every entity has content
    entities = {e["id"]: e for e in first["entities"]}
    assert list(entities) == ["robots", "humans", "goals", "plans", "predictions"]
    obs, out = episode.observations[1], episode.outputs[1]
    assert all(e["frame_id"] == "world" for e in entities.values())
    sec, nsec = divmod(recording.start_time_ns + 400_000_000, NS)  # the message's log time
    assert entities["robots"]["timestamp"] == {"sec": sec, "nsec": nsec}
    robots = entities["robots"]["spheres"]
    xyz = [[s["pose"]["position"][c] for c in "xyz"] for s in robots]
    np.testing.assert_allclose(np.array(xyz)[:, :2], obs.robot_positions, atol=5e-4)  # rounded to 1 mm
    assert all(p[2] == 0.3 for p in xyz)  # sphere centre at z = radius: standing on the ground
    assert robots[0]["size"] == {"x": 0.6, "y": 0.6, "z": 0.6}
    assert len({json.dumps(s["color"]) for s in robots}) == 3  # one colour per robot
    assert len(entities["humans"]["spheres"]) == 4 and len(entities["goals"]["spheres"]) == 3
    plans = entities["plans"]["lines"]
    assert len(plans) == 3 and all(line["type"] == 0 for line in plans)  # LINE_STRIP
    plan0 = [[p["x"], p["y"]] for p in plans[0]["points"]]
    np.testing.assert_allclose(plan0, np.vstack([obs.robot_positions[0], out.plan[0]]), atol=5e-4)
    predictions = entities["predictions"]["lines"]
    assert len(predictions) == 4 and len(predictions[0]["points"]) == HORIZON + 1
    # human 1's strip: from where it stands through its predicted positions, prediction[:, 1] ((H, N, 2))
    human1 = [[p["x"], p["y"]] for p in predictions[1]["points"]]
    np.testing.assert_allclose(human1, np.vstack([obs.human_positions[1], out.prediction[:, 1]]), atol=5e-4)
    last = {e["id"]: e for e in scenes[-1].data["entities"]}  # terminal state: no plan any more
    assert last["plans"]["lines"] == [] and len(last["robots"]["spheres"]) == 3


def test_the_scene_draws_the_predictions_of_the_humans_predicted_only():
    """A human out of a controller's view is NaN in its prediction; the scene drew no prediction at all
    then (every strip needs numbers), now a strip per human predicted, each its own."""
    from pipelines.logs.scene import SceneBuilder

    builder = SceneBuilder(1, 3, 0.3)
    humans = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]])
    prediction = np.array(
        [[[1.0, 1.0], [np.nan, np.nan], [3.0, 1.0]], [[1.0, 2.0], [np.nan, np.nan], [3.0, 2.0]]]
    )
    scene = json.loads(builder.update(0, np.zeros((1, 2)), np.ones((1, 2)), humans, None, prediction))
    (lines,) = [e["lines"] for e in scene["entities"] if e["id"] == "predictions"]
    strips = [[[p["x"], p["y"]] for p in line["points"]] for line in lines]
    assert strips == [[[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]], [[3.0, 0.0], [3.0, 1.0], [3.0, 2.0]]]
    none = json.loads(builder.update(0, np.zeros((1, 2)), np.ones((1, 2)), humans, None, prediction * np.nan))
    assert [e["lines"] for e in none["entities"] if e["id"] == "predictions"] == [[]]


def test_episode_metrics_at_the_end(episode, recording):
    (message,) = recording.messages["/episode/metrics"]
    assert recording.sim_seconds(message.log_time_ns) == 2.0  # the terminal state's time, 5 steps of 0.4 s
    got = message.data
    assert (got["seed"], got["scenario"], got["controller"], got["predictor"]) == (
        7,
        "circle",
        "handmade",
        "constant_velocity",
    )
    assert got["metrics"] == episode.result.metrics.as_dict()
    solver = got["solver"]
    assert solver["steps"] == 5 and solver["total_ms"] == pytest.approx(150.0)
    assert solver["median_ms"] == pytest.approx(30.0)  # solve times 10, 20, .., 50 ms
    assert solver["max_ms"] == pytest.approx(50.0)
    assert solver["statuses"] == {"Solve_Succeeded": 2, "ok": 3}
    assert solver["fallbacks"] == {"shifted": 1} and solver["fallback_steps"] == 1
    assert got == episode.result.record().to_dict() == EpisodeRecord.from_dict(got).to_dict()


def test_metadata_present(recording):
    meta = recording.metadata
    code = dict(meta["crowdmpc"])
    assert (code.pop("version"), code.pop("format")) == (version("crowdmpc"), FORMAT)
    # the code behind the numbers: this clone's commit (a git checkout), and the libraries' versions
    if (REPO / ".git").exists():
        commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True)
        assert code.pop("commit") == commit.stdout.strip() and code.pop("dirty") in ("true", "false")
        # which uncommitted changes: their diff's sha256, null for a clean tree
        diff = code.pop("diff_sha256")
        assert diff == "null" if meta["crowdmpc"]["dirty"] == "false" else len(diff) == 64
    else:  # a copy of the tree without its history: nothing to name
        assert (code.pop("commit"), code.pop("dirty"), code.pop("diff_sha256")) == ("null", "null", "null")
    assert code == {name: version(name) for name in ("casadi", "torch", "numpy")} | {
        "python": platform.python_version()
    }
    episode = dict(meta["episode"])
    assert 0 < time.time_ns() - int(episode.pop("start_time_ns")) < 600 * NS  # wall clock, this session
    assert episode == {
        "seed": "7",
        "scenario": "circle",
        "controller": "handmade",
        "predictor": "constant_velocity",
        "predictor_sha256": "ab" * 32,
        "n_robots": "3",
        "n_humans": "4",
        "dt": "0.4",
        "radius": "0.3",
    }
    assert recording.config() == {"env": {"dt": 0.4, "radius": 0.3}, "horizon": HORIZON}
    assert recording.run_meta() == {"argv": ["test"]}


def test_every_message_matches_its_schema(recording):
    checked, errors = check_recording(recording)
    assert errors == [] and checked == sum(len(m) for m in recording.messages.values()) == 34


def test_iterations_only_when_asked_and_no_plan_channels_without_a_plan(tmp_path):
    plain = read_recording(record_episode(tmp_path / "a", steps=2).path)
    assert all(p["iterations"] == [] for p in plain.data("/mpc/prediction"))
    baseline = read_recording(record_episode(tmp_path / "b", steps=2, with_plan=False).path)
    assert "/mpc/plan" not in baseline.messages and "/mpc/prediction" not in baseline.messages
    assert len(baseline.data("/mpc/solver")) == 2


def test_an_episode_left_without_on_end_is_finished_by_the_next_reset(tmp_path):
    first = record_episode(tmp_path, seed=1, steps=2, end=False)
    recorder = McapEpisodeRecorder(tmp_path)
    obs = first.observations[0]
    recorder.on_reset(obs, {**first.meta, "seed": 2})
    recorder.on_step(obs, control_output(obs), first.observations[1])
    recorder.on_reset(obs, {**first.meta, "seed": 3})  # no on_end for seed 2
    recorder.close()
    for path in recorder.paths:
        rec = read_recording(path)
        assert not rec.truncated and "/episode/metrics" not in rec.messages
    assert [p.name for p in recorder.paths] == ["circle_seed000002.mcap", "circle_seed000003.mcap"]


def test_recorders_sharing_a_folder_never_take_one_number(tmp_path, monkeypatch):
    """Two recorders may list the folder before either has created its file: the one that lists first and
    creates last must move past the number the other took, whether that one is still writing (its .part) or
    has finished (its .mcap). A stale listing is forced here: every number looks free."""
    import pipelines.logs.recording as recording

    monkeypatch.setattr(recording, "next_unseeded", lambda out_dir, scenario, written=-1: written + 1)
    first = record_episode(tmp_path / "x", steps=1)
    finished, writing = tmp_path / "circle_000000.mcap", tmp_path / "circle_000001.mcap.part"
    finished.write_bytes(b"another recorder's finished episode")
    writing.write_bytes(b"another recorder's episode in progress")
    recorder = McapEpisodeRecorder(tmp_path)
    recorder.on_reset(first.observations[0], {**first.meta, "seed": None})
    recorder.close()
    assert [p.name for p in recorder.paths] == ["circle_000002.mcap"]
    assert finished.read_bytes() == b"another recorder's finished episode"
    assert writing.read_bytes() == b"another recorder's episode in progress"
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == [
        "circle_000000.mcap",
        "circle_000001.mcap.part",
        "circle_000002.mcap",
    ]


def test_an_unseeded_recorder_lists_its_folder_once_a_scenario_and_again_only_after_a_clash(
    tmp_path, monkeypatch
):
    """Listing the folder for every episode made a long gym run's recording quadratic in its files."""
    import pipelines.logs.recording as recording

    listings = []
    real = recording.next_unseeded

    def counted(out_dir, scenario, written=-1):
        listings.append((scenario, written))
        return real(out_dir, scenario, written)

    monkeypatch.setattr(recording, "next_unseeded", counted)
    first = record_episode(tmp_path / "x", steps=1)
    (tmp_path / "circle_000000.mcap").write_bytes(b"an earlier run's")
    recorder = McapEpisodeRecorder(tmp_path)
    for _ in range(3):
        recorder.on_reset(first.observations[0], {**first.meta, "seed": None})
    assert listings == [("circle", -1)]
    (tmp_path / "circle_000004.mcap.part").write_bytes(b"another recorder's, taken meanwhile")
    recorder.on_reset(first.observations[0], {**first.meta, "seed": None})
    recorder.on_reset(first.observations[0], {**first.meta, "seed": None, "scenario": "perpendicular"})
    recorder.close()
    assert listings == [("circle", -1), ("circle", 4), ("perpendicular", -1)]
    assert [p.name for p in recorder.paths] == [
        "circle_000001.mcap",
        "circle_000002.mcap",
        "circle_000003.mcap",
        "circle_000005.mcap",
        "perpendicular_000000.mcap",
    ]


def test_misuse_is_reported(tmp_path):
    recorder = McapEpisodeRecorder(tmp_path)
    obs = record_episode(tmp_path / "x", steps=1).observations[0]
    with pytest.raises(PipelineError, match=r"needs \['scenario'\]"):
        recorder.on_reset(obs, {"seed": 1})
    with pytest.raises(PipelineError, match="before on_reset"):
        recorder.on_step(obs, control_output(obs), obs)
    (tmp_path / "file").write_text("")
    with pytest.raises(PipelineError, match="is a file"):
        McapEpisodeRecorder(tmp_path / "file")


def test_a_run_of_other_settings_does_not_replace_a_recording_a_rerun_does(tmp_path):
    """A file name is the episode (scenario, seed), not the run: another simulator or controller setting
    (formation, horizon) is refused, naming what differs; the same run again replaces its own recording,
    a recording from before formation existed counts as "auto", and a setting it predates tells nothing."""
    first = record_episode(tmp_path, seed=1, steps=2)  # env config without formation; horizon 4
    held = first.path.read_bytes()
    obs = first.observations[0]
    env = {"dt": 0.4, "radius": 0.3}
    wedge = env | {"formation": "wedge"}

    def reset(config: dict) -> None:
        recorder = McapEpisodeRecorder(tmp_path)
        recorder.on_reset(obs, {**first.meta, "config": config})
        recorder.close()

    for config, differs in (
        ({"env": wedge, "horizon": 4}, "env.formation auto; this run: env.formation wedge"),
        ({"env": env, "horizon": 5}, "horizon 4; this run: horizon 5"),
        ({"env": env}, "horizon 4; this run: horizon (not set)"),
    ):
        with pytest.raises(PipelineError, match=re.escape(f"holds another run's episode ({differs})")):
            reset(config)
        assert first.path.read_bytes() == held
    reset({"env": {**env, "formation": "auto"}, "horizon": 4})  # the same run, as recorded today
    assert first.path.read_bytes() != held and not read_recording(first.path).data("/robots")
    reset({"env": {**env, "formation": "auto", "crossing": "v1"}, "horizon": 4})  # a setting it predates
    with pytest.raises(PipelineError, match=re.escape("(env.crossing v1; this run: env.crossing paper)")):
        reset({"env": {**env, "formation": "auto", "crossing": "paper"}, "horizon": 4})


def test_another_runs_unfinished_or_cut_recording_is_refused_and_its_own_runs_replaced(tmp_path):
    """A killed run leaves its episode in <name>.part, and a copy that stopped leaves a cut <name>; `crowdmpc
    review` reads both. Another run recording that episode into the folder replaced them unchecked (the
    .part was not looked at, the cut file's metadata were read through its summary, which it lacks)."""
    first = record_episode(tmp_path, seed=1, steps=2)
    whole, obs = first.path.read_bytes(), first.observations[0]
    part = tmp_path / "circle_seed000001.mcap.part"
    cut = whole[: len(whole) - 200]

    def reset(controller: str, seed: int = 1, seeds: tuple[int, ...] = ()) -> None:
        recorder = McapEpisodeRecorder(tmp_path, seeds=seeds)
        recorder.on_reset(obs, {**first.meta, "seed": seed, "controller": controller})
        recorder.close()

    for held, content in ((part, whole), (first.path, cut)):
        first.path.unlink()
        held.write_bytes(content)
        assert read_recording(held).truncated == (held == first.path)
        refusal = re.escape(
            f"{held}: it holds another run's episode (controller handmade; this run: controller other)"
        )
        with pytest.raises(PipelineError, match=refusal):
            reset("other")
        with pytest.raises(PipelineError, match=refusal):  # a later seed of the run: before any episode
            reset("other", seed=2, seeds=(2, 1))
        assert held.read_bytes() == content and not (tmp_path / "circle_seed000002.mcap").exists()
        reset("handmade")  # its own run's rerun
        assert not part.exists() and not read_recording(first.path).truncated


def test_a_setting_of_speed_only_does_not_make_another_run(tmp_path):
    """jit compiles the same NLP and DMPC's threads give the serial result: a rerun with --set mpc.jit=true
    replaces its recording as the same command's does; a setting that changes the episodes is refused."""
    first = record_episode(tmp_path, seed=1, steps=2)
    obs = first.observations[0]
    env = {"dt": 0.4, "radius": 0.3, "formation": "auto"}

    def reset(mpc: dict) -> None:
        recorder = McapEpisodeRecorder(tmp_path)
        recorder.on_reset(obs, {**first.meta, "config": {"env": env, "horizon": 4, "mpc": mpc}})
        recorder.close()

    reset({"horizon": 4, "jit": False, "dmpc_parallel": "serial"})
    reset({"horizon": 4, "jit": True, "dmpc_parallel": "threads"})  # replaced: no refusal
    with pytest.raises(PipelineError, match=re.escape("(mpc.horizon 4; this run: mpc.horizon 5)")):
        reset({"horizon": 5, "jit": True, "dmpc_parallel": "threads"})


def test_array_json_writes_a_non_finite_value_as_null():
    # "%.6f" % nan is "nan", which no JSON reader takes: the whole message would be lost
    assert json.loads(array_json(np.array([[np.nan, 1.0], [np.inf, -2.5]]), 6)) == [[None, 1.0], [None, -2.5]]
    assert array_json(np.array([[0.1234567, 2.0]]), 6) == "[[0.123457,2.000000]]"


def test_simulation_times_become_the_nearest_nanosecond():
    # a time summed step by step: 0.1 added 8 times is 0.7999999999999999 s, which truncation would log at
    # 799 999 999 ns, a nanosecond before the step's 0.8 s
    assert seconds_to_ns(sum([0.1] * 8)) == 800_000_000
    assert seconds_to_ns(0.4) == 400_000_000


def test_the_next_unseeded_number_passes_unfinished_files_and_the_recorders_own(tmp_path):
    (tmp_path / "circle_000003.mcap.part").write_bytes(b"")  # a run still writing (or killed) holds 3
    (tmp_path / "circle_000001.mcap").write_bytes(b"")
    (tmp_path / "other_000009.mcap").write_bytes(b"")  # another scenario's numbers are its own
    assert next_unseeded(tmp_path, "circle") == 4
    # this recorder wrote number 7 (since moved away): its next episode is 8, never 7 again
    assert next_unseeded(tmp_path, "circle", written=7) == 8


def test_reached_flags_and_dt_are_recorded_as_observed(tmp_path):
    """The short episodes above reach no goal and run at the default 0.4 s: here a robot has arrived and the
    step is 0.25 s, which the "episode" record keeps exactly (review's dt)."""
    env = CrowdEnv(EnvConfig(time_limit=2.0, timeout_margin=0.0))
    obs = env.reset(7, "circle", 4, 3)
    obs = dataclasses.replace(obs, robot_reached=np.array([True, False, True]), dt=0.25)
    out = control_output(obs)
    next_obs, _, _ = env.step(out.accelerations)
    with McapEpisodeRecorder(tmp_path) as recorder:
        recorder.on_reset(obs, {"seed": 7, "scenario": "circle"})
        recorder.on_step(obs, out, next_obs)
    got = read_recording(tmp_path / episode_filename("circle", 7))
    assert got.metadata["episode"]["dt"] == "0.25"
    assert got.data("/robots")[0]["reached"] == [True, False, True]
