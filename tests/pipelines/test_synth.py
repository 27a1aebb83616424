"""Synthetic TrajNet++ scenes from ORCA crowds, read back with trajnetplusplustools."""

import numpy as np
import pytest
import trajnetplusplustools as tt

from crowdsim.env import CrowdEnv
from crowdsim.env_config import EnvConfig
from pipelines.errors import PipelineError
from pipelines.experiments.synth import synthesize


def test_synth_writes_trajnet_scenes_matching_the_simulation(tmp_path):
    out = tmp_path / "orca.ndjson"
    summary = synthesize(out, episodes=2, n_humans=3, seed=5)
    assert summary["episodes"] == 2 and summary["pedestrians"] == 6 and summary["scenes"] > 0
    scenes = list(tt.Reader(str(out), scene_type="paths").scenes())
    assert len(scenes) == summary["scenes"]
    for _, paths in scenes:
        frames = [row.frame for row in paths[0]]
        assert len(frames) == 21 and np.all(np.diff(frames) == 10)  # 21 steps, 10 frame ids per 0.4 s
    # Episode 0 is seed 5, pedestrians 0-2; episode 1 is seed 6, pedestrians 3-5 on later frames.
    start = CrowdEnv().reset(5, "circle", 3, 0).human_positions
    first = {row.pedestrian: row for _, paths in scenes for row in paths[0] if row.frame == 0}
    assert first  # scenes starting at frame 0 exist
    for ped, row in first.items():
        np.testing.assert_allclose([row.x, row.y], start[ped], atol=0.005)  # written in centimetres
    primaries = {paths[0][0].pedestrian for _, paths in scenes}
    assert primaries <= set(range(6)) and primaries & {3, 4, 5}
    starts = {paths[0][0].pedestrian: paths[0][0].frame for _, paths in scenes}
    assert min(f for p, f in starts.items() if p >= 3) > max(f for p, f in starts.items() if p < 3)


def test_the_summary_counts_the_rows_and_pedestrians_the_file_holds(tmp_path):
    """It counted those simulated: rows after an episode's last scene, and robots only ever neighbours of
    scenes that end before they move, are simulated but not written (1590 rows against 1537 in one run)."""
    import json

    out = tmp_path / "orca.ndjson"
    summary = synthesize(out, episodes=2, n_humans=4, seed=0, scenario="perpendicular", with_robots=True)
    tracks = [json.loads(line)["track"] for line in out.read_text().splitlines() if '"track"' in line]
    assert summary["rows"] == len(tracks)
    assert summary["pedestrians"] == len({row["p"] for row in tracks})


def test_synth_with_robots_never_makes_a_robot_primary(tmp_path):
    out = tmp_path / "orca_robots.ndjson"
    summary = synthesize(out, episodes=1, n_humans=4, seed=0, scenario="perpendicular", with_robots=True)
    assert summary["robots_per_episode"] == 3
    scenes = list(tt.Reader(str(out), scene_type="paths").scenes())
    assert scenes and all(paths[0][0].pedestrian >= 3 for _, paths in scenes)  # ids 0-2 are the robots


def test_synth_rejects_bad_sizes(tmp_path):
    with pytest.raises(PipelineError, match="episodes.*0"):
        synthesize(tmp_path / "x.ndjson", episodes=0, n_humans=3, seed=0)


def test_synth_refuses_a_step_other_than_trajnets(tmp_path):
    # the scenes are written at 2.5 fps: a 0.2 s step wrote 1 m/s walkers as 0.4 m/s ones
    out = tmp_path / "x.ndjson"
    with pytest.raises(PipelineError, match=r"env_config.dt must be 0.4 s .*got 0.2 s"):
        synthesize(out, episodes=1, n_humans=3, seed=0, env_config=EnvConfig(dt=0.2))
    assert not out.exists()


def test_one_human_without_robots_is_refused_before_any_episode(tmp_path, monkeypatch):
    """It was refused only after every episode had run (about 6 s for 1000): one agent never gives a scene
    the two agents' rows it needs."""
    from pipelines.experiments import synth

    ran = []
    with monkeypatch.context() as patched:
        patched.setattr(synth, "episode_tracks", lambda *a: ran.append(a))
        with pytest.raises(PipelineError, match=r"1 human without robots makes no TrajNet\+\+ scene"):
            synthesize(tmp_path / "x.ndjson", episodes=1000, n_humans=1, seed=0)
    assert not ran and not (tmp_path / "x.ndjson").exists()
    one = synthesize(tmp_path / "y.ndjson", episodes=1, n_humans=1, seed=0, with_robots=True)
    assert one["scenes"] > 0  # with the robots a human is a primary beside them


def test_synth_shows_a_bar_of_its_episodes_and_writes_the_same_file_without(tmp_path, capsys):
    """Up to 100 000 episodes ran with nothing on the terminal."""
    from pipelines.cli import main

    argv = ["data", "synth", "--episodes", "3", "--humans", "4", "--seed", "0"]
    synthesize(tmp_path / "a.ndjson", 3, 4, 0, progress=True)
    assert "synth circle: 100%|██████████| 3/3 [" in capsys.readouterr().err
    assert main([*argv, "--out", str(tmp_path / "b.ndjson"), "--no-progress"]) == 0
    assert "synth circle" not in capsys.readouterr().err
    assert (tmp_path / "a.ndjson").read_bytes() == (tmp_path / "b.ndjson").read_bytes()
