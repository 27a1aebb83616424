"""benchmarks/export.py: the IBR prediction time per call is that of the loop's call path."""

import casadi as ca
import numpy as np

from mpc.fastcall import BufferedFunction
from tests.benchmark_modules import load_benchmark

export = load_benchmark("export")


def test_a_call_is_timed_through_the_loops_buffers(monkeypatch):
    """The loop calls a twin through mpc/fastcall.py's BufferedFunction (MPCController._twin); CasADi's own
    call, which the benchmark timed, converts its arguments at a quarter more per call (0.32 against 0.24 ms,
    social_lstm_eth, 7 humans)."""
    context, plan = ca.MX.sym("context", 3), ca.MX.sym("plan", 2)
    twin = ca.Function("twin", [context, plan], [ca.sum1(context) * plan])
    buffered = []
    call = BufferedFunction.__call__

    def counted(self, *args):
        buffered.append(self.function.name())
        return call(self, *args)

    monkeypatch.setattr(BufferedFunction, "__call__", counted)
    export.per_call_ms(twin, np.ones(3), np.ones(2), calls=4)
    assert buffered == ["twin"] * 5  # one untimed call, then the timed ones
