"""benchmarks/bench_cli.py: what a user types into a benchmark is checked when parsed, a user's error ends a
script in one line, and --json files land where asked."""

import argparse
import json
import math
import sys

import numpy as np
import pytest

from tests.benchmark_modules import BENCHMARKS, load_benchmark

bench_cli = load_benchmark("bench_cli")


def test_counts_take_their_range_and_name_themselves():
    assert [bench_cli.robot_count(t) for t in ("1", "12")] == [1, 12]
    assert [bench_cli.human_count(t) for t in ("0", "50")] == [0, 50]
    for bad in ("0", "13", "-1", "3.5", "x"):
        with pytest.raises(
            argparse.ArgumentTypeError, match=rf"robots must be an integer in 1\.\.12, got '{bad}'"
        ):
            bench_cli.robot_count(bad)
    with pytest.raises(argparse.ArgumentTypeError, match="humans must be an integer in 0..50, got '51'"):
        bench_cli.human_count("51")
    assert bench_cli.episode_count("100000") == 100_000  # no upper bound
    for count, bad, message in (
        (bench_cli.episode_count, "0", r"episodes must be an integer >= 1, got '0'"),
        (bench_cli.seed_number, "-1", r"seed must be an integer >= 0, got '-1'"),
        (bench_cli.count_in("calls", 1), "2.5", r"calls must be an integer >= 1, got '2\.5'"),
    ):
        with pytest.raises(argparse.ArgumentTypeError, match=message):
            count(bad)


def test_the_episode_bar_counts_the_episodes_on_stderr_only(capsys):
    assert list(bench_cli.episode_bar(3, "cmpc M=3")) == [0, 1, 2]
    out, err = capsys.readouterr()
    assert out == ""  # stdout holds the figures alone
    assert "cmpc M=3:   0%" in err and "0/3 [" in err  # tqdm redraws at most every 0.1 s
    assert err.endswith("\r")  # and clears its line at the end, before the table is printed


# Every script's repeat count: zero ended in a division by zero, an empty reduction or a table of nan.
ZERO_REPEATS = [
    *[
        (script, ["--episodes", "0"], "argument --episodes: episodes must be an integer >= 1, got '0'")
        for script in (
            "control_step",
            "cost_scale",
            "dmpc_scaling",
            "exact_coupling",
            "ibr_solves",
            "orca_contacts",
            "orca_step",
            "recording_overhead",
            "replay_contacts",
            "robot_scaling",
            "solvers",
        )
    ],
    ("robot_scaling", ["--seed", "-1"], "argument --seed: seed must be an integer >= 0"),
    ("orca_contacts", ["--seed", "-1"], "argument --seed: seed must be an integer >= 0"),
    ("dmpc_scaling", ["--replay-reps", "0"], "replay reps must be an integer >= 1"),
    ("exact_coupling", ["--max-iter", "0"], "max iter must be an integer >= 1"),
    ("orca_step", ["--repeats", "0"], "repeats must be an integer >= 1"),
    ("export", ["--calls", "0"], "calls must be an integer >= 1"),
    # no human: an empty twin (a division by zero scalars, an IndexError in the parity check)
    ("export", ["--humans", "0", "--models", "nosuch"], "humans must be an integer in 1..50, got '0'"),
    (
        "predictor_floor",
        ["--humans", "0", "--calls", "1", "--horizon", "1"],
        "humans must be an integer in 1..50, got '0'",
    ),
    ("predictor_floor", ["--horizon", "0"], "horizon must be an integer >= 1"),
    ("run_all", ["--steps", "0"], "steps must be an integer >= 1"),
    ("batching", ["--epochs", "0"], "argument --epochs: epochs must be an integer >= 1, got '0'"),
    ("run_all", ["--workers", "0"], "workers must be an integer >= 1"),
    ("compile_cache", ["--payback-episodes", "-1"], "payback episodes must be an integer >= 0"),
    ("sweep_kills", ["--episodes-per-cell", "0"], "episodes per cell must be an integer >= 1"),
    # an experiment the sweep does not know ended in a FileNotFoundError about sweep.json
    (
        "sweep_kills",
        ["--experiment", "nope", "--kills", "0"],
        "argument --experiment: invalid choice: 'nope'",
    ),
    (
        "sweep_kills",
        ["--experiment", "predictors", "--predictor", "constant_velocity", "--kills", "0"],
        "experiment 'predictors' has no predictor to replace",
    ),  # fmt: skip
    # a name the sweep does not know failed only in the first sweep, exit 1
    ("compile_cache", ["--predictors", "nope"], "argument --predictors: unknown predictor 'nope'"),
    ("compile_cache", ["--predictors", "constant_velocity, constant_velocity"], "named more than once"),
]


def test_a_reader_that_left_ends_a_benchmark_quietly(monkeypatch):
    """`benchmarks/X.py | head` ended in a BrokenPipeError traceback; crowdmpc's commands end quietly, with
    the status of a SIGPIPE, and so do the benchmarks. Another pipe's error is a real one."""
    import pipelines.commands as commands

    def prints_to_a_closed_pipe() -> int:
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(commands, "quit_closed_stdout", lambda: commands.CLOSED_PIPE_STATUS)
    monkeypatch.setattr(commands, "stdout_reader_left", lambda: True)
    assert bench_cli.run_main(prints_to_a_closed_pipe) == commands.CLOSED_PIPE_STATUS
    monkeypatch.setattr(commands, "stdout_reader_left", lambda: False)  # a worker's pipe, say
    with pytest.raises(BrokenPipeError):
        bench_cli.run_main(prints_to_a_closed_pipe)


@pytest.mark.parametrize(
    ("script", "argv", "message"), ZERO_REPEATS, ids=[f"{s} {' '.join(a)}" for s, a, _ in ZERO_REPEATS]
)
def test_a_count_that_measures_nothing_is_refused_when_parsed(
    script, argv, message, capsys, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *argv])  # the scripts whose main() reads sys.argv
    module = load_benchmark(script)
    with pytest.raises(SystemExit) as stop:
        module.main(argv) if module.main.__code__.co_argcount else module.main()
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_predictor_is_checked_against_the_registry_and_the_zoo():
    assert bench_cli.predictor_name("constant_velocity") == "constant_velocity"
    assert bench_cli.predictor_name("social_lstm_eth") == "social_lstm_eth"  # a shipped zoo entry
    with pytest.raises(
        argparse.ArgumentTypeError, match="unknown predictor 'nosuch'; choose from .*constant_velocity"
    ):
        bench_cli.predictor_name("nosuch")


def test_an_output_file_may_not_be_a_folder_and_its_folder_is_created(tmp_path):
    with pytest.raises(argparse.ArgumentTypeError, match="is a folder; expected the path of a file"):
        bench_cli.output_file(str(tmp_path))
    path = bench_cli.output_file(str(tmp_path / "new" / "deeper" / "out.json"))
    bench_cli.write_json(path, {"path": path, "x": (1.5, float("nan"), -math.inf), "n": np.int64(3)})
    # strict JSON: a figure not measured is null, not NaN
    assert json.loads(path.read_text()) == {"path": str(path), "x": [1.5, None, None], "n": 3}
    assert path.read_text().endswith("\n")
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    with pytest.raises(
        argparse.ArgumentTypeError, match=f"file {blocker / 'x.json'}: {blocker} is not a directory"
    ):
        bench_cli.output_file(str(blocker / "x.json"))
    with pytest.raises(TypeError, match="set is not JSON serializable"):
        bench_cli.write_json(tmp_path / "bad.json", {"x": {1}})


def test_a_json_report_replaces_only_a_json_report(tmp_path):
    """As ``crowdmpc simulate --json``: a mistyped --json naming a data file or a config refused it, not
    replaced it after the run."""
    data = tmp_path / "episodes.csv"
    data.write_text("a,b\n1,2\n")
    with pytest.raises(argparse.ArgumentTypeError, match="the file exists and is not a JSON report"):
        bench_cli.output_file(str(data))
    assert data.read_text() == "a,b\n1,2\n"
    report = tmp_path / "old.json"
    report.write_text('{"rows": []}')
    assert bench_cli.output_file(str(report)) == report  # an earlier report is replaced


@pytest.mark.parametrize(("script", "measure"), [("robot_scaling", "run_row"), ("cost_scale", "measure")])
def test_a_json_report_is_none_of_the_scripts_inputs(script, measure, capsys, tmp_path, monkeypatch):
    config = tmp_path / "empty.toml"  # empty: a file a JSON report may replace, were it not the input
    config.write_text("")
    module = load_benchmark(script)

    def no_episodes(*args, **kwargs):
        raise AssertionError("an episode ran; the command line should have been refused")

    monkeypatch.setattr(module, measure, no_episodes)
    with pytest.raises(SystemExit) as stop:
        module.main(["--config", str(config), "--json", str(config)])
    assert stop.value.code == 2
    assert "that is one of the command's inputs" in capsys.readouterr().err
    assert config.read_text() == ""


def test_a_figure_not_measured_prints_as_a_dash_of_the_same_width():
    assert bench_cli.figure(1.5, "8.2f") == "    1.50"
    assert bench_cli.figure(math.nan, "8.2f") == "       -"
    assert bench_cli.figure(3e-5, "10.1e") == "   3.0e-05"
    assert bench_cli.figure(math.nan, "10.1e") == " " * 9 + "-"


def test_mpc_items_become_set_items_and_a_malformed_one_is_named_as_typed():
    assert bench_cli.mpc_sets(["cost_scale=0.01", "w_floc = 2"]) == ["mpc.cost_scale=0.01", "mpc.w_floc = 2"]
    for bad in ("cost_scale", "=3", "mpc.cost_scale=1"):
        with pytest.raises(
            bench_cli.ConfigError, match=f"--mpc '{bad}': expected KEY=VALUE of the \\[mpc\\]"
        ):
            bench_cli.mpc_sets([bad])


def test_run_main_ends_a_users_error_in_one_line_and_keeps_a_bugs_traceback(capsys):
    from pipelines.errors import PipelineError

    def users_error() -> int:
        raise PipelineError("--config x.toml: no such file")

    assert bench_cli.run_main(users_error) == 2
    assert capsys.readouterr().err.strip().endswith("error: --config x.toml: no such file")
    assert bench_cli.run_main(lambda: None) == 0
    assert bench_cli.run_main(lambda: 3) == 3

    def bug() -> int:
        raise KeyError("a bug")

    with pytest.raises(KeyError):
        bench_cli.run_main(bug)


@pytest.mark.parametrize(
    ("script", "argv", "message"),
    [
        ("robot_scaling", ["--robots", "3", "13"], "argument --robots: robots must be an integer in 1..12"),
        ("robot_scaling", ["--mpc", "cost_scale"], "--mpc 'cost_scale': expected KEY=VALUE"),
        ("dmpc_scaling", ["--robots", "0"], "argument --robots: robots must be an integer in 1..12"),
        ("cost_scale", ["--config", "nope.toml"], "--config nope.toml: no such file"),
        ("cost_scale", ["--cost-scale", "-1"], "cost_scale: must be > 0"),
        ("control_step", ["--predictor", "nosuch"], "unknown predictor 'nosuch'"),
        ("control_step", ["--no-ibr"], "nothing to measure"),
        # it measured nothing without 7 humans, and said nothing
        ("control_step", ["--humans", "1", "--dmpc-parallel"], "--dmpc-parallel runs at 7 humans: add 7"),
        ("run_all", ["--sweep-episodes", "1"], "--sweep-episodes must be >= 2"),
        # a repeat ran twice and printed twice, and the JSON keyed by it kept one (6 rows printed, 3 written)
        ("control_step", ["--humans", "0", "0", "--episodes", "1"], "--humans names 0 more than once"),
        (
            "dmpc_scaling",
            ["--robots", "1", "1", "--humans", "0", "--episodes", "1", "--parallel", "serial"],
            "--robots names 1 more than once",
        ),
        (
            "dmpc_scaling",
            ["--robots", "1", "--humans", "0", "--episodes", "1", "--parallel", "serial", "serial"],
            "--parallel names serial more than once",
        ),
        # no row is lost there (rows are lists), but the repeat ran and printed twice
        (
            "robot_scaling",
            ["--robots", "1", "1", "--humans", "0", "--episodes", "1"],
            "--robots names 1 more",
        ),
        (
            "cost_scale",
            ["--cost-scale", "1", "1", "--episodes", "1"],
            "--cost-scale names 1.0 more than once",
        ),
        ("cost_scale", ["--robots", "1", "1", "--episodes", "1"], "--robots names 1 more than once"),
        ("orca_step", ["--humans", "0", "0", "--episodes", "1"], "--humans names 0 more than once"),
        ("pooling", ["--agents", "2", "2", "--repeats", "1"], "--agents names 2 more than once"),
        # a user error, as crowdmpc's: exit 2 (it was 1)
        ("predictor_floor", ["--model", "constant_velocity"], "not a learned predictor"),
    ],
)
def test_a_bad_command_line_stops_before_any_episode(script, argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a missing --config is looked up here, and nothing may be written
    with pytest.raises(SystemExit) as stop:
        load_benchmark(script).main(argv)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


class _Parsed(Exception):
    """Raised right after a script's command line is parsed: the example's options exist, nothing runs."""


def _help_examples() -> list[tuple[str, list[str]]]:
    """Every ``.venv/bin/python benchmarks/NAME.py ...`` line of every script's docstring (its --help), as
    (NAME, argv), continuation lines joined and trailing comments dropped."""
    import ast
    import re
    import shlex

    pattern = re.compile(r"^\s+(?:nice -n \d+ )?\.venv/bin/python benchmarks/(\w+)\.py(.*)$")
    examples = []
    for path in sorted(BENCHMARKS.glob("*.py")):
        doc = (ast.get_docstring(ast.parse(path.read_text())) or "").replace("\\\n", " ")
        for line in doc.splitlines():
            match = pattern.match(line)
            if match and match.group(1) == path.stem:
                examples.append((path.stem, shlex.split(match.group(2), comments=True)))
    return examples


HELP_EXAMPLES = _help_examples()


def test_every_benchmark_with_a_main_has_help_examples():
    scripts = {p.stem for p in BENCHMARKS.glob("*.py")} - {"bench_cli", "run_all_table", "dmpc_scaling_table"}
    assert {name for name, _ in HELP_EXAMPLES} == scripts


def test_no_help_example_lost_its_line_break():
    """In a docstring that is not raw, ``\\`` at a line's end joins the lines, leaving a run of spaces before
    the next option in --help (robot_scaling's examples printed so)."""
    import ast
    import re

    for path in sorted(BENCHMARKS.glob("*.py")):
        for line in (ast.get_docstring(ast.parse(path.read_text())) or "").splitlines():
            if "benchmarks/" in line and ".venv/bin/python" in line:
                assert not re.search(r"\S {4,}--", line), (
                    f"{path.name}: a swallowed line break in {line.strip()}"
                )


@pytest.mark.parametrize(("script", "argv"), HELP_EXAMPLES, ids=[" ".join([s, *a]) for s, a in HELP_EXAMPLES])
def test_every_help_example_parses_as_printed(script, argv, tmp_path, monkeypatch):
    """An example's options are the script's (a flag renamed, or a value argparse reads as an option, as
    ``--opt -O1`` was, fails here); the script stops right after parsing."""
    parse = argparse.ArgumentParser.parse_args

    def parse_then_stop(self, args=None, namespace=None):
        parse(self, args, namespace)
        raise _Parsed

    monkeypatch.chdir(tmp_path)  # an example's output file is checked writable here
    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse_then_stop)
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *argv])
    module = load_benchmark(script)
    with pytest.raises(_Parsed):
        module.main(argv) if module.main.__code__.co_argcount else module.main()


def test_sweep_kills_reports_the_sweeps_own_error(capsys, monkeypatch):
    """A sweep that failed before writing sweep.json was reported as FileNotFoundError for sweep.json."""
    import subprocess

    sweep_kills = load_benchmark("sweep_kills")

    def failed(cmd, **kwargs):
        return subprocess.CompletedProcess(cmd, 2, "", "crowdmpc sweep: error: the reason the sweep gave\n")

    monkeypatch.setattr(sweep_kills.subprocess, "run", failed)
    monkeypatch.setattr(sys, "argv", ["sweep_kills.py", "--kills", "0"])
    assert bench_cli.run_main(sweep_kills.main) == 2
    err = capsys.readouterr().err
    assert "the final sweep exited 2:\ncrowdmpc sweep: error: the reason the sweep gave" in err
    assert "error: the sweep failed (exit 2) before it planned a run" in err


def test_sweep_kills_counts_only_its_own_sweeps_scratch(capsys, monkeypatch, tmp_path):
    """Another crowdmpc sweep running meanwhile (a test suite beside it) made a scratch folder in the system's
    temp directory, which was counted as left behind by the killed sweeps: exit 1 on a sweep that was fine.
    The sweeps now run with a temp directory of their own, and a folder left there still counts."""
    import subprocess
    import tempfile
    from pathlib import Path

    sweep_kills = load_benchmark("sweep_kills")
    system_temp = tmp_path / "system"
    system_temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system_temp))

    def finished(cmd, leave: bool, **kwargs):
        (system_temp / "crowdmpc-sweep-1-another").mkdir()  # someone else's sweep, still running
        if leave:
            (Path(kwargs["env"]["TMPDIR"]) / "crowdmpc-sweep-2-ours").mkdir()
        out = Path(cmd[cmd.index("--out") + 1])
        out.mkdir()
        (out / "sweep.json").write_text(json.dumps({"runs": [{"planned": 1}]}), encoding="utf-8")
        (out / "episodes.jsonl").write_text(json.dumps({"key": "a"}) + "\n", encoding="utf-8")
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr(sys, "argv", ["sweep_kills.py", "--kills", "0"])
    monkeypatch.setattr(sweep_kills.subprocess, "run", lambda cmd, **kw: finished(cmd, False, **kw))
    assert bench_cli.run_main(sweep_kills.main) == 0
    assert "scratch folders left in the sweeps' temp directory: 0 []" in capsys.readouterr().out
    (system_temp / "crowdmpc-sweep-1-another").rmdir()
    monkeypatch.setattr(sweep_kills.subprocess, "run", lambda cmd, **kw: finished(cmd, True, **kw))
    assert bench_cli.run_main(sweep_kills.main) == 1
    assert "temp directory: 1 ['crowdmpc-sweep-2-ours']" in capsys.readouterr().out


def test_run_all_scaling_rows_say_how_many_steps_they_timed():
    """The humans' rows time whole episodes and the robots' their first --steps steps from rest: without the
    count, 46.8 ms over 2 steps stood beside 3.8 ms over 38 as one measurement."""
    table = load_benchmark("run_all_table")
    stats = {"median_ms": 3.81, "p95_ms": 9.0, "steps": 38}
    lines = table._step_rows({"scaling": {"cmpc_h5_r3": stats, "cmpc_h7_r6": {**stats, "steps": 2}}})
    assert lines[0].startswith("| control step cmpc_h5_r3 (38 steps) | 3.81 |")
    assert lines[1].startswith("| control step cmpc_h7_r6 (2 steps) |")


def test_run_all_control_rows_say_how_many_steps_they_timed():
    """The oracle's row (and the baselines') times the first --steps steps of each episode from rest, the
    other predictors' rows whole episodes: 59.7 ms over 16 steps stood beside 48.0 ms over 50 as one
    measurement, the oracle seemingly the dearest predictor."""
    table = load_benchmark("run_all_table")
    whole = {"median_ms": 48.02, "p95_ms": 97.9, "steps": 50, "iterations_mean": 2.34}
    first = {**whole, "median_ms": 59.73, "steps": 16}
    control = {"cmpc/social_lstm_eth": whole, "cmpc/orca_oracle": first, "dmpc": None}
    lines = table._step_rows({"control_step": control})
    assert lines[0].startswith("| control step cmpc/social_lstm_eth (7 humans, 50 steps) | 48.02 |")
    assert lines[1].startswith("| control step cmpc/orca_oracle (7 humans, 16 steps) | 59.73 |")
    assert lines[2] == "| control step dmpc (7 humans) | failed | | |"


# Each benchmark's file arguments, missing: each refused in one line before torch and Lightning are imported
BAD_FILES = [
    ("batching", ["--train", "nope.ndjson"], "--train file nope.ndjson does not exist"),
    ("batching", ["--train", "."], "--train . is not a data file (a directory or a device)"),
    ("batching", ["--data-dir", "nope"], "--data-dir nope is not a directory"),
    ("cost_scale", ["--config", "nope.toml"], "--config nope.toml: no such file"),
    ("robot_scaling", ["--config", "nope.toml"], "--config nope.toml: no such file"),
    ("robot_swaps", ["--config", "nope.toml"], "--config nope.toml: no such file"),
    ("sensor_range", ["--config", "nope.toml"], "--config nope.toml: no such file"),
    (
        "plot_scaling",
        ["nope.json", "--out", "x.png"],
        "runs: nope.json does not exist; expected a robot_scaling.py --json file",
    ),
]

_REFUSE_ALL = """
import contextlib, io, json, sys
from tests.benchmark_modules import load_benchmark
sys.path.insert(0, sys.argv[1])
from bench_cli import run_main
answers = []
for script, argv in json.loads(sys.argv[2]):
    module = load_benchmark(script)
    err = io.StringIO()
    sys.argv = [script + ".py", *argv]  # the scripts whose main() reads them there
    takes_argv = module.main.__code__.co_argcount > 0
    with contextlib.redirect_stderr(err):
        try:
            status = run_main(lambda: module.main(argv) if takes_argv else module.main())
        except SystemExit as stop:
            status = stop.code
    heavy = sorted(m for m in ("torch", "lightning") if m in sys.modules)
    answers.append([script, status, err.getvalue(), heavy])
print(json.dumps(answers))
"""


def _refused_before_torch(cases: list[tuple[str, list[str], str]], folder) -> None:
    """Each script and command line of ``cases`` run in one fresh process, in turn, in ``folder``: refused in
    one line ending in its message, exit 2, torch and Lightning not imported after it, nothing written."""
    import os
    import subprocess

    from tests.benchmark_modules import BENCHMARKS

    argvs = json.dumps([[script, argv] for script, argv, _ in cases])
    env = os.environ | {"PYTHONPATH": str(BENCHMARKS.parent)}
    done = subprocess.run(
        [sys.executable, "-c", _REFUSE_ALL, str(BENCHMARKS), argvs],
        cwd=folder, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    for (script, status, err, heavy), (_, argv, message) in zip(json.loads(done.stdout), cases, strict=True):
        assert (status, heavy) == (2, []), (script, argv, err)
        # the error's one line (after argparse's usage, where the parser refused it)
        last = err.splitlines()[-1]
        assert last.endswith(message) and "error: " in last and "Traceback" not in err, (script, argv, err)
    assert list(folder.iterdir()) == []


def test_a_missing_file_argument_is_refused_before_torch_is_imported(tmp_path):
    """batching.py --train nope.ndjson was refused by the data module, after torch and Lightning had been
    imported: a minute on a cold machine for a mistyped name. Each script runs in one fresh process, in turn,
    and the heavy libraries are looked for after each refusal."""
    _refused_before_torch(BAD_FILES, tmp_path)


def test_batchings_protocol_options_with_train_files_are_refused_as_crowdmpc_train_refuses_them(tmp_path):
    """batching.py --train F --protocol loo (or --dataset, --data-dir) trained on F alone, the options ignored
    without a word, where `crowdmpc train` refuses them; now in its words, before torch is imported."""
    replace = "(explicit files replace the prepared files of --protocol, --dataset and --data-dir); give one "
    replace += "or the other"
    train = ["--train", "nope.ndjson"]  # refused for the options before the file is looked for
    _refused_before_torch(
        [
            ("batching", [*train, "--protocol", "loo"], f"--protocol does not go with --train {replace}"),
            ("batching", [*train, "--dataset", "biwi_eth"], f"--dataset does not go with --train {replace}"),
            (
                "batching",
                ["--data-dir", ".", *train, "--protocol", "paper"],
                f"--protocol and --data-dir do not go with --train {replace}",
            ),
        ],
        tmp_path,
    )
