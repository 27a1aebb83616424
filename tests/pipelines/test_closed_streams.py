"""A command or benchmark started with standard error or output closed (``2>&-``, ``>&-``, as cron and
service managers may start one) runs as it would with them on /dev/null: its progress bar has somewhere to
go, and no file it writes takes the closed descriptor's number, where whatever a C library or child process
writes on that descriptor would land in the file."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.benchmark_modules import BENCHMARKS

ROOT = Path(__file__).resolve().parents[2]
NOISY = "tests.plugins.toy_controller:StderrNoise"


def _run(argv: list[str], cwd: Path, closed: int) -> subprocess.CompletedProcess:
    """``argv`` under this Python with descriptor ``closed`` closed; the other of 1 and 2 captured."""
    env = os.environ | {"PYTHONPATH": str(ROOT), "CROWDMPC_CACHE": str(cwd / "cache")}
    streams = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE}
    streams["stdout" if closed == 1 else "stderr"] = None
    close = lambda: os.close(closed)  # noqa: E731
    return subprocess.run(
        [sys.executable, *argv], cwd=cwd, env=env, text=True, timeout=300, preexec_fn=close, **streams
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["-m", "pipelines.cli", "simulate", "--controller", "orca", "--humans", "2", "--episodes", "2"],
        [str(BENCHMARKS / "orca_contacts.py"), "--humans", "2", "--episodes", "2"],
    ],
    ids=["simulate", "benchmark"],
)
def test_a_progress_bar_with_stderr_closed_runs_to_the_end(argv, tmp_path):
    # the bar wrote on sys.stderr, None when Python starts with descriptor 2 closed: AttributeError, status 1
    done = _run(argv, tmp_path, closed=2)
    assert done.returncode == 0 and "episodes" in done.stdout


@pytest.mark.parametrize("closed", [1, 2])
def test_what_is_written_on_a_closed_descriptor_stays_out_of_the_log(closed, tmp_path):
    # the MCAP log was the first file opened: it took the closed number, and what the controller writes on
    # that descriptor (standing in for a C library's messages) went into it
    run = [
        "-m", "pipelines.cli", "--plugin", NOISY, "simulate", "--controller", NOISY, "--humans", "2",
        "--episodes", "1", "--no-progress", "--record", "rec", "--json", "out.json",
    ]  # fmt: skip
    done = _run(run, tmp_path, closed=closed)
    assert done.returncode == 0
    (log,) = (tmp_path / "rec").glob("*.mcap")
    assert b"C library" not in log.read_bytes() and b"C library" not in (tmp_path / "out.json").read_bytes()
    check = subprocess.run(
        [sys.executable, "-m", "pipelines.cli", "review", str(log), "--check"], cwd=tmp_path,
        env=os.environ | {"PYTHONPATH": str(ROOT)}, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert check.returncode == 0, check.stdout + check.stderr


LIBRARY_RUN = """
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.episode import run_episodes
results = run_episodes(ControllerSpec(controller="orca"), episodes=2, seed=0, scenario="circle", n_humans=2)
print("episodes", len(results))
"""


def test_the_library_draws_no_bar_where_python_has_no_stderr(tmp_path):
    # a program importing crowdmpc (pythonw, a service) holds no descriptor for it: run_episodes'
    # progress bar, then on by default, failed at its first write (AttributeError on None), status 1
    done = _run(["-c", LIBRARY_RUN], tmp_path, closed=2)
    assert done.returncode == 0 and "episodes 2" in done.stdout


@pytest.mark.parametrize("show", [True, None])
def test_a_progress_bar_without_stderr_is_off(show, monkeypatch):
    from predictors.progress import progress_bar

    monkeypatch.setattr(sys, "stderr", None)
    bar = progress_bar(range(3), show=show, desc="x")
    assert list(bar) == [0, 1, 2] and bar.disable


def test_the_library_draws_its_bar_on_a_terminal_only(tmp_path):
    """The README says bars are drawn on a terminal only; run_episodes' default drew one into a pipe (a
    notebook's or a job's log), frame after frame."""
    env = os.environ | {"PYTHONPATH": str(ROOT), "CROWDMPC_CACHE": str(tmp_path / "cache")}
    done = subprocess.run(
        [sys.executable, "-c", LIBRARY_RUN],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0 and "episodes 2" in done.stdout
    assert "orca circle" not in done.stderr and "ep/s" not in done.stderr
