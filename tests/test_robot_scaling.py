"""benchmarks/robot_scaling.py's failure kinds, on episodes whose ending is set by hand."""

import warnings

import numpy as np
import pytest

from crowdsim.metrics import Trajectory, episode_metrics
from crowdsim.scenarios import make_layout, start_overlaps
from tests.benchmark_modules import load_benchmark

robot_scaling = load_benchmark("robot_scaling")
DT = 0.4


def _episode(offsets: np.ndarray) -> Trajectory:
    """Two robots heading along x for goals at (10, 0) and (10, 5), ``offsets`` (T+1, 2) their distances
    short of them at every step; one human far away."""
    steps = len(offsets)
    goals = np.array([[10.0, 0.0], [10.0, 5.0]])
    robots = goals[None] - np.stack([offsets, np.zeros_like(offsets)], axis=-1)
    return Trajectory(
        robot_positions=robots,
        robot_velocities=np.zeros_like(robots),
        human_positions=np.full((steps, 1, 2), 50.0),
        human_velocities=np.zeros((steps, 1, 2)),
        robot_goals=goals,
        human_goals=np.full((1, 2), 50.0),
        robot_accelerations=np.zeros((steps - 1, 2, 2)),
        dt=DT,
        radius=0.3,
    )


def _kind(offsets) -> str | None:
    trajectory = _episode(np.asarray(offsets, dtype=float))
    return robot_scaling.failure_kind(trajectory, episode_metrics(trajectory))


def test_failure_kinds_by_hand():
    window = round(robot_scaling.CLOSING_WINDOW_S / DT)  # 25 steps
    steps = 2 * window
    closing = np.linspace(6.0, 0.5, steps)  # 5.5 m in 50 steps: 2.75 m in the last 25, still off at the end
    parked = np.zeros(steps)
    assert _kind(np.stack([parked, parked], axis=1)) is None  # on their goals from the start: a success
    assert _kind(np.stack([parked, closing], axis=1)) == "late"
    # Robot 1 came 0.4 m closer in the last 10 s: less than CLOSING_M, stuck.
    slow = np.concatenate([np.full(window, 3.0), np.linspace(3.0, 2.6, window)])
    assert _kind(np.stack([parked, slow], axis=1)) == "stuck"
    # Robot 0 reached its goal at step 10 and was pushed 0.5 m off. With robot 1 still closing in, robot 1's
    # late arrival is the failure; with robot 1 arriving at step 20, after the push, and staying, the push is.
    pushed = np.concatenate([np.linspace(2.0, 0.0, 11), np.full(steps - 11, 0.5)])
    assert _kind(np.stack([pushed, closing], axis=1)) == "late"
    assert _kind(np.stack([pushed, slow], axis=1)) == "stuck"
    arrives = np.concatenate([np.linspace(2.0, 0.0, 21), np.zeros(steps - 21)])
    assert _kind(np.stack([pushed, arrives], axis=1)) == "pushed_off"


def test_halfway_by_hand():
    steps = 50
    closing = np.linspace(6.0, 0.5, steps)  # 6 - 5.5 k / 49 <= 3 from k = 27
    trajectory = _episode(np.stack([closing, closing], axis=1))
    assert robot_scaling.halfway_s(trajectory) == 27 * DT
    # Robot 1 stays 6 m off: the mean starts at 6 m and ends at (0.5 + 6) / 2 = 3.25 m, never half of it.
    held = _episode(np.stack([closing, np.full(steps, 6.0)], axis=1))
    assert np.isnan(robot_scaling.halfway_s(held))


def _formation_passed(monkeypatch, tmp_path, *options: str) -> str:
    """The formation main() hands run_row, with ``[env] formation = "two_rows"`` in --config."""
    config = tmp_path / "run.toml"
    config.write_text('[env]\nformation = "two_rows"\n')
    seen = []

    def row(*args, **kwargs):
        seen.append(args[7])  # formation, after controller .. scenarios
        return {
            "controller": args[0], "robots": args[2], "formation": args[7], "goals": "fixed",
            "success_rate": 0.0, "collision_rate": 0.0, "timeout_rate": 0.0, "travel_time_mean": 0.0,
            "min_distance_robots": 0.0, "reached_pct": 0.0, "median_ms": 0.0, "p95_ms": 0.0, "p99_ms": 0.0,
            "steps": 0, "j_max_steps": 0, "fallback_steps": 0, "halfway_s_success": 0.0,
            "halfway_s_failed": 0.0, "failures": dict.fromkeys(robot_scaling.FAILURES, 0),
        }  # fmt: skip

    monkeypatch.setattr(robot_scaling, "run_row", row)
    argv = ["--robots", "4", "--episodes", "1", "--controllers", "cmpc", "--config", str(config), *options]
    assert robot_scaling.main(argv) == 0
    return seen[0]


def test_the_formation_comes_from_the_config_unless_the_option_gives_one(monkeypatch, tmp_path, capsys):
    assert _formation_passed(monkeypatch, tmp_path) == "two_rows"
    assert "formation two_rows" in capsys.readouterr().out
    assert _formation_passed(monkeypatch, tmp_path, "--formation", "wedge") == "wedge"
    assert "formation wedge" in capsys.readouterr().out


def test_the_episodes_are_resets_and_run_the_perpendicular_overlaps_without_a_warning():
    """Seed 1's 16-human perpendicular crowd keeps two overlapping starts (the paper sampler's 100 draws):
    CrowdEnv.reset runs it silently, where the layout through reset_layout warned (LayoutWarning)."""
    layout = make_layout("perpendicular", 16, 1, np.random.default_rng(1))
    assert start_overlaps(layout)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        row = robot_scaling.run_row("cmpc", "constant_velocity", 1, 16, 1, 1, ("perpendicular",), "auto")
    assert row["episodes"] == 1 and row["steps"] > 0


def test_one_robot_prints_no_robot_distance(capsys):
    """One robot has no robot-robot pair: its row printed "inf" as the smallest robot-robot distance."""
    row = {
        "controller": "cmpc",
        "robots": 1,
        "formation": "row",
        "goals": "fixed",
        "failures": dict.fromkeys(robot_scaling.FAILURES, 0),
        **dict.fromkeys(("success_rate", "collision_rate", "timeout_rate", "reached_pct"), 100.0),
        **dict.fromkeys(("travel_time_mean", "median_ms", "p95_ms", "p99_ms"), 1.0),
        **dict.fromkeys(("halfway_s_success", "halfway_s_failed"), 2.0),
        **dict.fromkeys(("steps", "j_max_steps", "fallback_steps"), 0),
        "min_distance_robots": float("inf"),
    }
    robot_scaling.print_table([row])
    line = capsys.readouterr().out.splitlines()[1]
    assert "inf" not in line and line.split()[8] == "-"


def test_antipodal_goals_as_slots_are_refused_naming_this_scripts_options(capsys):
    """The simulator refuses the pair together in its own words (EnvConfig.formation, goal_assignment); the
    script's refusal names the options that chose them, before any row."""
    robot_scaling = load_benchmark("robot_scaling")
    with pytest.raises(SystemExit) as info:
        robot_scaling.main(
            ["--formation", "antipodal", "--goals", "slots", "--robots", "3", "--episodes", "1"]
        )
    assert info.value.code == 2
    err = capsys.readouterr().err.splitlines()[-1]
    assert err.split(": ", 1)[1].startswith(
        "error: --formation antipodal with --goals slots (or the --config"
    )
    assert "would deal the goals anew" in err
