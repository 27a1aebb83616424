"""What simulate's and review's figures say of the run they draw: how it ended, and when. Each test runs the
command line and reads the figures' titles and legends."""

from __future__ import annotations

import pytest

from tests.cli_calls import run_cli


@pytest.fixture
def timed_out(tmp_path, capsys, monkeypatch):
    """simulate --controller straight --humans 4 --set env.time_limit=6 --plot --record: a timeout, its
    last step started at 4.8 s (the paper's profile starts none at or after 6 - 1 s) and ended at 5.2 s;
    simulate's figure and the recording."""
    import pipelines.commands.simulate_table as simulate_table

    figures = []
    original = simulate_table.first_episode_figure
    monkeypatch.setattr(
        simulate_table, "first_episode_figure", lambda *a: figures.append(original(*a)) or figures[-1]
    )
    argv = ["simulate", "--controller", "straight", "--humans", "4", "--set", "env.time_limit=6"]
    argv += ["--plot", str(tmp_path / "p.png"), "--record", str(tmp_path), "--no-progress"]
    code, out, _ = run_cli(capsys, *argv)
    assert code == 0 and "timeout                   100.0 %" in out
    (figure,) = figures
    (path,) = tmp_path.glob("*.mcap")
    return figure, path


def test_a_timeouts_titles_say_when_and_at_which_limit(timed_out):
    """simulate --plot titled the run "... timeout, min robot-human distance ..." and review --plot and
    --animate "straight / circle / seed 0": neither said when it ended nor the limit it ran under. All three
    now say "timeout at 5.2 s (time limit 6 s)"."""
    from pipelines.logs.animation import animation_figure
    from pipelines.logs.plots import recording_figure
    from pipelines.logs.reader import read_recording

    figure, path = timed_out
    said = "timeout at 5.2 s (time limit 6 s)"
    assert figure.axes[0].get_title().splitlines()[1].startswith(f"{said}, min robot-human distance ")
    rec = read_recording(path)
    plotted, _ = recording_figure(rec)
    assert plotted.axes[0].get_title().splitlines() == [f"straight / circle / seed 0: {said}", "agents at "
                                                        "t = 0, 1.2, 2.4, 4, 5.2 s"]  # fmt: skip
    animated, draw, view = animation_figure(rec)
    assert draw(len(view.times) - 1)[-2:] == [animated.axes[0].title, animated.axes[0].texts[0]]
    assert animated.axes[0].get_title() == f"straight / circle / seed 0: {said}"  # its last frame


def test_an_animation_says_the_end_only_on_its_last_frame(timed_out):
    """review --animate titled every frame "... timeout at 5.2 s (time limit 6 s)", the first, of robots
    setting off, too. Frames before the end now say the label, their clock the time so far of the end's."""
    from pipelines.logs.animation import animation_figure
    from pipelines.logs.reader import read_recording

    fig, draw, view = animation_figure(read_recording(timed_out[1]))
    ax = fig.axes[0]
    frames = {}
    for row in (0, 3, len(view.times) - 1):
        draw(row)
        frames[row] = (ax.get_title(), ax.texts[0].get_text())
    assert list(frames.values()) == [
        ("straight / circle / seed 0", "t = 0.0 s of 5.2 s"),
        ("straight / circle / seed 0", "t = 1.2 s of 5.2 s"),
        ("straight / circle / seed 0: timeout at 5.2 s (time limit 6 s)", "t = 5.2 s of 5.2 s"),
    ]


def test_an_animation_frame_lists_only_what_it_draws(timed_out):
    """review --animate's frame 0 listed "robot path" under the axes before any path was drawn. A frame now
    shows the entry of the paths, plans and predictions only where it draws them, hiding (not removing) the
    others so that the legend keeps its place."""
    from pipelines.logs.animation import animation_figure
    from pipelines.logs.reader import read_recording

    fig, draw, view = animation_figure(read_recording(timed_out[1]))
    (legend,) = fig.legends

    def shown(row: int) -> dict[str, bool]:
        draw(row)
        return {
            t.get_text(): t.get_visible() and h.get_visible()
            for h, t in zip(legend.legend_handles, legend.get_texts(), strict=True)
        }

    assert shown(0) == {"robot": True, "human": True, "robot goal": True, "robot path": False}
    assert shown(1)["robot path"] and shown(len(view.times) - 1)["robot path"]
    assert not shown(0)["robot path"]  # back at the start: hidden again


def test_the_last_frame_of_a_planned_run_lists_no_plan(tmp_path):
    """The state after a run's last step has no plan and no prediction recorded: its frame drew neither and
    listed both; nor did frame 0 draw a prediction of a crowd standing still, which it listed."""
    from pipelines.logs.animation import animation_figure
    from pipelines.logs.reader import read_recording
    from tests.pipelines.mcap_episode import record_episode

    fig, draw, view = animation_figure(read_recording(record_episode(tmp_path, steps=3).path))
    (legend,) = fig.legends
    planned = ("robot plan", "predicted human path")
    assert set(planned) <= {t.get_text() for t in legend.get_texts()}
    # at t = 0 the constant-velocity prediction of people standing still strays 5e-7 m: drawn as a point
    rows = {0: (True, False), 1: (True, True), len(view.times) - 1: (False, False)}
    for row, expected in rows.items():
        draw(row)
        shown = {t.get_text(): t.get_visible() and h.get_visible() for h, t in zip(legend.legend_handles,
                 legend.get_texts(), strict=True)}  # fmt: skip
        assert (shown["robot plan"], shown["predicted human path"]) == expected, row


def test_the_overlays_legend_says_how_each_run_ended(timed_out, tmp_path, capsys):
    """review --compare --plot tagged each run by its label alone, 'A: straight / circle / seed 0 /
    env.time_limit 6.0', a timeout as a success; each tag now says how its run ended, on a line of its own,
    in the words of review's titles."""
    from pipelines.logs.plots import compare_figure
    from pipelines.logs.reader import read_recording

    argv = ["simulate", "--controller", "straight", "--humans", "4", "--record", str(tmp_path / "b")]
    assert run_cli(capsys, *argv, "--no-progress")[0] == 0
    (other,) = (tmp_path / "b").glob("*.mcap")
    fig = compare_figure(read_recording(timed_out[1]), read_recording(other))
    tags = [t.get_text() for t in fig.axes[0].get_legend().get_texts() if t.get_text()[:2] in ("A:", "B:")]
    assert tags == [
        "A: straight / circle / seed 0 / env.time_limit 6.0\ntimeout at 5.2 s (time limit 6 s)",
        "B: straight / circle / seed 0 / env.time_limit 40.0\nsuccess in 10.4 s",
    ]
