"""``--json -``: the JSON document alone on standard output, everything else on standard error, for every
command and benchmark script with a ``--json`` option and for a config file's ``json = "-"``; a failed write
on standard output is one line and a non-zero exit.

The commands run as processes (standard output a real descriptor, as in a shell pipe), with the fastest
settings each allows; the benchmarks that take minutes even so run in this process, their measurement
replaced by a fixed one."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from predictors.data.prepare import prepare_ewap
from tests.benchmark_modules import BENCHMARKS, load_benchmark
from tests.predictors.samples import write_tiny_ewap

ROOT = Path(__file__).resolve().parents[2]
QUICK_SIMULATE = ["simulate", "--controller", "straight", "--humans", "0", "--episodes", "1"]


def _run(argv: list[str], cwd: Path, **streams) -> subprocess.CompletedProcess:
    env = os.environ | {"PYTHONPATH": str(ROOT)}
    streams = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE} | streams
    return subprocess.run([sys.executable, *argv], cwd=cwd, env=env, text=True, timeout=300, **streams)


def _only_json(stdout: str) -> object:
    """The document on stdout; json.loads refuses anything before or after it."""
    return json.loads(stdout)


@pytest.fixture(scope="module")
def prepared(tmp_path_factory) -> Path:
    """Tiny prepared scenes: evaluate's cheapest data (the shared data's cache is rebuilt per session)."""
    raw = write_tiny_ewap(tmp_path_factory.mktemp("data") / "raw")
    out = raw.parent / "prepared"
    prepare_ewap(raw, out, categorize_scenes=False, log=lambda msg: None)
    return out


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("rec")
    done = _run(["-m", "pipelines.cli", *QUICK_SIMULATE, "--no-progress", "--record", "r"], folder)
    assert done.returncode == 0, done.stderr
    (path,) = (folder / "r").glob("*.mcap")
    return path


@pytest.mark.parametrize(
    ("argv", "key", "on_stderr"),
    [
        (QUICK_SIMULATE, "summary", "success"),  # the progress bar too: --no-progress not given
        (["--set", "simulate.json=-", *QUICK_SIMULATE[:-2]], "summary", "success"),  # a config's json
        (
            ["evaluate", "--predictor", "constant_velocity", "--no-progress", "--data-dir"],
            "files",
            "protocol",
        ),
        (
            [
                "calibrate",
                "--predictor",
                "constant_velocity",
                "--source",
                "real",
                "--dry-run",
                "--no-progress",
                "--data-dir",
            ],
            "blocks",
            "real calibration",
        ),
    ],
    ids=["simulate", "simulate-config", "evaluate", "calibrate"],
)
def test_a_commands_json_goes_alone_to_stdout(argv, key, on_stderr, prepared, tmp_path):
    argv = [*argv, str(prepared)] if argv[-1] == "--data-dir" else argv
    json_option = [] if "--set" in argv else ["--json", "-"]
    done = _run(["-m", "pipelines.cli", *argv, *json_option], tmp_path)
    assert done.returncode == 0, done.stderr
    assert key in _only_json(done.stdout)
    assert on_stderr in done.stderr  # the table and notes moved, not lost
    assert list(tmp_path.iterdir()) == []  # no file named "-"


def test_review_json_goes_alone_to_stdout(recording, tmp_path):
    done = _run(["-m", "pipelines.cli", "review", str(recording), "--json", "-"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "summary" in _only_json(done.stdout)
    assert done.stderr.strip()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("argv", "field"),
    [([*QUICK_SIMULATE, "--no-progress"], "summary"), (["cache", "info"], "directory")],
    ids=["simulate", "cache-info"],
)
def test_a_path_to_a_file_named_dash_still_writes_that_file(argv, field, tmp_path):
    done = _run(["-m", "pipelines.cli", *argv, "--json", "./-"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert field in json.loads((tmp_path / "-").read_text())
    assert done.stdout.splitlines()[-1] == "wrote ./-"  # not "wrote -", which reads as standard output


# A command and a benchmark script, with the prefix of their one-line errors.
ONE_LINE_RUNS = pytest.mark.parametrize(
    ("argv", "prefix"),
    [
        (["-m", "pipelines.cli", *QUICK_SIMULATE, "--no-progress"], "crowdmpc simulate: error: "),
        (
            [str(BENCHMARKS / "cost_scale.py"), "--robots", "1", "--humans", "0", "--episodes", "1"],
            "cost_scale.py: error: ",
        ),
    ],
    ids=["simulate", "benchmark"],
)


@ONE_LINE_RUNS
def test_a_failed_write_on_stdout_is_one_line(argv, prefix, tmp_path):
    with open("/dev/full", "w", encoding="utf-8") as full:
        done = _run([*argv, "--json", "-"], tmp_path, stdout=full, stderr=subprocess.PIPE)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr
    assert done.stderr.splitlines()[-1] == (
        f"{prefix}--json -: could not write to standard output (No space left on device)"
    )


@ONE_LINE_RUNS
def test_json_on_a_closed_stdout_is_one_line(argv, prefix, tmp_path):
    # `>&-`: Python starts with sys.stdout None, which the diversion and the final flush took for a stream
    done = _run([*argv, "--json", "-"], tmp_path, stdout=None, preexec_fn=lambda: os.close(1))
    assert done.returncode == 2
    assert done.stderr.splitlines() == [f"{prefix}--json -: standard output is closed; name a file instead"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("json_args", [["--json", "-"], ["--json"]], ids=["dash", "bare"])
def test_cache_info_json_on_a_closed_stdout_is_one_line(json_args, monkeypatch, tmp_path):
    # cache info writes its document without json_on_stdout, whose check for sys.stdout None it never met:
    # write_document wrote to None, an AttributeError traceback and status 1
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "cache"))
    argv = ["-m", "pipelines.cli", "cache", "info", *json_args]
    done = _run(argv, tmp_path, stdout=None, preexec_fn=lambda: os.close(1))
    assert done.returncode == 2
    message = "crowdmpc cache info: error: --json -: standard output is closed; name a file instead"
    assert done.stderr.splitlines() == [message]


@pytest.mark.parametrize(
    "argv",
    [
        ["cost_scale.py", "--robots", "1", "--humans", "0", "--episodes", "1", "--cost-scale", "1"],
        ["control_step.py", "--humans", "0", "--episodes", "1"],
        ["robot_scaling.py", "--robots", "1", "--humans", "0", "--episodes", "1", "--controllers", "cmpc"],
        ["dmpc_scaling.py", "--robots", "1", "--humans", "0", "--episodes", "1", "--parallel", "serial"],
        ["exact_coupling.py", "--humans", "1", "--episodes", "1", "--max-iter", "1"],
        ["review_memory.py", "--files", "1", "--episodes", "1", "--humans", "0"],
        ["sweep_log_scale.py", "--experiment", "baselines", "--humans", "3", "--episodes", "2"],
        ["run_all.py", "--quick", "--sections", "simulator"],
        # these two printed their table on stdout before the JSON
        ["first_step.py", "--predictor", "constant_velocity", "--episodes", "1", "--humans", "1"],
        [
            "replay_coverage.py",
            *("--predictor", "constant_velocity", "--crowds", "orca", "--episodes", "1", "--humans", "1"),
        ],
    ],
    ids=lambda argv: argv[0],
)
def test_a_benchmarks_json_goes_alone_to_stdout(argv, tmp_path):
    done = _run([str(BENCHMARKS / argv[0]), *argv[1:], "--json", "-"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert isinstance(_only_json(done.stdout), dict)
    assert done.stderr.strip()  # the table
    assert list(tmp_path.iterdir()) == []


def _fake_sweep(out, jit, episodes, predictors, env):
    print(f"sweep {jit}")  # what a real one's progress would print: it must not reach stdout
    return {
        "wall_s": 1.0,
        "episodes": 1,
        "episode_cpu_s": 1.0,
        "load_before": (0.0, 0.0, 0.0),
        "load_after": (0.0, 0.0, 0.0),
        "metrics": {},
    }


def _fake_replay(nlp, cfg, problems):
    return {
        "ms_per_solve": 1.0,
        "iterations_mean": 1.0,
        "failures": 0,
        "ipopt_retries": None,
        "build_s": 0.0,
        "costs": [1.0],
    }


@pytest.mark.parametrize(
    ("script", "fakes"),
    [
        ("sweep_floor", {"measure": lambda n: [{"cell": "c", "wall_s": 1.0, "solve": 0.5}]}),
        (
            "solvers",
            {
                "record_problems": lambda *a: {"local": [], "joint": []},
                "nlp_of": lambda *a: {},
                "replay": _fake_replay,
            },
        ),
        ("compile_cache", {"run_sweep": _fake_sweep}),
    ],
)
def test_a_long_benchmarks_json_goes_alone_to_stdout(script, fakes, capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    module = load_benchmark(script)
    for name, fake in fakes.items():
        monkeypatch.setattr(module, name, fake)
    if module.main.__code__.co_argcount:
        assert module.main(["--json", "-"]) == 0
    else:  # compile_cache reads sys.argv
        monkeypatch.setattr(sys, "argv", [f"{script}.py", "--payback-episodes", "0", "--json", "-"])
        assert module.main() == 0
    out, err = capsys.readouterr()
    assert isinstance(_only_json(out), dict)
    assert err.strip()
    assert list(tmp_path.iterdir()) == []
