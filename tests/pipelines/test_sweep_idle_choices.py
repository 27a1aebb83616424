"""A sweep refuses, in simulate's one line and before any worker starts, what the command line chose that no
cell of its plan would read (pipelines.commands.idle_choices): track lengths for ORCA and the straight line, a
visibility among a plain replayed crowd, ORCA's sampling rules among any replayed crowd, a team's settings
for lone robots. Each made a cell of its own whose episodes were the default's. What a sweep folder recorded
reads back: its report, its config, a comparison, a rerun from the config it recorded."""

from __future__ import annotations

import json

import pytest

from pipelines.cli import main

LONE = (
    "changes nothing here, where --robots 1 leaves the robot no teammate to flock, re-plan or stand in "
    "formation with; leave it out"
)
PAST = "on the humans' current positions and velocities, not their pasts, so track lengths change nothing for"
UNSAMPLED = (
    "replays recorded people, placed by their tracks; crossing and spawn_separation sample the humans of "
    "crowd orca; leave it out"
)


def _unseen(crowd: str) -> str:
    return (
        f"crowd {crowd!r} replays people who see no robot whatever the visibility (crowd {crowd}_reactive "
        "yields to visible robots); leave it out"
    )


def _error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    return lines[0]


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["baselines", "--sensor-range", "2", "--no-sensor-tracks"],
            f"--no-sensor-tracks: controllers 'straight' and 'orca' act {PAST} them; leave it out",
        ),
        (
            [
                "controllers",
                "--controllers",
                "orca",
                "--sensor-range",
                "2",
                "--set",
                "simulate.sensor_tracks=false",
            ],
            f"--set simulate.sensor_tracks false: controller 'orca' acts {PAST} it; leave it out",
        ),
        (
            ["table2", "--crowd", "eth_test", "--visibility", "invisible"],
            f"--visibility invisible: {_unseen('eth_test')}",
        ),
        (
            ["baselines", "--set", "env.crowd=hotel_test", "--set", "env.robots_visible=true"],
            f"--set env.robots_visible true: {_unseen('hotel_test')}",
        ),
        (
            ["baselines", "--crowd", "eth_test", "--set", "env.spawn_separation=2"],
            f"--set env.spawn_separation 2.0: crowd 'eth_test' {UNSAMPLED}",
        ),
        (
            ["table2", "--crowd", "hotel_test_reactive", "--vary", "env.crossing=paper,v1"],
            f"--vary env.crossing=paper,v1: crowd 'hotel_test_reactive' {UNSAMPLED}",
        ),
        (
            ["table2", "--robots", "1", "--set", "controller.flocking=false"],
            f"--set controller.flocking false {LONE}",
        ),
        (
            ["table2", "--robots", "1", "--set", "mpc.stall_release_s=2"],
            f"--set mpc.stall_release_s 2.0 {LONE}",
        ),
        (["table2", "--robots", "1", "--vary", "mpc.w_floc=1,2"], f"--vary mpc.w_floc=1.0,2.0 {LONE}"),
        (["baselines", "--robots", "1", "--set", "env.formation=row"], f"--set env.formation row {LONE}"),
        (
            ["baselines", "--robots", "1", "--set", "env.goal_assignment=slots"],
            f"--set env.goal_assignment slots {LONE}",
        ),
        (
            ["baselines", "--robots", "1", "--vary", "env.robot_spacing=1,2"],
            f"--vary env.robot_spacing=1.0,2.0 {LONE}",
        ),
    ],
)
def test_a_choice_no_cell_reads_is_refused_in_one_line(options, message, tmp_path, capsys):
    """In the dry run too: it listed a cell per value, whose episodes would be the default's."""
    out = tmp_path / "sw"
    assert main(["sweep", "--experiment", *options, "--humans", "3", "--dry-run", "--out", str(out)]) == 2
    assert _error_line(capsys) == f"crowdmpc sweep: error: {message}"
    assert not out.exists()


def test_the_refusal_comes_before_any_worker(tmp_path, capsys, monkeypatch):
    def no_workers(*args, **kwargs):
        raise AssertionError("the sweep ran before its choices were checked")

    monkeypatch.setattr("pipelines.commands.sweep_run.run_cells", no_workers)
    out = tmp_path / "sw"
    sweep = ["sweep", "--experiment", "baselines", "--crowd", "eth_test", "--visibility", "visible"]
    assert main([*sweep, "--humans", "3", "--backend", "inline", "--out", str(out)]) == 2
    assert _error_line(capsys) == f"crowdmpc sweep: error: --visibility visible: {_unseen('eth_test')}"
    assert not (out / "episodes.jsonl").exists()


@pytest.mark.parametrize(
    "options",
    [
        ["controllers", "--controllers", "cmpc,orca", "--sensor-range", "2", "--no-sensor-tracks"],
        [
            "table2",
            "--crowd",
            "eth_test_reactive",
            "--visibility",
            "invisible",
        ],  # it yields to visible robots
        ["baselines", "--vary", "env.crossing=paper,v1", "--set", "env.spawn_separation=2"],  # ORCA's humans
        ["table2", "--vary", "scenario.robots=1,2", "--vary", "mpc.w_floc=1,2"],  # the 2 robots' columns
        ["table2", "--vary", "scenario.robots=1,3", "--set", "env.robot_spacing=2"],
        ["baselines", "--robots", "1", "--set", "env.formation=antipodal"],  # a lone robot's, as simulate's
    ],
)
def test_a_choice_some_cell_reads_is_taken(options, tmp_path, capsys):
    assert (
        main(["sweep", "--experiment", *options, "--humans", "3", "--dry-run", "--out", str(tmp_path)]) == 0
    )


def test_a_config_files_choices_pass_as_they_may_serve_other_sweeps(tmp_path, capsys):
    (tmp_path / "run.toml").write_text("[env]\nrobots_visible = false\nrobot_spacing = 2.0\n")
    sweep = ["sweep", "--experiment", "baselines", "--crowd", "eth_test", "--robots", "1", "--humans", "3"]
    out = tmp_path / "out"  # not the config's folder: a sweep and its dry run refuse a folder of others
    assert main(["--config", str(tmp_path / "run.toml"), *sweep, "--dry-run", "--out", str(out)]) == 0


# Every refused choice at once, as a sweep made before the refusal ran them: 2 methods x 2 crossings.
RECORDED = (
    "--experiment baselines --crowd eth_test --visibility invisible --robots 1 --set env.robot_spacing=2 "
    "--sensor-range 2 --no-sensor-tracks --vary env.crossing=paper,v1 --humans 3 --episodes-per-cell 1"
).split()


def test_a_folder_swept_with_such_choices_reads_back(tmp_path, capsys, monkeypatch):
    """Its report (with the choices typed again too), its config, a comparison and a rerun from the config
    `config show --from-sweep` prints: a folder is never refused for what it recorded."""
    out = tmp_path / "sw"
    sweep = ["sweep", *RECORDED, "--backend", "inline", "--no-progress", "--out", str(out)]
    assert main(sweep) == 2  # refused now
    capsys.readouterr()
    monkeypatch.setattr("pipelines.commands.idle_choices.check_sweep_choices", lambda *args: None)
    assert main(sweep) == 0  # as the code before the refusal ran it
    monkeypatch.undo()
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(records) == 4 and all("-invisible-sensed2m-notracks-eth_test-" in r["cell"] for r in records)
    (out / "table.md").unlink()
    for report in (["sweep", "--report-only", "--out", str(out)], [*sweep, "--report-only"]):
        capsys.readouterr()
        assert main(report) == 0, capsys.readouterr().err
        assert (out / "table.md").is_file()
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    shown = capsys.readouterr().out
    assert "robots_visible = false" in shown and "robot_spacing = 2.0" in shown
    (tmp_path / "recorded.toml").write_text(shown)
    assert main(["--config", str(tmp_path / "recorded.toml"), "sweep", "--no-progress"]) == 0  # all ran
    capsys.readouterr()
    assert main(["compare", "--by-cell", "--no-progress", f"a={out}", f"b={out}"]) == 0, (
        capsys.readouterr().err
    )
