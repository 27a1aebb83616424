"""benchmarks/plot_scaling.py: which of robot_scaling.py's rows make which line, and its errors."""

import json
import shutil

import matplotlib
import pytest
from matplotlib.colors import same_color as same_colour

from tests.benchmark_modules import load_benchmark

plot_scaling = load_benchmark("plot_scaling")


def _report(humans: int, rows: list[tuple[str, str, int, float]]) -> dict:
    """A robot_scaling.py --json report: rows (controller, goals, robots, success %)."""
    return {
        "args": {"humans": humans},
        "rows": [
            {
                "controller": c,
                "goals": g,
                "robots": m,
                "success_rate": s,
                "collision_rate": 100.0 - s,
                "median_ms": 2.0 * m,
                "p99_ms": 10.0 * m,
            }
            for c, g, m, s in rows
        ],
    }


M_RUN = _report(7, [("cmpc", "fixed", 12, 94.0), ("cmpc", "fixed", 3, 100.0), ("dmpc", "slots", 5, 98.0)])
N_RUNS = [_report(n, [("cmpc", "fixed", 3, s)]) for n, s in ((5, 100.0), (50, 52.0))]


def test_rows_join_into_lines_along_robots_and_along_humans():
    pts = plot_scaling.points([("m.json", M_RUN)] + [(f"n{i}.json", r) for i, r in enumerate(N_RUNS)])
    assert len(pts) == 5
    by_robots = plot_scaling.series(pts, "robots")
    # DMPC has one robot count only: no line; CMPC's two rows at 7 humans, sorted by M.
    assert list(by_robots) == [("cmpc", "fixed", 7)]
    assert [(p.robots, p.success, p.collision) for p in by_robots[("cmpc", "fixed", 7)]] == [
        (3, 100.0, 0.0),
        (12, 94.0, 6.0),
    ]
    # The 3-robot rows at 5, 7 and 50 humans make the line against N, the M run's row among them.
    by_humans = plot_scaling.series(pts, "humans")
    assert list(by_humans) == [("cmpc", "fixed", 3)]
    assert [(p.humans, p.success) for p in by_humans[("cmpc", "fixed", 3)]] == [
        (5, 100.0),
        (7, 100.0),
        (50, 52.0),
    ]


def test_a_row_on_no_line_is_named(tmp_path, capsys):
    pts = plot_scaling.points([("m.json", M_RUN)] + [(f"n{i}.json", r) for i, r in enumerate(N_RUNS)])
    # DMPC's slots row at 5 robots is alone along M and along N; every CMPC row is on a line.
    assert [(p.controller, p.robots, p.humans) for p in plot_scaling.undrawn(pts)] == [("dmpc", 5, 7)]
    path = tmp_path / "m.json"
    path.write_text(json.dumps(M_RUN))
    assert plot_scaling.main([str(path), "--out", str(tmp_path / "m.png")]) == 0
    out = capsys.readouterr().out
    assert "(2 of 3 rows drawn)" in out
    assert "not drawn (no row to make a line with): dmpc slots goals, M=5, N=7" in out
    # one run at one crowd size: nothing to draw against N, and the figure says so
    assert "the panels against humans N are empty: no two rows differ in humans N alone" in out
    assert "against robots M are empty" not in out


def test_the_same_row_in_two_files_is_named(tmp_path, capsys):
    with pytest.raises(ValueError, match="a.json and m.json both hold"):
        plot_scaling.points([("m.json", M_RUN), ("a.json", M_RUN)])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"rows": []}))
    assert plot_scaling.run_main(lambda: plot_scaling.main([str(bad), "--out", str(tmp_path / "x.png")])) == 2
    assert (
        "error: " + str(bad) + " is not robot_scaling.py --json output (no 'args')" in capsys.readouterr().err
    )
    assert not (tmp_path / "x.png").exists()
    wrong = {"args": {"humans": 7}, "rows": [{**M_RUN["rows"][0], "robots": "many"}]}
    with pytest.raises(ValueError, match="w.json is not robot_scaling.py --json output"):
        plot_scaling.points([("w.json", wrong)])


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("nope.json", "nope.json does not exist; expected a robot_scaling.py --json file"),
        (".", ". is not a file (a folder or a device); expected a robot_scaling.py --json file"),
    ],
)
def test_a_run_file_that_is_missing_or_a_folder_is_refused_naming_the_argument(
    name, message, tmp_path, capsys, monkeypatch
):
    """plot_scaling.py nope.json said Python's "[Errno 2] No such file or directory: 'nope.json'", naming
    neither the argument nor what it should be; a folder, "[Errno 21] Is a directory: '.'"."""
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "m.json"
    run.write_text(json.dumps(M_RUN))
    with pytest.raises(SystemExit) as stop:
        plot_scaling.main([str(run), name, "--out", "fig.png"])
    assert stop.value.code == 2
    (line,) = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("usage:")]
    assert line.endswith(f"error: runs: {message}")
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_a_run_file_that_cannot_be_read_is_named(tmp_path, capsys, monkeypatch):
    """One the parser found but that cannot be read (no permission) said "[Errno 13] Permission denied"."""
    from pathlib import Path

    run = tmp_path / "m.json"
    run.write_text(json.dumps(M_RUN))

    def refuse(path: Path, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(Path, "read_text", refuse)
    args = [str(run), "--out", str(tmp_path / "fig.png")]
    assert plot_scaling.run_main(lambda: plot_scaling.main(args)) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.endswith(
        f" error: runs: cannot read {run} (Permission denied); expected a robot_scaling.py --json file"
    )


def test_main_writes_the_figure(tmp_path):
    paths = []
    for i, report in enumerate([M_RUN, *N_RUNS]):
        paths.append(tmp_path / f"run{i}.json")
        paths[-1].write_text(json.dumps(report))
    out = tmp_path / "fig" / "scaling.png"
    assert plot_scaling.main([*map(str, paths), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_robot_and_human_axes_tick_whole_numbers():
    """The robots axis had ticks at 3.5, 4.5, ... robots (matplotlib's default locator)."""
    few = _report(7, [("cmpc", "fixed", 3, 100.0), ("cmpc", "fixed", 5, 98.0), ("cmpc", "fixed", 6, 96.0)])
    fig = plot_scaling.figure(plot_scaling.points([("m.json", few), ("n5", N_RUNS[0]), ("n50", N_RUNS[1])]))
    for ax in fig.axes:
        ticks = [t for t in ax.get_xticks() if ax.get_xlim()[0] <= t <= ax.get_xlim()[1]]
        assert ticks and all(float(t).is_integer() for t in ticks)


def test_the_path_printed_is_the_path_written(tmp_path, capsys):
    """--out X wrote X.png (matplotlib's default format) and printed "wrote X"."""
    run = tmp_path / "m.json"
    run.write_text(json.dumps(M_RUN))
    assert plot_scaling.main([str(run), "--out", str(tmp_path / "fig")]) == 0
    assert f"wrote {tmp_path / 'fig.png'} (" in capsys.readouterr().out
    assert [p.name for p in sorted(tmp_path.iterdir())] == ["fig.png", "m.json"]
    assert plot_scaling.main([str(run), "--out", str(tmp_path / "fig.svg")]) == 0
    assert (tmp_path / "fig.svg").read_text().lstrip().startswith("<?xml")


@pytest.mark.parametrize(
    ("out", "message"),
    [
        ("fig.pdfx", "fig.pdfx: cannot write a figure of type 'pdfx'; name it with one of ["),
        ("m.json", "m.json: cannot write a figure of type 'json'"),
        ("fig.pgf", "fig.pgf: a .pgf figure is typeset by xelatex, which is not installed here"),
    ],
)
def test_a_format_matplotlib_cannot_write_is_refused_when_parsed(out, message, tmp_path, capsys, monkeypatch):
    """fig.pdfx ended in matplotlib's traceback, after the runs were read; so did fig.pgf without TeX."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setitem(matplotlib.rcParams, "pgf.texsystem", "xelatex")
    monkeypatch.setattr(shutil, "which", lambda _name: None)  # whether or not this machine has TeX
    run = tmp_path / "m.json"
    run.write_text(json.dumps(M_RUN))
    with pytest.raises(SystemExit) as stop:
        plot_scaling.main([str(run), "--out", out])
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]


def test_success_is_drawn_with_its_interval_when_the_rows_give_their_episodes():
    """docs/robot_scaling.png drew each row's success rate of 50 episodes bare: 94 % at 12 robots looked
    below 100 % at 3, when 47 of 50 has the 95% Wilson interval [83.8, 97.9] %. Rows that give their
    episodes get that interval as error bars; older reports without them, none."""
    report = _report(7, [("cmpc", "fixed", 3, 100.0), ("cmpc", "fixed", 12, 94.0)])
    rows = [{**row, "episodes": 50} for row in report["rows"]]
    pts = plot_scaling.points([("m.json", {"args": {"humans": 7}, "rows": rows})])
    (bars,) = plot_scaling.figure(pts).axes[0].containers
    (segments,) = bars.lines[2]
    lows, highs = zip(*((seg[0][1], seg[1][1]) for seg in segments.get_segments()), strict=True)
    assert lows == pytest.approx((92.9, 83.8), abs=0.05) and highs == pytest.approx((100.0, 97.9), abs=0.05)
    old = plot_scaling.points([("m.json", M_RUN)])
    assert not plot_scaling.figure(old).axes[0].containers[0].has_yerr


def test_an_empty_panel_says_why_in_the_figure():
    """One robot_scaling.py run of 1 and 2 robots at 3 humans: the panels against humans N stood empty, axes
    from 0 to 1 humans and nothing said why but a line on the terminal; each now says it in the panel, and
    the panels that have lines carry no such note."""
    run = _report(3, [("cmpc", "fixed", 1, 100.0), ("cmpc", "fixed", 2, 100.0)])
    fig = plot_scaling.figure(plot_scaling.points([("m.json", run)]))
    axes = fig.axes  # row by row: robots, humans; robots, humans
    note = "no two rows differ in humans N alone"
    assert all(note in [t.get_text() for t in axes[k].texts] for k in (1, 3))
    assert not any("no two rows" in t.get_text() for k in (0, 2) for t in axes[k].texts)
    matplotlib.pyplot.close(fig)


def test_two_controllers_with_the_same_success_both_show():
    """One run of CMPC and DMPC at 1 and 2 robots, both 100 % successful: DMPC's success line and markers
    lay exactly on CMPC's, same width, and only the orange one showed. The line drawn above is now the
    narrower, with smaller markers, so the one below shows round it, at the values it had."""
    run = _report(3, [(c, "fixed", m, 100.0) for c in ("cmpc", "dmpc") for m in (1, 2)])
    fig = plot_scaling.figure(plot_scaling.points([("m.json", run)]))
    for ax in fig.axes[0], fig.axes[2]:  # success and collision; step times
        lines = [line for line in ax.get_lines() if len(line.get_xdata()) == 2]  # not the 0.4 s line
        below = [line for line in lines if same_colour(line.get_color(), "tab:blue")]  # CMPC's
        above = [line for line in lines if same_colour(line.get_color(), "tab:orange")]  # DMPC's
        assert below and len(below) == len(above)
        for low, high in zip(below, above, strict=True):
            assert high.get_zorder() > low.get_zorder()
            assert high.get_linewidth() < low.get_linewidth()
            assert high.get_markersize() < low.get_markersize()
    (cmpc, dmpc) = (bars.lines[0] for bars in fig.axes[0].containers)
    assert list(cmpc.get_ydata()) == list(dmpc.get_ydata()) == [100.0, 100.0]
    matplotlib.pyplot.close(fig)
