"""The gymnasium environment among the replayed BIWI crowds: ``make_env`` reads the recording, a controller
through ``run_gym_episode`` has ``run_episode``'s episode bit for bit (shown only the people tracked now), a
policy's episodes keep who was tracked, and the observation is never clipped."""

import numpy as np
import pytest

from crowdsim.baselines import StraightController
from crowdsim.env_config import EnvConfig
from crowdsim.gym_env import POSITION, PRESENT, VELOCITY
from pipelines.errors import PipelineError
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode
from pipelines.loop.gym_loop import ObserveEpisodes, make_env, run_gym_episode
from tests.pipelines.test_gym_loop import Calls
from tests.pipelines.test_replay_loop import data  # noqa: F401 (a fixture)


@pytest.mark.parametrize("crowd", ["eth_test", "eth_test_reactive"])
def test_a_controller_among_replayed_people_through_gym_is_run_episode(data, crowd):  # noqa: F811
    config = EnvConfig(crowd=crowd)
    spec = ControllerSpec("cmpc", "constant_velocity")
    seen, gym_seen = Calls(), Calls()
    direct = run_episode(
        make_controller(spec), seed=2, scenario="circle", n_humans=10, env_config=config, observers=[seen]
    )
    env = make_env(config, n_humans=10)
    through = run_gym_episode(make_controller(spec), env, seed=2, observers=[gym_seen])

    np.testing.assert_array_equal(through.robot_positions, direct.robot_positions)
    np.testing.assert_array_equal(through.human_positions, direct.human_positions)
    np.testing.assert_array_equal(through.human_present, direct.human_present)
    assert not through.human_present.all()  # people come and go: the sensing mattered
    assert through.metrics.as_dict() == direct.metrics.as_dict()
    assert through.statuses == direct.statuses
    assert gym_seen.meta == seen.meta
    for (obs, out, nxt), (obs2, out2, nxt2) in zip(gym_seen.steps, seen.steps, strict=True):
        assert obs == obs2 and nxt == nxt2
        np.testing.assert_array_equal(out.accelerations, out2.accelerations)


def test_a_policys_replayed_episode_keeps_who_was_tracked_and_is_never_clipped(data):  # noqa: F811
    env = ObserveEpisodes(make_env(EnvConfig(crowd="eth_test_reactive"), n_humans=10), [])
    policy = StraightController()
    array, info = env.reset(seed=5)
    policy.reset(info["observation"])
    done = False
    while not done:
        obs = info["observation"]
        humans, tracked = array[3:], obs.human_present
        # every value as the simulator has it: the bounds hold the recording, nothing was clipped
        np.testing.assert_array_equal(humans[tracked, POSITION], obs.human_positions[tracked])
        np.testing.assert_array_equal(humans[tracked, VELOCITY], obs.human_velocities[tracked])
        np.testing.assert_array_equal(humans[:, PRESENT], tracked.astype(float))
        np.testing.assert_array_equal(array[:3, POSITION], obs.robot_positions)
        array, _, terminated, truncated, info = env.step(policy.act(obs).accelerations)
        done = terminated or truncated
    result = env.results[-1]
    np.testing.assert_array_equal(result.human_present, env.unwrapped.simulator.trajectory().human_present)
    assert result.metrics == info["episode_metrics"]


def test_make_env_names_what_it_cannot_do(data, monkeypatch):  # noqa: F811
    with pytest.raises(PipelineError, match="make_env reads the recording of config.crowd itself"):
        make_env(EnvConfig(crowd="eth"), recording=None)
    with pytest.raises(PipelineError, match="make_env: config must be an EnvConfig or a mapping of its fiel"):
        make_env("eth")
    with pytest.raises(PipelineError, match="make_env: config has no field 'crwd'; expected profile, vis"):
        make_env({"crwd": "eth"})
    assert make_env({"crowd": "hotel_test"}).unwrapped.simulator.recording is not None  # plain data: YAML's
    assert make_env().unwrapped.simulator.recording is None  # ORCA's crowd reads nothing
    monkeypatch.delenv("CROWDMPC_DATA")
    with pytest.raises(PipelineError, match="crowd 'hotel_test' replays the raw BIWI tracks: set CROWDMPC"):
        make_env(EnvConfig(crowd="hotel_test"))


def test_the_docs_velocity_policy_runs_among_real_people(data, tmp_path, capsys):  # noqa: F811
    import importlib.util

    from tests.pipelines.test_gym_loop import EXAMPLE

    spec = importlib.util.spec_from_file_location("gym_velocity_policy", EXAMPLE)
    assert spec is not None and spec.loader is not None
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    example.main(episodes=1, out_dir=str(tmp_path / "runs"), crowd="eth_test", n_humans=8)
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("seed 0: return ") and out[-1] == f"wrote 1 MCAP file to {tmp_path / 'runs'}"
    from pipelines.logs.reader import read_recording

    (path,) = (tmp_path / "runs").glob("*.mcap")
    present = [h["present"] for h in read_recording(path).data("/humans")]
    assert len(present[0]) == 8 and not all(map(all, present))  # the recording keeps who was tracked
