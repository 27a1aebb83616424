"""benchmarks/sweep_floor.py: its arithmetic by hand, and its clock on real CasADi functions."""

import casadi as ca
import numpy as np
import pytest

from mpc.fastcall import BufferedFunction
from predictors.learned import LearnedPredictor
from tests.benchmark_modules import load_benchmark

sweep_floor = load_benchmark("sweep_floor")


def test_the_projection_and_the_python_cut_by_hand():
    # Two episodes of 0.3 and 0.1 s: 0.2 s each on average, 0.15 s of it in CasADi, 0.05 s Python.
    rows = [
        {"cell": "a", "wall_s": 0.3, "fatrop local": 0.2, "encoder": 0.02},
        {"cell": "b", "wall_s": 0.1, "fatrop local": 0.08},
    ]
    out = sweep_floor.summary(rows, workers=2)
    assert out["episode_ms"] == pytest.approx(200.0)
    assert out["casadi_ms"] == pytest.approx({"encoder": 10.0, "fatrop local": 140.0})
    assert out["casadi_share"] == pytest.approx(0.75)
    assert out["python_ms"] == pytest.approx(50.0)
    # 10 000 episodes on 2 cores: 5000 x 0.2 s = 16.67 min, 5000 x 0.15 s = 12.5 min. 15 min allows 0.18 s an
    # episode, 0.03 s of Python: 40 % of the 0.05 s must go.
    assert out["table2_min"] == pytest.approx(5000 * 0.2 / 60)
    assert out["table2_min_without_python"] == pytest.approx(12.5)
    assert out["python_cut_needed_for_target"] == pytest.approx(0.4)


def test_a_floor_above_the_target_needs_all_of_the_python_gone():
    out = sweep_floor.summary([{"cell": "a", "wall_s": 0.3, "fatrop joint": 0.25}], workers=2)
    assert out["python_cut_needed_for_target"] == pytest.approx(1.0)


def _nlpsol(plugin: str, name: str) -> ca.Function:
    x = ca.SX.sym("x", 2)
    options = {"print_time": False}
    options |= (
        {"structure_detection": "none", "fatrop": {"print_level": 0}}
        if plugin == "fatrop"
        else {"ipopt": {"print_level": 0, "sb": "yes"}}
    )
    return ca.nlpsol(name, plugin, {"x": x, "f": ca.sumsqr(x - 1)}, options)


def test_parts_are_named_by_solver_and_nlp():
    assert sweep_floor.part_of(_nlpsol("fatrop", "joint_3r_7h")) == "fatrop joint"
    assert sweep_floor.part_of(_nlpsol("ipopt", "local_3r_7h_0")) == "ipopt local"
    x = ca.SX.sym("x")
    assert sweep_floor.part_of(ca.Function("twin", [x], [2 * x])) == "twin and cost maps"


def test_the_clock_times_calls_made_while_installed_and_undoes_its_patches():
    init, stats, encoder = BufferedFunction.__init__, BufferedFunction.stats, LearnedPredictor.casadi_encoder
    clock = sweep_floor.CasadiClock()
    clock.install()
    try:
        solver = BufferedFunction(_nlpsol("fatrop", "local_x"))
        out = solver.call({"x0": [0.0, 0.0], "lbx": -5.0, "ubx": 5.0})
        solver.stats()
    finally:
        clock.close()
    np.testing.assert_allclose(out["x"], [1.0, 1.0], atol=1e-6)
    assert set(clock.now) == {"fatrop local", "solver statistics"}
    assert all(seconds > 0 for seconds in clock.now.values())
    assert (BufferedFunction.__init__, BufferedFunction.stats) == (init, stats)
    assert LearnedPredictor.casadi_encoder is encoder
    before = dict(clock.now)
    BufferedFunction(_nlpsol("fatrop", "local_y")).call({"x0": [0.0, 0.0]})
    assert clock.now == before  # built after close: not timed


def test_a_target_met_already_needs_nothing_cut_and_says_so():
    """On 8 workers the projection is under 15 min: the cut printed as "-672 % of the Python time gone"."""
    rows = [{"cell": "a", "wall_s": 0.2, "fatrop local": 0.15}]
    out = sweep_floor.summary(rows, workers=8)  # 10 000 x 0.2 s / 8 = 4.2 min
    assert out["python_cut_needed_for_target"] == 0.0
    assert sweep_floor.target_verdict(out) == "15 min is met at this rate on 8 cores"
    assert sweep_floor.target_verdict(sweep_floor.summary(rows, workers=2)) == (
        "15 min needs 40 % of the Python time gone"
    )
    above = sweep_floor.summary([{"cell": "a", "wall_s": 0.3, "fatrop joint": 0.25}], workers=2)
    assert sweep_floor.target_verdict(above) == "15 min is out of reach on 2 cores even with no Python time"
