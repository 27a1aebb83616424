"""BufferedFunction: CasADi's buffer interface gives the same numbers as an ordinary call."""

import casadi as ca
import numpy as np
import pytest

from mpc.fastcall import BufferedFunction


def test_values_match_an_ordinary_call_and_outputs_are_fresh_arrays():
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    f = ca.Function("f", [x, p], [ca.sumsqr(x) * p[0], x * p[1]], ["x", "p"], ["s", "v"])
    fast = BufferedFunction(f)
    s, v = fast(np.array([1.0, 2.0, 3.0]), [2.0, -1.0])
    assert s.tolist() == [28.0] and v.tolist() == [-1.0, -2.0, -3.0]
    s2, _ = fast(np.ones((3, 1)), 0.5)  # any shape with the right number of elements; a scalar broadcasts
    assert s2.tolist() == [1.5] and s.tolist() == [28.0]  # the first result was a copy, not the buffer
    named = fast.call({"p": [1.0, 1.0], "x": [0.0, 3.0, 4.0]})
    assert named["s"].tolist() == [25.0] and named["v"].tolist() == [0.0, 3.0, 4.0]
    with pytest.raises(TypeError, match="2 arguments"):
        fast(np.zeros(3))


def test_solver_statistics_come_from_the_buffered_call():
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p")
    nlp = {"x": x, "p": p, "f": (x[0] - p) ** 2 + (x[1] + p) ** 2}
    solver = BufferedFunction(ca.nlpsol("s", "ipopt", nlp, {"print_time": False, "ipopt.print_level": 0}))
    out = solver.call({"x0": [0.0, 0.0], "p": 1.5, "lbx": -10.0, "ubx": 10.0})
    np.testing.assert_allclose(out["x"], [1.5, -1.5], atol=1e-8)
    assert solver.stats()["return_status"] == "Solve_Succeeded" and solver.stats()["iter_count"] >= 1


def test_sparse_inputs_are_refused():
    x = ca.SX.sym("x", ca.Sparsity.diag(2))
    with pytest.raises(ValueError, match="not dense"):
        BufferedFunction(ca.Function("g", [x], [ca.sum1(ca.sum2(x))]))
