"""A run's identity (pipelines.logs.identity) against hand-written values: which episode and config values
make another run, and what the refusal to replace another run's recording says."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.writer import Writer

from pipelines.errors import PipelineError
from pipelines.logs.identity import check_replaceable, run_identity, shown

EPISODE = {"controller": "cmpc", "predictor": "constant_velocity", "n_robots": "3", "n_humans": "7"}


def test_run_identity_hand_value():
    """The episode's four values (its scenario and seed name the file, so they are no part of it), the
    config flattened to dotted keys (an empty table kept as a value), the formation, robot spacing and crowd
    of recordings that predate them, and the speed-only settings left out; a config key named like an episode
    value does not override the episode's."""
    episode = EPISODE | {"scenario": "circle", "seed": "4"}
    config = {
        "env": {"dt": 0.4},
        "margins": {},
        "mpc": {"horizon": 4, "jit": True, "dmpc_parallel": True},
        "controller": "orca",
    }
    assert run_identity(episode, config) == {
        "controller": "cmpc",
        "predictor": "constant_velocity",
        "n_robots": "3",
        "n_humans": "7",
        "env.dt": 0.4,
        "margins": {},
        "mpc.horizon": 4,
        "env.formation": "auto",
        "env.robot_spacing": None,
        "env.crowd": "orca",
        "sensing.radius_m": None,
        "sensing.report_tracks": None,
        "mpc.flock_distance": "uniform",  # its [mpc] predates the option: the one d_flock it ran
        "mpc.flock_range": 0.0,  # and every pair flocking
        "mpc.dmpc_conflicts": False,  # and no conflict moves
    }
    # no [mpc] section (ORCA's recordings): no MPC option is added to tell it from an MPC's
    assert "mpc.flock_distance" not in run_identity(episode, {"env": {"dt": 0.4}})


def _recording(path: Path, episode: dict[str, str] | None, config: dict) -> Path:
    with open(path, "wb") as f:
        writer = Writer(f)
        writer.start()
        if episode is not None:
            writer.add_metadata("episode", episode)
        writer.add_metadata("config", {k: json.dumps(v) for k, v in config.items()})
        writer.finish()
    return path


@pytest.mark.parametrize(("name", "other"), [("n_humans", "9"), ("predictor", "social_lstm_eth")])
def test_another_crowd_or_predictor_is_another_run(tmp_path, name, other):
    path = _recording(tmp_path / "circle_1.mcap", EPISODE, {"mpc": {"horizon": 4}})
    check_replaceable(path, run_identity(EPISODE, {"mpc": {"horizon": 4}}))  # its own rerun replaces it
    with pytest.raises(PipelineError, match=f"holds another run's episode \\({name} "):
        check_replaceable(path, run_identity(EPISODE | {name: other}, {"mpc": {"horizon": 4}}))


def test_the_refusal_names_eight_differences_and_counts_the_rest(tmp_path):
    held = {f"k{i}": i for i in range(10)}  # ten settings, every one different in this run
    path = _recording(tmp_path / "circle_1.mcap", EPISODE, held)
    with pytest.raises(PipelineError) as refusal:
        check_replaceable(path, run_identity(EPISODE, {k: v + 1 for k, v in held.items()}))
    message = str(refusal.value)
    assert "(k0 0, k1 1, k2 2, k3 3, k4 4, k5 5, k6 6, k7 7, and 2 more; this run: k0 1," in message


def test_an_empty_setting_is_shown_as_a_dash(tmp_path):
    path = _recording(tmp_path / "circle_1.mcap", EPISODE, {"note": "x"})
    with pytest.raises(PipelineError, match=r"\(note x; this run: note -\)"):
        check_replaceable(path, run_identity(EPISODE, {"note": ""}))
    assert (shown(""), shown("row"), shown(4), shown(None)) == ("-", "row", "4", "null")


def test_a_file_that_is_no_recording_is_taken_over_only_as_an_unfinished_part(tmp_path):
    """A killed run's ``.part`` cut inside its header names no run: the recorder takes it over. At the
    episode's own name, where only a finished recording is renamed to, a file that is none is the user's: a
    note of theirs named circle_seed000000.mcap was replaced without a word. A symbolic link or a folder
    there is refused too, before the episode runs (a folder was found after it, as an unwritable .part)."""
    identity = run_identity(EPISODE, {"mpc": {"horizon": 4}})
    for made in (
        lambda p: _recording(p, None, {"mpc": {"horizon": 9}}),  # an MCAP file, no episode
        lambda p: p.write_text("my notes"),
        lambda p: p.write_bytes(b""),
    ):
        part = tmp_path / "circle_seed000000.mcap.part"
        made(part)
        check_replaceable(part, identity)
        final = tmp_path / "circle_seed000000.mcap"
        made(final)
        with pytest.raises(PipelineError, match="it holds no crowdmpc recording .a file of your own.."):
            check_replaceable(final, identity)
        part.unlink()
        final.unlink()
    (tmp_path / "elsewhere.mcap").write_text("x")
    (tmp_path / "circle_seed000000.mcap").symlink_to(tmp_path / "elsewhere.mcap")
    with pytest.raises(PipelineError, match="it is a symbolic link; remove it"):
        check_replaceable(tmp_path / "circle_seed000000.mcap", identity)
    (tmp_path / "circle_seed000001.mcap").mkdir()
    with pytest.raises(PipelineError, match="a folder .or another thing than a file. has that name"):
        check_replaceable(tmp_path / "circle_seed000001.mcap", identity)


def test_a_sensed_run_does_not_replace_the_full_observations_recording(tmp_path):
    """A run without a sensor records no "sensing": a --sensor-range run into its folder replaced its files
    without a word (the held recording named nothing the new run differed in), the reverse refused."""
    path = _recording(tmp_path / "circle_1.mcap", EPISODE, {"mpc": {"horizon": 4}})
    sensed = {"mpc": {"horizon": 4}, "sensing": {"radius_m": 2.0, "report_tracks": True}}
    with pytest.raises(
        PipelineError, match=r"another run's episode \(sensing.radius_m null, sensing.report_"
    ):
        check_replaceable(path, run_identity(EPISODE, sensed))
    check_replaceable(path, run_identity(EPISODE, {"mpc": {"horizon": 4}}))  # its own rerun replaces it
