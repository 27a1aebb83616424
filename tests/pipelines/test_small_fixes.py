"""Small fixes of issue 15: a closed stdout, the report's plots by method, the animation's legend, wall-clock
MCAP log times (old 0-based files still read), and review's output paths checked before any work."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from pipelines import commands
from pipelines.cli import main
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.report import STALE_STAGING_S, write_report
from pipelines.experiments.report_plots import OUTCOMES, outcome_figure
from pipelines.experiments.summary import summarize as summarize_cells
from pipelines.logs.animation import animation_figure
from pipelines.logs.reader import read_recording
from pipelines.logs.review import summarize
from pipelines.logs.schema_check import check_recording
from tests.pipelines.mcap_episode import record_episode
from tests.pipelines.mcap_files import write_mcap

ROOT = Path(__file__).resolve().parents[2]
NS = 1_000_000_000


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    """A 5-step recorded episode, and the wall clock just before and after it was recorded."""
    before = time.time_ns()
    recorded = record_episode(tmp_path_factory.mktemp("runs"), steps=5)
    return recorded, before, time.time_ns()


# ---------------------------------------------------------------------------------------- a closed stdout
@pytest.mark.parametrize("extra", [[], ["--check"]])
def test_a_reader_that_leaves_ends_the_command_quietly(episode, extra):
    """`crowdmpc review FILE | head`, head gone before the output is flushed: no traceback, status 141."""
    command = [sys.executable, "-m", "pipelines.cli", "review", str(episode[0].path), *extra]
    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert process.stdout is not None and process.stderr is not None
    process.stdout.close()  # the only reader: every write to stdout now fails with EPIPE
    err = process.stderr.read().decode()
    assert process.wait(timeout=120) == commands.CLOSED_PIPE_STATUS == 141
    assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err, err


def test_a_broken_pipe_that_is_not_stdout_is_still_an_error(monkeypatch, episode):
    import pipelines.commands.review as review_command

    def broken(args):
        raise BrokenPipeError("a worker's pipe")

    monkeypatch.setattr(review_command, "run", broken)
    assert not commands.stdout_reader_left()  # pytest's captured stdout: no pipe at all
    with pytest.raises(BrokenPipeError, match="a worker's pipe"):
        main(["review", str(episode[0].path)])


# ------------------------------------------------------------------------------------------ report plots
def _records(experiment, outcomes):
    """Synthetic records: (method, humans) -> per episode (success, collision, contact, discomfort)."""
    records = []
    for cell in experiment.cells():
        for i, (success, collision, contact, discomfort) in enumerate(
            outcomes.get((cell.method, cell.n_humans), [])
        ):
            metrics = {
                "success": success,
                "travel_time": 18.0 + i if success else None,
                "collision": collision,
            }
            metrics |= {"contact": contact, "discomfort": discomfort, "min_distance": 1.0, "n_steps": 50}
            solver = {"steps": 50, "total_ms": 500.0, "median_ms": 10.0, "p95_ms": 20.0, "max_ms": 30.0}
            solver |= {
                "mean_iterations": 2.0,
                "max_iterations": 3,
                "fallback_steps": 0,
                "statuses": {"ok": 50},
            }
            key = {
                "key": f"{cell.key}/{i}",
                "cell": cell.key,
                "method": cell.method,
                "n_humans": cell.n_humans,
            }
            where = {"scenario": ("circle", "perpendicular")[i % 2], "seed": i // 2, "wall_s": 1.0}
            records.append(key | where | {"metrics": metrics, "solver": solver})
    return records


EPISODES = [(True, False, False, False), (True, True, False, True), (False, True, True, False)]


def test_one_crowd_size_plots_each_outcome_by_method(tmp_path):
    swap = get_experiment("predictors")
    cells = swap.cells()[:2]
    records = _records(swap, {(c.method, c.n_humans): EPISODES for c in cells})
    names = {p.name for p in write_report(tmp_path, swap, cells, records).files if p.suffix == ".png"}
    outcomes = ["success", "travel_time", "collision", "contact", "discomfort"]
    assert {f"{o}_by_method.png" for o in outcomes} <= names
    assert not any(name.endswith("_vs_humans.png") for name in names)
    for outcome in outcomes:
        assert (tmp_path / f"{outcome}_by_method.png").read_bytes().startswith(b"\x89PNG")


def test_the_paper_marks_stand_on_their_methods_bars():
    """Table II at 5 humans only: a bar per method at x = 0, 1, the paper's figure on each (not at x = 5)."""
    table2 = get_experiment("table2")
    cells = [c for c in table2.cells() if c.n_humans == 5]
    records = _records(table2, {(c.method, 5): EPISODES for c in cells})
    summaries = summarize_cells(table2, cells, records)
    collision = next(o for o in OUTCOMES if o.name == "collision")
    ax = outcome_figure(table2, summaries, collision).axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["CMPC", "DMPC"]
    (paper,) = [line for line in ax.get_lines() if line.get_label() == "paper"]
    assert list(paper.get_xdata()) == [0, 1]
    assert list(paper.get_ydata()) == [s.paper.collision for s in summaries]
    assert [round(bar.get_height(), 3) for bar in ax.patches] == [66.667, 66.667]  # 2 of 3 under 0.8 m
    assert "personal-space violation" in ax.get_title() and ax.get_ylabel() == "Collision rate (%)"


def test_several_crowd_sizes_keep_the_vs_humans_names(tmp_path):
    table2 = get_experiment("table2")
    cells = [c for c in table2.cells() if c.n_humans in (5, 6)]
    records = _records(table2, {(c.method, c.n_humans): EPISODES for c in cells})
    names = {p.name for p in write_report(tmp_path, table2, cells, records).files}
    assert {"success_vs_humans.png", "collision_vs_humans.png", "contact_vs_humans.png"} <= names
    assert not any(name.endswith("_by_method.png") for name in names)


def test_an_interrupted_report_leaves_every_file_whole(tmp_path, monkeypatch):
    """A second Ctrl-C while the report is written (here: in its last plot) leaves the previous report's
    files as they were, not half written, and no staging folder; a killed report's staging folder (its
    process gone) is removed by the next report."""
    import pipelines.experiments.safety_plots as safety

    table2 = get_experiment("table2")
    cells = [c for c in table2.cells() if c.n_humans == 5]
    first = write_report(tmp_path, table2, cells, _records(table2, {(c.method, 5): EPISODES for c in cells}))
    before = {p.name: p.read_bytes() for p in first.files}
    fewer = _records(table2, {(c.method, 5): EPISODES[:1] for c in cells})

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(safety, "plot_safety", interrupted)
        with pytest.raises(KeyboardInterrupt):
            write_report(tmp_path, table2, cells, fewer)
    assert {p.name: p.read_bytes() for p in first.files} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(before)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    killed = tmp_path / f".report-{dead.pid}-x"  # a report killed before it renamed its files, an hour ago
    killed.mkdir()
    os.utime(killed, (time.time() - STALE_STAGING_S - 60,) * 2)
    again = write_report(tmp_path, table2, cells, fewer)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(before)
    assert (tmp_path / "cells.csv").read_bytes() != before["cells.csv"] and again.files == first.files


def test_a_report_leaves_the_staging_folder_of_a_report_on_another_machine(tmp_path):
    """Two reports of one sweep folder from two machines (a job's on a cluster node, `sweep --report-only`
    on the login node): the other's staging folder has a pid no process here has, and was removed under it
    as a killed report's ("No such file or directory: 'OUT/.report-PID-.../safety_tradeoff.png'")."""
    table2 = get_experiment("table2")
    cells = [c for c in table2.cells() if c.n_humans == 5]
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    elsewhere = tmp_path / f".report-{dead.pid}-x"  # its pid: no process here
    elsewhere.mkdir()
    (elsewhere / "cells.csv").write_text("being written")
    write_report(tmp_path, table2, cells, _records(table2, {(c.method, 5): EPISODES for c in cells}))
    assert (elsewhere / "cells.csv").read_text() == "being written"


# --------------------------------------------------------------------------------------- animation legend
def _legend(recording) -> list[str]:
    fig, draw, _ = animation_figure(recording)
    draw(0)
    (legend,) = fig.legends
    return [t.get_text() for t in legend.get_texts()]


def test_the_animation_has_a_legend(episode, tmp_path):
    everything = ["robot", "human", "robot goal", "robot path", "robot plan", "predicted human path"]
    assert _legend(read_recording(episode[0].path)) == everything
    baseline = read_recording(record_episode(tmp_path, steps=2, with_plan=False).path)
    assert _legend(baseline) == everything[:4]  # nothing planned, nothing predicted: not in the legend


# ---------------------------------------------------------------------------------- wall-clock log times
def test_log_time_is_the_wall_clock_start_plus_simulation_time(episode):
    recorded, before, after = episode
    rec = read_recording(recorded.path)
    start = rec.start_time_ns
    assert before <= start <= after and rec.metadata["episode"]["start_time_ns"] == str(start)
    for topic in ("/robots", "/humans", "/mpc/plan", "/mpc/prediction", "/mpc/solver"):
        for message in rec.messages[topic]:  # the simulation time is still in every message
            assert message.log_time_ns == start + round(message.data["time"] * NS), topic
    for message in rec.messages["/scene"]:  # Foxglove's stamps are the log time
        stamps = {(e["timestamp"]["sec"], e["timestamp"]["nsec"]) for e in message.data["entities"]}
        assert stamps == {divmod(message.log_time_ns, NS)}
    with recorded.path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics is not None
    assert summary.statistics.message_start_time == start  # what Foxglove's clock starts from: not 1970
    assert rec.sim_seconds(summary.statistics.message_end_time) == pytest.approx(2.0)  # 5 steps of 0.4 s
    assert summarize(rec)["started"] == time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime(start // NS))


def _rewritten(source: Path, out: Path, episode_metadata: dict[str, str] | None, shift_ns: int) -> Path:
    """``source`` with every log time less ``shift_ns`` and the "episode" metadata replaced."""
    with source.open("rb") as f:
        reader = make_reader(f)
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = list(reader.iter_messages())
    if episode_metadata is not None:
        metadata["episode"] = episode_metadata
    return write_mcap(out, metadata, messages, shift_ns=shift_ns)


def test_files_with_log_times_from_zero_still_read_and_review(episode, tmp_path, capsys):
    recorded = episode[0]
    new = read_recording(recorded.path)
    old_meta = {k: v for k, v in new.metadata["episode"].items() if k != "start_time_ns"}
    old = read_recording(_rewritten(recorded.path, tmp_path / "old.mcap", old_meta, new.start_time_ns))
    assert old.start_time_ns == 0 and old.problems == []
    assert [m.log_time_ns for m in old.messages["/robots"]] == [k * 400_000_000 for k in range(6)]
    assert old.sim_seconds(old.messages["/robots"][-1].log_time_ns) == pytest.approx(2.0)
    assert old.messages["/robots"][2].where("/robots", old.start_time_ns) == "/robots @ 0.800 s"
    assert new.messages["/robots"][2].where("/robots", new.start_time_ns) == "/robots @ 0.800 s"
    assert check_recording(old)[1] == [] and summarize(old)["started"] is None
    assert summarize(old)["metrics"] == summarize(new)["metrics"]
    plot = tmp_path / "old.png"
    assert main(["review", str(old.path), "--plot", str(plot), "--times", "0.8"]) == 0
    out = capsys.readouterr().out
    assert "at t = 0.8 s)" in out
    assert [line.split() for line in out.splitlines() if line.startswith("started")] == [["started", "-"]]
    assert plot.read_bytes().startswith(b"\x89PNG")


def test_a_bad_start_time_is_a_problem_and_times_count_from_zero(episode, tmp_path):
    recorded = episode[0]
    new = read_recording(recorded.path)
    bad_meta = new.metadata["episode"] | {"start_time_ns": "soon"}
    bad = read_recording(_rewritten(recorded.path, tmp_path / "bad.mcap", bad_meta, 0))
    assert bad.start_time_ns == 0
    assert bad.problems == [
        "metadata 'episode': start_time_ns = 'soon' is not a log time (an integer of ns in 0 .. 2^64 - 1); "
        "times are log times from 0"
    ]


# ------------------------------------------------------------------------- review's outputs checked first
@pytest.mark.parametrize(
    ("option", "name", "message"),
    [
        ("--plot", "p.png", "--plot {blocked}/p.png: {blocked} is not a directory"),
        ("--animate", "a.gif", "--animate {blocked}/a.gif: {blocked} is not a directory"),
        ("--json", "r.json", "--json {blocked}/r.json: {blocked} is not a directory"),
        ("--animate", "a.png", "--animate writes .gif or .mp4, got 'a.png'"),
    ],
)
def test_review_checks_its_output_paths_before_reading(tmp_path, capsys, option, name, message):
    blocked = tmp_path / "a-file"
    blocked.write_text("")
    missing = tmp_path / "missing.mcap"  # never read: the output is refused first
    assert main(["review", str(missing), option, str(blocked / name)]) == 2
    err = capsys.readouterr().err
    assert message.format(blocked=blocked) in err and "no such recording" not in err


def test_a_report_the_disk_refuses_names_its_folder_and_keeps_the_earlier_one(tmp_path):
    """A full disk (here `ulimit -f`) failed the report with an OSError naming no file, and the CLI's line
    said "could not write (File too large)"; it names the report's folder, whose earlier files stay whole."""
    import errno

    from tests.read_only import file_size_limit

    table2 = get_experiment("table2")
    cells = [c for c in table2.cells() if c.n_humans == 5]
    records = _records(table2, {(c.method, 5): EPISODES for c in cells})
    write_report(tmp_path, table2, cells, records)
    before = (tmp_path / "table.md").read_text()
    with file_size_limit(1024), pytest.raises(OSError) as refused:
        write_report(tmp_path, table2, cells, records)
    assert (refused.value.errno, refused.value.filename) == (errno.EFBIG, str(tmp_path))
    assert (tmp_path / "table.md").read_text() == before
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no staging folder left
