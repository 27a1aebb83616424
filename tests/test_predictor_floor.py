"""benchmarks/predictor_floor.py: the functions it times are the loop's, and their scalar expansion computes
the same numbers (else its timings compare different work)."""

import numpy as np

from predictors.registry import load_predictor
from tests.benchmark_modules import load_benchmark

predictor_floor = load_benchmark("predictor_floor")


def test_the_encoder_and_twin_are_the_loops_and_their_expansion_agrees():
    predictor = load_predictor("social_lstm_eth")
    timed = predictor_floor.functions(predictor, 2, 1, 3)
    (encoder, encoder_args), (twin, twin_args) = timed["encoder"], timed["twin"]
    history, mask, humans, plan = predictor_floor.crossing_scene(2, 1, 3, predictor.obs_len)
    # The twin at the encoder's context is the loop's prediction (pipelines/loop/mpc.py, _predict_fn).
    np.testing.assert_array_equal(twin_args[0], predictor.encode(history, mask, humans))
    np.testing.assert_array_equal(twin_args[1], plan.ravel())
    assert encoder.size1_in(0) == predictor.obs_len * 3 * 2
    for function, args in ((encoder, encoder_args), (twin, twin_args)):
        mx = [np.asarray(out, dtype=float).ravel() for out in function.call(args)]
        sx = [np.asarray(out, dtype=float).ravel() for out in function.expand().call(args)]
        assert predictor_floor.largest_difference(mx, sx) < 1e-12
        assert predictor_floor.largest_difference(mx, [2 * x for x in sx]) > 1e-3  # it measures something


def test_largest_difference():
    a = [np.array([1.0, 2.0]), np.array([3.0])]
    b = [np.array([1.0, 2.5]), np.array([2.0])]
    assert predictor_floor.largest_difference(a, b) == 1.0
    assert predictor_floor.largest_difference(a, a) == 0.0


def test_a_flag_gcc_refuses_is_a_users_one_line_error(tmp_path):
    """--opt=-Qbogus ended in a CalledProcessError traceback."""
    import casadi as ca
    import pytest

    from mpc.compile_cache import compiler
    from pipelines.errors import PipelineError

    if compiler() is None:
        pytest.skip("no gcc on the PATH")
    x = ca.SX.sym("x")
    with pytest.raises(PipelineError, match=r"gcc -Qbogus failed on f's C \(exit \d+\): .*-Qbogus"):
        predictor_floor.compiled(ca.Function("f", [x], [2 * x]), "-Qbogus", tmp_path)
