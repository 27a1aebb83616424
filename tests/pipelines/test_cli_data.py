"""``crowdmpc data`` and ``crowdmpc evaluate`` from the command line: results, and one-line errors."""

import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
import types
from pathlib import Path

import pytest

from pipelines.cli import main
from predictors.data.prepare import prepare_ewap
from tests.cli_calls import run_cli as run
from tests.predictors.samples import (
    scene,
    track,
    vouch_for,
    walk_scene_records,
    write_lines,
    write_tiny_ewap,
    write_walk_file,
)


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path_factory.mktemp("cache")))


@pytest.fixture
def prepared(tmp_path):
    raw = write_tiny_ewap(tmp_path / "data")
    out = tmp_path / "prepared"
    prepare_ewap(raw, out, categorize_scenes=False, log=lambda msg: None)
    return out


def assert_one_line_error(code, err, *fragments):
    assert code == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for fragment in fragments:
        assert fragment in lines[0]


def test_stats_table(tmp_path, capsys):
    write_walk_file(tmp_path / "a" / "walk.ndjson")
    code, out, _ = run(capsys, "data", "stats", str(tmp_path))
    assert code == 0
    header, _, row = out.splitlines()[:3]
    assert header.split()[:4] == ["file", "scenes", "tracks", "peds"]
    assert row.split()[:7] == ["a/walk.ndjson", "2", "45", "3", "3", "3.0", "3"]


def test_stats_parses_each_file_once(tmp_path, capsys, monkeypatch):
    """`data stats` validated a file, then read it again to build its scenes: every line was parsed and
    checked twice (5 % of the time of a 1.6 MB TrajNet++ students file, one pass being the whole read)."""
    import predictors.data.validate as validate

    write_walk_file(tmp_path / "walk.ndjson")
    parsed = []
    parse = validate.parse_ndjson
    monkeypatch.setattr(validate, "parse_ndjson", lambda path: parsed.append(path) or parse(path))
    for module in ("predictors.data.stats", "predictors.data.trajnet_io"):
        if hasattr(sys.modules.get(module), "parse_ndjson"):
            monkeypatch.setattr(sys.modules[module], "parse_ndjson", validate.parse_ndjson)
    code, out, err = run(capsys, "data", "stats", str(tmp_path))
    assert code == 0, err
    assert out.splitlines()[2].split()[:2] == ["walk.ndjson", "2"]
    assert len(parsed) == 1


def test_stats_shows_progress_over_scenes_on_a_terminal_only(tmp_path, capsys):
    """`data stats` of dense crowds ran for minutes without a sign of life (66 s, over 120 s on a loaded
    machine, for 26 000 scenes of 243 agents on average): a bar over each file's scenes, drawn on a
    terminal, and never into a piped table."""
    from predictors.data.stats import file_stats

    write_walk_file(tmp_path / "walk.ndjson")
    assert file_stats(tmp_path / "walk.ndjson", progress=True).scenes == 2
    assert "reading walk.ndjson" in capsys.readouterr().err
    code, out, err = run(capsys, "data", "stats", str(tmp_path))  # stderr is no terminal here
    assert code == 0 and "reading" not in err and "reading" not in out


def test_stats_total_ignores_files_without_scenes(tmp_path, capsys):
    write_walk_file(tmp_path / "walk.ndjson")
    write_lines(tmp_path / "empty.ndjson", [])  # an empty split is a valid file
    code, out, _ = run(capsys, "data", "stats", str(tmp_path))
    assert code == 0
    total = out.splitlines()[-1].split()
    assert total[:2] == ["total", "2"] and total[4] == "3"  # min agents/scene: the walk's 3, not 0


def test_stats_counts_only_integer_scene_types(tmp_path, capsys):
    """The Reader passes a scene's tag through unchecked: a float type (2.0) ended `data stats` in a
    TypeError and `true` counted as type I. Only an integer 1..4 is a TrajNet++ type."""
    for k, tag in enumerate([[2.0, []], [True, []], [3, [1]], [5, []], "III", [4, [1]], [4, []]]):
        records = walk_scene_records()
        records[0]["scene"]["tag"] = tag
        write_lines(tmp_path / f"t{k}.ndjson", records)
    code, out, err = run(capsys, "data", "stats", str(tmp_path))
    assert code == 0, err
    assert out.splitlines()[-1].split()[0] == "total" and out.splitlines()[-1].split()[-2] == "0/0/1/2"
    # and the four scenes counted in no column are named, each with its tag, not passed over in silence
    odd = [line for line in err.splitlines() if "tagged with no TrajNet++ type" in line]
    assert [line.split(": ")[1] for line in odd] == [str(tmp_path / f"t{k}.ndjson") for k in (0, 1, 3, 4)]
    assert odd[0].endswith("1 scene tagged with no TrajNet++ type (an integer 1-4), e.g. [2.0, []]: left out "
                           "of the types column") and 'e.g. "III"' in odd[3]  # fmt: skip
    assert "untagged" not in err
    records = walk_scene_records()
    records[0]["scene"].pop("tag", None)
    write_lines(tmp_path / "t9.ndjson", records)
    code, _, err = run(capsys, "data", "stats", str(tmp_path / "t9.ndjson"))
    assert code == 0 and f"note: 1 scene in {tmp_path / 't9.ndjson'} is untagged" in err


BAD_LINES = {
    "bad json": ('{"track": {"f": 0, "p": 1', "invalid JSON"),
    "missing keys": (json.dumps({"track": {"f": 0, "p": 1}}), "lacks key(s) ['x', 'y']"),
    "non-numeric coordinate": (json.dumps(track(0, 1, "a", 0.0)), "'x' must be a number"),
    "frame outside every scene": (
        json.dumps(track(9999, 1, 0.0, 0.0)),
        "frame 9999 lies outside every scene",
    ),
    # an unhashable value of an optional field ended both commands in a TypeError traceback
    "prediction_number a list": (
        json.dumps({"track": {"f": 0, "p": 1, "x": 0.0, "y": 0.0, "prediction_number": [1]}}),
        "track 'prediction_number' must be an integer, got [1]",
    ),
    "scene_id an object": (
        json.dumps({"track": {"f": 0, "p": 1, "x": 0.0, "y": 0.0, "scene_id": {"a": 1}}}),
        "track 'scene_id' must be an integer, got {'a': 1}",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_LINES))
@pytest.mark.parametrize("command", ["stats", "evaluate"])
def test_malformed_input_is_one_line_and_exit_2(case, command, tmp_path, capsys, prepared):
    line, reason = BAD_LINES[case]
    if command == "stats":
        path = write_lines(tmp_path / "bad" / "bad.ndjson", [*walk_scene_records(), line])
        code, _, err = run(capsys, "data", "stats", str(tmp_path / "bad"))
    else:
        path = prepared / "test" / "biwi_eth.ndjson"
        path.write_text(path.read_text() + line + "\n")
        vouch_for(prepared, "test/biwi_eth.ndjson")  # a file the manifest lists, malformed
        code, _, err = run(
            capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(prepared)
        )
    n_lines = len(path.read_text().splitlines())
    assert_one_line_error(code, err, f"{path}:{n_lines}: ", reason)


def _stop_on_second_move(monkeypatch):
    """os.replace, stopped (Ctrl-C) when a preparation moves its second file into place."""
    real_replace, moved = os.replace, []

    def replace(src, dst):
        if ".prepare-" in str(src) and ".prepare-" not in str(dst):  # from the staging folder into place
            moved.append(dst)
            if len(moved) == 2:
                raise KeyboardInterrupt
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)


def test_an_interrupted_prepare_leaves_no_old_manifest_and_is_rerun(tmp_path, capsys, monkeypatch):
    """A prepare stopped on the way left new files beside the old manifest (read as complete: evaluate and
    stats ran on mixed data), or, into a new folder, files without a manifest that the rerun refused."""
    raw = write_tiny_ewap(tmp_path / "data")
    out = tmp_path / "prepared"
    argv = ["data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags"]
    assert run(capsys, *argv)[0] == 0
    reference = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    for again in (argv, [*argv[:-1], "--keep-all"]):  # a new folder; then in place, with other options
        _stop_on_second_move(monkeypatch)
        if again is argv:
            shutil.rmtree(out)
        assert run(capsys, *again)[2].strip().splitlines()[-1] == "crowdmpc data prepare: interrupted"
        monkeypatch.undo()
        assert not (out / "manifest.json").exists()
        assert [p.name for p in tmp_path.iterdir() if ".prepare-" in p.name] == []  # the staging is gone
        code, _, err = run(capsys, "data", "stats", str(out))
        assert_one_line_error(code, err, "a `data prepare` into it was stopped before it finished")
        code, _, err = run(capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(out))
        assert_one_line_error(code, err, "holds neither prepared splits")
        assert run(capsys, *again)[0] == 0  # the same command finishes it
        assert {p.relative_to(out) for p in out.rglob("*") if p.is_file()} == set(reference)
    assert run(capsys, *argv)[0] == 0
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == reference


def test_prepared_files_that_are_not_the_manifests_are_named(tmp_path, capsys):
    raw = write_tiny_ewap(tmp_path / "data")
    prepare = ["data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "a"), "--no-tags"]
    assert run(capsys, *prepare)[0] == 0
    mixed = tmp_path / "a" / "train" / "biwi_eth.ndjson"
    original = mixed.read_bytes()
    mixed.write_bytes((tmp_path / "a" / "val" / "biwi_eth.ndjson").read_bytes())  # not the manifest's
    for argv in (["data", "stats"], ["evaluate", "--predictor", "constant_velocity", "--data-dir"]):
        code, _, err = run(capsys, *argv, str(tmp_path / "a"))
        assert_one_line_error(code, err, "train/biwi_eth.ndjson ")
    mixed.write_bytes(b"[" + original[1:])  # the same size, other bytes
    code, _, err = run(capsys, "data", "stats", str(tmp_path / "a"))
    assert_one_line_error(code, err, "train/biwi_eth.ndjson is not the file the manifest lists")
    # what every reader says to do, the prepare in place, is taken (it was refused as "no prepared data")
    assert run(capsys, *prepare)[0] == 0 and mixed.read_bytes() == original
    assert run(capsys, "data", "stats", str(tmp_path / "a"))[0] == 0


def test_a_prepare_into_another_file_system_copies_its_files_in(tmp_path, capsys, monkeypatch):
    """--out on another file system than its parent (a mount point, a link to another disk): the moves from
    the staging folder failed with EXDEV after the old manifest had gone, in a traceback."""
    import errno

    raw = write_tiny_ewap(tmp_path / "data")
    argv = ["data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "a"), "--no-tags"]
    assert run(capsys, *argv)[0] == 0
    reference = {p.relative_to(tmp_path / "a"): p.read_bytes() for p in (tmp_path / "a").rglob("*")
                 if p.is_file()}  # fmt: skip
    real_replace = os.replace

    def across_devices(src, dst):
        if ".prepare-" in str(src) and ".prepare-" not in str(dst):
            raise OSError(errno.EXDEV, "Invalid cross-device link")
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", across_devices)
    assert run(capsys, *argv)[0] == 0
    monkeypatch.undo()
    found = {
        p.relative_to(tmp_path / "a"): p.read_bytes() for p in (tmp_path / "a").rglob("*") if p.is_file()
    }
    assert found == reference


def test_stats_without_files(tmp_path, capsys):
    code, _, err = run(capsys, "data", "stats", str(tmp_path))
    assert_one_line_error(code, err, "no .ndjson files under")


@pytest.mark.parametrize("kind", ["fifo", "dangling link"])
def test_stats_names_a_file_named_ndjson_it_cannot_read(tmp_path, capsys, kind):
    """A FIFO or a dangling symbolic link named *.ndjson in the folder was left out without a word: the table
    described fewer files than the folder holds, exit 0. Evaluate and train refuse such a file too."""
    folder = tmp_path / "d"
    write_walk_file(folder / "walk.ndjson")
    odd = folder / "p.ndjson"
    if kind == "fifo":
        os.mkfifo(odd)
    else:
        odd.symlink_to(tmp_path / "gone.ndjson")
    code, _, err = run(capsys, "data", "stats", str(folder))
    what = (
        "not a regular file (a pipe" if kind == "fifo" else f"a symbolic link to {tmp_path / 'gone.ndjson'}"
    )
    assert_one_line_error(code, err, f"{odd}: {what}", f"named *.ndjson under {folder}; remove it")


def test_prepare_and_evaluate(tmp_path, capsys):
    raw = write_tiny_ewap(tmp_path / "data")
    out = tmp_path / "prepared"
    code, stdout, _ = run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags")
    assert code == 0
    assert "biwi_eth    test" in stdout and (out / "manifest.json").is_file()
    # no reference conversion beside the raw folder: each check not made is said (ETH's was not)
    skipped = [line for line in stdout.splitlines() if line.startswith("self-check skipped")]
    assert skipped == [
        f"self-check skipped: no official TrajNet++ biwi_hotel.ndjson found at {raw.resolve().parent}"
        "/trajnetpp_vita/train/real_data",
        "self-check skipped: no unofficial (pedro-mgb, TrajNet++ converter) biwi_eth.ndjson found at "
        f"{raw.resolve().parent}/trajnetpp_pedro-mgb/test_private/real_data",
    ]
    report = tmp_path / "r.json"
    code, stdout, _ = run(
        capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(out), "--json", str(report)
    )
    assert code == 0
    assert "test/biwi_eth.ndjson" in stdout and "ADE [m]" in stdout
    result = json.loads(report.read_text())
    assert result["protocol"] == "paper" and result["split"] == "test"
    # what else the numbers depend on: weights (none for constant velocity), the sampling seed, the code
    assert (result["predictor_sha256"], result["seed"]) == (None, 0) and "commit" in result["code"]
    data = out / "test" / "biwi_eth.ndjson"
    before = data.read_bytes()
    code, _, err = run(
        capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(out), "--json", str(data)
    )
    assert_one_line_error(code, err, "the file exists and is not a JSON report")
    assert data.read_bytes() == before  # a mistyped --json no longer overwrites the data
    # the walkers keep a constant velocity; only the centimetre rounding of the written files is left
    assert result["overall"]["scenes"] > 0 and result["overall"]["ade"] < 0.05


def test_evaluate_json_that_cannot_be_written_is_one_line(prepared, capsys):
    """`evaluate --json /dev/full` (a full disk) ended in an OSError traceback after the evaluation."""
    code, stdout, err = run(
        capsys,
        "evaluate",
        "--predictor",
        "constant_velocity",
        "--data-dir",
        str(prepared),
        "--json",
        "/dev/full",
    )
    assert "ADE [m]" in stdout  # the table is printed before the report is written
    assert_one_line_error(code, err, "--json /dev/full: could not write it (No space left on device)")


def test_prepare_rejects_a_directory_without_ewap(tmp_path, capsys):
    code, _, err = run(capsys, "data", "prepare", "--raw", str(tmp_path), "--out", str(tmp_path / "o"))
    # a researcher's other raw data (Social-GAN's 'frame ped x y' text) is told the way in
    assert_one_line_error(code, err, "expected a BIWI EWAP directory", "evaluate --test", "Your own data")


@pytest.mark.parametrize(
    ("kind", "what"), [("fifo", "not a regular file"), ("folder", "is a directory, not a data file")]
)
def test_prepare_names_an_obsmat_that_is_no_regular_file(tmp_path, capsys, kind, what):
    """R/seq_eth/obsmat.txt a FIFO or a folder got the general "expected a BIWI EWAP directory holding
    seq_eth/obsmat.txt and seq_hotel/obsmat.txt", naming neither the file nor what was wrong with it."""
    raw = write_tiny_ewap(tmp_path / "data")
    obsmat = raw / "seq_eth" / "obsmat.txt"
    obsmat.unlink()
    os.mkfifo(obsmat) if kind == "fifo" else obsmat.mkdir()
    code, _, err = run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "o"))
    assert_one_line_error(code, err, f"--raw {raw}: {obsmat}: {what} (expected a BIWI EWAP obsmat.txt)")
    assert not (tmp_path / "o").exists()


def test_prepare_reports_a_malformed_obsmat_line(tmp_path, capsys):
    raw = write_tiny_ewap(tmp_path / "data")
    obsmat = raw / "seq_hotel" / "obsmat.txt"
    obsmat.write_bytes(obsmat.read_bytes() + b"  1.0 2.0 oops\r\n")
    code, _, err = run(
        capsys, "data", "prepare", "--raw", str(raw), "--out", str(tmp_path / "o"), "--no-tags"
    )
    n_lines = len(obsmat.read_bytes().splitlines())
    assert_one_line_error(code, err, f"{obsmat}:{n_lines}: expected 8 numeric columns, found 3")


def test_evaluate_without_a_data_directory(monkeypatch, capsys):
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)
    code, _, err = run(capsys, "evaluate", "--predictor", "constant_velocity")
    assert_one_line_error(code, err, "pass --data-dir DIR or set CROWDMPC_DATA")


def test_evaluate_unknown_predictor(prepared, capsys):
    code, _, err = run(capsys, "evaluate", "--predictor", "oracle_of_delphi", "--data-dir", str(prepared))
    assert_one_line_error(code, err, "unknown predictor 'oracle_of_delphi'")


def test_evaluate_refuses_the_orca_oracle_naming_it(prepared, capsys):
    # it used to fail on the first scene with "call observe(obs) first", an API no command-line user calls
    code, _, err = run(capsys, "evaluate", "--predictor", "orca_oracle", "--data-dir", str(prepared))
    assert_one_line_error(code, err, "predictor 'orca_oracle' predicts from the simulator's state")


def test_evaluate_on_a_directory_without_data(tmp_path, capsys):
    code, _, err = run(capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(tmp_path))
    assert_one_line_error(code, err, "neither prepared splits")


def test_evaluate_a_scene_file_without_ground_truth(prepared, capsys):
    target = prepared / "test" / "biwi_eth.ndjson"
    write_lines(target, [scene(0, 1, 0, 80)] + [track(10 * k, 1, 0.5 * k, 0.0) for k in range(9)])
    vouch_for(prepared, "test/biwi_eth.ndjson")
    code, _, err = run(capsys, "evaluate", "--predictor", "constant_velocity", "--data-dir", str(prepared))
    assert_one_line_error(code, err, f"{target}:1: scene 0 has 9 steps, the evaluation needs 21")


def test_synth_forwards_its_options(monkeypatch, tmp_path, capsys):
    calls = []

    def synthesize(
        out_path,
        episodes,
        n_humans,
        seed,
        scenario="circle",
        with_robots=False,
        env_config=None,
        progress=None,
    ):
        calls.append((out_path, episodes, n_humans, seed, scenario, with_robots))
        out_path.write_text("scenes\n")
        return {"scenes": 12, "out": str(out_path)}

    monkeypatch.setitem(
        sys.modules, "pipelines.experiments.synth", types.SimpleNamespace(synthesize=synthesize)
    )
    out = tmp_path / "s.ndjson"
    argv = ["data", "synth", "--out", str(out), "--episodes", "3", "--humans", "5", "--seed", "7"]
    code, stdout, _ = run(capsys, *argv, "--scenario", "perpendicular", "--with-robots")
    assert code == 0 and "scenes: 12" in stdout
    staged = calls[0][0]  # made beside --out under a temporary name, then renamed into place
    assert staged.parent == tmp_path and staged.name.endswith(".part") and not staged.exists()
    assert calls == [(staged, 3, 5, 7, "perpendicular", True)]
    assert out.read_text() == "scenes\n"
    # how the file was made, beside it: the options, the data's sha256, the code
    provenance = json.loads((tmp_path / "s.synth.json").read_text())
    assert provenance["format"] == "crowdmpc-synth" and provenance["data"] == "s.ndjson"
    assert provenance["options"] == {
        "episodes": 3, "humans": 5, "seed": 7, "scenario": "perpendicular", "with_robots": True
    }  # fmt: skip
    assert provenance["sha256"] == hashlib.sha256(b"scenes\n").hexdigest() and "commit" in provenance["code"]
    (tmp_path / "s.ndjson").unlink()  # a provenance file left behind is not replaced without --replace
    code, _, err = run(capsys, *argv)
    assert_one_line_error(code, err, f"--out {tmp_path / 's.synth.json'} exists; add --replace")
    assert len(calls) == 1
    with pytest.raises(SystemExit) as exc:  # counts are bounded by the parser
        main([*argv[:5], "0", *argv[6:]])
    assert exc.value.code == 2 and calls == [(staged, 3, 5, 7, "perpendicular", True)]
    assert "argument --episodes: expected an integer in 1..100000, got 0" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["data", "--help"], ["data", "prepare", "--help"], ["evaluate", "--help"]])
def test_help_shows_an_example(argv, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 0
    assert "example" in capsys.readouterr().out


def test_synth_help_says_how_its_robots_move(capsys):
    """--with-robots was said to drive the robots straight; synthesize drives them as ORCA agents, which
    swerve round the humans (1.05 m off the straight line in 5 episodes of 9 humans)."""
    from crowdsim.baselines import OrcaController
    from pipelines.experiments import synth

    assert synth.OrcaController is OrcaController
    with pytest.raises(SystemExit):
        main(["data", "synth", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--with-robots include three robots in the crowd, ORCA agents that avoid the humans" in text
    assert "straight" not in text


@pytest.mark.parametrize(
    "text", ['{"data": ' + "9" * 5000 + "}", "[" * 100_000], ids=["long-integer", "nested"]
)
def test_a_provenance_file_of_hostile_json_is_refused_as_one_that_exists(monkeypatch, tmp_path, capsys, text):
    """`data synth --out x.ndjson` beside an x.synth.json holding a 5000-digit integer ended in "ValueError:
    Exceeds the limit (4300 digits)": _provenance caught JSONDecodeError, not the ValueError json raises for
    such a number. It is now no provenance of this command, refused as any other file there."""
    monkeypatch.setitem(sys.modules, "pipelines.experiments.synth", types.SimpleNamespace(synthesize=None))
    (tmp_path / "x.synth.json").write_text(text)
    argv = ["data", "synth", "--out", str(tmp_path / "x.ndjson"), "--episodes", "1", "--humans", "2"]
    code, _, err = run(capsys, *argv, "--seed", "0")
    assert_one_line_error(code, err, f"--out {tmp_path / 'x.synth.json'} exists; add --replace")


def test_an_interrupted_synth_never_leaves_data_beside_another_provenance(monkeypatch, tmp_path, capsys):
    """`data synth` stopped between renaming the data into place and writing its provenance left data
    without provenance (the rerun said "exists; add --replace"), or with --replace, the new data beside the
    old provenance (another seed and sha256)."""

    def synthesize(out_path, episodes, n_humans, seed, **_options):  # the options: the test above
        out_path.write_text(f"scenes of seed {seed}\n")
        return {"scenes": 1}

    monkeypatch.setitem(
        sys.modules, "pipelines.experiments.synth", types.SimpleNamespace(synthesize=synthesize)
    )
    out = tmp_path / "s.ndjson"
    provenance = tmp_path / "s.synth.json"

    def argv(seed, *extra):
        return [
            "data",
            "synth",
            "--out",
            str(out),
            "--episodes",
            "1",
            "--humans",
            "2",
            "--seed",
            seed,
            *extra,
        ]

    def matches() -> bool:
        document = json.loads(provenance.read_text())
        return document["sha256"] == hashlib.sha256(out.read_bytes()).hexdigest()

    gone = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True).stdout)  # fmt: skip
    killed = tmp_path / f".s.ndjson.synth-{gone}.part"  # what a synth killed before its rename leaves
    killed.write_text("scenes of a killed synth\n")
    # and what one killed while writing its scenes leaves: write_ndjson's temporary of the staged file
    writing = tmp_path / f".{killed.name}.{gone}.tmp"
    writing.write_text("half the scenes of a killed synth\n")
    assert run(capsys, *argv("7"))[0] == 0 and matches()
    assert not killed.exists() and not writing.exists()
    real_replace = os.replace
    for seed, extra in (("8", ["--replace"]), ("9", [])):
        if not extra:
            out.unlink()
            provenance.unlink()

        def stopped(src, dst):
            if dst == out:  # stopped between the provenance and the data
                raise KeyboardInterrupt
            real_replace(src, dst)

        monkeypatch.setattr(os, "replace", stopped)
        code, _, err = run(capsys, *argv(seed, *extra))
        monkeypatch.setattr(os, "replace", real_replace)
        assert code != 0 and err.strip().splitlines()[-1] == "crowdmpc data synth: interrupted"
        left = sorted(p.name for p in tmp_path.iterdir())
        assert left == [".s.ndjson.synth.lock", "s.synth.json"]  # no old data, no temporary
        assert json.loads(provenance.read_text())["options"]["seed"] == int(seed)
        code, _, err = run(capsys, *argv(seed, *extra))  # the same command again
        assert code == 0, err
        left = sorted(p.name for p in tmp_path.iterdir())
        assert left == [".s.ndjson.synth.lock", "s.ndjson", "s.synth.json"] and matches()
        assert out.read_text() == f"scenes of seed {seed}\n"


def test_synth_writes_its_provenance_under_a_temporary_name_of_its_own(monkeypatch, tmp_path, capsys):
    """The provenance was written as a fixed ``.NAME.synth.json.part``: two synths into the same --out shared
    it (each removing or renaming the other's), one a killed run left as a folder failed every later synth,
    and one left as a link had the provenance written through it, over the file it points to."""
    monkeypatch.setitem(
        sys.modules,
        "pipelines.experiments.synth",
        types.SimpleNamespace(synthesize=lambda out_path, *_, **__: out_path.write_text("s\n") and {}),
    )
    out, provenance = tmp_path / "s.ndjson", tmp_path / "s.synth.json"
    precious = tmp_path / "precious.txt"
    precious.write_text("mine\n")
    fixed = tmp_path / ".s.synth.json.part"
    renamed: list[Path] = []
    real_replace = os.replace

    def replace(src, dst):
        if Path(dst) == provenance:
            renamed.append(Path(src))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    argv = ["data", "synth", "--out", str(out), "--episodes", "1", "--humans", "2", "--seed", "0"]
    for leftover in (fixed.mkdir, lambda: fixed.symlink_to(precious)):
        leftover()
        code, _, err = run(capsys, *argv, "--replace")
        assert code == 0, err
        assert precious.read_text() == "mine\n" and not provenance.is_symlink()
        assert json.loads(provenance.read_text())["data"] == "s.ndjson"
        if fixed.is_symlink():
            fixed.unlink()
        else:
            fixed.rmdir()
    # each run its own temporary, beside the provenance
    assert len(renamed) == len(set(renamed)) == 2 and all(p.parent == tmp_path for p in renamed)


def test_a_second_synth_into_the_same_out_is_refused_while_the_first_runs(monkeypatch, tmp_path, capsys):
    """Two synths into one --out finishing together could rename one's data over the other's after the other
    had written its provenance: seed 1's scenes beside seed 2's provenance (another sha256). The second,
    started here just before the first renames its data into place, is refused in one line; the first's data
    and provenance match."""

    def synthesize(out_path, episodes, n_humans, seed, **_options):
        out_path.write_text(f"scenes of seed {seed}\n")
        return {"scenes": 1}

    monkeypatch.setitem(
        sys.modules, "pipelines.experiments.synth", types.SimpleNamespace(synthesize=synthesize)
    )
    out, provenance = tmp_path / "s.ndjson", tmp_path / "s.synth.json"
    argv = ["data", "synth", "--out", str(out), "--episodes", "1", "--humans", "2", "--replace", "--seed"]
    real_replace = os.replace
    started: list[bool] = []
    second: list[tuple[int, str, str]] = []

    def replace(src, dst):
        if Path(dst) == out and not started:  # the first's provenance is written, its data not yet renamed
            started.append(True)
            with monkeypatch.context() as other:  # another process: its temporaries named by its own pid
                other.setattr(os, "getpid", os.getppid)
                second.append(run(capsys, *argv, "2"))
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    assert main([*argv, "1"]) == 0
    ((code, _, err),) = second
    assert_one_line_error(code, err, f"another crowdmpc data synth is writing --out {out}")
    assert out.read_text() == "scenes of seed 1\n"
    document = json.loads(provenance.read_text())
    assert document["options"]["seed"] == 1
    assert document["sha256"] == hashlib.sha256(out.read_bytes()).hexdigest()


@pytest.mark.parametrize("name", ["s.ndjson", "s.synth.json"])
def test_synth_refuses_a_pipe_or_device_as_its_output(name, monkeypatch, tmp_path, capsys):
    """The data and its provenance are renamed into place, which replaced the node itself: `data synth --out
    /dev/null` run as root left a regular file at /dev/null. A pipe (with a reader, which the check's open
    of it waits for) shows it without touching /dev."""
    import stat

    monkeypatch.setitem(
        sys.modules,
        "pipelines.experiments.synth",
        types.SimpleNamespace(synthesize=lambda out_path, *_, **__: out_path.write_text("s\n") and {}),
    )
    pipe = tmp_path / name
    os.mkfifo(pipe)
    reader = os.open(pipe, os.O_RDONLY | os.O_NONBLOCK)
    try:
        argv = ["--episodes", "1", "--humans", "2", "--seed", "0", "--replace"]
        code, _, err = run(capsys, "data", "synth", "--out", str(tmp_path / "s.ndjson"), *argv)
    finally:
        os.close(reader)
    assert_one_line_error(code, err, f"{pipe}: is not a regular file (a device or a pipe)")
    assert stat.S_ISFIFO(os.lstat(pipe).st_mode) and os.listdir(tmp_path) == [name]


def test_synth_never_takes_another_data_files_provenance(tmp_path, capsys):
    """``--out x.json`` beside ``x.ndjson`` shares its provenance name, x.synth.json: the same options read
    as a rerun of this command, so x.ndjson's provenance was replaced by x.json's, silently (and with
    --replace too). Both are refused; x.ndjson keeps its own."""
    options = ["--episodes", "1", "--humans", "3", "--seed", "0"]
    assert run(capsys, "data", "synth", "--out", str(tmp_path / "x.ndjson"), *options)[0] == 0
    provenance = tmp_path / "x.synth.json"
    before = provenance.read_text()
    for extra in ([], ["--replace"]):
        code, _, err = run(capsys, "data", "synth", "--out", str(tmp_path / "x.json"), *options, *extra)
        assert_one_line_error(
            code, err, f"--out {tmp_path / 'x.json'}: its provenance file {provenance} is that of "
        )
        assert provenance.read_text() == before and not (tmp_path / "x.json").exists()
    assert json.loads(before)["data"] == "x.ndjson"


def test_synth_and_prepare_do_not_overwrite_other_files(tmp_path, capsys):
    """`data synth --out` onto an existing training file replaced it; `data prepare --out` into a folder of
    other files replaced its train/val/test files. A prepared folder is prepared again in place."""
    train = tmp_path / "train.ndjson"
    train.write_text('{"scene": {"id": 0, "p": 1, "s": 0, "e": 200}}\n')
    code, _, err = run(
        capsys, "data", "synth", "--out", str(train), "--episodes", "1", "--humans", "2", "--seed", "0"
    )
    assert_one_line_error(code, err, f"--out {train} exists; add --replace to replace it")
    assert train.read_text().startswith('{"scene"')
    other = tmp_path / "mine"
    (other / "train").mkdir(parents=True)
    (other / "train" / "biwi_eth.ndjson").write_text("precious\n")
    raw = write_tiny_ewap(tmp_path / "data")
    code, _, err = run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(other), "--no-tags")
    assert_one_line_error(code, err, "holds files but no prepared data")
    assert (other / "train" / "biwi_eth.ndjson").read_text() == "precious\n"
    prepared = tmp_path / "prepared"
    for _ in range(2):  # a prepared folder again: fine
        code, _, _ = run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(prepared), "--no-tags")
        assert code == 0


def test_evaluate_records_the_protocol_a_zoo_model_was_trained_under(prepared, tmp_path, capsys):
    """Both protocols score the same test file: --protocol picks the files, not how the model was trained,
    so a mismatch is said and recorded, never passed for leave-one-out results."""
    report = tmp_path / "r.json"
    argv = ["evaluate", "--predictor", "social_lstm_eth", "--data-dir", str(prepared), "--json", str(report)]
    code, _, err = run(capsys, *argv, "--no-progress")
    assert code == 0 and "note:" not in err
    assert json.loads(report.read_text())["trained_protocol"] == "paper"
    write_walk_file(prepared / "trajnetpp_vita" / "train" / "real_data" / "walk.ndjson")  # what loo trains on
    code, _, err = run(capsys, *argv, "--no-progress", "--protocol", "loo")
    assert code == 0, err
    assert "note: social_lstm_eth was trained under protocol 'paper'; --protocol loo chooses the files" in err
    result = json.loads(report.read_text())
    assert (result["protocol"], result["trained_protocol"]) == ("loo", "paper")


def test_prepare_refuses_a_linked_split_folder_or_marker_and_writes_nothing_outside(tmp_path, capsys):
    """A symbolic link for val/ in a prepared folder had `data prepare` replace the files of the folder it
    named; one for the marker of an unfinished prepare had it create the file the link named."""
    raw = write_tiny_ewap(tmp_path / "data")
    out = tmp_path / "prepared"
    argv = ["data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags"]
    assert run(capsys, *argv)[0] == 0
    victim = tmp_path / "victim"
    victim.mkdir()
    (victim / "biwi_eth.ndjson").write_text("precious\n")
    shutil.rmtree(out / "val")
    (out / "val").symlink_to(victim)
    code, _, err = run(capsys, *argv)
    assert_one_line_error(code, err, f"{out / 'val'} is a symbolic link")
    assert [p.name for p in victim.iterdir()] == ["biwi_eth.ndjson"]
    assert (victim / "biwi_eth.ndjson").read_text() == "precious\n"
    (out / "val").unlink()
    assert run(capsys, *argv)[0] == 0
    outside = tmp_path / "outside" / "created-by-prepare"
    outside.parent.mkdir()
    (out / ".prepare-incomplete").symlink_to(outside)
    code, _, err = run(capsys, *argv)
    assert_one_line_error(code, err, f"{out / '.prepare-incomplete'} is a symbolic link")
    assert not outside.exists() and (out / "manifest.json").is_file()


@pytest.mark.parametrize("name", ["/etc/passwd", "../outside.ndjson", "train/../../outside.ndjson"])
def test_a_manifest_listing_a_file_outside_its_folder_is_malformed(name, prepared, capsys, monkeypatch):
    """A manifest's name was joined to the folder unchecked: `data stats` opened and hashed /etc/passwd."""
    from predictors.data import locate

    (prepared.parent / "outside.ndjson").write_text("not yours\n")
    manifest = json.loads((prepared / "manifest.json").read_text())
    manifest["files"][name] = {"scenes": 1, "frames": [0, 1], "sha256": "0" * 64, "bytes": 10}
    (prepared / "manifest.json").write_text(json.dumps(manifest))
    hashed = []
    monkeypatch.setattr(locate, "sha256_file", lambda path: hashed.append(path) or "0" * 64)
    for argv in (["data", "stats"], ["evaluate", "--predictor", "constant_velocity", "--data-dir"]):
        code, _, err = run(capsys, *argv, str(prepared))
        assert_one_line_error(code, err, f"manifest.json is malformed: it lists {name!r}")
    assert hashed == []


def test_prepare_names_each_file_where_it_ends_up(tmp_path, capsys):
    """Each file's line named the hidden staging folder, removed when the command ended."""
    raw = write_tiny_ewap(tmp_path / "data")
    out = tmp_path / "prepared"
    code, stdout, _ = run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags")
    assert code == 0
    named = [line.rsplit(" -> ", 1)[1] for line in stdout.splitlines() if " -> " in line]
    assert len(named) == 6 and all(os.path.isfile(path) for path in named)
    assert {os.path.relpath(path, out) for path in named} == set(
        json.loads((out / "manifest.json").read_text())["files"]
    )


def test_prepare_seed_is_refused_with_no_tags_and_said_to_seed_the_categorisation(tmp_path, capsys):
    """--seed with --no-tags changed nothing yet was recorded in the manifest as if it had; its help named
    only the acceptance, though it seeds the Kalman fits of the categorisation too (tags under --keep-all)."""
    raw = write_tiny_ewap(tmp_path / "data")
    out = tmp_path / "prepared"
    argv = ["data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags"]
    code, _, err = run(capsys, *argv, "--seed", "42")
    assert_one_line_error(code, err, "--seed 42 with --no-tags")
    assert not out.exists()
    assert run(capsys, *argv)[0] == 0  # the default seed, recorded as it always was: cache keys unchanged
    assert json.loads((out / "manifest.json").read_text())["parameters"]["seed"] == 42
    with pytest.raises(SystemExit):
        main(["data", "prepare", "--help"])
    assert "seed of the TrajNet++ categorisation" in " ".join(capsys.readouterr().out.split())


def test_a_prepare_waits_for_another_into_the_same_folder(tmp_path, capsys):
    """Two prepares into one folder at once each moved their files in; the last to finish won. Another
    process holds the lock of --out here: the prepare starts only once it lets go."""
    raw = write_tiny_ewap(tmp_path / "data")
    out = tmp_path / "prepared"
    held, released = tmp_path / "held", tmp_path / "released"
    holder = subprocess.Popen(
        [sys.executable, "-c", (
            "import fcntl, pathlib, sys, time\n"
            "with open(sys.argv[1], 'a') as lock:\n"
            "    fcntl.flock(lock, fcntl.LOCK_EX)\n"
            "    pathlib.Path(sys.argv[2]).touch()\n"
            "    time.sleep(1.5)\n"
            "    pathlib.Path(sys.argv[3]).touch()\n"
        ), str(tmp_path / ".prepared.prepare.lock"), str(held), str(released)],
    )  # fmt: skip
    try:
        while not held.exists() and holder.poll() is None:
            time.sleep(0.02)
        assert held.exists()
        code, stdout, _ = run(capsys, "data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags")
        assert code == 0 and released.exists()  # it ran after the other let go
        assert stdout.splitlines()[0] == f"waiting for another `data prepare` into {out} to finish"
    finally:
        holder.wait(timeout=30)


def test_synth_remakes_the_shipped_synth_models_data(tmp_path, capsys):
    """checkpoints/README.md's commands for social_lstm_synth's data made none of its 18 files (sha256 in the
    manifest) once the paper profile became the default: those were made by the first simulator, which
    `data synth` could not choose. --profile v1 makes them again, bit for bit (here the smallest)."""
    manifest = json.loads((Path(__file__).parents[2] / "checkpoints" / "manifest.json").read_text())
    (entry,) = [m for m in manifest["models"] if m["name"] == "social_lstm_synth"]
    out = tmp_path / "circle_h5.ndjson"  # val: the README's 7th command, seed 106000, 3 episodes
    argv = ["--episodes", "3", "--humans", "5", "--seed", "106000", "--scenario", "circle", "--with-robots"]
    code, _, err = run(capsys, "data", "synth", "--out", str(out), *argv, "--profile", "v1")
    assert code == 0, err
    want = entry["training_data"]["files"]["val"]["circle_h5.ndjson"]
    assert hashlib.sha256(out.read_bytes()).hexdigest() == want
    assert json.loads(out.with_suffix(".synth.json").read_text())["options"]["profile"] == "v1"


def test_evaluate_scores_files_given_with_test(tmp_path, monkeypatch, capsys):
    """A researcher's own TrajNet++ files: evaluate had no way to score them (only a protocol's split of the
    prepared ETH/Hotel data), so a zoo model could not be scored on them at all. The walkers keep a constant
    velocity, so constant velocity scores 0 on both scenes of each file."""
    monkeypatch.delenv("CROWDMPC_DATA", raising=False)  # no data directory is needed
    first, second = write_walk_file(tmp_path / "a.ndjson"), write_walk_file(tmp_path / "b.ndjson")
    report = tmp_path / "r.json"
    code, stdout, _ = run(
        capsys,
        "evaluate",
        "--predictor",
        "constant_velocity",
        "--test",
        str(first),
        str(second),
        "--json",
        str(report),
    )
    assert code == 0
    assert str(first) in stdout and str(second) in stdout and "overall" in stdout
    result = json.loads(report.read_text())
    assert (result["protocol"], result["dataset"], result["data_dir"]) == ("custom", None, None)
    assert result["files_evaluated"] == [str(first), str(second)]
    assert result["overall"]["scenes"] == 4 and result["overall"]["ade"] == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("option", [["--protocol", "loo"], ["--dataset", "biwi_hotel"], ["--split", "val"]])
def test_evaluate_test_files_refuse_the_options_that_choose_prepared_files(option, tmp_path, capsys):
    data = write_walk_file(tmp_path / "a.ndjson")
    code, _, err = run(capsys, "evaluate", "--predictor", "constant_velocity", "--test", str(data), *option)
    assert_one_line_error(code, err, f"{option[0]} does not go with --test")


def test_evaluate_test_file_that_is_missing_is_one_line(tmp_path, capsys):
    missing = tmp_path / "nope.ndjson"
    code, _, err = run(capsys, "evaluate", "--predictor", "constant_velocity", "--test", str(missing))
    assert_one_line_error(code, err, f"--test file {missing} does not exist")


def test_evaluate_test_file_named_twice_is_refused(tmp_path, monkeypatch, capsys):
    """Named twice (here as a relative and an absolute path), its scenes were scored twice in "overall"."""
    data = write_walk_file(tmp_path / "a.ndjson")
    monkeypatch.chdir(tmp_path)
    code, _, err = run(
        capsys, "evaluate", "--predictor", "constant_velocity", "--test", "a.ndjson", str(data)
    )
    assert_one_line_error(code, err, f"--test names {data} more than once (as a.ndjson)")


@pytest.mark.parametrize("command", ["synth", "prepare"])
def test_data_the_disk_refuses_names_out(tmp_path, capsys, command):
    """A full disk (here `ulimit -f`) ended `data synth` and `data prepare` in "could not write (File too
    large)", naming nothing: the line names --out now, and nothing is left at it."""
    from tests.read_only import file_size_limit

    out = tmp_path / ("s.ndjson" if command == "synth" else "prepared")
    if command == "synth":
        argv = ["data", "synth", "--out", str(out), "--episodes", "2", "--humans", "3", "--seed", "0"]
    else:
        raw = Path(os.environ.get("CROWDMPC_DATA", "../shared/data")) / "raw_ewap"
        argv = ["data", "prepare", "--raw", str(raw), "--out", str(out), "--no-tags", "--no-check"]
    with file_size_limit(200):
        assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(
        f"crowdmpc data {command}: error: could not write {out.resolve()} (File too large)"
    )
    assert not out.exists() or not any(out.iterdir())


def test_prepare_no_progress_draws_no_bar(tmp_path, capsys, monkeypatch):
    """`data prepare` drew its bars on a terminal with no --no-progress to stop them (README: "Progress bars
    are drawn on a terminal only (`--no-progress`: none)"); off a terminal it draws none either way."""
    import predictors.data.prepare as prepare_module

    raw = write_tiny_ewap(tmp_path / "data")
    asked = []

    def fast(*args, **kwargs):
        asked.append(kwargs["progress"])
        return prepare_ewap(*args, **{**kwargs, "categorize_scenes": False})

    monkeypatch.setattr(prepare_module, "prepare_ewap", fast)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    for k, extra in enumerate(([], ["--no-progress"])):
        argv = ["data", "prepare", "--raw", str(raw), "--out", str(tmp_path / f"out{k}"), "--no-check"]
        assert run(capsys, *argv, *extra)[0] == 0
    assert asked == [None, False]  # None: a bar on a terminal only, as every command's
