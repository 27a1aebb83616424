"""benchmarks/dmpc_scaling.py's bound on what threads can gain from uneven local solves, by hand."""

import numpy as np
import pytest

from tests.benchmark_modules import load_benchmark

dmpc_scaling = load_benchmark("dmpc_scaling")


def test_one_long_job_last_keeps_two_threads_waiting():
    # In order: the threads run 1+1+1 and 1+1, then one of them the 6 from t = 2: 8 against 11 serial.
    # Longest first: 6 on one thread, the five 1s on the other: 6.
    jobs = np.array([[1.0, 1.0, 1.0, 1.0, 1.0, 6.0]])
    assert dmpc_scaling.list_schedule_speedup(jobs, 2) == pytest.approx(11 / 8)
    assert dmpc_scaling.list_schedule_speedup(jobs, 2, longest_first=True) == pytest.approx(11 / 6)


def test_batches_add_up_and_even_jobs_reach_the_thread_count():
    even = np.ones((3, 6))
    assert dmpc_scaling.list_schedule_speedup(even, 2) == pytest.approx(2.0)
    assert dmpc_scaling.list_schedule_speedup(even, 3) == pytest.approx(3.0)
    # Serial 4 + 4 against 2 + 4 with two threads: the batches' times are summed (8 / 6), not their
    # speed-ups averaged ((2 + 1) / 2).
    mixed = np.array([[1.0, 1.0, 1.0, 1.0], [4.0, 0.0, 0.0, 0.0]])
    assert dmpc_scaling.list_schedule_speedup(mixed, 2) == pytest.approx(8 / 6)


def test_mpc_values_are_parsed_as_set_takes_them_and_the_rows_own_keys_are_refused():
    assert dmpc_scaling.mpc_overrides(["cost_scale=0.01"]) == (("cost_scale", 0.01),)
    assert dmpc_scaling.mpc_overrides([]) == ()
    with pytest.raises(dmpc_scaling.ConfigError, match="dmpc_update: set by --rules"):
        dmpc_scaling.mpc_overrides(["dmpc_update=gauss_seidel"])
    with pytest.raises(dmpc_scaling.ConfigError, match="cost_scale: must be > 0"):
        dmpc_scaling.mpc_overrides(["cost_scale=0"])


def test_mpc_values_reach_every_controller_and_the_rule_wins_its_own_keys():
    controller = dmpc_scaling._controller("jacobi:regret", "serial", (("cost_scale", 0.01),))
    try:
        assert controller.cfg.cost_scale == 0.01
        assert (controller.cfg.dmpc_update, controller.cfg.dmpc_stop) == ("jacobi", "regret")
    finally:
        controller.close()


def test_the_threads_speed_up_is_labelled_serial_over_threads(capsys):
    """The line read "threads/serial: step median x0.82" for serial / threads (a speed-up below 1: threads
    slower), the inverse of what it said."""
    import argparse

    def row(median_ms: float, phase_ms: float) -> dict:
        return {"median_ms": median_ms, "p95_ms": 1.0, "p99_ms": 1.0, "iterations_mean": 2.0, "at_j_max": 0.0,
                "solves_per_step": 3.0, "phase_ms_per_step": phase_ms, "success": 1, "collision": 0,
                "timeout": 0, "episodes": 1}  # fmt: skip

    report = {
        "cpus": 2,
        "load_before": (0.0, 0.0, 0.0),
        "load_after": (0.0, 0.0, 0.0),
        "wall_s": 1.0,
        "cells": {
            "r3 jacobi:regret": dmpc_scaling.cell_report(
                {"serial": row(8.2, 6.0), "threads": row(10.0, 4.0)}, True
            )
        },
    }
    # the JSON holds the speed-up the table prints (it held only the rows)
    speedup = report["cells"]["r3 jacobi:regret"]["speedup"]
    assert speedup == {"step_median": pytest.approx(0.82), "phase": pytest.approx(1.5)}
    args = argparse.Namespace(humans=7, episodes=1)
    dmpc_scaling.print_report(report, args, dmpc_scaling.PREDICTOR, ())
    line = capsys.readouterr().out.splitlines()[-1]
    assert "speed-up (serial / threads): step median x0.82, phase x1.50, same trajectories: True" in line
    assert "threads/serial" not in line


def _run(times_s, positions):
    """An episode's result as closed_loop reads it: step times and the robots' path (one robot, x only)."""
    from types import SimpleNamespace

    metrics = SimpleNamespace(success=True, collision=False, timeout=False)
    path = np.zeros((len(positions), 1, 2))
    path[:, 0, 0] = positions
    return SimpleNamespace(
        solve_times_s=np.asarray(times_s),
        iterations=[1] * len(times_s),
        metrics=metrics,
        robot_positions=path,
    )


def test_runs_are_compared_up_to_a_step_past_the_time_limit_and_no_further():
    within = _run([0.1, 0.1, 0.1], [0.0, 1.0, 2.0, 3.0])
    # step 1 ran past 1 s: positions 0..1 follow from step 0 alone; position 2 is step 1's, cut by the clock
    late = _run([0.1, 1.5, 0.1], [0.0, 1.0, 2.5, 3.5])
    assert dmpc_scaling.same_before_limit([within, late], 1.0) == (True, True)
    early = _run(
        [0.1, 1.5, 0.1], [0.0, 1.1, 2.5, 3.5]
    )  # parted at step 0, within the limit: a real difference
    assert dmpc_scaling.same_before_limit([within, early], 1.0) == (False, True)
    assert dmpc_scaling.same_before_limit([within, _run([0.1] * 3, [0.0, 1.0, 2.0, 3.1])], 1.0) == (
        False,
        False,
    )
    assert dmpc_scaling.same_before_limit([within, within], 1.0) == (True, False)


def test_a_serial_step_cut_by_the_time_limit_is_no_difference_and_is_said(monkeypatch):
    """At 6 robots on a loaded machine a serial step stopped at the 1 s limit, the threads' did not, and the
    check printed "same trajectories: False" for a difference the load made."""
    runs = iter([_run([0.1, 1.2], [0.0, 1.0, 2.5]), _run([0.1, 0.3], [0.0, 1.0, 2.0])])
    monkeypatch.setattr(dmpc_scaling, "run_episode", lambda *args, **kwargs: next(runs))
    # no phase was timed by these runs: the speed-ups' arithmetic is tested above, the check alone here
    monkeypatch.setattr(dmpc_scaling, "cell_report", lambda rows, same, cut=0: {"same": same, "cut": cut})
    cell = dmpc_scaling.closed_loop(2, 1, "jacobi:regret", ["serial", "threads"], 1)
    assert (cell["same"], cell["cut"]) == (True, 1)


def _solution(accels: float, status: str = "Solve_Succeeded"):
    from mpc.solvers import Solution

    return Solution(np.full((2, 2), accels), accels, status, True, 3, "fatrop", np.zeros(1), np.zeros(1))


def test_replayed_solves_past_the_time_limit_are_left_out_and_counted():
    """--replay compared every solve bit for bit, one the clock ended (past time_limit_s in one path) too,
    where the closed loop's comparison stops at such a step: the load could make it report a difference."""
    serial = [_solution(1.0), _solution(2.0, "Maximum_WallTime_Exceeded")]
    assert dmpc_scaling.same_within_limit(serial, [_solution(1.0), _solution(2.5)]) == (True, 1)
    assert dmpc_scaling.same_within_limit(
        [_solution(1.0), _solution(2.0)], [_solution(1.0), _solution(2.5, "Maximum_WallTime_Exceeded")]
    ) == (True, 1)
    # a solve within the limit in both must still agree bit for bit
    assert dmpc_scaling.same_within_limit(serial, [_solution(1.5), _solution(2.5)]) == (False, 1)
    assert dmpc_scaling.same_within_limit([_solution(1.0)], [_solution(1.0)]) == (True, 0)
