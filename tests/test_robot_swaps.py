"""benchmarks/robot_swaps.py: the antipodal circle by hand, its jitter within bounds and seeded, one row
end to end, and its options checked when parsed."""

import json

import numpy as np
import pytest

from tests.benchmark_modules import load_benchmark

robot_swaps = load_benchmark("robot_swaps")


def test_the_antipodal_circle_by_hand():
    """Four robots on a 4 m circle from the bottom, anticlockwise, each bound for the opposite point; the
    exact layout stays exact (cos(pi / 2) is 6e-17, set to 0), so robots 0 and 2 meet exactly head-on."""
    layout = robot_swaps.antipodal(4, 4.0, 0.0, np.random.default_rng(0))
    starts = [[0.0, -4.0], [4.0, 0.0], [0.0, 4.0], [-4.0, 0.0]]
    np.testing.assert_allclose(layout.robot_starts, starts, atol=1e-15)
    np.testing.assert_array_equal(layout.robot_starts[[0, 2], 0], [0.0, 0.0])
    np.testing.assert_array_equal(layout.robot_goals, -layout.robot_starts)
    assert layout.human_starts.shape == (0, 2) and layout.human_goals.shape == (0, 2)


def test_the_jitter_moves_every_coordinate_within_its_bound_and_follows_the_seed():
    exact = robot_swaps.antipodal(6, 4.0, 0.0, np.random.default_rng(3))
    moved = robot_swaps.antipodal(6, 4.0, 0.05, np.random.default_rng(3))
    again = robot_swaps.antipodal(6, 4.0, 0.05, np.random.default_rng(3))
    for name in ("robot_starts", "robot_goals"):
        shift = getattr(moved, name) - getattr(exact, name)
        assert np.all(np.abs(shift) <= 0.05) and np.all(shift != 0)
        np.testing.assert_array_equal(getattr(moved, name), getattr(again, name))


def test_people_are_placed_clear_of_the_robots_by_the_papers_rules_and_follow_the_seed():
    """Five people of the circle crossing, each start at least 2 radius + the spawn separation (1.1 m) from
    every robot's start and every other person's; the same seed, the same people."""
    one = robot_swaps.antipodal(4, 4.0, 0.05, np.random.default_rng(7), 5, "circle")
    two = robot_swaps.antipodal(4, 4.0, 0.05, np.random.default_rng(7), 5, "circle")
    np.testing.assert_array_equal(one.human_starts, two.human_starts)
    assert one.human_starts.shape == one.human_goals.shape == (5, 2)
    starts = np.concatenate([one.robot_starts, one.human_starts])
    gaps = np.linalg.norm(one.human_starts[:, None] - starts[None], axis=-1)
    gaps[:, 4:][np.diag_indices(5)] = np.inf  # a person and itself
    assert gaps.min() >= 1.1 - 1e-12


def test_a_config_file_gives_its_mpc_table_and_margins(tmp_path, monkeypatch):
    """--config: the [mpc] table (here d_min), the --mpc values over it, and the [controller] margins reach
    the MPC controllers; ORCA gets neither."""
    config = tmp_path / "c.toml"
    config.write_text('[controller]\nmargins = "fixed:0.1"\n[mpc]\nd_min = 0.9\n', encoding="utf-8")
    built = []

    def spy(spec, env_config):
        built.append(spec)
        raise SystemExit(0)

    monkeypatch.setattr(robot_swaps, "make_controller", spy)
    for controller in ("dmpc", "orca"):
        argv = [
            "--robots",
            "2",
            "--controllers",
            controller,
            "--config",
            str(config),
            "--mpc",
            "flock_range=2",
        ]
        with pytest.raises(SystemExit):
            robot_swaps.main(argv)
    dmpc, orca = built
    assert dict(dmpc.mpc_overrides) == {"d_min": 0.9, "flock_range": 2.0}
    assert dmpc.margins.mode == "fixed" and list(dmpc.margins.values) == [0.1]
    assert orca.mpc_overrides == () and orca.margins.mode == "none"


def test_one_row_end_to_end(tmp_path, capsys):
    """Two robots swapping places without flocking pass (the head-on tie broken), d_min apart; its rates in %
    as every `*_rate` the project writes (they were shares, 1.0 for all)."""
    out = tmp_path / "rows.json"
    robot_swaps.main(["--robots", "2", "--controllers", "cmpc", "--mpc", "w_floc=0", "--json", str(out)])
    printed = capsys.readouterr().out
    assert "cmpc         2    1     100%" in printed
    (row,) = json.loads(out.read_text(encoding="utf-8"))["rows"]
    assert row["success_rate"] == 100.0 and row["min_robot_distance"] > 0.8 and row["contact_rate"] == 0.0
    assert row["collision_rate"] == 0.0 and row["timeout_rate"] == 0.0


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--jitter", "0.6"], "--jitter: must be in [0, 0.5] m"),
        (["--radius", "0.5"], "--radius: must be in [1, 10] m"),
        (["--robots", "1"], "--robots"),
        (["--robots", "2", "2"], "--robots names 2 more than once"),
        (["--mpc", "flock_range=-1"], "--config/--mpc: "),
        (
            ["--robots", "12", "--radius", "1"],
            "--radius 1 puts 12 robots 0.52 m apart, too close for two",
        ),
        (["--robots", "4", "--radius", "1", "--jitter", "0.5"], "bodies moved by --jitter 0.5 (2.01 m)"),
        (["--humans", "51"], "--humans"),
    ],
)
def test_bad_options_are_refused_when_parsed(argv, message, capsys):
    with pytest.raises(SystemExit) as stop:
        robot_swaps.main(argv)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err


def test_standing_still_is_read_over_the_last_ten_seconds_by_hand():
    """At dt 0.4 s the last 10 s are 25 steps: robots 4 cm from where they stood 25 steps before stood still,
    6 cm did not, and an episode shorter than 10 s is no deadlock."""
    path = np.zeros((40, 2, 2))
    path[-1, 1, 0] = 0.04
    assert robot_swaps.stood_still(path, 0.4)
    path[-1, 1, 0] = 0.06
    assert not robot_swaps.stood_still(path, 0.4)
    path[:-26] = 5.0  # moved before the last 25 steps: still
    path[-1, 1, 0] = 0.0
    assert robot_swaps.stood_still(path, 0.4)
    assert not robot_swaps.stood_still(np.zeros((25, 2, 2)), 0.4)


def test_the_exact_swap_with_every_pair_flocking_is_said_to_be_a_deadlock(tmp_path, capsys):
    """At its defaults two robots swapping places timed out and the row said only that: Eq. 15 holds them
    1.42 m apart in the middle, their goal pulls cancelling exactly, for the rest of the episode."""
    out = tmp_path / "rows.json"
    robot_swaps.main(["--robots", "2", "--controllers", "cmpc", "--json", str(out)])
    (row,) = json.loads(out.read_text(encoding="utf-8"))["rows"]
    assert row["timeout_rate"] == 100.0 and row["deadlock_rate"] == 100.0
    printed = capsys.readouterr().out
    assert "100%      100%" in printed.splitlines()[1]
    assert "deadlock: timed out with no robot moving 0.05 m in the last 10 s" in printed
    assert "--mpc flock_range=2 frees them" in printed
