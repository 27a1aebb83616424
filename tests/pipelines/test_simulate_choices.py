"""simulate refuses, in one line before any episode, what its controller would ignore: a predictor for ORCA
and the straight line, flocking, record_iterations and [mpc] values for them (they plan with no MPC), and
--record-iterations with nothing to record to. Only values the user chose count."""

from __future__ import annotations

import json

import pytest

from pipelines.cli import main
from pipelines.loop import spec as registry

TOY = "tests.plugins.toy_controller:StraightLine"  # a plugin that plans with no predictor
RUN = ["--humans", "1", "--no-progress"]


def _no_episodes(monkeypatch) -> None:
    def no_episodes(*args, **kwargs):
        raise AssertionError("an episode ran before the choices were checked")

    monkeypatch.setattr("pipelines.loop.episode.run_episodes", no_episodes)


def _error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1 and captured.out == "", captured.err
    return lines[0]


NO_PREDICTOR = (
    "plans with no predictor; predictor, margins and coupling apply to the controllers that do (cmpc, dmpc)"
)
NO_MPC = (
    "plans with no MPC; flocking, record_iterations and [mpc] apply to the controllers that do (cmpc, dmpc)"
)


@pytest.mark.parametrize(
    "options, message",
    [
        (
            ["--predictor", "social_lstm_eth"],
            f"--predictor social_lstm_eth: controller 'orca' {NO_PREDICTOR}",
        ),
        (
            ["--no-flocking", "--record-iterations", "--set", "mpc.horizon=10"],
            f"--no-flocking, --record-iterations and --set mpc.horizon 10: controller 'orca' {NO_MPC}",
        ),
        (
            ["--set", "controller.flocking=true"],
            f"--set controller.flocking true: controller 'orca' {NO_MPC}",
        ),
        (
            ["--controller", "straight", "--set", "mpc.w_coll=1e6"],
            f"--set mpc.w_coll 1000000.0: controller 'straight' {NO_MPC}",
        ),
    ],
)
def test_what_orca_and_the_straight_line_would_ignore_is_refused(options, message, capsys, monkeypatch):
    """They were run as if the values did not exist, while the record's config stated them."""
    _no_episodes(monkeypatch)
    assert main(["simulate", "--controller", "orca", *RUN, *options]) == 2
    assert _error_line(capsys) == f"crowdmpc simulate: error: {message}"


def test_a_config_file_is_refused_only_for_what_it_changes(tmp_path, capsys, monkeypatch):
    """A file shared with cmpc may state the defaults (as `config show` writes them): those choose nothing."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "run.toml").write_text("[controller]\nflocking = true\n[mpc]\nhorizon = 4\nw_coll = 1e7\n")
    out = tmp_path / "run.json"
    assert main(["--config", "run.toml", "simulate", "--controller", "orca", *RUN, "--json", str(out)]) == 0
    assert json.loads(out.read_text())["run"]["controller"] == "orca"
    capsys.readouterr()
    _no_episodes(monkeypatch)
    (tmp_path / "run.toml").write_text("[controller]\nflocking = true\n[mpc]\nhorizon = 12\n")
    assert main(["--config", "run.toml", "simulate", "--controller", "orca", *RUN]) == 2
    assert (
        _error_line(capsys)
        == f"crowdmpc simulate: error: run.toml: mpc.horizon 12: controller 'orca' {NO_MPC}"
    )


@pytest.mark.parametrize("controller", ["orca", "straight"])
def test_no_sensor_tracks_is_refused_for_a_controller_that_reads_no_pasts(controller, capsys, monkeypatch):
    """ORCA and the straight line act on the humans' current positions and velocities: behind a tracker that
    reports no track lengths they drove as behind one that does, while the record's sensing said otherwise."""
    _no_episodes(monkeypatch)
    argv = ["simulate", "--controller", controller, *RUN, "--sensor-range", "2"]
    assert main([*argv, "--no-sensor-tracks"]) == 2
    assert _error_line(capsys) == (
        f"crowdmpc simulate: error: --no-sensor-tracks: controller {controller!r} acts on the humans' "
        "current positions and velocities, not their pasts, so track lengths change nothing for it; leave it "
        "out"
    )
    assert main([*argv, "--set", "simulate.sensor_tracks=false"]) == 2
    assert _error_line(capsys).startswith("crowdmpc simulate: error: --set simulate.sensor_tracks false: ")


@pytest.mark.parametrize(
    "options, shown",
    [
        (["--crowd", "eth", "--visibility", "invisible"], "--visibility invisible: crowd 'eth'"),
        (["--crowd", "hotel_test", "--visibility", "visible"], "--visibility visible: crowd 'hotel_test'"),
        (
            ["--set", "env.crowd=eth", "--set", "env.robots_visible=false"],
            "--set env.robots_visible false: crowd 'eth'",
        ),
    ],
)
def test_a_visibility_is_refused_for_a_crowd_that_sees_no_robot(options, shown, capsys, monkeypatch):
    """A plain replay walks its recorded tracks whether the robots are visible or not: the choice was run as
    if not given (the summary's conventions dropped it), while the record stated it."""
    _no_episodes(monkeypatch)
    assert main(["simulate", "--controller", "straight", *RUN, *options]) == 2
    crowd = shown.split("'")[1]
    assert _error_line(capsys) == (
        f"crowdmpc simulate: error: {shown} replays people who see no robot whatever the visibility (crowd "
        f"{crowd}_reactive yields to visible robots); leave it out"
    )


@pytest.mark.parametrize(
    "crowd, option",
    [("eth", "env.spawn_separation=3"), ("hotel_test_reactive", "env.crossing=v1")],
)
def test_the_sampling_rules_are_refused_for_a_replayed_crowd(crowd, option, capsys, monkeypatch):
    """A replay's people stand where their tracks put them: the episodes were those of the default rules."""
    _no_episodes(monkeypatch)
    assert main(["simulate", "--controller", "straight", *RUN, "--crowd", crowd, "--set", option]) == 2
    key, value = option.split("=")
    assert _error_line(capsys) == (
        f"crowdmpc simulate: error: --set {key} {float(value) if value[0].isdigit() else value}: crowd "
        f"{crowd!r} replays recorded people, placed by their tracks; crossing and spawn_separation sample "
        "the humans of crowd orca; leave it out"
    )


LONE = (
    "changes nothing here, where --robots 1 leaves the robot no teammate to flock, re-plan or stand in "
    "formation with"
)


@pytest.mark.parametrize(
    "controller, options, shown",
    [
        ("cmpc", ["--no-flocking"], "--no-flocking"),
        ("dmpc", ["--set", "mpc.w_floc=1"], "--set mpc.w_floc 1.0"),
        ("dmpc", ["--set", "mpc.stall_release_s=2"], "--set mpc.stall_release_s 2.0"),
        ("cmpc", ["--set", "env.goal_assignment=slots"], "--set env.goal_assignment slots"),
        ("orca", ["--set", "env.formation=wedge"], "--set env.formation wedge"),
        ("straight", ["--set", "env.robot_spacing=2"], "--set env.robot_spacing 2.0"),
    ],
)
def test_a_team_setting_is_refused_for_a_lone_robot(controller, options, shown, capsys, monkeypatch):
    """One robot has no pair for Eq. 15 and no formation to keep: these ran their defaults' episodes."""
    _no_episodes(monkeypatch)
    assert main(["simulate", "--controller", controller, *RUN, "--robots", "1", *options]) == 2
    assert _error_line(capsys) == f"crowdmpc simulate: error: {shown} {LONE}; leave it out"


def test_a_lone_robot_keeps_the_antipodal_formation_and_a_files_team_settings(tmp_path, capsys):
    """Antipodal moves even one robot (across a 3.5 m circle); a file may serve every team size."""
    out = tmp_path / "run.json"
    argv = ["simulate", "--controller", "straight", *RUN, "--robots", "1", "--json", str(out)]
    assert main([*argv, "--set", "env.formation=antipodal"]) == 0
    (tmp_path / "team.toml").write_text('[env]\nformation = "wedge"\n')
    assert main([*argv, "--config", str(tmp_path / "team.toml")]) == 0


def test_record_iterations_needs_a_recording(capsys, monkeypatch):
    """--record-iterations without --record was accepted and wrote nothing."""
    _no_episodes(monkeypatch)
    assert main(["simulate", "--controller", "cmpc", *RUN, "--record-iterations"]) == 2
    assert _error_line(capsys) == (
        "crowdmpc simulate: error: --record-iterations: the iterations are written to the MCAP recordings; "
        "give --record DIR too (or [simulate] record)"
    )


def test_a_plugin_keeps_the_mpc_settings_but_not_a_predictor(capsys, monkeypatch):
    """A plugin reads the spec as it sees fit (flocking, [mpc]); one that plans with no predictor has none to
    take."""
    monkeypatch.setattr(registry, "_PLUGINS", {})
    monkeypatch.delenv(registry.PLUGINS_ENV, raising=False)
    argv = ["--plugin", TOY, "simulate", "--controller", TOY, *RUN]
    assert main([*argv, "--no-flocking", "--set", "mpc.horizon=10"]) == 0
    capsys.readouterr()
    assert main([*argv, "--predictor", "social_lstm_eth"]) == 2
    assert _error_line(capsys).endswith(f"--predictor social_lstm_eth: controller '{TOY}' {NO_PREDICTOR}")
