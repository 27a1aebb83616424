"""The CasADi side of a learned predictor (predictors.learned's docstring): the net's ``encode`` and
``decode_step`` exported by ``predictors.export``, the context's layout they fix, and the symbolic
prediction ``to_casadi`` builds around the decoder step. ``LearnedPredictor`` takes it as a base class; its
torch side (``rollout``, ``encode``) and the first export's check against torch stay in predictors.learned.
"""

from __future__ import annotations

import math
import re
from typing import Any

import casadi as ca
import numpy as np

from predictors import base
from predictors.errors import PredictorError
from predictors.export import TensorSpec, export_function, output_shapes

# (humans, robots, horizon) of the check on first export: small, but with neighbours and a recursion.
PARITY_SIZE = (2, 1, 3)


def casadi_name(text: str) -> str:
    """A valid CasADi function name: a letter first, then letters, digits and single underscores."""
    name = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", text)).strip("_")
    return name if name[:1].isalpha() else f"predictor_{name}"


class ExportedTwin:
    """The exported functions of ``net``, built once per size and kept (a mixin of ``LearnedPredictor``)."""

    name: str
    net: Any  # the step contract's net (predictors.nets.contract)

    def _init_twin(self) -> None:
        self._functions: dict[tuple[int, int, int], ca.Function] = {}
        self._export_checked = False  # to_casadi's first build is checked against torch (_check_export)
        self._export_failure: PredictorError | None = None  # what that check raised: raised again
        self._encoders: dict[tuple[int, int], ca.Function] = {}
        self._steps: dict[int, ca.Function] = {}
        # Per agent: each state tensor's trailing dims, and the head output's width (``_layout``).
        self._layout_memo: tuple[tuple[tuple[int, ...], ...], int] | None = None

    def _check_export(self) -> None:
        """The first export's check against torch: the predictor, which has the torch side, defines it."""
        raise NotImplementedError

    def _layout(self) -> tuple[tuple[tuple[int, ...], ...], int]:
        """Per agent: the trailing dims of each state tensor (an LSTM's ``(D,)``, a window's ``(K, 2)``) and
        the width of the head output, from a symbolic run of encode with one and with two agents, which also
        checks that every output is ``(B, N, ...)``."""
        if self._layout_memo is None:
            shapes = []
            for n in (1, 2):
                specs = [TensorSpec("positions", (1, 2, n, 2)), TensorSpec("mask", (1, 2, n), True)]
                shapes.append(output_shapes(self.net, self.net.encode, specs))
            if len(shapes[0]) < 2 or any(
                len(a) < 2 or a[:2] != (1, 1) or b[:2] != (1, 2) or a[2:] != b[2:]
                for a, b in zip(*shapes, strict=True)
            ):
                raise PredictorError(
                    f"{self.name}: encode must return (*state, out), each of shape (B, N, ...); got "
                    f"{shapes[1]} for B=1, N=2 (see predictors/nets/contract.py)"
                )
            out_width = math.prod(shapes[0][-1][2:])
            if out_width < 2:
                raise PredictorError(
                    f"{self.name}: the head output must have at least 2 values (the mean step)"
                )
            self._layout_memo = (tuple(shape[2:] for shape in shapes[0][:-1]), out_width)
        return self._layout_memo

    def _widths(self) -> tuple[tuple[int, ...], int]:
        """Per agent: the width of each state tensor (flattened) and of the head output."""
        dims, out_width = self._layout()
        return tuple(math.prod(d) for d in dims), out_width

    def context_size(self, n_humans: int, n_robots: int) -> int:
        base.check_sizes(n_humans, n_robots)
        n_agents = n_humans + n_robots
        return n_agents * (sum(self._widths()[0]) + 2 + 1) + 2 * n_humans

    def to_casadi(self, n_humans: int, n_robots: int, horizon: int) -> ca.Function:
        """``f(context, robots_future) -> humans_future`` (see ``predictors.base``); built once per size."""
        base.check_sizes(n_humans, n_robots, horizon)
        key = (int(n_humans), int(n_robots), int(horizon))
        if self._export_failure is not None:
            raise self._export_failure  # every size is built the same way: it would fail the same
        if key not in self._functions:
            self._functions[key] = self._prediction(*key)
            if not self._export_checked:
                self._export_checked = True  # the check calls to_casadi for its own size
                try:
                    self._check_export()
                except PredictorError as exc:
                    # nothing unchecked may be handed out later, nor rebuilt and checked again per size
                    self._functions.clear()
                    self._export_failure = exc
                    raise
                except BaseException:  # an interrupt: the next call builds and checks again
                    self._export_checked = False
                    self._functions.clear()
                    raise
        return self._functions[key]

    def _prediction(self, n_humans: int, n_robots: int, horizon: int) -> ca.Function:
        """The recursion of ``_decode`` around the exported decoder step, on flat row-major vectors."""
        widths, out_width = self._widths()
        n = n_humans + n_robots
        context = ca.MX.sym("context", self.context_size(n_humans, n_robots))
        robots_future = ca.MX.sym("robots_future", horizon * n_robots * 2)
        bounds = np.cumsum([0, *[n * w for w in widths], 2 * n, 2 * n_humans, n]).tolist()
        blocks = [context[bounds[i] : bounds[i + 1]] for i in range(len(bounds) - 1)]
        state, (now, first, present) = blocks[: len(widths)], blocks[len(widths) :]
        plan = [robots_future[2 * n_robots * k : 2 * n_robots * (k + 1)] for k in range(horizon)]
        # The humans' mean steps in the step's flat (N, K) output: entries K*i and K*i + 1 of human i.
        means = [out_width * i + j for i in range(n_humans) for j in (0, 1)]
        previous, current, outputs = now, ca.vertcat(first, plan[0]), [first]
        for k in range(1, horizon):
            *state, out = self.casadi_step(n)(*state, previous, current, present)
            humans_next = current[: 2 * n_humans] + out[means]
            outputs.append(humans_next)
            previous, current = current, ca.vertcat(humans_next, plan[k])
        return ca.Function(
            casadi_name(f"{self.name}_h{n_humans}_r{n_robots}_H{horizon}"),
            [context, robots_future],
            [ca.vertcat(*outputs)],
            ["context", "robots_future"],
            ["humans_future"],
        )

    def casadi_step(self, n_agents: int) -> ca.Function:
        """``step(*state, prev, cur, neighbours) -> (*state, out)``: ``net.decode_step`` exported for one
        scene of ``n_agents`` (row-major flat inputs and outputs), built once per size."""
        if n_agents not in self._steps:
            # The state tensors' own shapes (an LSTM's (1, N, D); a window's (1, N, K, 2)), not flat widths.
            state_shapes = [(1, n_agents, *dims) for dims in self._layout()[0]]
            specs = [TensorSpec(f"state_{i}", shape) for i, shape in enumerate(state_shapes)]
            specs += [
                TensorSpec("prev", (1, n_agents, 2)),
                TensorSpec("cur", (1, n_agents, 2)),
                TensorSpec("neighbours", (1, n_agents), True),
            ]
            names = [f"next_state_{i}" for i in range(len(state_shapes))] + ["out"]
            self._steps[n_agents] = export_function(
                self.net, self.net.decode_step, specs, names, casadi_name(f"{self.name}_step_n{n_agents}")
            )
        return self._steps[n_agents]

    def casadi_encoder(self, n_agents: int, length: int) -> ca.Function:
        """``encoder(positions, seen) -> (*state, out)``: ``net.encode`` exported, built once per size.

        Inputs are ``_prepare``'s arrays, flattened row-major: ``positions`` (L, N, 2) and ``seen`` (L, N) as
        0/1 floats. Outputs, row-major: each state tensor (N, ...) and the head output ``out`` (N, K), whose
        first two columns are the mean step to the first future position. A generator's noise is zero.
        """
        if n_agents < 1 or length < 1:
            raise PredictorError(f"casadi_encoder needs n_agents, length >= 1, got {n_agents}, {length}")
        key = (n_agents, length)
        if key not in self._encoders:
            widths, _ = self._widths()
            specs = [
                TensorSpec("positions", (1, length, n_agents, 2)),
                TensorSpec("seen", (1, length, n_agents), True),
            ]
            names = [f"state_{i}" for i in range(len(widths))] + ["out"]
            self._encoders[key] = export_function(
                self.net,
                self.net.encode,
                specs,
                names,
                casadi_name(f"{self.name}_encoder_n{n_agents}_L{length}"),
            )
        return self._encoders[key]
