"""Calling a CasADi function on numpy vectors without CasADi's Python call overhead.

``casadi.Function.__call__`` converts every argument to a DM, checks it, evaluates, and converts every output
back: about 45 us a call here, where the evaluation itself of a cost function of the NLPs takes a few. The
closed loop calls such functions thousands of times an episode (DMPC's C_i comparisons, solvers, the
predictor's twin), so they go through CasADi's buffer interface instead: the inputs and outputs are numpy
arrays bound to the function once, and a call copies the arguments in and triggers the evaluation (~5 us).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import casadi as ca
import numpy as np
from numpy.typing import ArrayLike


class BufferedFunction:
    """``f(*args) -> outputs`` for a CasADi function with dense inputs and outputs, through ``f.buffer()``.

    Arguments are anything ``np.ravel`` makes into the input's number of elements (or a scalar, broadcast);
    outputs are fresh float64 vectors. One instance must not be called from two threads at once (its
    buffers are shared); the function's own memory is checked out per instance, so separate instances of the
    same function may run in separate threads.
    """

    def __init__(self, function: ca.Function):
        for i in range(function.n_in()):
            if not function.sparsity_in(i).is_dense():
                raise ValueError(f"{function.name()}: input {function.name_in(i)} is not dense")
        for i in range(function.n_out()):
            if not function.sparsity_out(i).is_dense():
                raise ValueError(f"{function.name()}: output {function.name_out(i)} is not dense")
        self.function = function
        self._args = [np.zeros(function.nnz_in(i)) for i in range(function.n_in())]
        self._res = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
        self._buffer, self._trigger = function.buffer()
        for i, a in enumerate(self._args):
            # numpy declares ndarray.__buffer__ only for Python >= 3.12; an ndarray is a buffer on 3.11 too.
            self._buffer.set_arg(i, memoryview(a))  # type: ignore[arg-type]
        for i, r in enumerate(self._res):
            self._buffer.set_res(i, memoryview(r))  # type: ignore[arg-type]  # as set_arg above
        self.names_in = tuple(function.name_in())
        self.names_out = tuple(function.name_out())

    def __call__(self, *args) -> list[np.ndarray]:
        if len(args) != len(self._args):
            raise TypeError(f"{self.function.name()} takes {len(self._args)} arguments, got {len(args)}")
        self._fill(args)
        self._trigger()
        return [r.copy() for r in self._res]

    def call(self, values: Mapping[str, ArrayLike]) -> dict[str, np.ndarray]:
        """Inputs and outputs by name (an nlpsol's ``x0``, ``p``, ... -> ``x``, ``f``, ...); inputs left out
        are zero."""
        args: list[ArrayLike] = [0.0] * len(self._args)
        for name, value in values.items():
            args[self.names_in.index(name)] = value
        return dict(zip(self.names_out, self(*args), strict=True))

    def _fill(self, args: Sequence[ArrayLike]) -> None:
        for buffer, value in zip(self._args, args, strict=True):
            buffer[:] = np.ravel(value) if np.ndim(value) else value

    def stats(self) -> dict:
        """The statistics of the last call (a solver's ``return_status``, ``iter_count``, ...)."""
        return self._buffer.stats()
