"""crowdmpc review: summaries, truncated files, the schema check, pictures, comparison, folders."""

from __future__ import annotations

import json
import os
import re
import shutil
import sys

import numpy as np
import pytest
from PIL import Image

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.logs.reader import read_recording
from pipelines.logs.recorder import McapRecorder
from pipelines.logs.recording import McapEpisodeRecorder
from pipelines.logs.review import summarize
from pipelines.logs.run_tables import setups_table
from pipelines.logs.schemas import ROBOTS
from pipelines.logs.view import episode_view
from tests.pipelines.mcap_episode import control_output, cut_before_episode_metadata, record_episode


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two finished 8-step episodes in one folder."""
    folder = tmp_path_factory.mktemp("runs")
    return [record_episode(folder, seed=seed, steps=8) for seed in (1, 2)]


def test_summary_of_a_finished_run(runs, capsys):
    assert main(["review", str(runs[0].path)]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    for expected in (
        "circle (seed 1)",
        "3 robots, 4 humans",
        "handmade",
        "constant_velocity",
        "ab" * 32,
        "9 states, 3.2 s simulated",
        "median 45.0 ms",  # solve times 10..80 ms
    ):
        assert expected in out, expected
    assert [line.split()[1:] for line in out.splitlines() if line.startswith("fallbacks")] == [
        ["shifted", "1"]
    ]
    summary = summarize(read_recording(runs[0].path))
    assert summary["metrics"] == runs[0].result.metrics.as_dict()
    assert summary["solver"]["statuses"] == {"Solve_Succeeded": 3, "ok": 5}
    from pipelines.plugins import code_with_plugins
    from pipelines.version import dirty_text

    code = code_with_plugins()
    commit = code["commit"]  # the recording's code, when this tree is a git checkout
    (crowdmpc,) = [line for line in out.splitlines() if line.startswith("crowdmpc ")]
    dirty = dirty_text(code["dirty"], code["diff_sha256"])  # from a tree with uncommitted changes
    assert crowdmpc.endswith(f"(commit {commit[:12]}{dirty})" if commit else code["version"])


@pytest.mark.parametrize("cut", [1, 0.5])
def test_a_truncated_file_reads_up_to_its_last_chunk_with_a_warning(tmp_path, cut, capsys):
    # A long episode makes several 64 KiB chunks; cutting bytes off the end is a killed run.
    full = record_episode(tmp_path / "full", steps=75, n_humans=7)
    n_full = len(full.observations)
    assert n_full > 20
    data = full.path.read_bytes()
    kept = len(data) - 1 if cut == 1 else int(len(data) * cut)
    cut_path = tmp_path / "cut.mcap"
    cut_path.write_bytes(data[:kept])

    rec = read_recording(cut_path)
    assert rec.truncated and "truncated" in rec.warning
    complete = read_recording(full.path)
    n_states = len(rec.data("/robots"))
    if cut == 1:  # only the closing magic is damaged: every message is still there
        assert rec.messages.keys() == complete.messages.keys()
        assert n_states == n_full
    else:
        assert 0 < n_states < n_full and "/episode/metrics" not in rec.messages
    # what was read is what was written
    np.testing.assert_array_equal(
        episode_view(rec).robot_positions,
        episode_view(complete).robot_positions[: len(episode_view(rec).times)],
    )

    assert main(["review", str(cut_path), "--check"]) == 1  # its messages pass; the file is cut
    out, err = capsys.readouterr()
    assert "warning" in err and "truncated" in err
    assert f"check {cut_path}: {sum(len(m) for m in rec.messages.values())} messages read, truncated: " in out
    assert out.splitlines()[-1].endswith(" messages, each valid; fails: truncated")  # its verdict, last
    if cut != 1:
        assert "metrics           missing" in out


def test_check_catches_a_bad_message(tmp_path, capsys):
    path = tmp_path / "bad.mcap"
    good = {
        "time": 0.0,
        "step": 0,
        "positions": [[0.0, 0.0]],
        "velocities": [[0.0, 0.0]],
        "goals": [[1.0, 1.0]],
        "actions": None,
        "commanded": None,
        "reached": [False],
    }
    with McapRecorder(path) as rec:  # the recorder does not validate (cheap); --check does
        rec.write("/robots", good, 0, schema=ROBOTS)
        rec.write(
            "/robots", {**good, "step": 1, "positions": [[0.0]], "speed": 2}, 400_000_000, schema=ROBOTS
        )
    assert main(["review", str(path), "--check", "--json", str(tmp_path / "r.json")]) == 1
    out = capsys.readouterr().out
    assert "2 messages, 2 invalid" in out
    assert "/robots @ 0.400 s (crowdmpc.Robots): $.positions[0]: 1 items, expected at least 2" in out
    assert "$: unexpected property 'speed'" in out
    report = json.loads((tmp_path / "r.json").read_text())
    assert len(report["check"][str(path)]["errors"]) == 2


@pytest.mark.parametrize("bad", [1e308, -2e6])  # the recorder writes no NaN or inf (strict JSON)
def test_positions_no_episode_has_are_refused_for_pictures_naming_the_check(tmp_path, capsys, bad):
    """A robot at 1e308 m was drawn with numpy's overflow warnings and their source lines, exit 0."""
    from pipelines.logs.schemas import HUMANS

    path = tmp_path / "bad.mcap"
    robots = {"time": 0.0, "step": 0, "positions": [[0.0, 0.0]], "velocities": [[0.0, 0.0]]}
    robots |= {"goals": [[1.0, 1.0]], "actions": None, "commanded": None, "reached": [False]}
    humans = {"time": 0.0, "step": 0, "positions": [[2.0, 0.0]], "velocities": [[0.0, 0.0]]}
    humans |= {"goals": [[3.0, 0.0]]}
    with McapRecorder(path) as rec:
        for step in (0, 1):
            at = {"time": 0.4 * step, "step": step}
            moved = [[bad, 0.0]] if step else [[0.0, 0.0]]
            rec.write("/robots", robots | at | {"positions": moved}, step * 400_000_000, schema=ROBOTS)
            rec.write("/humans", humans | at, step * 400_000_000, schema=HUMANS)
    capsys.readouterr()
    assert main(["review", str(path), "--plot", str(tmp_path / "p.png")]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc review: error: {path}: its /robots or /humans positions hold values no episode has (inf, "
        "NaN or beyond 1e+06 m): a damaged recording; --check names the messages\n"
    )
    assert not (tmp_path / "p.png").exists()


def test_recorded_episodes_pass_the_check(runs, capsys):
    assert main(["review", str(runs[0].path.parent), "--check"]) == 0
    assert capsys.readouterr().out.count(" ok\n") == 2


def test_folder_gives_one_row_per_run_and_the_rates(runs, capsys, tmp_path):
    assert main(["review", str(runs[0].path.parent), "--json", str(tmp_path / "all.json")]) == 0
    out = capsys.readouterr().out
    assert "circle_seed000001.mcap" in out and "circle_seed000002.mcap" in out
    assert "\n2 runs\n" in out
    expected_success = sum(r.result.metrics.success for r in runs) * 50.0
    assert f"success {expected_success:.1f} % " in out
    assert "over 16 steps; fallback steps 2" in out  # 8 steps each, one "shifted" fallback per run
    between = ", ".join(
        f"{name} {50.0 * hits:.1f} % ({hits}/2)"
        for name in ("collision", "contact")
        for hits in [sum(bool(getattr(r.result.metrics, f"{name}_between_steps")) for r in runs)]
    )
    assert f"\nbetween steps (straight motion within each step): {between}\n" in out
    report = json.loads((tmp_path / "all.json").read_text())
    totals = report["totals"]
    (group,) = report["groups"]  # one set-up: "groups" as for several, and "totals" at the top too
    assert group["totals"] == totals and group["files"] == [str(r.path) for r in runs]
    assert group["name"] == "handmade, predictor constant_velocity, 3 robots, 4 humans"
    assert totals["episodes"] == 2 and totals["success_rate"] == expected_success
    assert totals["solve_time_max_ms"] == pytest.approx(80.0)
    assert main(["review", str(runs[0].path.parent), "--plot", str(tmp_path / "p.png")]) == 2
    err = capsys.readouterr().err
    assert "--plot needs one .mcap file" in err
    assert f"give one of its files, e.g. {runs[0].path.parent / 'circle_seed000001.mcap'}" in err
    folder = tmp_path / "with_a_folder"  # its example named a folder "a.mcap", which --plot refuses
    (folder / "a.mcap").mkdir(parents=True)
    shutil.copy(runs[0].path, folder / "b.mcap")
    assert main(["review", str(folder), "--animate", str(tmp_path / "a.gif")]) == 2
    assert f"give one of its files, e.g. {folder / 'b.mcap'}\n" in capsys.readouterr().err


def test_plot_animation_and_comparison(runs, tmp_path, capsys):
    png, gif, overlay = tmp_path / "p.png", tmp_path / "a.gif", tmp_path / "o.png"
    assert (
        main(["review", str(runs[0].path), "--plot", str(png), "--times", "0,1.2,2.5", "--animate", str(gif)])
        == 0
    )
    out = capsys.readouterr().out
    assert (
        "(plans and predictions at t = 0, 1.2, 2.4 s)" in out
    )  # 2.5 s is no state: the nearest one, 2.4 s, is drawn
    assert Image.open(png).size[0] > 300
    with Image.open(gif) as animation:
        assert animation.n_frames == 9 and animation.info["duration"] == 400  # one frame per 0.4 s step
    assert main(["review", str(runs[0].path), "--compare", str(runs[1].path), "--plot", str(overlay)]) == 0
    out = capsys.readouterr().out
    assert "A: circle_seed000001.mcap" in out and "B: circle_seed000002.mcap" in out and "travel_time" in out
    assert overlay.stat().st_size > 0


def test_an_episode_without_humans_passes_the_check_and_draws(tmp_path, capsys):
    """JSON has no shape for an empty list: numpy reads no humans as (0,) and an empty prediction as (H, 0),
    which the checks took for malformed arrays, so every message of a crowd-free run was left out."""
    run = record_episode(tmp_path, n_humans=0, steps=3)
    assert main(["review", str(run.path), "--check"]) == 0
    assert "ok" in capsys.readouterr().out
    view = episode_view(read_recording(run.path))
    assert view.human_positions.shape == (4, 0, 2) and view.predictions[0].shape == (4, 0, 2)
    assert main(["review", str(run.path), "--plot", str(tmp_path / "p.png")]) == 0
    # and no legend names humans, which neither the plot nor the animation draws
    from pipelines.logs.animation import animation_figure
    from pipelines.logs.plots import recording_figure

    fig, _ = recording_figure(read_recording(run.path))
    assert not {"humans", "prediction"} & {t.get_text() for t in fig.axes[0].get_legend().get_texts()}
    fig, _, _ = animation_figure(read_recording(run.path))
    labels = {t.get_text() for t in fig.legends[0].get_texts()}
    assert "robot plan" in labels and not {"human", "predicted human path"} & labels


def test_a_long_episode_is_animated_in_at_most_max_frames(runs, tmp_path, capsys, monkeypatch):
    """Pillow holds every frame: a 10 000-step episode needed 13 GB. Past MAX_FRAMES, one state in k (and
    the last) is drawn, each shown k steps long, so the animation keeps the episode's length."""
    from pipelines.logs import animation

    monkeypatch.setattr(animation, "MAX_FRAMES", 4)
    gif = tmp_path / "a.gif"
    assert main(["review", str(runs[0].path), "--animate", str(gif)]) == 0  # 9 states: 0, 3, 6 and 8
    assert "(4 frames, one state in 3)" in capsys.readouterr().out
    with Image.open(gif) as animation:
        assert animation.n_frames == 4 and animation.info["duration"] == 1200


def test_an_animation_shows_a_bar_of_its_frames_on_a_terminal(runs, tmp_path, capsys, monkeypatch):
    """--animate drew for 20 s (a 50-step demo episode; a minute at the time limit) without a sign of life,
    where every other long step of the commands shows a bar on a terminal; off a terminal it draws none."""
    gif = tmp_path / "a.gif"
    assert main(["review", str(runs[0].path), "--animate", str(gif)]) == 0
    assert "animating" not in capsys.readouterr().err  # captured: no terminal
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(["review", str(runs[0].path), "--animate", str(gif)]) == 0
    err = capsys.readouterr().err
    # "/9 [", not "9/9": tqdm redraws at most every 0.1 s, so under load the bar was cleared (leave=False)
    # at 8/9 without drawing its last frame (2 failures in 8 runs)
    assert "animating a.gif" in err and "/9 [" in err, err


def test_no_progress_draws_no_bar_on_a_terminal(runs, tmp_path, capsys, monkeypatch):
    """review drew its bars (a folder's files, an animation's frames) on a terminal with no --no-progress to
    stop them, where simulate, sweep and train have one and README says every bar has."""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    gif = tmp_path / "a.gif"
    for argv in ([str(runs[0].path.parent)], [str(runs[0].path), "--animate", str(gif)]):
        assert main(["review", *argv]) == 0
        assert "\r" in capsys.readouterr().err  # the bar, drawn and cleared (leave=False)
        assert main(["review", *argv, "--no-progress"]) == 0
        err = capsys.readouterr().err
        assert "\r" not in err and "reading" not in err and "animating" not in err, err


@pytest.mark.parametrize("recorded", [3.0, 1e6, 1e300])
def test_a_sensor_ring_far_beyond_the_view_is_drawn_at_a_bound(runs, monkeypatch, recorded):
    """A recording from before the 1000 m bound on the sensor range (crowdsim.world.SENSOR_RANGE) drew its
    dashed ring at the recorded radius, which matplotlib dashes whole: 1e6 m took 24 s a plot, 1e300 m never
    ended. A ring that encloses the whole view is now drawn at twice the view's farthest corner, as unseen;
    a ring in view (3 m) is drawn as before, and the legend names the recorded range either way."""
    from matplotlib.patches import Circle

    from pipelines.logs.animation import animation_figure
    from pipelines.logs.plots import recording_figure

    monkeypatch.setattr("pipelines.loop.sensing.recorded_sensor_range", lambda config: recorded)
    rec = read_recording(runs[0].path)
    fig, drawn = recording_figure(rec)
    ax = fig.axes[0]
    rings = [p for p in ax.patches if isinstance(p, Circle) and p.get_linestyle() == "--"]
    assert len(rings) == 3 * len(drawn)  # robots x snapshots
    view = max(np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()))
    assert (
        all(r.radius == recorded for r in rings)
        if recorded == 3.0
        else all(r.radius < 4 * view for r in rings)
    )
    assert f"sensor range ({recorded:g} m)" in {t.get_text() for t in ax.get_legend().get_texts()}
    fig, _, _ = animation_figure(rec)
    rings = [p for p in fig.axes[0].patches if isinstance(p, Circle) and p.get_linestyle() == "--"]
    assert len(rings) == 3 and all(r.radius == min(recorded, rings[0].radius) < 1e3 for r in rings)
    assert f"sensor range ({recorded:g} m)" in {t.get_text() for t in fig.legends[0].get_texts()}


def test_unreadable_input_is_a_user_error(tmp_path, capsys):
    not_mcap = tmp_path / "x.mcap"
    not_mcap.write_text("hello, not an mcap file")
    assert main(["review", str(not_mcap)]) == 2
    assert "is not an MCAP file" in capsys.readouterr().err
    assert main(["review", str(tmp_path / "missing.mcap")]) == 2
    assert main(["review", str(tmp_path)]) == 2  # a folder with no valid recordings
    assert main(["review", str(not_mcap), "--times", "0,4"]) == 2  # --times without --plot
    capsys.readouterr()
    assert main(["review", str(not_mcap), "--plot", str(tmp_path / "p")]) == 2  # checked before reading
    assert "cannot write a figure of type '(no suffix)'" in capsys.readouterr().err


def test_a_device_or_a_pipe_is_named_as_no_regular_file(tmp_path, capsys):
    """`review /dev/zero` (or a pipe) said "no such recording" of a path that exists."""
    fifo = tmp_path / "run.mcap"
    os.mkfifo(fifo)
    for path in ("/dev/zero", str(fifo)):
        assert main(["review", path]) == 2
        err = capsys.readouterr().err
        assert err == f"crowdmpc review: error: {path}: is not a regular file (a device or a pipe)\n"
    assert main(["review", str(tmp_path / "missing.mcap")]) == 2
    assert capsys.readouterr().err.endswith("missing.mcap: no such recording\n")


def _other_programs_file(path, topics=("/foo",), metadata=(), schema="Foo", library="other"):
    from mcap.writer import Writer

    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library=library)
        schema_id = writer.register_schema(schema, "jsonschema", b'{"type": "object"}')
        for name in metadata:
            writer.add_metadata(name, {"k": "v"})
        for topic in topics:
            channel = writer.register_channel(topic, "json", schema_id)
            for k in range(5):
                writer.add_message(channel, log_time=k, data=json.dumps({"x": k}).encode(), publish_time=k)
        writer.finish()


def _not_a_recording(path, holds):
    return (
        f"{path} is an MCAP file but not a crowdmpc recording: its header names library 'other', where a "
        f"recording's names 'crowdmpc', and it holds {holds}, but no 'crowdmpc' metadata record nor a "
        "crowdmpc.* schema"
    )


def test_another_programs_mcap_file_is_no_recording(runs, tmp_path, capsys):
    """An MCAP file with none of a recording's metadata or topics was reviewed as one: a table of dashes and,
    under --check, "5 messages, ok", exit 0, and in a folder a row counted among its runs."""
    path = tmp_path / "other.mcap"
    _other_programs_file(path)
    foo = "topic '/foo'"
    for check in ([], ["--check"]):
        assert main(["review", str(path), *check]) == 2
        out, err = capsys.readouterr()
        assert out == "" and err == f"crowdmpc review: error: {_not_a_recording(path, foo)}\n"
    many = tmp_path / "many.mcap"
    _other_programs_file(many, topics=("/a", "/b", "/c", "/d"), metadata=("m",))
    with pytest.raises(PipelineError, match=r"topics '/a', '/b', '/c' and 1 more; metadata record 'm', but"):
        read_recording(many)
    # what only a recording carries makes one, whatever program wrote the rest
    _other_programs_file(path, library="crowdmpc")
    assert read_recording(path).channels.keys() == {"/foo"}
    _other_programs_file(path, topics=("/foo", "/robots"), schema="crowdmpc.Robots")
    assert read_recording(path).channels.keys() == {"/foo", "/robots"}
    _other_programs_file(path, metadata=("crowdmpc",))
    assert read_recording(path).metadata == {"crowdmpc": {"k": "v"}}

    folder = tmp_path / "folder"
    folder.mkdir()
    shutil.copy(runs[0].path, folder)
    _other_programs_file(folder / "other.mcap")
    assert main(["review", str(folder)]) == 0
    out, err = capsys.readouterr()
    assert "\n1 run\n" in out and "other.mcap" not in out
    assert f"crowdmpc review: unreadable: {folder / 'other.mcap'} is an MCAP file but not a crowdmpc " in err
    assert main(["review", str(folder), "--check"]) == 1


def test_a_file_with_a_recordings_topic_or_metadata_names_alone_is_no_recording(runs, tmp_path, capsys):
    """Another program's file with a /scene of its own (a topic name many write), or a metadata record named
    "episode", counted as a crowdmpc recording: review printed a table of dashes with exit 0, compare said its
    episode did not finish."""
    path = tmp_path / "scene.mcap"
    _other_programs_file(path, topics=("/scene",), schema="foxglove.SceneUpdate")
    refused = _not_a_recording(path, "topic '/scene'")
    assert main(["review", str(path)]) == 2
    assert capsys.readouterr().err == f"crowdmpc review: error: {refused}\n"
    assert main(["compare", str(path), str(runs[0].path)]) == 2
    assert capsys.readouterr().err.endswith(f"{refused}\n")
    _other_programs_file(path, topics=(), metadata=("episode",))
    with pytest.raises(PipelineError, match="it holds metadata record 'episode', but no 'crowdmpc' metadata"):
        read_recording(path)


def test_a_folder_of_run_folders_is_reviewed_one_and_two_levels_down(runs, tmp_path, capsys):
    """A folder with no recordings of its own stands for those one and two levels below it (runs/ over
    runs/cmpc/, a sweep's DIR over DIR/mcap/CELL/), named by their paths below it, since cells hold files of
    the same names; a folder with recordings of its own is never mixed with its subfolders'."""
    empty = tmp_path / "nothing"
    (empty / "a" / "b" / "c").mkdir(parents=True)
    (empty / "a" / "b" / "c" / "deep.mcap").write_bytes(runs[0].path.read_bytes())  # three levels: not read
    assert main(["review", str(empty)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"no .mcap files in {empty}, nor in the two levels of folders below it; " in err
    above = tmp_path / "above"
    for cell, humans in (("mcap/cell_a", 4), ("mcap/cell_b", 5)):  # a sweep's layout: one file name, 2 cells
        record_episode(above / cell, seed=1, steps=8, n_humans=humans)
    assert main(["review", str(above), "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    name = runs[0].path.name
    assert f"mcap/cell_a/{name}" in out and f"mcap/cell_b/{name}" in out
    report = json.loads((tmp_path / "r.json").read_text())
    assert [g["totals"]["runs"] for g in report["groups"]] == [1, 1] and len(report["runs"]) == 2
    assert main(["review", str(above / "mcap")]) == 0
    assert f"cell_a/{name}" in capsys.readouterr().out
    shutil.copy(runs[1].path, above / runs[1].path.name)  # now the folder has one of its own
    assert main(["review", str(above), "--json", str(tmp_path / "r.json")]) == 0
    assert json.loads((tmp_path / "r.json").read_text())["totals"]["runs"] == 1
    assert "its subfolders hold 2 recordings, not read" in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("ffmpeg") is not None, reason="ffmpeg is installed: an mp4 would be written")
def test_mp4_without_ffmpeg_says_so(runs, tmp_path):
    with pytest.raises(PipelineError, match="needs ffmpeg"):
        from pipelines.logs.animation import animate_recording

        animate_recording(read_recording(runs[0].path), tmp_path / "a.mp4")


def test_folder_with_a_truncated_run(runs, tmp_path, capsys):
    shutil.copy(runs[0].path, tmp_path / "a.mcap")
    data = runs[1].path.read_bytes()
    (tmp_path / "b.mcap").write_bytes(data[: len(data) // 3])
    assert main(["review", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "2 runs, 1 whose episode did not end (no metrics)" in out
    assert "b.mcap is truncated" in err


@pytest.mark.parametrize(
    "times, expected",
    [
        ("nan", "non-negative seconds"),
        ("0,inf", "non-negative seconds"),
        ("-1", "non-negative seconds"),
        ("a", "seconds separated by commas"),
    ],
)
def test_times_must_be_finite_non_negative_seconds(runs, tmp_path, times, expected, capsys):
    with pytest.raises(SystemExit) as done:
        main(["review", str(runs[0].path), "--plot", str(tmp_path / "p.png"), "--times", times])
    err = capsys.readouterr().err
    assert done.value.code == 2 and err.count("\n") == 1
    assert f"argument --times: expected {expected}, e.g. 0,4,8; got '{times}'" in err


@pytest.mark.parametrize("t", [1e3, 1e17, 1e308])
def test_a_time_past_the_episode_draws_its_last_state(runs, t):
    """`--times 1e17` drew the plans at t = 0 s: |times - 1e17| rounds to 1e17 for every state, and argmin
    took the first. 8 steps of 0.4 s: the last recorded state is at 3.2 s."""
    view = episode_view(read_recording(runs[0].path))
    assert view.row_at(t) == len(view.times) - 1 and view.times[-1] == pytest.approx(3.2)
    assert view.row_at(1.3) == 3  # 1.2 s, the nearest state within the episode


@pytest.mark.parametrize("t", ["1e3", "1e17", "1e308"])
def test_a_time_past_the_episode_draws_its_last_plan(runs, tmp_path, t, capsys):
    """review --plot uses planned_row_at, which took t unclipped: --times 1e17 drew the plans at t = 0 s
    (on a 13.2 s episode, at 8.4 s) while 1e3 drew the last plan. 8 steps of 0.4 s: the last plan is at
    2.8 s. A time past the episode's end is said so (the title alone showed the time had moved); one within
    it is not."""
    assert main(["review", str(runs[0].path), "--plot", str(tmp_path / "p.png"), "--times", t]) == 0
    late = f"; --times {float(t):g} past the episode's end at 3.2 s"
    assert f"(plans and predictions at t = 2.8 s{late})" in capsys.readouterr().out
    assert main(["review", str(runs[0].path), "--plot", str(tmp_path / "p.png"), "--times", "0,3.2"]) == 0
    assert "(plans and predictions at t = 0, 2.8 s)" in capsys.readouterr().out


def test_a_run_summary_names_the_units_of_its_metrics(runs, capsys):
    assert main(["review", str(runs[0].path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    metrics = runs[0].result.metrics
    for name, unit in (("travel_time", "s"), ("min_distance", "m"), ("path_length", "m")):
        assert any(line.split()[:2] == [name, f"({unit})"] for line in lines), name
    assert any(line.split()[:2] == ["success", "yes" if metrics.success else "no"] for line in lines)


def test_a_folders_table_names_the_units_of_its_columns(runs):
    """review DIR's row per file headed its columns `travel_time` and `min_distance`, no unit, where the
    same table's step times read "median ms" and the set-ups' table "mean travel time s"."""
    from pipelines.logs.run_tables import aggregate_table

    text, _ = aggregate_table([summarize(read_recording(r.path)) for r in runs], [])
    header = re.split(r"\s{2,}", text.splitlines()[0].strip())  # columns two spaces apart at least
    assert "travel_time s" in header and "min_distance m" in header
    assert "travel_time" not in header and "min_distance" not in header


def test_a_recording_of_another_format_is_reviewed_with_a_warning(tmp_path, capsys, monkeypatch):
    """The recorder writes its format ("crowdmpc-episode/3", bumped when a channel's meaning changes) into the
    file's "crowdmpc" metadata, but nothing read it: a crowdmpc-episode/4 file was reviewed, --check "ok", as
    if its channels meant what this version's do; it is a problem of the file, named with its format."""
    import pipelines.logs.recording as recording

    monkeypatch.setattr(recording, "FORMAT", "crowdmpc-episode/4")
    run = record_episode(tmp_path, seed=1, steps=4)
    monkeypatch.undo()
    assert main(["review", str(run.path), "--check"]) == 1
    out, err = capsys.readouterr()
    assert "recorded in format 'crowdmpc-episode/4'; this crowdmpc reads 'crowdmpc-episode/3'" in out + err


def test_compare_names_the_code_that_recorded_each_run(tmp_path, capsys, monkeypatch):
    """`review A --compare B` of a run recorded before an upgrade and one after it set their metrics side by
    side without saying which code made either (A's summary above names A's alone, B's nowhere)."""
    import pipelines.logs.recording as recording
    from pipelines.plugins import code_with_plugins

    a = record_episode(tmp_path / "a", seed=1, steps=4)
    monkeypatch.setattr(
        recording,
        "code_with_plugins",
        lambda: {**code_with_plugins(), "commit": "0123456789abcdef", "dirty": False},
    )
    b = record_episode(tmp_path / "b", seed=1, steps=4)
    monkeypatch.undo()
    assert main(["review", str(a.path), "--compare", str(b.path)]) == 0
    table = capsys.readouterr().out.split(f"A: a/{a.path.name}")[
        1
    ]  # the side-by-side table, after A's summary
    (row,) = [line for line in table.splitlines() if line.startswith("crowdmpc ")]
    assert row.split()[-2:] == ["(commit", "0123456789ab)"]


def test_compare_tells_two_runs_of_one_scene_apart(tmp_path, capsys, monkeypatch):
    """The demo beside a rerun with `--set mpc.w_coll=1e6` into runs/demo-w6 (README): both files are
    circle_seed000000.mcap, so the table's columns read "A: circle_seed000000.mcap" and "B: ..." alike, the
    overlay's legend "A: cmpc / social_lstm_eth / circle / seed 0" and "B:" the same, and neither said that
    w_coll differed. The columns name the folders; a row and the legend name each differing setting."""
    import pipelines.logs.plots as plots

    a = record_episode(tmp_path / "demo", seed=1, steps=4, config={"mpc": {"w_coll": 1e7, "horizon": 4}})
    b = record_episode(tmp_path / "demo-w6", seed=1, steps=4, config={"mpc": {"w_coll": 1e6, "horizon": 4}})
    labels = []
    monkeypatch.setattr(
        plots, "_dedupe_legend", lambda ax, below: labels.extend(ax.get_legend_handles_labels()[1])
    )
    overlay = tmp_path / "o.png"
    assert main(["review", str(a.path), "--compare", str(b.path), "--plot", str(overlay)]) == 0
    table = capsys.readouterr().out.split("A: demo/circle_seed000001.mcap")[1]
    assert "B: demo-w6/circle_seed000001.mcap" in table.splitlines()[0]
    rows = {line.split()[0]: line.split()[1:] for line in table.splitlines()[2:] if line.strip()}
    assert rows["mpc.w_coll"] == ["10000000.0", "1000000.0"]
    assert "mpc.horizon" not in rows  # the same in both: no row
    ended = "\nno success, ended at 1.6 s"  # the handmade file does not say what ended it
    assert [label for label in labels if label.startswith(("A:", "B:"))] == [
        f"A: handmade / constant_velocity / circle / seed 1 / mpc.w_coll 10000000.0{ended}",
        f"B: handmade / constant_velocity / circle / seed 1 / mpc.w_coll 1000000.0{ended}",
    ]


def test_a_folder_of_runs_recorded_by_different_code_says_so(tmp_path, capsys, monkeypatch):
    """A run recorded before an upgrade beside one recorded after it, same set-up: review DIR pooled them into
    one aggregate without a word (a 4a16d16^ recording, which names no commit, beside a f01a943 one), where a
    resumed sweep says its episodes are mixed; a warning names the commits of the set-up's runs."""
    import pipelines.logs.recording as recording
    from pipelines.plugins import code_with_plugins

    record_episode(tmp_path, seed=1, steps=4)
    now = code_with_plugins()
    monkeypatch.setattr(recording, "code_with_plugins", lambda: {**now, "commit": "0123456789abcdef"})
    record_episode(tmp_path, seed=2, steps=4)
    assert main(["review", str(tmp_path)]) == 0
    err = capsys.readouterr().err
    assert "runs recorded by different code" in err and "commit 0123456789ab" in err
    monkeypatch.undo()
    for other in tmp_path.glob("*seed000002*"):
        other.unlink()
    record_episode(tmp_path, seed=2, steps=4)  # both by this code: nothing to say
    assert main(["review", str(tmp_path)]) == 0
    assert "different code" not in capsys.readouterr().err


def test_a_folder_of_different_set_ups_gets_an_aggregate_for_each(tmp_path, capsys):
    """A 4-human and a 5-human run pooled would be one rate over two experiments: one aggregate each."""
    for seed, humans in ((1, 4), (2, 5), (3, 5)):
        record_episode(tmp_path, seed=seed, steps=4, n_humans=humans)
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    out, err = capsys.readouterr()
    four, five = (
        "handmade, predictor constant_velocity, 3 robots, 4 humans",
        "handmade, predictor constant_velocity, 3 robots, 5 humans",
    )
    assert f"holds runs of 2 different set-ups ({four}; {five})" in err
    assert "review: note: " in err and "warning" not in err  # a sweep's cells are so by design: no warning
    assert f"== {four}: 1 run ==" in out and f"== {five}: 2 runs ==" in out
    assert "\n1 run\n" in out and "\n2 runs\n" in out  # "1 run" (was "1 runs")
    report = json.loads((tmp_path / "r.json").read_text())
    assert "totals" not in report and len(report["runs"]) == 3
    assert [(g["n_humans"], g["totals"]["runs"]) for g in report["groups"]] == [(4, 1), (5, 2)]
    assert [g["name"] for g in report["groups"]] == [four, five]


def test_a_recording_of_unknown_set_up_joins_the_one_known_or_stands_apart(tmp_path, capsys):
    """A file cut before its metadata names no set-up: with one set-up in the folder it is among its runs
    (as the folder's one aggregate always counted it); beside two, it is a group of its own, so named."""
    first = record_episode(tmp_path, seed=1, steps=4, n_humans=4)
    (tmp_path / "cut.mcap").write_bytes(cut_before_episode_metadata(first.path.read_bytes()))
    assert main(["review", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "different set-ups" not in err and "\n2 runs, 1 whose episode did not end" in out
    record_episode(tmp_path, seed=2, steps=4, n_humans=5)
    assert main(["review", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    assert "holds runs of 3 different set-ups" in err
    assert "== set-up unknown (no readable episode metadata): 1 run ==" in out


def test_runs_under_other_simulator_settings_are_other_set_ups(tmp_path, capsys):
    """A paper/visible/auto run and a v1/invisible/two_rows one of the same controller and crowd are two
    experiments: an aggregate each, named by profile, visibility and formation (and never "1 robots")."""
    import dataclasses

    from crowdsim.profiles import make_env_config
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.episode import run_episode

    controller = make_controller(ControllerSpec("straight"))
    v1 = dataclasses.replace(make_env_config("v1", "invisible"), formation="two_rows")
    with McapEpisodeRecorder(tmp_path) as recorder:
        for seed, env_config in enumerate((make_env_config(), make_env_config(), v1)):
            run_episode(
                controller, seed=seed, scenario="circle", n_humans=1, n_robots=1, env_config=env_config,
                observers=[recorder],
            )  # fmt: skip
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    out, err = capsys.readouterr()
    paper = "straight, predictor none, 1 robot, 1 human, profile paper, robots visible, formation auto"
    other = "straight, predictor none, 1 robot, 1 human, profile v1, robots invisible, formation two_rows"
    assert f"holds runs of 2 different set-ups ({paper}; {other})" in err
    assert f"== {paper}: 2 runs ==" in out and f"== {other}: 1 run ==" in out
    report = json.loads((tmp_path / "r.json").read_text())
    assert "totals" not in report
    assert [(g["name"], g["totals"]["runs"]) for g in report["groups"]] == [(paper, 2), (other, 1)]
    assert report["groups"][1]["settings"] == {
        "env.profile": "v1",
        "env.robots_visible": False,
        "env.formation": "two_rows",
    }


def test_a_controller_setting_tells_set_ups_apart_and_a_formation_not_recorded_is_auto(tmp_path, capsys):
    """Recordings from before formation existed ran the automatic one: they pool with "auto" runs; another
    controller setting (the MPC's horizon here) makes another set-up, named by it."""
    first = record_episode(tmp_path, seed=1, steps=2)  # its env config names no formation
    obs, after = first.observations[:2]
    recorder = McapEpisodeRecorder(tmp_path)
    env = {"dt": 0.4, "radius": 0.3, "formation": "auto"}
    for seed, horizon in ((2, 4), (3, 6)):
        recorder.on_reset(obs, {**first.meta, "seed": seed, "config": {"env": env, "horizon": horizon}})
        recorder.on_step(obs, control_output(obs), after)
    recorder.close()
    assert main(["review", str(tmp_path)]) == 0
    out, err = capsys.readouterr()
    base = "handmade, predictor constant_velocity, 3 robots, 4 humans"
    assert f"holds runs of 2 different set-ups ({base}, horizon 4; {base}, horizon 6)" in err
    assert f"== {base}, horizon 4: 2 runs ==" in out and f"== {base}, horizon 6: 1 run ==" in out


def test_margins_name_a_set_up_by_their_label_not_by_their_numbers(tmp_path, capsys):
    """A safety sweep's cells differ in margins: "margins cp0.1" names the set-up, not the margins' metres
    (mpc.human_margins) nor their mode, which the label stands for."""
    first = record_episode(tmp_path / "x", seed=1, steps=2)  # its folder: its config has no margins
    obs, after = first.observations[:2]
    recorder = McapEpisodeRecorder(tmp_path / "runs")
    for seed, margins, label in ((2, [0.11, 0.23, 0.35, 0.47], "cp0.1"), (3, [], "none")):
        config = {
            "env": {"dt": 0.4, "radius": 0.3},
            "mpc": {"human_margins": margins},
            "margins": {"mode": "none" if label == "none" else "conformal", "label": label},
        }
        recorder.on_reset(obs, {**first.meta, "seed": seed, "config": config})
        recorder.on_step(obs, control_output(obs), after)
    recorder.close()
    assert main(["review", str(tmp_path / "runs")]) == 0
    out, err = capsys.readouterr()
    base = "handmade, predictor constant_velocity, 3 robots, 4 humans"
    assert f"({base}, margins cp0.1; {base}, margins none)" in err and "0.23" not in err
    assert f"== {base}, margins cp0.1: 1 run ==" in out


def test_margins_only_one_controller_records_do_not_name_the_set_ups(tmp_path, capsys):
    """`review runs/` over `simulate --controller cmpc --record runs/cmpc` and `--controller orca --record
    runs/orca` named the ORCA set-up "orca, predictor none, margins.label not recorded": ORCA plans with no
    margins and records none, and the controllers already tell the two apart. Margins that differ among
    the set-ups that record them still name each, a set-up without them as "margins not recorded"."""
    first = record_episode(tmp_path / "x", seed=1, steps=2)
    obs, after = first.observations[:2]
    env = {"dt": 0.4, "radius": 0.3}
    runs = (
        ("mpc_like", {"env": env, "margins": {"mode": "none", "label": "none"}}),
        ("baseline", {"env": env}),  # no margins recorded
    )
    recorder = McapEpisodeRecorder(tmp_path / "runs")
    for seed, (controller, config) in enumerate(runs, start=2):
        recorder.on_reset(obs, {**first.meta, "seed": seed, "controller": controller, "config": config})
        recorder.on_step(obs, control_output(obs), after)
    recorder.close()
    assert main(["review", str(tmp_path / "runs")]) == 0
    out, err = capsys.readouterr()
    tail = "predictor constant_velocity, 3 robots, 4 humans"
    assert f"(mpc_like, {tail}; baseline, {tail})" in err and "not recorded" not in out + err
    recorder = McapEpisodeRecorder(tmp_path / "runs")  # a second MPC set-up, other margins
    config = {"env": env, "margins": {"mode": "conformal", "label": "cp0.1"}}
    recorder.on_reset(obs, {**first.meta, "seed": 4, "controller": "mpc_like", "config": config})
    recorder.on_step(obs, control_output(obs), after)
    recorder.close()
    assert main(["review", str(tmp_path / "runs")]) == 0
    err = capsys.readouterr().err
    assert f"mpc_like, {tail}, margins none; baseline, {tail}, margins not recorded; mpc_like" in err


def test_set_ups_side_by_side_name_each_by_what_differs(tmp_path, capsys):
    """After a table per set-up, one row each: named by the parts of its name the others do not share, with
    the figures of its own aggregate."""
    for folder, humans in (("a", 3), ("b", 4)):
        record_episode(tmp_path / folder, seed=1, n_humans=humans, steps=3)
    assert main(["review", str(tmp_path), "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    groups = json.loads((tmp_path / "r.json").read_text())["groups"]
    assert [g["n_humans"] for g in groups] == [3, 4]
    table = out.split("== 2 set-ups side by side ==\n")[1].splitlines()[:4]
    assert table[0].split("  ")[0] == "set-up"
    for line, group in zip(table[2:], groups, strict=True):
        t = group["totals"]
        cells = line.split()
        assert cells[:4] == [str(group["n_humans"]), "humans", "1", f"{t['success_rate']:.1f}"]
        assert cells[4] == f"({t['success_count']}/1)"
        # robots touching each other, after contact: its rate and count
        assert cells[9:11] == [f"{t['robot_contact_rate']:.1f}", f"({t['robot_contact_count']}/1)"]
        # printed to 3 significant digits
        assert float(cells[-2]) == pytest.approx(t["solve_time_median_ms"], rel=5e-3)


def test_set_ups_side_by_side_print_a_fast_controllers_steps_to_three_digits():
    """The times were rounded to 0.1 ms before the table's 3 significant digits: ORCA's 0.156 ms median
    printed as 0.200 (28 % off)."""
    totals = {"runs": 2, "control_steps": 80, "solve_time_median_ms": 0.156, "solve_time_p95_ms": 0.2534}
    row = setups_table(["orca"], [totals]).splitlines()[-1].split()
    assert row[0] == "orca" and row[-2:] == ["0.156", "0.253"]


def test_times_with_compare_is_refused_before_reading(runs, tmp_path, capsys):
    """--compare's overlay draws both runs' paths and no plan: --times was accepted and went unused, the
    overlay written as if it had been honoured (exit 0)."""
    overlay = tmp_path / "overlay.png"
    argv = ["review", str(runs[0].path), "--compare", str(runs[1].path), "--plot", str(overlay)]
    assert main([*argv, "--times", "0,1.2"]) == 2
    assert "--compare's overlay draws none" in capsys.readouterr().err
    assert not overlay.exists()
    assert main(argv) == 0 and overlay.exists()  # the overlay itself as before


def test_plot_times_fall_on_states_with_a_plan(runs, tmp_path, tmp_path_factory, capsys):
    """The final state has no plan (no step is taken from it): --times at or past the end drew that state
    and said "plans at t = 3.2 s" with no plan or prediction drawn. Now the nearest state with a plan; a
    recording without plans keeps the nearest state of all."""
    png = tmp_path / "p.png"
    assert main(["review", str(runs[0].path), "--plot", str(png), "--times", "100,3.2,0.5"]) == 0
    said = "(plans and predictions at t = 0.4, 2.8 s; --times 100 past the episode's end at 3.2 s)"
    assert said in capsys.readouterr().out
    plain = record_episode(tmp_path_factory.mktemp("plain"), seed=1, steps=8, with_plan=False)
    assert main(["review", str(plain.path), "--plot", str(png), "--times", "100"]) == 0
    # it records no plan: it had said "plans"
    assert "(agents at t = 3.2 s; --times 100 past the episode's end at 3.2 s)" in capsys.readouterr().out


def test_a_compare_file_that_cannot_be_read_is_the_one_line_alone(runs, tmp_path, capsys):
    """`review A --compare /dev/zero` printed A's whole summary before the one-line error."""
    for other in ("/dev/zero", str(tmp_path / "missing.mcap")):
        assert main(["review", str(runs[0].path), "--compare", other]) == 2
        out, err = capsys.readouterr()
        assert out == "" and len(err.strip().splitlines()) == 1 and other in err


def test_the_plots_legend_hides_nothing_drawn(runs):
    """`review RUN --plot` moved plot_episode's legend into the axes (loc="best"): on a 12-robot run it
    covered the goals and several paths. It stands beside the axes now, as simulate --plot's does."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from pipelines.logs.plots import recording_figure

    fig, _ = recording_figure(read_recording(runs[0].path))
    FigureCanvasAgg(fig).draw()
    ax = fig.axes[0]
    legend = ax.get_legend()
    assert {"plan", "prediction", "robot goals"} <= {t.get_text() for t in legend.get_texts()}
    assert not legend.get_window_extent().overlaps(ax.get_window_extent())


def test_the_plots_title_promises_plans_only_when_the_file_has_them(runs, tmp_path):
    """`review` of an ORCA run (6 robots, 50 humans) was titled "plans and predictions at t = 0, 13.2, 26 s"
    over a plot with neither: ORCA records none."""
    from pipelines.logs.plots import recording_figure

    planned, _ = recording_figure(read_recording(runs[0].path), [0.0])
    assert planned.axes[0].get_title().endswith("\nplans and predictions at t = 0 s")
    bare = record_episode(tmp_path, with_plan=False, steps=3)
    fig, _ = recording_figure(read_recording(bare.path), [0.0])
    assert fig.axes[0].get_title().endswith("\nagents at t = 0 s")


def test_the_animations_clock_shows_the_recorded_times(runs, monkeypatch):
    """With a 0.25 s step (`--set world.dt=0.25`) the clock read "t = 0.2 s", "0.8 s", "1.2 s" at 0.25,
    0.75 and 1.25 s: one decimal, rounded."""
    import dataclasses

    import pipelines.logs.animation as animation
    from pipelines.logs.ending import clock_decimals

    def quarter_steps(rec):
        view = episode_view(rec)
        return dataclasses.replace(view, times=view.steps * 0.25, dt=0.25)

    monkeypatch.setattr(animation, "episode_view", quarter_steps)
    _, draw, _ = animation.animation_figure(read_recording(runs[0].path))
    assert [draw(row)[-1].get_text() for row in (1, 3, 5)] == [
        f"t = {t} s of 2.00 s" for t in ("0.25", "0.75", "1.25")
    ]
    assert [clock_decimals(dt) for dt in (0.4, 0.1, 0.25, 0.05, 0.125)] == [1, 1, 2, 2, 3]


def test_a_run_without_plans_is_drawn_to_its_end(tmp_path):
    """The default times are those of plans (the last state has none): a straight or ORCA run was drawn
    at 0, 3.6 and 6.8 s of 10.4 s, the robots never shown at their goals. Without plans it gets
    simulate --plot's snapshots, the last state among them."""
    from pipelines.logs.plots import recording_figure

    bare = record_episode(tmp_path, with_plan=False, steps=8)
    _, drawn = recording_figure(read_recording(bare.path))
    view = episode_view(read_recording(bare.path))
    assert drawn[0] == 0.0 and drawn[-1] == view.times[-1] and len(drawn) == 5


def test_a_recording_shows_itself_in_one_short_line(runs):
    """``read_recording(path)`` as a notebook cell's last line printed the dataclass's repr: every message
    of every topic, 420 kB for a CMPC episode of 3 robots and 4 humans (256 messages). It names the file,
    the run and what was read."""
    rec = read_recording(runs[0].path)
    text = repr(rec)
    assert "\n" not in text and len(text) < 400
    messages = sum(len(m) for m in rec.messages.values())
    assert text == (
        f"Recording({str(runs[0].path)!r}, {rec.label!r}, {messages} messages on {len(rec.messages)} topics, "
        "complete, 0 problems)"
    )


def _swap_sides(out_dir) -> None:
    """Two straight-line robots swapping sides 0.24 m apart sideways, no human, recorded into ``out_dir``."""
    import gymnasium as gym

    import crowdsim
    from crowdsim.env import EnvConfig
    from crowdsim.scenarios import Layout
    from pipelines.loop.controllers import ControllerSpec, make_controller
    from pipelines.loop.gym_loop import run_gym_episode

    config = EnvConfig()
    env = gym.make(crowdsim.ENV_ID, n_humans=0, n_robots=2, config=config)
    layout = Layout(
        robot_starts=[[-4.0, 0.12], [4.0, -0.12]],
        robot_goals=[[4.0, 0.12], [-4.0, -0.12]],
        human_starts=[],
        human_goals=[],
    )
    controller = make_controller(ControllerSpec("straight"), config)
    with McapEpisodeRecorder(out_dir) as recorder:
        run_gym_episode(controller, env, seed=0, options={"layout": layout}, observers=[recorder])


def test_folder_totals_say_when_robots_touched(tmp_path, capsys):
    """Two robots passing 0.34 m apart (sampled; sum of the radii 0.6 m) reviewed as a clean success: the
    rates were all robot-human. The totals say it now, marked as not a metric of the paper."""
    _swap_sides(tmp_path)
    (path,) = tmp_path.glob("*.mcap")
    m = summarize(read_recording(path))["metrics"]
    assert m["success"] and m["robot_contact"] and m["min_distance_robots"] < 0.6
    assert (m["robot_contact_steps"], m["n_steps"]) == (1, 21)  # one state of 22 closer than 0.6 m
    assert main(["review", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (
        "\nrobot-robot contact (two robots touching, not in the paper): 100.0 % (1/1), 4.55 % of states; "
        "between steps 100.0 % (1/1)\n" in out
    )
    assert m["robot_contact_between_steps"] and m["min_distance_robots_between_steps"] < 0.34


def test_robot_contact_reads_n_a_for_recordings_before_it(runs):
    from pipelines.logs.run_tables import aggregate_table

    summaries = [summarize(read_recording(r.path)) for r in runs]
    text, totals = aggregate_table(summaries, [])
    assert (
        "robot-robot contact (two robots touching, not in the paper): 0.0 % (0/2), 0.00 % of states; "
        "between steps 0.0 % (0/2)\n" in text
    )
    for s in summaries:  # a recording of the thirty-fourth session: robot contact at the states only
        del s["metrics"]["robot_contact_between_steps"], s["metrics"]["min_distance_robots_between_steps"]
    text, totals = aggregate_table(summaries, [])
    before = "robot-robot contact (two robots touching, not in the paper): 0.0 % (0/2), 0.00 % of states\n"
    assert before in text
    for s in summaries:
        del s["metrics"]["robot_contact"], s["metrics"]["robot_contact_steps"]
    text, totals = aggregate_table(summaries, [])
    assert (
        "robot-robot contact (two robots touching, not in the paper): n/a (metrics recorded before it)"
        in text
    )
    assert totals["robot_contact_rate"] is None and totals["contact_count"] == 0  # the others still count


def test_set_ups_side_by_side_say_n_a_for_robot_contact_their_runs_predate():
    """A set-up whose runs' metrics predate robot contact (None in the totals, from NaN) reads "n/a" in that
    column, one without ended episodes "-"; the other rates as before."""
    from pipelines.logs.run_tables import setups_table

    rates = {
        f"{k}_{x}": v for k in ("success", "collision", "contact") for x, v in (("rate", 50.0), ("count", 1))
    }
    old = {"runs": 2, "episodes": 2, **rates, "robot_contact_rate": None, "robot_contact_count": None}
    new = {**old, "robot_contact_rate": 0.0, "robot_contact_count": 0}
    lines = setups_table(["old", "new", "none"], [old, new, {"runs": 1}]).splitlines()
    header = [cell.strip() for cell in lines[0].split("  ") if cell.strip()]
    assert header[:6] == ["set-up", "runs", "success %", "collision %", "contact %", "robot contact %"]
    assert lines[2].split()[8] == "n/a" and lines[3].split()[8:10] == ["0.0", "(0/2)"]
    assert lines[4].split()[5] == "-"


def test_a_sweeps_recordings_of_its_failures_only_say_their_rates_are_not_the_sweeps(runs, tmp_path, capsys):
    """`sweep --record failures` keeps the episodes where not every robot arrived or a robot came within
    0.8 m of a human: reviewed, a straight-line sweep of 20 episodes with 19 collisions (95 %) read
    "collision 100.0 % (19/19)", unsaid that the runs are a selection. Reviewed as the sweep's DIR, DIR/mcap
    or DIR/mcap/CELL, a warning says so; a sweep that kept every episode, or any other folder, gets none."""
    sweep = tmp_path / "sweep"
    (sweep / "mcap" / "cell_a").mkdir(parents=True)
    shutil.copy(runs[0].path, sweep / "mcap" / "cell_a" / runs[0].path.name)
    policies = ("all", "failures")  # a sweep extended by a second run that kept only its failures
    meta = {"runs": [{"config": {"sweep": {"record": policy}}} for policy in policies]}
    (sweep / "sweep.json").write_text(json.dumps(meta))
    for folder in (sweep, sweep / "mcap", sweep / "mcap" / "cell_a"):
        assert main(["review", str(folder)]) == 0
        err = capsys.readouterr().err
        assert f"crowdmpc review: warning: {sweep} kept the recordings of its failed episodes only" in err
        assert "not the sweep's: its table.md and cells.csv give those" in err
    meta["runs"] = meta["runs"][:1]
    (sweep / "sweep.json").write_text(json.dumps(meta))
    assert main(["review", str(sweep)]) == 0
    assert "failed episodes only" not in capsys.readouterr().err
