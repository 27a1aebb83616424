"""benchmarks/first_step.py: Fatrop alone is the default solver without the exploration of a step from
braking, restored afterwards; the script prints the three ways on the same seeds."""

import json
import subprocess
import sys
from pathlib import Path

from mpc import solvers
from tests.benchmark_modules import BENCHMARKS, load_benchmark

first_step = load_benchmark("first_step")
ROOT = Path(__file__).resolve().parents[1]


def test_fatrop_alone_never_explores_and_puts_the_solver_back(monkeypatch):
    asked = []

    def recording(self, x0, p, lbx, ubx, lbg, ubg, lam_x0=None, lam_g0=None, explore=False):
        asked.append(explore)
        return "out", {}

    monkeypatch.setattr(solvers._Solver, "solve", recording)
    with first_step.fatrop_alone():
        solvers._Solver.solve(None, 1, 2, 3, 4, 5, 6, None, None, True)
        solvers._Solver.solve(None, 1, 2, 3, 4, 5, 6, explore=True)
    solvers._Solver.solve(None, 1, 2, 3, 4, 5, 6, None, None, True)
    assert asked == [False, False, True]


def test_the_script_runs_the_three_ways_on_the_same_seeds(tmp_path):
    out = tmp_path / "first.json"
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / "first_step.py"), "--predictor", "constant_velocity", "--episodes",
         "1", "--humans", "3", "--json", str(out)],
        capture_output=True, text=True, timeout=300, cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith("CMPC, constant_velocity, 3 humans, circle, paper, seeds 0..0: ")
    assert [line.split()[0] for line in lines[1:]] == list(first_step.MODES)
    report = json.loads(out.read_text())
    assert report["modes"]["default"]["first_step_elsewhere"] == 0  # the default against itself
    assert set(report["modes"]["fatrop_alone"]) == {
        "success_pct",
        "collision_pct",
        "contact_pct",
        "travel_time_s",
        "first_step_elsewhere",
    }
