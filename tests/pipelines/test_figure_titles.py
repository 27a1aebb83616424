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
    from pipelines.logs.plots import animation_figure, recording_figure
    from pipelines.logs.reader import read_recording

    figure, path = timed_out
    said = "timeout at 5.2 s (time limit 6 s)"
    assert figure.axes[0].get_title().splitlines()[1].startswith(f"{said}, min robot-human distance ")
    rec = read_recording(path)
    plotted, _ = recording_figure(rec)
    assert plotted.axes[0].get_title().splitlines() == [f"straight / circle / seed 0: {said}", "agents at "
                                                        "t = 0, 1.2, 2.4, 4, 5.2 s"]  # fmt: skip
    animated, _, _ = animation_figure(rec)
    assert animated.axes[0].get_title() == f"straight / circle / seed 0: {said}"
