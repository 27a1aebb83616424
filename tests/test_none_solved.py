"""benchmarks/exact_coupling.py and cost_scale.py: a figure that nothing measured is said in words or printed
as bench_cli.figure's dash, never as "nan"."""

import math

from tests.benchmark_modules import load_benchmark


def test_exact_coupling_with_no_exact_solve_solved_says_so(capsys, monkeypatch):
    """--episodes 1 --humans 1 --max-iter 1: every exact solve stops at its iteration limit, and the gains
    printed as "median nan, max nan"."""
    exact_coupling = load_benchmark("exact_coupling")
    row = {
        "predictor": "p",
        "humans": 1,
        "episodes": 1,
        "first_order_success_rate": 100.0,
        "first_order_collision_rate": 0.0,
        "exact_max_iter": 1,
        "steps": 38,
        "statuses": {"Maximum_Iterations_Exceeded": 38},
        "exact_solver": "ipopt",  # a network's: IPOPT alone
        "returned_by": {"ipopt": 38},
        "exact_iterations_median": 1.0,
        "exact_iterations_p90": 1.0,
        "exact_ms_median": 3.0,
        "exact_ms_p95": 4.0,
        "F_gain_median": math.nan,
        "F_gain_max": math.nan,
    }
    monkeypatch.setattr(exact_coupling, "measure", lambda *args: dict(row))
    assert exact_coupling.main(["--episodes", "1", "--humans", "1", "--max-iter", "1"]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out
    assert "solved steps: none solved (the exact solve succeeded on none of the 38 steps)" in out
    assert "(38 steps, max_iter 1, IPOPT):" in out and "  IPOPT iterations median 1.0, p90 1.0;" in out
    no_steps = row | {"steps": 0, "statuses": {}, "returned_by": {}}
    no_steps |= {k: math.nan for k in row if k.startswith("exact_") and k != "exact_solver"}
    monkeypatch.setattr(exact_coupling, "measure", lambda *args: dict(no_steps))
    assert exact_coupling.main(["--episodes", "1"]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out and "none solved: the first-order solve never succeeded" in out


def test_cost_scale_with_no_fatrop_solve_prints_dashes_and_says_why(tmp_path, capsys, monkeypatch):
    """A config with solver = "ipopt" makes no Fatrop solve: "it med nan, it p90 nan"."""
    cost_scale = load_benchmark("cost_scale")
    config = tmp_path / "ipopt.toml"
    config.write_text('[mpc]\nsolver = "ipopt"\n')

    def measure(run, n_robots, n_humans, episodes, predictor):
        return {
            "cost_scale": run.mpc.cost_scale,
            "robots": n_robots,
            "fatrop_solves": 0,
            "fatrop_failed": 0,
            "iterations_median": math.nan,
            "iterations_p90": math.nan,
            "step_median_ms": 1.2,
            "step_p95_ms": 2.3,
            "step_p99_ms": 2.8,
            "success_rate": 100.0,
        }

    monkeypatch.setattr(cost_scale, "measure", measure)
    assert cost_scale.main(["--config", str(config), "--robots", "1", "--cost-scale", "1"]) == 0
    out = capsys.readouterr().out
    assert "nan" not in out
    assert "  1      1      0      0      -      -      -     1.2     2.3     2.8  100.0" in out.splitlines()
    assert "-: none solved by Fatrop in that row" in out
