"""``crowdmpc simulate --sensor-range M [--no-sensor-tracks]``: the controller behind a range-limited tracker
(pipelines.loop.sensing), from the command line and a config file."""

import json

import numpy as np
import pytest

from pipelines.cli import main

RUN = [
    "simulate",
    "--controller",
    "cmpc",
    "--predictor",
    "social_lstm_eth",
    "--humans",
    "4",
    "--episodes",
    "2",
]


def _episodes(tmp_path, name, *options):
    out = tmp_path / f"{name}.json"
    assert main([*RUN, *options, "--no-progress", "--json", str(out)]) == 0
    return json.loads(out.read_text())["episodes"]


def test_a_range_that_sees_everyone_from_the_start_is_the_full_observation_and_is_recorded(tmp_path):
    full = _episodes(tmp_path, "full")
    wide = _episodes(tmp_path, "wide", "--sensor-range", "30")
    assert [e["metrics"] for e in wide] == [e["metrics"] for e in full]
    assert [e["config"]["sensing"] for e in wide] == [{"radius_m": 30.0, "report_tracks": True}] * 2
    assert "sensing" not in full[0]["config"]


def test_a_short_range_plans_around_fewer_humans_and_the_tracks_switch_is_recorded(tmp_path):
    near = _episodes(tmp_path, "near", "--sensor-range", "1.5", "--no-sensor-tracks")
    full = _episodes(tmp_path, "full")
    assert [e["metrics"] for e in near] != [e["metrics"] for e in full]
    assert near[0]["config"]["sensing"] == {"radius_m": 1.5, "report_tracks": False}


def test_a_config_file_sets_the_sensor(tmp_path):
    config = tmp_path / "run.toml"
    config.write_text("[simulate]\nsensor_range = 30\nsensor_tracks = false\n")
    (episode, _) = _episodes(tmp_path, "file", "--config", str(config))
    assert episode["config"]["sensing"] == {"radius_m": 30.0, "report_tracks": False}


@pytest.mark.parametrize(
    "options, message",
    [
        (["--sensor-range", "0"], "--sensor-range must be a finite number of metres > 0, got 0.0"),
        (["--sensor-range", "inf"], "--sensor-range must be a finite number of metres > 0, got inf"),
        (["--sensor-range", "nan"], "--sensor-range must be a finite number of metres > 0, got nan"),
        (
            ["--no-sensor-tracks"],
            "--no-sensor-tracks: track lengths are a sensor's; give --sensor-range M too",
        ),
        (["--set", "simulate.sensor_range=true"], "simulate.sensor_range"),
    ],
)
def test_a_sensor_that_is_no_distance_is_a_one_line_error(options, message, capsys, monkeypatch):
    def no_episodes(*args, **kwargs):
        raise AssertionError("an episode ran before the options were checked")

    monkeypatch.setattr("pipelines.loop.episode.run_episodes", no_episodes)
    assert main([*RUN, *options, "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.splitlines()) == 1
    assert message in captured.err


def test_the_printed_summary_names_the_sensor(capsys):
    # it read "controller cmpc | predictor social_lstm_eth | margins none | paper/visible | scenario circle
    # | ...", the line of a full observation's run
    assert main([*RUN[:-1], "1", "--sensor-range", "2.5", "--no-sensor-tracks", "--no-progress"]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert "| sensor 2.5 m without tracks | scenario circle |" in header
    assert main([*RUN[:-1], "1", "--no-progress"]) == 0
    assert "sensor" not in capsys.readouterr().out.splitlines()[0]


def test_a_controller_behind_a_sensor_records_its_predictions_of_the_humans_in_view(tmp_path, capsys):
    """It was refused (--record-iterations) or recorded no /mpc/prediction at all: the sensor dropped the
    predictions. Now each message holds every human, null for those out of view, and passes the schema."""
    from pipelines.logs.reader import read_recording
    from pipelines.logs.schema_check import check_recording
    from pipelines.logs.view import episode_view

    options = ["--sensor-range", "3", "--record", str(tmp_path / "rec"), "--record-iterations"]
    assert main([*RUN[:-1], "1", *options, "--no-progress"]) == 0
    capsys.readouterr()
    (path,) = (tmp_path / "rec").glob("*.mcap")
    rec = read_recording(path)
    assert check_recording(rec)[1] == []
    messages = rec.data("/mpc/prediction")
    assert len(messages) == len(rec.data("/mpc/solver")) and all(m["iterations"] for m in messages)
    seen = [[row[0] is not None for row in m["positions"][0]] for m in messages]
    assert all(len(s) == 4 for s in seen) and any(all(s) for s in seen) and not all(map(all, seen))
    visible = [m["extra"]["visible"] for m in rec.data("/mpc/solver")]
    assert [[j for j, s in enumerate(row) if s] for row in seen] == visible  # the humans in view, no other
    first = episode_view(rec).predictions[0]  # read back, null as NaN: humans 1 to 3 out of view at first
    assert first.shape[1:] == (4, 2) and np.isfinite(first[:, 0]).all() and np.isnan(first[:, 1:]).all()
    # review draws each robot's sensor range (the recorded config's sensing): a dashed circle of 3 m around
    # each robot at each snapshot of the plot, following the robots in the animation
    from matplotlib.patches import Circle

    from pipelines.logs.animation import animation_figure
    from pipelines.logs.plots import recording_figure, sensor_radius

    assert sensor_radius(rec) == 3.0
    fig, drawn = recording_figure(rec)
    ranges = [p for p in fig.axes[0].patches if isinstance(p, Circle) and p.radius == 3.0]
    assert len(ranges) == 3 * len(drawn)  # robots x snapshots
    assert "sensor range (3 m)" in {t.get_text() for t in fig.axes[0].get_legend().get_texts()}
    fig, draw, view = animation_figure(rec)
    assert "sensor range (3 m)" in {t.get_text() for t in fig.legends[0].get_texts()}
    circles = [p for p in fig.axes[0].patches if isinstance(p, Circle) and p.radius == 3.0]
    draw(5)
    assert [tuple(c.center) for c in circles] == [tuple(p) for p in view.robot_positions[5]]
    # and Foxglove's /scene a closed ring of 3 m per robot, around it at every step (1 mm rounding)
    for message, robots in zip(rec.data("/scene"), view.robot_positions, strict=False):
        (sensors,) = [e for e in message["entities"] if e["id"] == "sensors"]
        assert len(sensors["lines"]) == 3
        for line, robot in zip(sensors["lines"], robots, strict=True):
            ring = np.array([[p["x"], p["y"]] for p in line["points"]])
            assert len(ring) == 33 and np.allclose(ring[0], ring[-1], atol=2e-3)
            assert np.allclose(np.linalg.norm(ring - robot, axis=1), 3.0, atol=3e-3)


def test_a_run_that_sees_everyone_draws_no_sensor(tmp_path, capsys):
    from pipelines.logs.plots import recording_figure, sensor_radius
    from pipelines.logs.reader import read_recording

    assert main([*RUN[:-1], "1", "--record", str(tmp_path / "rec"), "--no-progress"]) == 0
    (path,) = (tmp_path / "rec").glob("*.mcap")
    rec = read_recording(path)
    assert sensor_radius(rec) is None
    fig, _ = recording_figure(rec)
    assert not any("sensor" in t.get_text() for t in fig.axes[0].get_legend().get_texts())
    assert not any(e["id"] == "sensors" for m in rec.data("/scene") for e in m["entities"])


@pytest.mark.parametrize("sensor", [["--sensor-range", "3"], []])
def test_simulate_plot_draws_the_sensor_range_of_a_run_behind_one(sensor, tmp_path, capsys, monkeypatch):
    """simulate --plot drew a run behind --sensor-range as one that saw every human, where review --plot of
    its recording drew each robot's range; now a dashed 3 m circle per robot and snapshot, named in the
    legend, and none for a run without a sensor."""
    from matplotlib.patches import Circle

    import pipelines.commands.simulate_table as simulate_table

    figures = []
    original = simulate_table.first_episode_figure
    monkeypatch.setattr(
        simulate_table, "first_episode_figure", lambda *a: figures.append(original(*a)) or figures[-1]
    )
    options = ["--humans", "3", "--robots", "2", "--plot", str(tmp_path / "p.png"), "--no-progress"]
    assert main(["simulate", "--controller", "orca", *options, *sensor]) == 0
    capsys.readouterr()
    (fig,) = figures
    ax = fig.axes[0]
    ranges = [p for p in ax.patches if isinstance(p, Circle) and p.radius == 3.0]
    legend = {t.get_text() for t in ax.get_legend().get_texts()}
    if sensor:
        assert len(ranges) == 2 * 5 and "sensor range (3 m)" in legend  # robots x snapshots
        assert all(p.get_linestyle() == "--" for p in ranges)
    else:
        assert not ranges and not any("sensor" in text for text in legend)
