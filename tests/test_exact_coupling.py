"""benchmarks/exact_coupling.py: its iterations are those of the solvers that ran, and it says which ran."""

import json

from tests.benchmark_modules import load_benchmark


def test_an_expanded_predictors_exact_solve_counts_fatrop_and_ipopt_and_says_so(tmp_path, capsys):
    """Constant velocity expands into the NLP, which Fatrop solves first and IPOPT after a failure: at
    --max-iter 1 every solve ran both, and the 3 iterations added up were printed as "IPOPT iterations"
    (docs/outputs.md said IPOPT's), one solver's limit being 1."""
    exact_coupling = load_benchmark("exact_coupling")
    out = tmp_path / "exact.json"
    argv = ["--predictor", "constant_velocity", "--humans", "1", "--episodes", "1", "--max-iter", "1"]
    assert exact_coupling.main([*argv, "--json", str(out)]) == 0
    row = json.loads(out.read_text())
    steps = row["steps"]
    assert steps > 0 and row["statuses"] == {"Maximum_Iterations_Exceeded": steps}
    assert row["exact_solver"] == "fatrop" and row["returned_by"] == {"ipopt": steps}
    assert row["exact_iterations_median"] > row["exact_max_iter"]  # both solvers' iterations
    printed = capsys.readouterr().out
    assert f"({steps} steps, max_iter 1, Fatrop, IPOPT where it failed):" in printed
    assert "  Fatrop (+ IPOPT where it failed) iterations median " in printed
    assert f"  the point returned by: IPOPT {steps}\n" in printed
    assert "  IPOPT iterations" not in printed
