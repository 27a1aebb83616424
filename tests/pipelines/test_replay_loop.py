"""A replayed crowd in the closed loop (``[env] crowd = "eth" | "hotel"``): the recording read from the BIWI
data, a controller shown only the humans tracked now, the command line and the sweep's cells naming it."""

import json
import math

import numpy as np
import pytest

from crowdsim.env import EnvConfig, Observation
from pipelines.errors import PipelineError
from pipelines.loop.episode import run_episode
from pipelines.loop.replay_data import recording
from pipelines.loop.sensing import RangeLimited
from tests.cli_calls import one_line, parser_error, run_cli
from tests.pipelines.test_sensing import Keep, observation
from tests.predictors.samples import shared_data_dir


@pytest.fixture
def data(monkeypatch):
    root = shared_data_dir()
    if root is None:
        pytest.skip("shared data (../shared/data or $CROWDMPC_DATA) not available")
    monkeypatch.setenv("CROWDMPC_DATA", str(root))
    return root


def tracked(obs, present, observed):
    """``obs`` of a replayed crowd: which humans are tracked now, and for how many rows."""
    return Observation(
        **{**obs.__dict__, "human_present": np.array(present), "human_observed": np.array(observed)}
    )


def test_without_a_range_the_controller_sees_the_tracked_humans_with_their_track_lengths():
    sensor = RangeLimited(Keep(), math.inf)
    first = tracked(observation(10, [[1.0, 0.0], [50.0, 0.0], [0.0, 2.5]]), [True, True, False], [2, 9, 0])
    sensor.reset(first)
    seen = sensor.inner.seen
    np.testing.assert_array_equal(seen.human_positions, [[1.0, 0.0], [50.0, 0.0]])  # any distance
    np.testing.assert_array_equal(seen.human_observed, [2, 4])  # the track's rows, at most the history's
    np.testing.assert_allclose(seen.history[:, 1, 0], [0.9, 0.9, 0.9, 1.0])  # padded before its track
    assert seen.human_present is None  # all it is handed are there
    # the third appears: a track of its own from now
    sensor.act(
        tracked(observation(11, [[1.0, 0.0], [50.0, 0.0], [0.0, 2.5]]), [True, True, True], [3, 10, 1])
    )
    np.testing.assert_array_equal(sensor.inner.seen.human_observed, [3, 5, 1])
    assert (
        sensor.describe() == Keep().describe()
    )  # no sensor to record: the simulator's config names the crowd


def test_the_recording_is_read_once_and_a_data_folder_without_raw_tracks_is_named(data, tmp_path):
    eth = recording("eth")
    assert recording("eth") is eth and eth.frame_step == 6 and eth.positions.shape[1] == 360
    assert recording("hotel").frame_step == 10
    # the test split alone: the last 20 % of the frames (predictors.data.ewap.split_frames), on ETH's grid
    held_out = recording("eth_test")
    assert held_out.frame_step == 6 and 100 < held_out.positions.shape[1] < 360
    assert held_out.frames[0] > eth.frames[int(0.79 * len(eth.frames))]
    with pytest.raises(PipelineError, match=f"{tmp_path} holds no raw_ewap/seq_eth/obsmat.txt"):
        recording("eth", tmp_path)
    with pytest.raises(PipelineError, match="crowd 'zara' is no recording"):
        recording("zara")


def test_a_recording_annotated_faster_than_biwi_is_refused_as_data_prepare_refuses_it(tmp_path):
    """Four walkers at 0.8 m/s annotated every 0.1 s (frame step 4, the velocity columns say so) were
    replayed at 0.1 m a 0.4 s step, a quarter of their speed, without a word."""
    from predictors.errors import DatasetFormatError

    rows = [
        (1 + 4 * k, p, -12.0 + 0.08 * k, float(p), 0.0, 0.8, 0.0, 0.0)
        for p in range(1, 5)
        for k in range(150)
    ]
    lines = ("".join(f"{v:16.7e}" for v in row) + "\n" for row in sorted(rows))
    text = "".join(lines)
    for sequence in ("seq_eth", "seq_hotel"):  # a raw folder holds both
        (tmp_path / "raw_ewap" / sequence).mkdir(parents=True)
        (tmp_path / "raw_ewap" / sequence / "obsmat.txt").write_text(text, encoding="utf-8")
    with pytest.raises(DatasetFormatError, match=r"its velocity columns imply 0\.100 s per annotated step"):
        recording("eth", tmp_path)


class Counting(Keep):
    """Keep, counting the humans handed over at each call."""

    def __init__(self):
        self.counts = []

    def act(self, obs):
        self.counts.append(obs.n_humans)
        return super().act(obs)


def test_an_episode_among_replayed_people_shows_the_controller_only_those_tracked_now(data):
    controller = Counting()
    result = run_episode(
        controller, seed=3, scenario="perpendicular", n_humans=10, env_config=EnvConfig(crowd="eth")
    )
    present = result.human_present
    assert present.shape == result.human_positions.shape[:2] and present.shape[1] == 10
    assert controller.counts == present[:-1].sum(axis=1).tolist()
    assert 0 < present.sum(axis=1).max() < 10  # people come and go
    assert result.metrics.n_steps == len(controller.counts)


def test_simulate_names_the_replayed_crowd_and_records_it(data, tmp_path, capsys):
    out = tmp_path / "run.json"
    argv = ["simulate", "--controller", "cmpc", "--crowd", "eth", "--humans", "6", "--episodes", "1"]
    code, stdout, _ = run_cli(capsys, *argv, "--no-progress", "--json", str(out))
    assert code == 0 and "| margins none | paper | crowd eth (replayed) | scenario circle |" in stdout
    record = json.loads(out.read_text())
    assert record["run"]["crowd"] == "eth" and record["episodes"][0]["config"]["env"]["crowd"] == "eth"
    assert "sensing" not in record["episodes"][0]["config"]


def test_a_crowd_that_is_none_is_refused_in_one_line(capsys):
    assert "invalid choice: 'zara'" in parser_error(
        capsys, "simulate", "--controller", "cmpc", "--crowd", "zara"
    )
    code, _, err = run_cli(capsys, "simulate", "--controller", "cmpc", "--set", "env.crowd=zara")
    assert one_line(err).endswith(
        "--set env.crowd: must be one of ['orca', 'eth', 'hotel', 'eth_test', 'hotel_test', 'eth_reactive', "
        "'hotel_reactive', 'eth_test_reactive', 'hotel_test_reactive'], got 'zara'"
    )
    assert code == 2


def test_a_sweeps_cells_among_a_replayed_crowd_have_keys_of_their_own():
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load

    cfg = load(sets=["env.crowd=hotel", "sweep.experiment=table2"])
    experiment = configured_experiment(cfg)
    cells = experiment.cells([5])
    assert cells and all(c.key.endswith("-paper-visible-hotel-h5-r3") for c in cells)
    assert all(c.world.env_config().crowd == "hotel" for c in cells)
    assert "among the HOTEL pedestrians replayed" in experiment.title


def test_a_replayed_sweeps_table_says_who_the_humans_are_and_that_the_oracle_is_none():
    from pipelines.commands.sweep_plan import configured_experiment
    from pipelines.config import load
    from pipelines.experiments.safety_report import world_note

    experiment = configured_experiment(load(sets=["env.crowd=eth_test", "sweep.experiment=predictors"]))
    assert experiment.title.endswith("(where orca_oracle is no oracle: it predicts ORCA humans)")
    line, per_column = world_note(experiment.cells([7]))
    assert line == "Margins: none; profile paper, humans replayed from BIWI eth_test (reacting to no one)."
    assert per_column is None
    ordinary, _ = world_note(configured_experiment(load(sets=["sweep.experiment=predictors"])).cells([7]))
    assert ordinary == "Margins: none; profile paper, robots visible to the humans."


def test_closed_loop_margins_among_a_replayed_crowd_are_noted_as_covering_less_there():
    from pipelines.commands.calibration_notes import calibration_world_note
    from pipelines.loop.controllers import ControllerSpec
    from pipelines.loop.margins import parse_margins

    spec = ControllerSpec("cmpc", "social_lstm_eth", margins=parse_margins("conformal:0.1"))
    assert calibration_world_note(spec, "paper", "visible") is None  # calibrated under these conventions
    note = calibration_world_note(spec, "paper", "visible", "eth_test")
    assert note == (
        "note: the closed-loop margins of 'social_lstm_eth' at alpha=0.1 were calibrated among ORCA's "
        "humans, this run replays BIWI's eth_test: there they cover less than calibrated at the first "
        "horizon steps (docs/replayed_crowds.md; conformal:ALPHA:real, calibrated on real people, covers "
        "more)"
    )
    assert (
        calibration_world_note(ControllerSpec("cmpc", "social_lstm_eth"), "paper", "visible", "eth") is None
    )


def test_compiling_counts_every_crowd_size_a_replayed_cell_meets():
    """Among a replayed crowd a CMPC meets 0..n humans as people come and go, an NLP each, as behind a
    sensor: --jit auto counts them all."""
    import dataclasses

    from mpc.compile_cache import COMPILE_S, SAVING_PER_EPISODE_S
    from pipelines.commands.sweep_jit import jit_pays
    from pipelines.experiments.tasks import Cell, World
    from pipelines.loop.controllers import ControllerSpec

    full = Cell("CMPC", ControllerSpec("cmpc", "social_lstm_eth"), 7)
    replayed = dataclasses.replace(full, world=World(crowd="eth_test"))
    episodes = math.ceil(COMPILE_S["joint"] / SAVING_PER_EPISODE_S["joint"])  # one NLP's compile, not eight
    assert jit_pays([full], episodes) and not jit_pays([replayed], episodes)
    assert jit_pays([replayed], 8 * episodes)


def test_a_replayed_run_without_its_data_is_refused_before_any_work(monkeypatch, tmp_path, capsys):
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    run = ["simulate", "--controller", "cmpc", "--episodes", "1", "--no-progress"]
    code, out, err = run_cli(capsys, *run, "--crowd", "eth")
    assert code == 2 and out == ""  # no episode ran
    assert one_line(err).endswith(
        "--crowd eth: crowd 'eth' replays the raw BIWI tracks: set CROWDMPC_DATA to the folder holding "
        "raw_ewap/ (data/README.md)"
    )
    monkeypatch.setenv("CROWDMPC_DATA", str(tmp_path))
    sweep = ["sweep", "--experiment", "table2", "--set", "env.crowd=hotel", "--out", str(tmp_path / "s")]
    code, _, err = run_cli(capsys, *sweep)
    assert code == 2 and not (tmp_path / "s").exists()
    named = "--set env.crowd hotel: crowd 'hotel' replays the raw BIWI tracks, and the data directory"
    assert f"{named} {tmp_path} holds no raw_ewap/seq_hotel/obsmat.txt" in one_line(err)


def test_a_replayed_run_records_its_predictions_of_the_people_tracked_now(data, tmp_path, capsys):
    """Refused before (--record-iterations), and the recordings held no /mpc/prediction: the loop's filter
    dropped them. Now a person not tracked is null in each message, and everyone tracked is predicted."""
    from pipelines.logs.reader import read_recording
    from pipelines.logs.schema_check import check_recording

    run = ["simulate", "--controller", "cmpc", "--crowd", "eth_test", "--humans", "8", "--episodes", "1"]
    code, _, _ = run_cli(capsys, *run, "--record", str(tmp_path), "--record-iterations", "--no-progress")
    assert code == 0
    rec = read_recording(next(tmp_path.glob("*.mcap")))
    assert check_recording(rec)[1] == []
    present = [h["present"] for h in rec.data("/humans")]
    predicted = [[row[0] is not None for row in p["positions"][0]] for p in rec.data("/mpc/prediction")]
    assert predicted == present[: len(predicted)] and not all(map(all, present))
    assert all(len(p["iterations"]) >= 1 for p in rec.data("/mpc/prediction"))


def test_an_mpc_handed_people_who_are_not_there_says_how_the_loop_hands_them(data):
    from crowdsim.env import CrowdEnv
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.replay_data import recording as read

    env = CrowdEnv(EnvConfig(crowd="eth_test"), read("eth_test"))
    obs = env.reset(0, "circle", 10, 3)
    assert not obs.human_present.all()  # someone comes later
    controller = make_controller(ControllerSpec("cmpc"))
    with pytest.raises(PipelineError, match=r"does not track now .*RangeLimited\(controller, math.inf\)"):
        controller.reset(obs)
        controller.act(obs)
    wrapped = RangeLimited(controller, math.inf)
    wrapped.reset(obs)
    assert wrapped.act(obs).accelerations.shape == (3, 2)


def test_a_crowd_the_recording_cannot_give_is_refused_before_any_nlp_is_built(
    data, monkeypatch, tmp_path, capsys
):
    """50 pedestrians of ETH at once around 12 robots: simulate built the 12 robots' NLPs (2.5 minutes)
    before the first episode's window said none exists, and a sweep raised it in every episode, each after
    its cell's NLPs, with a traceback in errors.jsonl. Both now draw the first window first."""
    from crowdsim.errors import SimulationError
    from pipelines.loop import episode
    from pipelines.loop.controllers import ControllerSpec

    def built(*_args, **_kwargs):
        raise AssertionError("the controller was built")

    with monkeypatch.context() as patched:
        patched.setattr(episode, "make_controller", built)
        with pytest.raises(SimulationError, match="no window in 200 draws has 50 pedestrians"):
            episode.run_episodes(ControllerSpec("cmpc", "constant_velocity"), episodes=1, seed=0,
                                 scenario="circle", n_humans=50, n_robots=3, progress=False,
                                 env_config=EnvConfig(crowd="eth"))  # fmt: skip
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "table2", "--crowd", "eth_reactive", "--humans", "50", "--out", str(out)]
    for dry in ([], ["--dry-run"]):
        code, _, err = run_cli(capsys, *argv, *dry, "--episodes-per-cell", "1", "--backend", "inline")
        assert code == 2 and one_line(err).startswith(
            "crowdmpc sweep: error: cell 'CMPC' at 50 humans, crowd eth_reactive: the recording gives no "
            "window for its first circle episode: crowd 'eth_reactive' (recording 'eth'): no window"
        )
        assert not out.exists()
    # the draw depends on the seed: at 46 of ETH's people seed 3's circle finds no window and seed 0's does;
    # a crowd whose first episodes can be drawn in part runs, its failures recorded as before
    assert run_cli(capsys, *argv[:-2], "--humans", "46", "--seed", "3", "--episodes-per-cell", "20",
                   "--dry-run", "--out", str(out))[0] == 0  # fmt: skip


def test_the_figures_of_a_replayed_run_name_its_crowd(data, tmp_path, capsys, monkeypatch):
    """simulate --plot titled an eth_test run "orca, circle, 3 robots, 2 humans, seed 0" and review --plot,
    --animate and --compare "orca / circle / seed 0", as if ORCA's people had crossed the circle; both name
    the replayed crowd now, and a run among ORCA's people is titled as before."""
    import pipelines.commands.simulate_table as simulate_table
    from pipelines.logs.plots import recording_figure
    from pipelines.logs.reader import read_recording

    figures = []
    original = simulate_table.first_episode_figure
    monkeypatch.setattr(
        simulate_table, "first_episode_figure", lambda *a: figures.append(original(*a)) or figures[-1]
    )
    titles = []
    for crowd in ("eth_test", "orca"):
        rec = tmp_path / crowd
        argv = [
            "simulate",
            "--controller",
            "orca",
            "--crowd",
            crowd,
            "--humans",
            "2",
            "--plot",
            str(rec / "p.png"),
        ]
        code, _, _ = run_cli(capsys, *argv, "--record", str(rec), "--no-progress")
        assert code == 0
        (path,) = rec.glob("*.mcap")
        titles.append(
            (figures[-1].axes[0].get_title(), recording_figure(read_recording(path))[0].axes[0].get_title())
        )
    (replayed, replayed_review), (orca, orca_review) = titles
    assert replayed.startswith("orca, circle, 3 robots, 2 humans, crowd eth_test, seed 0\n")
    assert replayed_review.startswith("orca / circle / crowd eth_test / seed 0: success in ")
    assert orca.startswith("orca, circle, 3 robots, 2 humans, seed 0\n")
    assert orca_review.startswith("orca / circle / seed 0: success in ")
