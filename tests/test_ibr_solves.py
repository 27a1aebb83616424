"""benchmarks/ibr_solves.py: the floor is one bare solve, and every solve of a step is counted."""

import pytest

from mpc.nlp import JointNLP
from tests.benchmark_modules import load_benchmark

ibr_solves = load_benchmark("ibr_solves")
run_all_table = load_benchmark("run_all_table")


def test_a_restart_from_braking_is_a_later_solve_not_part_of_the_floor(monkeypatch):
    """The first solve_multi_start call of a step solves twice when its plan still pays collision penalty
    (multi_start). Timing calls put both solves in "the first solve" (the floor) and counted one solve."""
    solves_by_call = []
    multi_start = JointNLP.solve_multi_start

    def counting(self, *args, **kwargs):
        result = multi_start(self, *args, **kwargs)
        solves_by_call.append(result[1])
        return result

    monkeypatch.setattr(JointNLP, "solve_multi_start", counting)
    row = ibr_solves.measure("social_lstm_eth", 7, 1, False)
    assert 2 in solves_by_call  # this episode restarts: the case the split must get right
    assert row["solves_per_step"] == sum(solves_by_call) / row["steps"]
    assert row["first_solve_ms"] <= row["step_ms"]
    # the ratio of the two medians, printed beside them, is not the median of the steps' own ratios
    assert row["step_median_over_first_median"] == pytest.approx(row["step_ms"] / row["first_solve_ms"])


def test_run_alls_table_labels_both_ratios():
    """run_all's ibr row printed the median of per-step ratios as "step / first solve" beside the medians of
    step and first solve, where it reads as their ratio (7.83 / 1.18 = 6.6 printed as 4.09)."""
    row = {"first_solve_ms": 1.18, "later_solves_ms": 5.0, "encode_ms": 0.5, "twin_ms": 0.5, "step_ms": 7.83}
    row |= {"step_median_over_first_median": 7.83 / 1.18, "step_over_first": 4.09, "bound_over_first": 3.9}
    (line,) = run_all_table._formation_rows({"ibr": {"jit off": row}})
    assert "median step / median first solve 6.64" in line
    assert "median of per-step (step / first solve) 4.09 (3.90 without bookkeeping)" in line
