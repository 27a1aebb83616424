"""A reactive replay in the closed loop (``--crowd eth_test_reactive``): read from the same recording as the
plain replay, the same episode's people until a robot is in their way, and named as a crowd that sees the
robots in the run's header, the sweep's title and the table's note."""

import json

import numpy as np

from crowdsim.env import EnvConfig
from pipelines.loop.episode import run_episode
from pipelines.loop.replay_data import recording
from tests.cli_calls import run_cli
from tests.pipelines.test_replay_loop import Counting, data  # noqa: F401 (data: a fixture)


def test_a_reactive_episode_plays_the_plain_replays_people_and_bends_their_tracks(data):  # noqa: F811
    runs = {
        crowd: run_episode(
            Counting(), seed=3, scenario="perpendicular", n_humans=10, env_config=EnvConfig(crowd=crowd)
        )
        for crowd in ("eth", "eth_reactive")
    }
    plain, reactive = runs["eth"], runs["eth_reactive"]
    assert recording("eth_reactive") is recording("eth")  # one recording, read once
    np.testing.assert_array_equal(reactive.human_present, plain.human_present)  # the same people, window
    steps = min(len(plain.human_positions), len(reactive.human_positions))
    off = np.linalg.norm(reactive.human_positions[:steps] - plain.human_positions[:steps], axis=-1)
    assert off[0].max() == 0.0 and off.max() > 0.0  # the robots, standing still, are in someone's way


def test_simulate_names_the_reactive_crowd_with_the_robots_visibility(data, tmp_path, capsys):  # noqa: F811
    out = tmp_path / "run.json"
    argv = ["simulate", "--controller", "cmpc", "--crowd", "eth_reactive", "--humans", "6", "--episodes", "1"]
    code, stdout, _ = run_cli(capsys, *argv, "--no-progress", "--json", str(out))
    header = "| margins none | paper/visible | crowd eth_reactive (replayed, yielding) | scenario circle |"
    assert code == 0 and header in stdout
    record = json.loads(out.read_text())
    assert record["episodes"][0]["config"]["env"]["crowd"] == "eth_reactive"


def test_a_reactive_crowd_without_its_data_is_refused_by_its_own_name(monkeypatch, capsys):
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    code, _, err = run_cli(capsys, "simulate", "--controller", "cmpc", "--crowd", "hotel_test_reactive")
    assert code == 2 and err.strip().endswith(
        "--crowd hotel_test_reactive: crowd 'hotel_test_reactive' replays the raw BIWI tracks: set "
        "CROWDMPC_DATA to the folder holding raw_ewap/ (data/README.md)"
    )


def test_a_reactive_sweep_has_keys_and_a_note_of_its_own():
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load
    from pipelines.experiments.safety_report import world_note

    config = load(sets=["env.crowd=hotel_test_reactive", "sweep.experiment=table2"])
    experiment = configured_experiment(config)
    cells = experiment.cells([5])
    assert cells and all(c.key.endswith("-paper-visible-hotel_test_reactive-h5-r3") for c in cells)
    assert "among the HOTEL_TEST pedestrians replayed, yielding to the robots" in experiment.title
    line, _ = world_note(cells)
    assert line == (
        "Margins: none; profile paper, humans replayed from BIWI hotel_test_reactive (yielding to visible "
        "robots), robots visible to the humans."
    )
