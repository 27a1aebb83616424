"""``crowdmpc compare`` on MCAP recordings (``simulate --record DIR``): a folder pairs with its run's
``--json`` file episode for episode, every metric equal; a file that cannot be read is left out with a
warning in a folder and refused alone; a sweep's recordings are refused for the sweep's folder."""

import json
import shutil
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.logs.reader import read_recording

RUN = ["simulate", "--controller", "cmpc", "--predictor", "constant_velocity", "--humans", "2"]
RUN += ["--episodes", "2", "--seed", "4", "--no-progress"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    """One run's recordings (rec/) and JSON (run.json), and a run with another goal weight (other/)."""
    root = tmp_path_factory.mktemp("recorded")
    assert main([*RUN, "--record", str(root / "rec"), "--json", str(root / "run.json")]) == 0
    assert main([*RUN, "--record", str(root / "other"), "--set", "mpc.w_goal=5"]) == 0
    return root


def one_line_err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


def test_recordings_are_their_runs_json_episode_for_episode(recorded, capsys):
    capsys.readouterr()
    assert main(["compare", str(recorded / "run.json"), str(recorded / "rec"), "--expect-identical"]) == 0
    out = capsys.readouterr().out
    assert "identical: 2 episodes, every metric equal" in out
    assert "rec ran with the settings of run." in out
    single = recorded / "rec" / "circle_seed000005.mcap"
    assert main(["compare", str(recorded / "rec"), f"one={single}", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "Compared on the 1 episode every run holds:" in out
    assert f"one: {single}, 1 episode, code " in out


def test_the_setting_two_recorded_runs_differ_in_is_named(recorded, capsys):
    capsys.readouterr()
    assert main(["compare", str(recorded / "rec"), str(recorded / "other"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "| cmpc | 2 | 3 | other | 2 |" in out
    assert (
        "Settings other's episodes ran with where they differ from rec's:\n  mpc.w_goal: 10.0 -> 5.0" in out
    )


def test_a_folders_unreadable_recordings_are_left_out_with_a_warning(recorded, tmp_path, capsys):
    damaged = tmp_path / "damaged"
    shutil.copytree(recorded / "rec", damaged)
    cut = damaged / "circle_seed000005.mcap"
    cut.write_bytes(cut.read_bytes()[:2000])  # killed mid-episode: its metrics were never written
    (damaged / "empty.mcap").write_bytes(b"")
    (damaged / "next.mcap.part").write_bytes(b"")
    capsys.readouterr()
    assert main(["compare", str(recorded / "run.json"), str(damaged), "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "Compared on the 1 episode every run holds:" in captured.out
    warnings = captured.err.strip().splitlines()
    assert len(warnings) == 3 and all(w.startswith("crowdmpc compare: warning: damaged: ") for w in warnings)
    assert "next.mcap.part is unfinished" in warnings[0]
    assert "circle_seed000005.mcap holds no /episode/metrics message" in captured.err
    assert "empty.mcap is empty (0 bytes)" in captured.err
    assert main(["compare", str(recorded / "run.json"), str(damaged), "--expect-identical"]) == 1
    assert "run holds 1 episode not in every run" in capsys.readouterr().err
    part = tmp_path / "ended.mcap.part"  # a run killed after its metrics: read when named, as review does
    shutil.copy(recorded / "rec" / "circle_seed000004.mcap", part)
    assert main(["compare", str(recorded / "run.json"), str(part), "--no-progress"]) == 0
    assert f"ended.mcap: {part}, 1 episode" in capsys.readouterr().out
    (damaged / "next.mcap.part").write_bytes(cut.read_bytes())
    for alone, message in [
        (cut, "holds no /episode/metrics message (its episode did not finish"),
        (damaged / "next.mcap.part", "holds no /episode/metrics message (its episode did not finish"),
        (damaged / "empty.mcap", "is empty (0 bytes)"),
        (tmp_path / "missing.mcap", "does not exist (a sweep folder, a simulate --json file, or recordings"),
    ]:
        assert main(["compare", str(recorded / "run.json"), str(alone)]) == 2
        assert message in one_line_err(capsys)


def test_a_folder_without_a_sweeps_log_or_recordings_is_refused(recorded, tmp_path, capsys):
    (tmp_path / "nothing").mkdir()
    assert main(["compare", str(recorded / "run.json"), str(tmp_path / "nothing")]) == 2
    assert "holds no episodes.jsonl (a `crowdmpc sweep --out` folder has one) and no .mcap" in one_line_err(
        capsys
    )


def test_a_folder_of_unreadable_recordings_holds_no_episode(tmp_path, capsys):
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "a.mcap").write_bytes(b"not mcap")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "b.mcap").write_bytes(b"")
    assert main(["compare", str(tmp_path / "broken"), str(tmp_path / "other")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].endswith(
        "a.mcap is not an MCAP file (it does not start with MCAP's magic bytes); left out"
    )
    assert lines[1] == f"crowdmpc compare: error: broken: {tmp_path / 'broken'} holds no episode"


def test_a_sweeps_recordings_are_refused_for_the_sweeps_folder(recorded, tmp_path, capsys):
    """They may be its failed episodes alone (sweep --record failures), whose rates are not the sweep's."""
    sweep = tmp_path / "sweep"
    shutil.copytree(recorded / "rec", sweep / "mcap" / "cmpc-cell")
    (sweep / "episodes.jsonl").write_text("")
    for named in (
        sweep / "mcap",
        sweep / "mcap" / "cmpc-cell",
        sweep / "mcap" / "cmpc-cell" / "circle_seed000004.mcap",
    ):
        assert main(["compare", str(recorded / "run.json"), str(named)]) == 2
        err = one_line_err(capsys)
        assert (
            "is a sweep's recordings, which may be some of its episodes only (sweep --record failures)" in err
        )
        assert f"compare the sweep's folder {sweep}, whose episodes.jsonl has all" in err


def test_two_runs_of_one_controller_in_one_folder_are_told_to_be_compared_apart(recorded, tmp_path, capsys):
    both = tmp_path / "both"
    shutil.copytree(recorded / "rec", both / "a")
    shutil.copytree(recorded / "other", both / "b")
    assert main(["compare", str(recorded / "run.json"), str(both)]) == 2
    err = one_line_err(capsys)
    assert (
        "two episodes of method 'cmpc' on one crowd (a/circle_seed000004.mcap and b/circle_seed000004.mcap)"
        in err
    )
    assert "compare each folder as a run of its own" in err


def test_reading_one_topic_reads_its_messages_as_a_full_read_does(recorded):
    path = recorded / "rec" / "circle_seed000004.mcap"
    full, only = read_recording(path), read_recording(path, topics=["/episode/metrics"])
    assert set(only.messages) == set(only.channels) == {"/episode/metrics"}
    assert len(full.messages) > 5 and only.metadata == full.metadata
    assert only.data("/episode/metrics") == full.data("/episode/metrics")
    metrics = only.data("/episode/metrics")[-1]
    episodes = json.loads((recorded / "run.json").read_text())["episodes"]
    assert {**metrics, "config": only.config()} == {k: v for k, v in episodes[0].items()}


def test_a_metrics_message_the_review_cannot_use_is_named(recorded, tmp_path, capsys):
    from mcap.writer import Writer

    folder = tmp_path / "odd"
    shutil.copytree(recorded / "rec", folder)
    with (folder / "odd.mcap").open("wb") as f:
        writer = Writer(f)
        writer.start(library="crowdmpc")  # a recording's, whose metrics message is not one
        schema = writer.register_schema("metrics", "jsonschema", b"{}")
        channel = writer.register_channel("/episode/metrics", "json", schema)
        writer.add_message(channel, 0, b'{"metrics": 1}', 0)
        writer.finish()
    capsys.readouterr()
    assert main(["compare", str(recorded / "run.json"), str(folder), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert (
        "odd.mcap holds no /episode/metrics message that reads (/episode/metrics @ 0.000 s: 'metrics' is a"
        in err
    )
    assert "expected an object; `crowdmpc review --check` lists every problem); left out\n" in err


def test_settings_the_controller_does_not_read_are_no_difference(recorded, tmp_path, capsys):
    """simulate applies every [mpc] value of a file, a sweep's CMPC cells their own alone: a CMPC run under
    safe_crossing.toml and the sweep's same episodes differed in DMPC's update rule, which CMPC never reads.
    A key it reads still differs."""
    config = tmp_path / "run.toml"
    config.write_text('[mpc]\ndmpc_update = "gauss_seidel"\ndmpc_stop = "no_improvement"\n', encoding="utf-8")
    assert main(["--config", str(config), *RUN, "--json", str(tmp_path / "dmpc_keys.json")]) == 0
    capsys.readouterr()
    run = str(recorded / "run.json")
    assert main(["compare", run, str(tmp_path / "dmpc_keys.json"), "--expect-identical"]) == 0
    assert "dmpc_keys ran with the settings of run." in capsys.readouterr().out
    assert main(["compare", run, str(recorded / "other"), "--no-progress"]) == 0
    assert "mpc.w_goal: 10.0 -> 5.0" in capsys.readouterr().out
    # without flocking the flocking weights are read by neither side: the flocking row says it all (they were
    # shown "(not recorded)" on the side that did not read them)
    assert main([*RUN, "--no-flocking", "--json", str(tmp_path / "nf.json")]) == 0
    capsys.readouterr()
    assert main(["compare", run, str(tmp_path / "nf.json"), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "  flocking: true -> false" in out and "w_floc" not in out and "not recorded" not in out


def test_a_recording_changed_after_writing_is_named(recorded, tmp_path, capsys):
    """A byte of a recording's "config" metadata changed after writing (w_goal 10.0 -> 11.0): compare said
    the run's episodes ran with w_goal 11.0, without a word of the file's data section CRC mismatch, which
    review reports."""
    folder = tmp_path / "changed"
    shutil.copytree(recorded / "rec", folder)
    path = folder / "circle_seed000004.mcap"
    data = bytearray(path.read_bytes())
    data[data.index(b'"w_goal": 10.0') + len('"w_goal": 1')] ^= 0x01
    path.write_bytes(bytes(data))
    capsys.readouterr()
    assert main(["compare", str(recorded / "run.json"), str(folder), "--no-progress"]) == 0
    out, err = capsys.readouterr()
    assert "mpc.w_goal: 10.0 -> 10.0 | 11.0" in out  # what the file says, now under a warning
    (line,) = err.splitlines()
    assert line.startswith(f"crowdmpc compare: warning: changed: {path}: data section CRC mismatch (")
    assert line.endswith("; `crowdmpc review --check` lists every problem")
