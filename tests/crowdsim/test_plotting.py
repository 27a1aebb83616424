"""plot_episode draws what Fig. 2 shows and saves a PNG."""

import shutil

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from crowdsim.errors import SimulationError
from crowdsim.plotting import check_figure_path, default_snapshots, plot_episode


def test_default_snapshots_include_first_and_last():
    assert default_snapshots(21) == [0, 5, 10, 15, 20]
    assert default_snapshots(3) == [0, 1, 2]


def test_plot_episode_draws_filled_robots_and_hollow_humans(tmp_path):
    t = np.linspace(0, 1, 11)[:, None]
    robots = np.stack(
        [np.hstack([t * 0, -5 + 10 * t]), np.hstack([1 + t * 0, -5 + 10 * t])], axis=1
    )  # (11, 2, 2)
    humans = np.stack([np.hstack([-5 + 10 * t, t * 0])], axis=1)  # (11, 1, 2)
    goals = robots[-1]
    fig = plot_episode(robots, humans, goals, title="test", snapshot_steps=[0, 5, 10], dt=0.4)
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    circles = [p for p in ax.patches if isinstance(p, Circle)]
    assert len(circles) == 3 * (2 + 1)
    assert sum(c.get_fill() for c in circles) == 3 * 2  # robots filled, humans hollow
    assert all(c.get_radius() == 0.3 for c in circles)
    # which ring is when: the legend says the earlier are fainter (it gave the times alone)
    legend = " ".join(t.get_text() for t in ax.get_legend().get_texts())
    assert "snapshots, faint to solid: 0 s, 2 s, 4 s" in legend
    # the rows of a log that lost states are not steps: their own times
    gappy = plot_episode(robots, humans, goals, snapshot_steps=[5], dt=0.4, times=np.arange(11) * 0.4 + 6)
    assert "snapshots: 8 s" in " ".join(t.get_text() for t in gappy.axes[0].get_legend().get_texts())
    out = tmp_path / "ep.png"
    fig.savefig(out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_episode_on_given_axes():
    fig = Figure()
    ax = fig.add_subplot()
    assert plot_episode(np.zeros((2, 1, 2)), np.zeros((2, 0, 2)), np.ones((1, 2)), ax=ax) is fig


def test_figure_paths_are_checked_by_suffix():
    check_figure_path("out/ep.PNG", "--plot")
    check_figure_path("ep.pdf", "--plot")
    with pytest.raises(SimulationError, match=r"--plot ep\.foo: cannot write a figure of type 'foo'"):
        check_figure_path("ep.foo", "--plot")


def test_a_pgf_figure_without_its_tex_system_is_refused_before_the_run(monkeypatch):
    """`simulate --plot ep.pgf` ran every episode and then ended in matplotlib's traceback ("'xelatex' not
    found"), exit status 1, no figure."""
    monkeypatch.setitem(matplotlib.rcParams, "pgf.texsystem", "lualatex")
    installed: list[str] = []
    monkeypatch.setattr(shutil, "which", lambda name: f"/usr/bin/{name}" if name in installed else None)
    with pytest.raises(
        SimulationError, match=r"--plot ep\.pgf: a \.pgf figure is typeset by lualatex, which"
    ):
        check_figure_path("ep.pgf", "--plot")
    with pytest.raises(SimulationError, match=r"cannot write a figure of type 'foo'") as refused:
        check_figure_path("ep.foo", "--plot")
    assert "'pgf'" not in str(refused.value) and "'pdf'" in str(refused.value)  # not offered, then refused
    installed.append("lualatex")
    check_figure_path("ep.pgf", "--plot")
    with pytest.raises(SimulationError, match=r"'pgf'"):
        check_figure_path("ep.foo", "--plot")


def test_every_robot_of_the_largest_team_has_its_own_colour():
    """With 12 robots (docs/examples/many_robots.toml) robots 10 and 11 were drawn in robot 0's and robot
    1's tab10 colours: two blue and two orange paths, told apart by nothing."""
    from crowdsim.plotting import GOAL_COLOR, HUMAN_COLOR
    from crowdsim.scenarios import MAX_ROBOTS

    t = np.linspace(0, 1, 5)[:, None, None]
    robots = np.arange(MAX_ROBOTS)[None, :, None] * np.array([1.0, 0.0]) + t * np.array([0.0, 10.0])
    fig = plot_episode(robots, np.zeros((5, 0, 2)), robots[-1])
    paths = [line for line in fig.axes[0].lines if line.get_label()[len("robot ") :].isdigit()]
    colours = {matplotlib.colors.to_hex(line.get_color()) for line in paths}
    assert len(paths) == len(colours) == MAX_ROBOTS
    assert not colours & {matplotlib.colors.to_hex(c) for c in (GOAL_COLOR, HUMAN_COLOR)}


def test_an_episode_without_humans_has_no_humans_in_its_legend():
    """The legend listed "humans" beside a plot of one robot in an empty room."""
    fig = plot_episode(np.zeros((2, 1, 2)), np.zeros((2, 0, 2)), np.ones((1, 2)))
    assert "humans" not in [t.get_text() for t in fig.axes[0].get_legend().get_texts()]


# Machado, Oliveira and Fernandes (2009), severity 1: what a dichromat sees, on linear RGB
DICHROMAT = {
    "deuteranopia": [
        [0.367322, 0.860646, -0.227968],
        [0.280085, 0.672501, 0.047413],
        [-0.01182, 0.04294, 0.968881],
    ],
    "protanopia": [
        [0.152286, 1.052583, -0.204868],
        [0.114503, 0.786281, 0.099216],
        [-0.003882, -0.048116, 1.051998],
    ],
}


def cielab(hex_colour: str, seen: np.ndarray) -> np.ndarray:
    """``hex_colour`` as a viewer with the linear-RGB matrix ``seen`` sees it, in CIELAB (D65)."""
    srgb = np.array(matplotlib.colors.to_rgb(hex_colour))
    linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
    xyz_matrix = [[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]
    xyz = np.asarray(xyz_matrix) @ np.clip(seen @ linear, 0.0, 1.0) / [0.95047, 1.0, 1.08883]
    f = np.where(xyz > 0.008856, np.cbrt(xyz), 7.787 * xyz + 16 / 116)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


@pytest.mark.parametrize("vision", ["normal", *DICHROMAT])
def test_the_first_eight_robots_colours_stay_apart_for_red_green_colour_blind_readers(vision):
    """tab10's green and red (robots 2 and 3) were 7.3 apart (CIELAB, delta E 1976) under simulated
    deuteranopia, its orange and green 4.6 under protanopia: one colour to about one man in twelve."""
    from crowdsim.plotting import ROBOT_COLORS

    seen = np.eye(3) if vision == "normal" else np.asarray(DICHROMAT[vision])
    labs = [cielab(c, seen) for c in ROBOT_COLORS[:8]]
    closest = min(np.linalg.norm(a - b) for i, a in enumerate(labs) for b in labs[i + 1 :])
    assert closest > 15.0
    tab10 = [cielab(c, seen) for c in ("#2ca02c", "#d62728", "#ff7f0e")]  # the check tells them apart
    assert vision == "normal" or min(np.linalg.norm(tab10[0] - t) for t in tab10[1:]) < 8.0
