"""Hostile input and faults: one-line parser errors, output paths checked before any work, sizes checked
before any worker starts, training numbers checked before Lightning, a raising NLP solve that falls back,
and a killed sweep's scratch removed by the next one."""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pipelines.cli import main
from pipelines.commands import check_writable, write_output
from pipelines.errors import PipelineError, storage_refusal, writes_named
from pipelines.experiments.log import EPISODES_FILE
from pipelines.experiments.worker import SCRATCH_PREFIX, remove_stale_scratch
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.episode import run_episode, summarize
from predictors.manifest import ZOO_FILES
from tests.predictors.samples import write_walk_file
from tests.read_only import file_size_limit

REPO = Path(__file__).resolve().parents[2]


def _one_error_line(capsys, command: str) -> str:
    """The one line a user error prints: ``crowdmpc <command>: error: ...``; nothing on stdout."""
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f"crowdmpc {command}: error: "), lines[0]
    assert captured.out == "", captured.out  # no table, no progress: no work was done
    return lines[0]


@pytest.mark.parametrize(
    ("argv", "command"),
    [
        (["data", "stats", "{d}/missing.ndjson"], "data stats"),
        (["zoo", "--dir", "{d}", "show", "nope"], "zoo show"),
        (["config", "show", "--set", "nope.key=1"], "config show"),
    ],
)
def test_an_error_of_a_commands_action_names_the_action(tmp_path, capsys, argv, command):
    """`crowdmpc data stats missing.ndjson` said "crowdmpc data: error: ...", as if of every data action,
    where argparse's own errors of that action name "crowdmpc data stats"."""
    assert main([a.format(d=tmp_path) for a in argv]) == 2
    _one_error_line(capsys, command)


def test_an_interrupted_action_names_the_action(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr("pipelines.commands.data.run_stats", interrupted)
    assert main(["data", "stats", "x.ndjson"]) == 130
    assert capsys.readouterr().err == "crowdmpc data stats: interrupted\n"


# ----------------------------------------------------------------------------------------------------------
# 1. Parser errors: one line and a pointer to --help, exit code 2
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "argv, command, named",
    [
        (["simulate", "--controller", "bogus"], "simulate", "--controller"),
        (["simulate", "--controller", "orca", "--humans", "many"], "simulate", "--humans"),
        (["simulate"], "simulate", "--controller"),
        (["sweep", "--experiment", "nope", "--out", "x"], "sweep", "--experiment"),
        (["sweep", "--experiment", "baselines", "--humans", "5,x", "--out", "x"], "sweep", "--humans"),
        (["train", "--model", "gpt"], "train", "--model"),
        (["calibrate", "--predictor", "cv", "--source", "real", "--alpha", "2"], "calibrate", "--alpha"),
        (["data"], "data", "ACTION"),
        (["data", "prepare", "--raw"], "data prepare", "--raw"),
        (["bogus"], "", "COMMAND"),
        (["simulate", "--controller", "orca", "--frobnicate"], "simulate", "--frobnicate"),
        # an empty path (an unset shell variable) read or wrote the current directory: Path("") is "."
        (["data", "prepare", "--raw", "r", "--out", ""], "data prepare", "--out: must be a path, got ''"),
        (["train", "--model", "vanilla_lstm", "--out", ""], "train", "--out: must be a path"),
        (["review", ""], "review", "path: must be a path"),
        (["export", "cv", "--out", ""], "export", "--out: must be a path"),
        (["evaluate", "--predictor", "cv", "--json", ""], "evaluate", "--json: must be a path"),
        # --data-dir '' fell back to $CROWDMPC_DATA without a word (calibrate's refused it)
        (["evaluate", "--predictor", "cv", "--data-dir", ""], "evaluate", "--data-dir: must be a path"),
        (["train", "--model", "vanilla_lstm", "--data-dir", ""], "train", "--data-dir: must be a path"),
    ],
)
def test_parser_errors_are_one_line_and_point_to_help(argv, command, named, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    captured = capsys.readouterr()
    prog = f"crowdmpc {command}".strip()
    assert captured.out == ""
    assert captured.err.count("\n") == 1, captured.err
    line = captured.err.rstrip("\n")
    assert line.startswith(f"{prog}: error: ") and named in line, line
    assert line.endswith(f"; see '{prog} --help'"), line


def test_a_parser_error_exits_2_from_the_command_line():
    done = subprocess.run(
        [sys.executable, "-m", "pipelines.cli", "simulate", "--controller", "bogus"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == (
        "crowdmpc simulate: error: argument --controller: invalid choice: 'bogus' "
        "(choose from 'cmpc', 'dmpc', 'orca', 'straight'); see 'crowdmpc simulate --help'\n"
    )


@pytest.mark.parametrize(
    ("argv", "prog"),
    [
        (
            ["calibrate", "--predictor", "constant_velocity", "--source", "real", "--robots", "1"],
            "crowdmpc calibrate",
        ),
        (["zoo", "list", "--robots", "1"], "crowdmpc zoo list"),
    ],
)
def test_an_unknown_option_names_its_command_and_that_commands_help(capsys, argv, prog):
    """argparse's top level refuses what no parser took: "crowdmpc: error: ... see 'crowdmpc --help'", the
    help without the command's options."""
    with pytest.raises(SystemExit) as done:
        main(argv)
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert err == f"{prog}: error: unrecognized arguments: --robots 1; see '{prog} --help'\n"


def test_plugin_after_the_command_says_where_it_goes(capsys):
    """--plugin is crowdmpc's own option; after the command argparse only says it does not know it."""
    with pytest.raises(SystemExit) as done:
        main(["evaluate", "--plugin", "mymod:MyNet", "--predictor", "constant_velocity"])
    assert done.value.code == 2
    assert capsys.readouterr().err == (
        "crowdmpc: error: unrecognized arguments: --plugin mymod:MyNet (--plugin goes before COMMAND: "
        "crowdmpc --plugin MODULE:CLASS COMMAND ...); see 'crowdmpc --help'\n"
    )
    # `train --plugin X --model X`: --model refused X as not registered first, without the hint
    toy = "tests.plugins.toy_predictor:ToyNet"
    with pytest.raises(SystemExit) as done:
        main(["train", "--plugin", toy, "--model", toy, "--epochs", "1"])
    assert done.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"crowdmpc train: error: argument --model: model {toy!r} is a plugin that is not")
    assert "(--plugin goes before COMMAND: crowdmpc --plugin MODULE:CLASS COMMAND ...)" in err


def test_plugin_after_the_command_before_its_argument_is_named_as_given(capsys):
    """`crowdmpc export --plugin m:C NAME`: argparse gave m:C to export's NAME and refused "--plugin NAME",
    naming the predictor as the plugin the user typed. The line names --plugin's value as given."""
    with pytest.raises(SystemExit) as done:
        main(["export", "--plugin", "mymod:MyNet", "social_lstm_eth", "--out", "x.casadi"])
    assert done.value.code == 2
    assert capsys.readouterr().err == (
        "crowdmpc: error: unrecognized arguments: --plugin mymod:MyNet (--plugin goes before COMMAND: "
        "crowdmpc --plugin MODULE:CLASS COMMAND ...); see 'crowdmpc --help'\n"
    )


# ----------------------------------------------------------------------------------------------------------
# 2. Output paths: checked before any work
# ----------------------------------------------------------------------------------------------------------


@pytest.fixture
def a_file(tmp_path) -> Path:
    path = tmp_path / "file"
    path.write_text("not a directory\n")
    return path


def test_check_writable(tmp_path, a_file):
    check_writable(None, "--json")
    check_writable(tmp_path / "new" / "deeper" / "out.json", "--json")  # created later, by the command
    check_writable(tmp_path / "new" / "dir", "--out", directory=True)
    check_writable(a_file, "--json")  # replaced
    check_writable(tmp_path, "--out", directory=True)  # written into
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # the checks create nothing
    assert a_file.read_text() == "not a directory\n"
    with pytest.raises(PipelineError, match=rf"^--json {a_file}/out.json: {a_file} is not a directory$"):
        check_writable(a_file / "out.json", "--json")
    with pytest.raises(PipelineError, match=rf"^--json {a_file}/a/b.json: {a_file} is not a directory$"):
        check_writable(a_file / "a" / "b.json", "--json")
    with pytest.raises(PipelineError, match=rf"^--json {tmp_path}: is a directory$"):
        check_writable(tmp_path, "--json")
    with pytest.raises(PipelineError, match=rf"^--out {a_file}: not a directory$"):
        check_writable(a_file, "--out", directory=True)


def test_a_file_output_is_never_written_through_a_symbolic_link(tmp_path, a_file):
    """A link planted in a folder (dangling, or to a file) would send the output wherever it points."""
    for target in (tmp_path / "elsewhere" / "out.json", a_file):
        link = tmp_path / f"link-{target.name}"
        link.symlink_to(target)
        with pytest.raises(PipelineError, match=rf"^--json {link}: is a symbolic link"):
            check_writable(link, "--json")
    assert not (tmp_path / "elsewhere").exists() and a_file.read_text() == "not a directory\n"


def test_an_output_through_a_dangling_or_looping_link_is_refused_before_the_work(tmp_path, capsys):
    """A dangling link (or a loop) as an output folder, or above one, can be neither written into nor made:
    `train --out LINK` ended in a FileExistsError traceback from mkdir, after the data had been read."""
    dangling = tmp_path / "dangling"
    dangling.symlink_to(tmp_path / "nowhere")
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    for out in (dangling, dangling / "run", loop):
        with pytest.raises(PipelineError, match=r"is a symbolic link to nothing"):
            check_writable(out, "--out", directory=True)
    with pytest.raises(PipelineError, match=rf"^--json {dangling}/r.json: {dangling} is a symbolic link"):
        check_writable(dangling / "r.json", "--json")
    assert main(["train", "--model", "vanilla_lstm", "--out", str(dangling), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--out {dangling}: {dangling} is a symbolic link to nothing" in err
    assert not (tmp_path / "nowhere").exists()


def test_a_path_the_system_cannot_take_is_refused_before_the_work(tmp_path, capsys):
    """Path.exists() is False for a NUL byte (reachable by a TOML escape) and raises for a name too long:
    the check passed, or ended in a traceback, and simulate lost its episodes when it wrote --json. The reason
    is Python's own: "embedded null byte" up to 3.12, "lstat: embedded null character in path" on 3.13."""
    nul = "embedded null (byte|character in path)"
    for bad, why in ((tmp_path / "r\0.json", nul), (tmp_path / ("a" * 300), "too long")):
        with pytest.raises(PipelineError, match=rf"^--json .*: not a usable path \(.*{why}"):
            check_writable(bad, "--json")
    argv = ["simulate", "--controller", "straight", "--humans", "0", "--no-progress"]
    assert main(argv + ["--set", f'simulate.json="{tmp_path}/r\\u0000.json"']) == 2
    assert "not a usable path" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--controller", "straight", "--humans", "1", "--no-progress", "--json"],
        ["data", "synth", "--episodes", "1", "--humans", "2", "--seed", "0", "--out"],
        ["data", "prepare", "--raw", "raw", "--out"],  # .NAME.prepare-PID.tmp beside the folder
    ],
    ids=["simulate-json", "synth-out", "prepare-out"],
)
def test_a_name_whose_temporary_name_is_too_long_is_refused_before_the_work(tmp_path, capsys, argv):
    """A 241-byte name fits, its temporary ".NAME.XXXXXXXX.part" (".NAME.synth-PID.part", a prepared
    folder's ".NAME.prepare-PID.tmp") does not: simulate ran its episodes and then could not write --json,
    data synth and data prepare ended in an OSError traceback. A folder written into is not staged beside."""
    out = tmp_path / ("a" * 236 + ".json")
    assert main([*argv, str(out)]) == 2
    line = _one_error_line(capsys, " ".join(argv[: 2 if argv[0] == "data" else 1]))
    # each output's own room: replace_file's +15, data prepare's +21, data synth's +33 (the next test)
    most = {"simulate": 240, "prepare": 234, "synth": 222}[argv[1] if argv[0] == "data" else argv[0]]
    assert line.endswith(
        f"{argv[-1]} {out}: not a usable path (a name of at most {most} bytes: crowdmpc writes it under a "
        "longer temporary name first)"
    )
    assert list(tmp_path.iterdir()) == []
    record = tmp_path / ("r" * 240)
    assert (
        main(
            [
                "simulate",
                "--controller",
                "straight",
                "--humans",
                "0",
                "--no-progress",
                "--record",
                str(record),
            ]
        )
        == 0
    )


def test_a_json_report_whose_temporary_name_fits_is_written(tmp_path, capsys):
    """One room for every output (21 bytes) refused a 240-byte --json, whose ".NAME.XXXXXXXX.part" fits."""
    out = tmp_path / ("a" * 235 + ".json")
    argv = ["simulate", "--controller", "straight", "--humans", "0", "--no-progress", "--json", str(out)]
    assert main(argv) == 0 and out.is_file()


_KILLED_WRITER = """
import sys, time
from pathlib import Path
from pipelines.commands import replace_file
replace_file(Path(sys.argv[1]), lambda name: (Path(name).write_text("half"), print("writing", flush=True),
                                             time.sleep(60)))
"""


def test_the_temporaries_of_killed_writers_are_removed_by_the_next_write(tmp_path):
    """An export or --json file written by a run killed before its rename (kill -9, SIGTERM: no finally runs)
    left its ".NAME.XXXXXXXX.part" beside the output for good, one more per kill, each as large as the output
    (an export's CasADi file). The next write of that output removes them; never a temporary a live writer
    holds locked, nor one just made (its writer may not have locked it yet)."""
    out = tmp_path / "report.json"
    writer = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(out)], stdout=subprocess.PIPE, text=True
    )
    assert writer.stdout is not None and writer.stdout.readline() == "writing\n"
    live = subprocess.Popen(
        [sys.executable, "-c", _KILLED_WRITER, str(out)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert live.stdout is not None and live.stdout.readline() == "writing\n"
        writer.kill()
        writer.wait()
        temporaries = set(tmp_path.glob(".report.json.*.part"))
        assert len(temporaries) == 2
        old = time.time() - 3600
        for path in temporaries:  # both written an hour ago: only the lock tells the live one apart
            os.utime(path, (old, old))
        fresh = tmp_path / ".report.json.abcdefgh.part"  # unlocked, but made just now
        fresh.write_text("")
        write_output(out, "{}", "--json")
        assert json.loads(out.read_text()) == {}
        left = set(tmp_path.glob(".report.json.*.part"))
        assert fresh in left and len(left) == 2  # the live writer's and the fresh one
    finally:
        live.kill()
        live.wait()


def test_data_synth_leaves_room_for_the_temporary_of_its_staged_data(tmp_path, capsys):
    """write_ndjson writes the staged ".NAME.synth-PID.part" under ".STAGED.PID.tmp" first, 33 bytes longer
    than --out's name with 7-digit PIDs: a 230-byte --out (passing the 234-byte limit, its provenance too)
    ended in an OSError traceback (File name too long) after the episodes; refused first, naming 222."""
    out = tmp_path / ("s" * 223 + ".ndjson")
    argv = ["data", "synth", "--episodes", "1", "--humans", "5", "--seed", "0", "--out", str(out)]
    assert main(argv) == 2
    assert _one_error_line(capsys, "data synth").endswith(
        f"--out {out}: not a usable path (a name of at most 222 bytes: crowdmpc writes it under a longer "
        "temporary name first)"
    )
    assert list(tmp_path.iterdir()) == []


def test_a_figure_with_a_long_name_is_written_as_matplotlib_saves_it_under_that_name(tmp_path, capsys):
    """--plot and --animate are saved under a temporary whose name does not grow with theirs
    (whole_files.save_figure): a 240-byte name was refused as "crowdmpc writes it under a longer temporary
    name first"; it does not."""
    record = tmp_path / "rec"
    plot = tmp_path / ("p" * 236 + ".png")
    argv = ["simulate", "--controller", "straight", "--humans", "1", "--no-progress", "--record", str(record)]
    assert main([*argv, "--plot", str(plot)]) == 0
    assert plot.stat().st_size > 0
    plot.unlink()
    (recording,) = record.glob("*.mcap")
    animation = tmp_path / ("a" * 236 + ".gif")
    assert main(["review", str(recording), "--plot", str(plot), "--animate", str(animation)]) == 0
    assert plot.stat().st_size > 0 and animation.stat().st_size > 0


def test_export_refuses_a_file_name_casadi_cannot_take_before_the_export(tmp_path):
    """A name with bytes that are not UTF-8 (Python holds them as surrogates) reaches CasADi's save as "":
    the export was built, then ended in a RuntimeError traceback ("Error opening stream ''")."""
    out = bytes(tmp_path) + b"/f\xff.casadi"
    done = subprocess.run(
        [sys.executable, "-m", "pipelines.cli", "export", "constant_velocity", "--out", out],
        cwd=REPO,
        capture_output=True,
        timeout=120,
    )
    assert (done.returncode, done.stdout) == (2, b"")
    assert done.stderr == (
        b"crowdmpc export: error: --out " + out.replace(b"\xff", b"\\udcff") + b": not a UTF-8 file name, "
        b"which CasADi cannot save to; name another file\n"
    )
    assert list(tmp_path.iterdir()) == []


def test_an_output_never_replaces_an_input_nor_a_json_report_a_non_json_file(tmp_path, a_file):
    """`review RUN.mcap --json RUN.mcap` replaced the recording by its summary, `evaluate --json` a data
    file: a file output is never one of the inputs, and a --json report replaces only a JSON document."""
    with pytest.raises(PipelineError, match=rf"^--plot {a_file}: that is one of the command's inputs"):
        check_writable(a_file, "--plot", inputs=[tmp_path / "missing", a_file])
    with pytest.raises(PipelineError, match=rf"^--json {a_file}: the file exists and is not a JSON report"):
        check_writable(a_file, "--json", json_only=True)
    report = tmp_path / "report.json"
    for text in ("", '{"ade": 0.6}\n'):  # empty, or a report of an earlier run: replaced
        report.write_text(text)
        check_writable(report, "--json", json_only=True)
    lines = tmp_path / "scenes.ndjson"
    lines.write_text('{"scene": 1}\n{"scene": 2}\n')  # two documents: data
    with pytest.raises(PipelineError, match="not a JSON report"):
        check_writable(lines, "--json", json_only=True)
    assert a_file.read_text() == "not a directory\n" and lines.read_text().count("\n") == 2
    # and never a JSON file crowdmpc keeps: by its crowdmpc format, or by a sweep's or a training run's name
    kept = {
        "manifest.json": '{"format": "crowdmpc-zoo", "version": 1, "models": []}',
        "sweep.json": '{"experiment": "table2", "runs": []}',
        "train_settings.json": '{"name": "x"}',
        "x.metrics.json": '{"name": "x"}',
    }
    for name, text in kept.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(PipelineError, match="that is a file crowdmpc keeps"):
            check_writable(tmp_path / name, "--json", json_only=True)


@pytest.mark.parametrize(
    "argv, name",
    [
        (
            ["calibrate", "--predictor", "constant_velocity", "--source", "real", "--json"],
            "calibrations.json",
        ),
        (["evaluate", "--predictor", "constant_velocity", "--json"], "manifest.json"),
        (["simulate", "--controller", "straight", "--humans", "0", "--json"], "Calibrations.json"),
    ],
)
def test_an_output_is_never_a_zoos_own_file_even_before_the_zoo_made_it(argv, name, capsys):
    """`calibrate --json ZOO/calibrations.json` on a new zoo stored its blocks, then wrote its report over
    them, and every conformal command after failed on the file; `evaluate --json ZOO/manifest.json` put a
    report where the zoo's manifest goes. Only an existing file was looked at."""
    from predictors.zoo import checkpoints_dir, user_zoo_dir

    zoo = user_zoo_dir()
    # the same file, however it is named (through an existing folder's "..": a missing one's is taken away
    # before any check, pipelines/commands/output_paths.py)
    target = zoo / ".." / zoo.name / name
    assert main([*argv, str(target), "--no-progress"]) == 2
    line = _one_error_line(capsys, argv[0])
    assert line.endswith(
        f"--json {target}: that is a file of the zoo {zoo}, its {ZOO_FILES[name.lower()]}; name another file"
    )
    assert list(zoo.iterdir()) == []
    with pytest.raises(PipelineError, match="that is a file of the zoo"):
        check_writable(checkpoints_dir() / "manifest.json", "--out")
    check_writable(zoo / "calibrations.json", "calibrations file", zoo_own=True)  # calibrate's own file


def test_a_report_that_cannot_be_written_is_one_line_and_keeps_the_earlier_one(tmp_path):
    """`--json` on a full disk (/dev/full, ``ulimit -f``) ended the commands in an OSError traceback after
    the work, the earlier report cut: one PipelineError naming the option, the earlier report whole, no part
    file left."""
    with pytest.raises(
        PipelineError, match=r"^--json /dev/full: could not write it \(No space left on device\)$"
    ):
        write_output(Path("/dev/full"), "{}\n", "--json")
    report = tmp_path / "deeper" / "report.json"
    write_output(report, '{"ade": 0.6}\n', "--json")  # its folder made
    with file_size_limit(64), pytest.raises(PipelineError, match=rf"^--json {report}: could not write it"):
        write_output(report, json.dumps({"ade": list(range(100))}), "--json")
    assert report.read_text() == '{"ade": 0.6}\n' and [p.name for p in report.parent.iterdir()] == [
        report.name
    ]
    write_output(report, '{"ade": 0.5}\n', "--json")
    assert report.read_text() == '{"ade": 0.5}\n'


def test_a_write_the_disk_refuses_ends_the_command_in_one_line(tmp_path, capsys):
    """A full disk, a quota or `ulimit -f` met by a write with no option of its own behind it (here data
    synth's scenes; a sweep's report, a zoo's manifest, a checkpoint) ended the command in an OSError
    traceback: one line with the cause and what to do, exit code 2, nothing left behind."""
    out = tmp_path / "synth.ndjson"
    argv = ["data", "synth", "--episodes", "2", "--humans", "3", "--seed", "0", "--out", str(out)]
    with file_size_limit(4096):
        code = main(argv)
    assert code == 2
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and line.startswith("crowdmpc data synth: error: could not write"), line
    assert line.endswith(
        "(File too large); free space (or raise the quota, or `ulimit -f`) and run the command again"
    )
    assert list(tmp_path.iterdir()) == []  # the lock of synths into --out neither, made by this one


def test_an_os_error_that_is_no_full_disk_keeps_its_traceback():
    """Only the storage's refusals are the user's to fix: any other OSError is a bug of ours."""
    assert storage_refusal(OSError(errno.EBADF, "Bad file descriptor")) is None
    assert storage_refusal(ValueError("x")) is None
    full = OSError(errno.ENOSPC, "No space left on device", "/scratch/episodes.jsonl")
    assert storage_refusal(full) == (
        "could not write /scratch/episodes.jsonl (No space left on device); free space (or raise the quota, "
        "or `ulimit -f`) and run the command again"
    )
    # shutil's copy names the source it read first: the refused file is the second
    copy = OSError(errno.ENOSPC, "No space left on device", "/tmp/tmpabc", None, "/runs/ckpt/last.ckpt")
    assert storage_refusal(copy).startswith("could not write /runs/ckpt/last.ckpt (No space")


def test_review_refuses_to_write_over_the_recording_it_reads(tmp_path, capsys):
    from tests.pipelines.mcap_episode import record_episode

    run = record_episode(tmp_path, seed=1, steps=3)
    before = run.path.read_bytes()
    assert main(["review", str(run.path), "--json", str(run.path)]) == 2
    assert "that is one of the command's inputs" in capsys.readouterr().err
    assert main(["review", str(tmp_path), "--json", str(run.path)]) == 2  # a folder's recordings too
    assert run.path.read_bytes() == before


@pytest.mark.parametrize("option", ["--json", "--plot"])
def test_simulate_refuses_to_write_over_its_config_file(tmp_path, capsys, option):
    """An empty config file is valid TOML, and --json takes an empty file: `--config c.toml simulate --json
    c.toml` replaced the config by the report."""
    config = tmp_path / ("c.toml" if option == "--json" else "c.png")
    config.write_text("")
    argv = ["--config", str(config), "simulate", "--controller", "straight", "--humans", "1", "--no-progress"]
    assert main([*argv, option, str(config)]) == 2
    assert "that is one of the command's inputs" in capsys.readouterr().err
    assert config.read_text() == ""


@pytest.mark.parametrize(
    ("first", "second", "name"), [("--plot", "--json", "same.png"), ("--plot", "--animate", "same.gif")]
)
def test_two_outputs_of_one_review_are_two_files(tmp_path, capsys, first, second, name):
    """`review RUN --plot same.png --json same.png` wrote the plot, then the report over it (exit 0, the plot
    lost), and `--plot a.gif --animate a.gif` the animation over the plot. Refused before any is written.

    matplotlib writes .gif figures since 3.11 only: before, `--plot a.gif` is refused for its type first.
    """
    from crowdsim.plotting import figure_refusal
    from tests.pipelines.mcap_episode import record_episode

    run = record_episode(tmp_path / "run", seed=1, steps=3)
    (tmp_path / "out").mkdir()  # an existing folder's "..": a missing one's is taken away when parsed
    same = tmp_path / "out" / ".." / name
    assert main(["review", str(run.path), first, str(same), second, str(tmp_path / name)]) == 2
    line = _one_error_line(capsys, "review")
    refusal = figure_refusal(same)
    if refusal is None:
        assert line.endswith(f"{first} and {second} name the same file {same}; give each its own")
    else:
        assert first == "--plot" and name.endswith(".gif")  # only .gif figures depend on the version
        assert line.endswith(f"{first} {same}: {refusal}")
    assert not (tmp_path / name).exists()


def test_review_writes_into_a_new_folder_and_strict_json(tmp_path, capsys):
    """The outputs' folders are made, as every other command makes them (the check passed, and the whole
    review was lost at the end); NaN in a foreign file's metrics is no reason to write invalid JSON."""
    from pipelines.logs.recorder import McapRecorder
    from pipelines.logs.schemas import EPISODE_METRICS
    from tests.pipelines.mcap_episode import record_episode

    run = record_episode(tmp_path, seed=1, steps=3)
    out = tmp_path / "new" / "deeper"
    argv = ["review", str(run.path), "--json", str(out / "s.json"), "--plot", str(out / "p.png")]
    assert main(argv + ["--animate", str(out / "a.gif")]) == 0
    assert {p.name for p in out.iterdir()} == {"s.json", "p.png", "a.gif"}
    foreign = tmp_path / "foreign.mcap"
    with McapRecorder(foreign, metadata={"episode": {"scenario": "circle", "seed": "1"}}) as rec:
        metrics = b'{"metrics": {"success": true, "travel_time": NaN, "min_distance": Infinity}}'
        rec.write_json("/episode/metrics", metrics, 0, schema=EPISODE_METRICS)
    assert main(["review", str(foreign), "--json", str(out / "f.json")]) == 0
    report = json.loads((out / "f.json").read_text(), parse_constant=lambda c: pytest.fail(f"{c} in JSON"))
    # a success's NaN travel time: the metrics are left out, reported, and no NaN reaches the JSON
    assert report["summary"]["metrics"] is None


@pytest.mark.parametrize("option", ["--json", "--plot", "--record"])
def test_simulate_checks_its_outputs_before_the_episodes(option, a_file, capsys, monkeypatch):
    def no_episodes(*args, **kwargs):
        raise AssertionError("an episode ran before the output paths were checked")

    monkeypatch.setattr("pipelines.loop.episode.run_episodes", no_episodes)
    target = a_file / "out.png"
    argv = ["simulate", "--controller", "orca", "--humans", "3", "--no-progress", option, str(target)]
    assert main(argv) == 2
    line = _one_error_line(capsys, "simulate")
    assert line == f"crowdmpc simulate: error: {option} {target}: {a_file} is not a directory"


@pytest.mark.parametrize(
    "options, message",
    [
        (["--json", "{d}/rec", "--record", "{d}/rec"], "--json {d}/rec is --record's folder; give it"),
        (["--plot", "{d}/rec.png", "--record", "{d}/rec.png"], "--plot {d}/rec.png is --record's folder"),
        (["--margins", "fixed:0.1,0.1,0.1,0.1"], "--margins fixed:0.1,0.1,0.1,0.1: controller 'orca' plans"),
        (["--coupling", "nlp"], "--coupling nlp: controller 'orca' plans with no predictor"),
    ],
)
def test_simulate_refuses_what_the_run_could_not_do_before_the_episodes(options, message, tmp_path, capsys,
                                                                        monkeypatch):  # fmt: skip
    """An output named as the recording folder failed after every episode (the recorder had made the folder);
    margins and coupling given to ORCA were printed and recorded as if it had planned with them."""

    def no_episodes(*args, **kwargs):
        raise AssertionError("an episode ran before the options were checked")

    monkeypatch.setattr("pipelines.loop.episode.run_episodes", no_episodes)
    argv = ["simulate", "--controller", "orca", "--humans", "3", "--no-progress"]
    assert main(argv + [o.format(d=tmp_path) for o in options]) == 2
    assert message.format(d=tmp_path) in _one_error_line(capsys, "simulate")


@pytest.mark.parametrize(
    "argv, option",
    [
        (["sweep", "--experiment", "baselines", "--humans", "5", "--episodes-per-cell", "1"], "--out"),
        (["evaluate", "--predictor", "constant_velocity"], "--json"),
        (["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop"], "--json"),
        (["data", "synth", "--episodes", "1", "--humans", "2", "--seed", "0"], "--out"),
        (["data", "prepare", "--raw", "."], "--out"),
    ],
)
def test_every_output_path_is_checked_first(argv, option, a_file, capsys):
    target = a_file / "out"
    assert main([*argv, option, str(target)]) == 2
    line = _one_error_line(capsys, " ".join(argv[: 2 if argv[0] == "data" else 1]))
    assert line.endswith(f"{option} {target}: {a_file} is not a directory")
    assert not target.exists()


# ----------------------------------------------------------------------------------------------------------
# 3. Sweep sizes: checked before any worker starts
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "options, message",
    [
        (["--humans", "1000"], "--humans must be in 1..50, got 1000"),
        (["--humans", "5,51"], "--humans must be in 1..50, got 51"),
        (["--robots", "50"], "--robots must be in 1..12, got 50"),
        (["--robots", "0"], "--robots must be in 1..12, got 0"),
        (["--episodes-per-cell", "1000001"], "--episodes-per-cell must be at most 100000, got 1000001"),
        (["--workers", "0"], "--workers must be at least 1 and at most 4096, got 0"),
        (["--workers", "100000", "--backend", "inline"], "--workers must be at least 1 and at most 4096"),
        (["--workers", "100000"], "--workers must be at least 1 and at most 4096, got 100000"),
        (["--workers", "4000"], "--workers 4000: at most "),  # this machine's limit, 4 per CPU
    ],
)
def test_sweep_sizes_are_refused_before_any_worker_starts(options, message, tmp_path, capsys, monkeypatch):
    def no_workers(*args, **kwargs):
        raise AssertionError("workers started")

    monkeypatch.setattr("pipelines.experiments.sweep.make_backend", no_workers)
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "baselines", "--episodes-per-cell", "2", "--workers", "1"]
    assert main([*argv, "--no-progress", "--out", str(out), *options]) == 2
    assert message in _one_error_line(capsys, "sweep")
    assert not out.exists()


@pytest.mark.parametrize("mode", [[], ["--dry-run"], ["--report-only"]], ids=["run", "dry-run", "report"])
@pytest.mark.parametrize(
    "options, message",
    [
        (["--humans", "5,6,5"], "argument --humans: --humans names 5 more than once, got '5,6,5'"),
        (["--set", "sweep.humans=[7,7]"], "--set sweep.humans: must name each crowd size once, got 7 more"),
    ],
)
def test_a_repeated_crowd_size_is_refused_whatever_the_sweep_does(mode, options, message, tmp_path, capsys):
    """--dry-run and --report-only took --humans 5,5 (a column and a row twice); only a run refused it."""
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "baselines", "--episodes-per-cell", "2", "--out", str(out), *mode]
    try:
        code = main([*argv, *options])
    except SystemExit as exc:  # argparse's error exits; ours return the status
        code = exc.code
    assert code == 2
    assert message in _one_error_line(capsys, "sweep")
    assert not out.exists()


# ----------------------------------------------------------------------------------------------------------
# 4. Training numbers: checked before Lightning
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "options, message",
    [
        (["--lr", "nan"], "--lr must be a finite number in (0, 10], got nan"),
        (["--lr", "inf"], "--lr must be a finite number in (0, 10], got inf"),
        (["--lr", "-0.001"], "--lr must be a finite number in (0, 10], got -0.001"),
        (["--lr", "0"], "--lr must be a finite number in (0, 10], got 0.0"),
        # beyond float32 (3.4e38) Adam ended in a traceback; far above any useful rate already
        (["--lr", "1e39"], "--lr must be a finite number in (0, 10], got 1e+39"),
        (["--lr", "10.5"], "--lr must be a finite number in (0, 10], got 10.5"),
        (["--epochs", "-1"], "--epochs must be in 1..100000, got -1"),
        (["--epochs", "10000000"], "--epochs must be in 1..100000, got 10000000"),
        (["--batch-size", "0"], "--batch-size must be in 1..65536, got 0"),
        (["--step-size", "-5"], "--step-size must be in 1..100000, got -5"),
        (["--hidden-dim", "0"], "--hidden-dim must be in 1..4096, got 0"),
        (["--hidden-dim", "100000"], "--hidden-dim must be in 1..4096, got 100000"),
        (["--seed", "-1"], "--seed must be in 0..4294967295, got -1"),
        (["--limit-batches", "0"], "--limit-batches must be in 1..1000000, got 0"),
    ],
)
def test_training_numbers_are_refused_in_one_line(options, message, tmp_path, capsys):
    data = write_walk_file(tmp_path / "walk.ndjson")
    argv = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data)]
    assert main([*argv, "--out", str(tmp_path / "run"), "--no-progress", *options]) == 2
    assert _one_error_line(capsys, "train") == f"crowdmpc train: error: {message}"
    assert not (tmp_path / "run").exists()


def test_training_numbers_are_checked_before_lightning_is_imported(tmp_path, a_file):
    data = write_walk_file(tmp_path / "walk.ndjson")
    script = (
        "import sys\n"
        "from pipelines.cli import main\n"
        "code = main(sys.argv[1:])\n"
        "print('lightning' in sys.modules)\n"
        "sys.exit(code)\n"
    )
    argv = ["train", "--model", "social_lstm", "--train", str(data), "--val", str(data)]
    for options, message in [
        (["--lr", "nan", "--out", str(tmp_path / "run")], "--lr must be a finite number in (0, 10], got nan"),
        (["--out", str(a_file / "run")], f"--out {a_file}/run: {a_file} is not a directory"),
    ]:
        done = subprocess.run(
            [sys.executable, "-c", script, *argv, *options],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert done.returncode == 2
        assert done.stdout == "False\n"
        assert done.stderr == f"crowdmpc train: error: {message}\n"


# ----------------------------------------------------------------------------------------------------------
# 5. Faults: a solve that raises falls back, and the episode goes on
# ----------------------------------------------------------------------------------------------------------


def _raising_solve(every: int = 1):
    """``_Solver.solve`` that raises as CasADi does when a call fails, on every ``every``-th call."""
    from mpc.solvers import _Solver

    original = _Solver.solve
    calls = {"n": 0}

    def solve(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] % every == 0:
            raise RuntimeError(".../casadi/core/function.cpp:1458: Error in Function::call for 'solver'")
        return original(self, *args, **kwargs)

    return solve


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_a_solve_that_raises_falls_back_and_the_episode_finishes(name, monkeypatch):
    monkeypatch.setattr("mpc.solvers._Solver.solve", _raising_solve())
    controller = make_controller(ControllerSpec(name))
    result = run_episode(controller, seed=0, scenario="circle", n_humans=2)
    steps = len(result.statuses)
    assert steps == result.metrics.n_steps > 1  # to the time limit: the robots only brake
    assert set(result.statuses) == {"exception: RuntimeError"}
    assert set(result.fallbacks) == {"brake"}  # nothing was ever solved: nothing to shift
    assert controller.solve_exceptions == steps
    summary = summarize([result])
    assert summary["fallback_steps"] == steps and summary["statuses"] == {"exception: RuntimeError": steps}


def test_a_raising_solve_between_good_ones_shifts_the_last_plan(monkeypatch):
    monkeypatch.setattr("mpc.solvers._Solver.solve", _raising_solve(every=5))
    controller = make_controller(ControllerSpec("cmpc"))
    result = run_episode(controller, seed=0, scenario="circle", n_humans=2)
    raised = [i for i, s in enumerate(result.statuses) if s == "exception: RuntimeError"]
    assert raised and controller.solve_exceptions == len(raised)
    after_a_solve = [i for i in raised if result.statuses[i - 1] == "ok"]
    assert after_a_solve and all(result.fallbacks[i] == "shifted" for i in after_a_solve)
    assert "ok" in result.statuses and np.isfinite(result.robot_positions).all()


def test_a_bug_in_the_solve_is_not_taken_for_a_solver_failure(monkeypatch):
    """Only CasADi's RuntimeError is a failed solve: a TypeError is a bug, and braking over it would hide it
    behind the solver-failure statistics of thousands of episodes."""
    from crowdsim.env import CrowdEnv

    def buggy(self, *args, **kwargs):
        raise TypeError("unsupported operand type(s) for +: 'NoneType' and 'float'")

    monkeypatch.setattr("mpc.solvers._Solver.solve", buggy)
    controller = make_controller(ControllerSpec("cmpc"))
    obs = CrowdEnv().reset(0, "circle", 2)
    controller.reset(obs)
    with pytest.raises(TypeError, match="unsupported operand"):
        controller.act(obs)
    assert controller.solve_exceptions == 0


def test_the_step_says_what_the_solve_raised(monkeypatch):
    from crowdsim.env import CrowdEnv

    monkeypatch.setattr("mpc.solvers._Solver.solve", _raising_solve())
    controller = make_controller(ControllerSpec("cmpc"))
    obs = CrowdEnv().reset(0, "circle", 2)
    controller.reset(obs)
    out = controller.act(obs)
    assert (out.status, out.fallback, out.iterations) == ("exception: RuntimeError", "brake", 0)
    assert out.extra["exception"].startswith("RuntimeError: .../casadi/core/function.cpp:1458")
    assert out.extra["solve_exceptions"] == 1 and out.plan.shape == (3, 4, 2)
    np.testing.assert_allclose(out.accelerations, 0.0)  # braking from rest


def test_the_steps_count_the_solves_that_raised_in_their_own_episode(monkeypatch):
    """Each step's extra["solve_exceptions"] (an episode's recording, /mpc/solver) counted since the
    controller was built: the second episode of a reused controller reported the first's too."""
    from crowdsim.env import CrowdEnv

    monkeypatch.setattr("mpc.solvers._Solver.solve", _raising_solve())
    controller = make_controller(ControllerSpec("cmpc"))
    env = CrowdEnv()
    for _ in range(2):
        obs = env.reset(0, "circle", 2)
        controller.reset(obs)
        counts = [controller.act(obs).extra["solve_exceptions"] for _ in range(2)]
        assert counts == [1, 2]


def test_a_predictor_that_raises_is_not_taken_for_the_solver(monkeypatch):
    from crowdsim.env import CrowdEnv

    controller = make_controller(ControllerSpec("cmpc"))
    obs = CrowdEnv().reset(0, "circle", 2)
    controller.reset(obs)

    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug in the predictor")

    monkeypatch.setattr(controller, "_twin", lambda n_humans, n_robots: None)
    monkeypatch.setattr(controller.model, "rollout", broken)
    with pytest.raises(ZeroDivisionError, match="a bug in the predictor"):
        controller.act(obs)
    assert controller.solve_exceptions == 0


# ----------------------------------------------------------------------------------------------------------
# 6. A sweep's scratch: owned by the driver, removed when it ends, and by the next sweep when it was killed
# ----------------------------------------------------------------------------------------------------------


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_stale_scratch_of_dead_drivers_is_removed(tmp_path):
    dead = tmp_path / f"{SCRATCH_PREFIX}{_dead_pid()}-abc"
    mine = tmp_path / f"{SCRATCH_PREFIX}{os.getpid()}-abc"
    parent = tmp_path / f"{SCRATCH_PREFIX}{os.getppid()}-abc"
    other = tmp_path / "crowdmpc-sweep-notapid"
    for folder in (dead, mine, parent, other):
        (folder / "worker-1-x").mkdir(parents=True)
        (folder / "worker-1-x" / "jit_tmp.c").write_text("int main;\n")
    assert remove_stale_scratch(tmp_path) == [dead]
    assert not dead.exists() and mine.exists() and parent.exists() and other.exists()


def test_a_sweep_removes_its_scratch(tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)  # read TMPDIR again
    argv = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "1"]
    assert (
        main([*argv, "--backend", "inline", "--record", "all", "--no-progress", "--out", str(tmp_path / "o")])
        == 0
    )
    assert list((tmp_path / "tmp").iterdir()) == []


def _sweep(out: Path, tmp: Path, episodes: int, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "pipelines.cli",
        "sweep",
        "--experiment",
        "baselines",
        "--humans",
        "9",
        "--episodes-per-cell",
        str(episodes),
        "--no-progress",
        "--out",
        str(out),
        *extra,
    ]


def _worker_folders(root: Path) -> list[Path]:
    return [p for p in root.iterdir() if p.is_dir()]


def _start_and_signal(
    tmp_path: Path, sig: int, group: bool = False
) -> tuple[subprocess.Popen, str, list[Path]]:
    """A process-pool sweep with its temp directory in ``tmp_path/tmp``, sent ``sig`` once it has recorded
    a few episodes (``group``: its every process, as a closed terminal sends SIGHUP); its stderr (read to
    the end: until the resource tracker, which shares it, is gone too) and the scratch roots its driver
    left."""
    tmp = tmp_path / "tmp"
    tmp.mkdir(exist_ok=True)
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        _sweep(out, tmp, 2000, "--workers", "2", "--backend", "process"),
        cwd=REPO,
        env=os.environ | {"TMPDIR": str(tmp)},
        start_new_session=True,
        # as a shell starts it: a test run in the background (nohup, `make test &`) has SIGHUP ignored, which
        # the sweep keeps ignoring (it is meant to outlive its terminal there)
        preexec_fn=None if sig == signal.SIGKILL else lambda: signal.signal(sig, signal.SIG_DFL),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        log = out / EPISODES_FILE

        def started() -> bool:
            """A few episodes recorded and both workers up (a worker process starts, and makes its folder,
            when the pool first needs it: the first may record its five before the second is up)."""
            roots = list(tmp.glob(SCRATCH_PREFIX + f"{proc.pid}-*"))
            recorded = log.exists() and log.read_bytes().count(b"\n") >= 5
            return recorded and len(roots) == 1 and len(_worker_folders(roots[0])) == 2

        while not started():
            assert proc.poll() is None, proc.stderr.read()
            assert time.monotonic() < deadline, "the sweep made no progress"
            time.sleep(0.02)
        roots = list(tmp.glob(SCRATCH_PREFIX + f"{proc.pid}-*"))
        assert len(roots) == 1 and len(_worker_folders(roots[0])) == 2  # a folder per worker, and the lock
        (os.killpg if group else os.kill)(proc.pid, sig)
        _, err = proc.communicate(timeout=30)
        return proc, err, roots
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)


@pytest.mark.slow
def test_a_killed_sweeps_scratch_is_removed_by_the_next_and_no_semaphore_warning(tmp_path):
    proc, err, roots = _start_and_signal(tmp_path, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    assert "leaked semaphore" not in err and "resource_tracker" not in err, err
    assert roots[0].exists()  # nobody could remove it: the driver was killed
    tmp = tmp_path / "tmp"
    done = subprocess.run(
        _sweep(tmp_path / "next", tmp, 1, "--backend", "inline"),
        cwd=REPO,
        env=os.environ | {"TMPDIR": str(tmp)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert list(tmp.iterdir()) == []  # the killed driver's root, and the next sweep's own


@pytest.mark.slow
def test_a_terminated_sweep_stops_in_order(tmp_path):
    proc, err, roots = _start_and_signal(tmp_path, signal.SIGTERM)
    assert proc.returncode == 143, err  # 128 + 15, as a shell reports it: not Ctrl-C's 130
    assert "interrupted: rerun the same command to resume" in err
    assert "leaked semaphore" not in err and "Traceback" not in err, err
    assert list((tmp_path / "tmp").iterdir()) == []
    records = [json.loads(line) for line in (tmp_path / "killed" / EPISODES_FILE).read_text().splitlines()]
    assert len(records) >= 5


@pytest.mark.slow
def test_a_closed_terminal_stops_a_sweep_in_order(tmp_path):
    """A closed terminal sends SIGHUP to every process of its job: multiprocessing's resource tracker, which
    ignores SIGINT and SIGTERM only, died of it, and the driver's orderly stop warned "resource_tracker:
    process died unexpectedly, relaunching. Some resources might leak." and the tracker it relaunched printed
    a KeyError traceback for each semaphore the pool released."""
    proc, err, roots = _start_and_signal(tmp_path, signal.SIGHUP, group=True)
    assert proc.returncode == 129, err  # 128 + 1
    assert "interrupted: rerun the same command to resume" in err
    assert "resource_tracker" not in err and "Traceback" not in err, err
    assert list((tmp_path / "tmp").iterdir()) == []


@pytest.mark.parametrize("name", ["cmpc", "dmpc"])
def test_ctrl_c_inside_a_solve_stops_instead_of_falling_back(name, monkeypatch):
    """CasADi hands a Ctrl-C raised in a Python callback during a solve (the predictor's) back as a
    SystemError caused by the KeyboardInterrupt; it was taken for a solver failure, braked, recorded as
    "exception: SystemError", and the run went on. It is the interrupt."""
    from crowdsim.env import CrowdEnv

    def interrupted(self, *args, **kwargs):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError(
                "<built-in function _function_buffer_eval> returned a result with an exception set"
            ) from exc

    monkeypatch.setattr("mpc.solvers._Solver.solve", interrupted)
    controller = make_controller(ControllerSpec(name))
    obs = CrowdEnv().reset(0, "circle", 2)
    controller.reset(obs)
    with pytest.raises(KeyboardInterrupt):
        controller.act(obs)
    assert controller.solve_exceptions == 0


def test_interrupt_behind_follows_the_chain_and_nothing_else():
    from pipelines.errors import interrupt_behind

    ctrl_c = KeyboardInterrupt()
    wrapped = SystemError("returned a result with an exception set")
    wrapped.__cause__ = ctrl_c
    outer = RuntimeError("while solving")
    outer.__context__ = wrapped
    assert interrupt_behind(outer) is ctrl_c and interrupt_behind(ctrl_c) is ctrl_c
    loop = RuntimeError("a")
    loop.__context__ = SystemError("b")
    loop.__context__.__context__ = loop  # a cycle ends the walk
    assert interrupt_behind(loop) is None and interrupt_behind(None) is None


def test_ctrl_c_in_simulate_keeps_the_episodes_that_finished(tmp_path, monkeypatch, capsys):
    """Interrupted in its second episode, simulate reports and writes the first (said so in the header and
    the JSON) and ends as interrupted; it used to lose every finished episode."""
    import pipelines.loop.episode as episode

    original = episode.run_episode
    calls = {"n": 0}

    def second_interrupted(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return original(*args, **kwargs)

    monkeypatch.setattr(episode, "run_episode", second_interrupted)
    report = tmp_path / "run.json"
    args = ["simulate", "--controller", "straight", "--humans", "2", "--episodes", "3", "--json", str(report)]
    assert main([*args, "--no-progress"]) == 130
    out, err = capsys.readouterr()
    assert "| interrupted: 1 episodes finished" in out and err.endswith("crowdmpc simulate: interrupted\n")
    payload = json.loads(report.read_text())
    assert (payload["interrupted"], payload["episodes_finished"], len(payload["episodes"])) == (True, 1, 1)
    assert payload["summary"]["episodes"] == 1


@pytest.mark.parametrize("cut_episode", [1, 2])
def test_ctrl_c_in_simulate_says_which_recording_it_cut(cut_episode, tmp_path, monkeypatch, capsys):
    """Ctrl-C in an episode leaves its MCAP file, finished without metrics under a whole episode's name;
    simulate said "wrote 2 MCAP file(s)" for one finished episode, and nothing when it cut the first."""
    from crowdsim.env import CrowdEnv

    resets = {"n": 0}
    original_reset, original_step = CrowdEnv.reset, CrowdEnv.step

    def reset(self, *args, **kwargs):
        resets["n"] += 1
        return original_reset(self, *args, **kwargs)

    def step(self, *args, **kwargs):
        if resets["n"] == cut_episode:
            raise KeyboardInterrupt  # after the episode's first state is recorded
        return original_step(self, *args, **kwargs)

    monkeypatch.setattr(CrowdEnv, "reset", reset)
    monkeypatch.setattr(CrowdEnv, "step", step)
    folder = tmp_path / "rec"
    args = ["simulate", "--controller", "straight", "--humans", "2", "--episodes", "3", "--no-progress"]
    assert main([*args, "--record", str(folder)]) == 130
    out = capsys.readouterr().out
    cut = f"circle_seed{cut_episode - 1:06d}.mcap"
    assert (folder / cut).is_file()
    assert f"wrote {cut_episode} MCAP file(s) to {folder}; {cut}: cut short, no metrics" in out


def test_a_second_controller_does_not_replace_the_firsts_recordings(tmp_path, capsys):
    """File names identify the episode (scenario, seed) and not the run: a rerun of the same command replaces
    its own recordings (`make demo`), another controller's run into the same folder is refused."""
    folder = tmp_path / "runs"
    base = ["simulate", "--humans", "2", "--episodes", "1", "--no-progress", "--record", str(folder)]
    assert main([*base, "--controller", "straight"]) == 0
    first = (folder / "circle_seed000000.mcap").read_bytes()
    assert main([*base, "--controller", "orca"]) == 2
    err = capsys.readouterr().err
    assert "holds another run's episode (controller straight; this run: controller orca)" in err
    assert (folder / "circle_seed000000.mcap").read_bytes() == first
    assert main([*base, "--controller", "straight"]) == 0  # the same run again: replaced
    assert main([*base, "--controller", "straight", "--humans", "3"]) == 2  # another crowd
    assert "n_humans 2; this run: n_humans 3" in capsys.readouterr().err


def test_another_runs_episode_at_a_later_seed_is_refused_before_the_first_episode(tmp_path, capsys):
    """The refusal comes before any episode runs: at the clashing episode it stopped the run there, and the
    summary and --json of the episodes before it were never written."""
    folder, report = tmp_path / "runs", tmp_path / "run.json"
    base = ["simulate", "--humans", "2", "--no-progress", "--record", str(folder)]
    assert main([*base, "--controller", "orca", "--episodes", "1", "--seed", "2"]) == 0
    held = (folder / "circle_seed000002.mcap").read_bytes()
    capsys.readouterr()
    assert main([*base, "--controller", "straight", "--episodes", "3", "--json", str(report)]) == 2
    out, err = capsys.readouterr()
    assert "circle_seed000002.mcap: it holds another run's episode (controller orca" in err
    # the file names the episode it refuses; seed 0, whose start checked the planned files, does not clash
    assert err.startswith("crowdmpc simulate: error: cannot record to ") and "seed 0" not in err
    assert sorted(p.name for p in folder.iterdir()) == ["circle_seed000002.mcap"]  # seeds 0 and 1 never ran
    assert (folder / "circle_seed000002.mcap").read_bytes() == held and not report.exists() and out == ""


def test_json_and_plot_of_one_simulate_are_two_files(tmp_path, capsys):
    same = str(tmp_path / "same.png")
    assert main(["simulate", "--controller", "orca", "--humans", "2", "--json", same, "--plot", same]) == 2
    assert "--json and --plot name the same file" in capsys.readouterr().err
    assert not (tmp_path / "same.png").exists()  # refused before the episode


def _wrapped_interrupt() -> SystemError:
    """What CasADi hands back for a Ctrl-C inside one of its calls."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as ctrl_c:
        wrapped = SystemError("<built-in function> returned a result with an exception set")
        wrapped.__cause__ = ctrl_c
        return wrapped


def test_ctrl_c_inside_casadi_outside_a_solve_ends_the_command_as_interrupted(monkeypatch, capsys):
    """Outside the controller's own catch-all (say in the predictor's encoder before a solve) the wrapped
    interrupt reached the command line as a SystemError traceback, and an inline sweep's worker recorded it
    as a failed episode and went on."""
    from pipelines.experiments.worker import EpisodeWorker

    def interrupted(self, task, controller):
        raise _wrapped_interrupt()

    monkeypatch.setattr(EpisodeWorker, "controller", lambda self, task: None)
    monkeypatch.setattr(EpisodeWorker, "_run", interrupted)
    with pytest.raises(KeyboardInterrupt):
        EpisodeWorker("none").run(None)  # type: ignore[arg-type]

    def simulate_interrupted(args):
        raise _wrapped_interrupt()

    monkeypatch.setattr("pipelines.commands.simulate.run", simulate_interrupted)
    assert main(["simulate", "--controller", "straight", "--humans", "2", "--no-progress"]) == 130
    assert capsys.readouterr().err == "crowdmpc simulate: interrupted\n"


@pytest.mark.parametrize(
    ("argv", "prog"),
    [
        (["review", "runs/x"], "crowdmpc review"),
        (["--plugin", "m:C", "--config=a.toml", "--set", "mpc.w_coll=1e6", "simulate"], "crowdmpc simulate"),
        (["--config", "review", "sweep", "--out", "x"], "crowdmpc sweep"),  # a file named as a command
        (["--conf", "review"], "crowdmpc"),  # argparse's abbreviation of --config, and its value
        (["--help"], "crowdmpc"),
        (["simulte"], "crowdmpc"),  # a typo: no command
        (["--", "zoo"], "crowdmpc"),
    ],
)
def test_ctrl_c_while_the_commands_are_imported_names_the_command_given(monkeypatch, capsys, argv, prog):
    """A Ctrl-C in the first second (the parser's imports) said "crowdmpc: interrupted" where one a moment
    later says "crowdmpc review: interrupted": the command is read off the words given."""

    def importing(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("pipelines.cli.build_parser", importing)
    assert main(argv) == 130
    assert capsys.readouterr().err == f"{prog}: interrupted\n"


def test_ctrl_c_while_the_commands_are_imported_ends_as_interrupted(monkeypatch, capsys):
    """Ctrl-C in the first second or two of any command (`crowdmpc sweep ...` importing scipy, torch and
    CasADi to build its parser) printed a KeyboardInterrupt traceback of some library's import, exit 1."""

    def importing(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("pipelines.cli.build_parser", importing)
    assert main(["sweep", "--experiment", "baselines", "--out", "x"]) == 130
    assert capsys.readouterr().err == "crowdmpc sweep: interrupted\n"

    def extension(*args, **kwargs):  # scipy's _highspy, interrupted as it loads (a probe: once in 8)
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    monkeypatch.setattr("pipelines.cli.build_parser", extension)
    assert main(["sweep", "--experiment", "baselines", "--out", "x"]) == 130
    assert capsys.readouterr().err == "crowdmpc sweep: interrupted\n"

    def broken(*args, **kwargs):  # an import that fails on its own is a bug: its traceback stays
        raise ImportError("no module named x")

    monkeypatch.setattr("pipelines.cli.build_parser", broken)
    with pytest.raises(ImportError, match="no module named x"):
        main(["sweep", "--experiment", "baselines", "--out", "x"])


def test_the_cli_module_imports_no_library_before_main_can_catch_ctrl_c():
    """`crowdmpc ...` imports pipelines.cli before main runs, and main's Ctrl-C handling covers only what
    follows: its top-level imports of the other packages' errors pulled in numpy and gymnasium (a third of
    a second), so a Ctrl-C then printed a KeyboardInterrupt traceback of numpy's import, or numpy's
    "Importing the numpy C-extensions failed" advice with exit 1."""
    probe = (
        "import sys, pipelines.cli\n"
        "libraries = ('numpy', 'gymnasium', 'crowdsim', 'mpc', 'predictors')\n"
        "print(sorted(m for m in libraries if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout == "[]\n"
    from pipelines.cli import USER_ERRORS  # still there for benchmarks/bench_cli.py

    assert PipelineError in USER_ERRORS


def test_a_scratch_root_whose_driver_holds_its_lock_is_kept_whatever_its_pid(tmp_path):
    """A driver on another machine sharing the temp folder has a pid that names no process here: its root is
    kept while its lock is held, and removed once released (a dead driver's)."""
    import fcntl

    from pipelines.experiments.worker import DRIVER_LOCK

    elsewhere = tmp_path / f"{SCRATCH_PREFIX}{_dead_pid()}-node2"
    (elsewhere / "worker-1-x").mkdir(parents=True)
    fd = os.open(elsewhere / DRIVER_LOCK, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # another open file description: flock tells them apart
        assert remove_stale_scratch(tmp_path) == [] and elsewhere.exists()
    finally:
        os.close(fd)
    assert remove_stale_scratch(tmp_path) == [elsewhere] and not elsewhere.exists()


def test_this_drivers_scratch_root_holds_its_lock_until_released(tmp_path, monkeypatch):
    import tempfile

    from pipelines.experiments.worker import DRIVER_LOCK, make_scratch_root, release_scratch_root
    from predictors.locking import unless_held

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    root = make_scratch_root()
    with unless_held(root / DRIVER_LOCK, gone=True) as free:
        assert not free
    release_scratch_root(root)
    assert not root.exists()


@pytest.mark.parametrize("error", [OSError("the codec refused the frame"), io.UnsupportedOperation("read")])
def test_writes_named_passes_an_oserror_without_an_errno_as_it_is(error):
    """writes_named names the output in a write's error that names no file (a full disk): an OSError with
    no errno is no refused write but a bug, and was raised again as "[Errno None] None: 'PATH'", its type
    and message gone (the context suppressed). A full disk's is still named."""

    with pytest.raises(type(error)) as raised, writes_named("/runs/report"):
        raise error
    assert raised.value is error
    with pytest.raises(OSError) as full, writes_named("/runs/report"):
        raise OSError(errno.ENOSPC, "No space left on device")
    assert (full.value.errno, full.value.filename) == (errno.ENOSPC, "/runs/report")
