"""benchmarks/ibr_solves.py: the floor is one bare solve, and every solve of a step is counted."""

from mpc.nlp import JointNLP
from tests.benchmark_modules import load_benchmark

ibr_solves = load_benchmark("ibr_solves")


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
