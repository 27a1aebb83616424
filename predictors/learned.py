"""Learned predictors: any net keeping the step contract (``predictors.nets.contract``) as a ``Predictor``.

One ``LearnedPredictor`` computes the same map two ways:

* ``rollout`` (and ``rollout_tensor``, ``sample``): float64 torch, recursive (Eq. 1): at every step the
  humans' predictions are fed back and the robots' positions are taken from ``robots_future`` (their own
  predictions are discarded). Training uses torch, and this is the reference the CasADi side is checked
  against;
* ``encode`` + ``to_casadi``: the net's own ``encode`` and ``decode_step`` exported to CasADi by
  ``predictors.export`` (no hand-written twin). The encoder's function is evaluated numerically; the decoder
  step is called ``H - 1`` times inside the symbolic prediction, so the MPC differentiates through it.

Context layout (``encode``), agents ordered humans (as given) then robots (increasing index):
``state_0 (N, ...) | ... | state_k (N, ...) | now (N, 2) | first (N_h, 2) | present (N)``, each block
row-major: the net's state after the observed past, the agents' current positions, the humans' predicted
positions at ``t+1`` (these depend on the past only) and 1/0 for agents observed at the current step (only
those are neighbours).

An agent missing now is extrapolated from its last observed step (constant velocity when its last two steps
were seen, else held), takes part in the recursion, but is never pooled; one never observed is refused.

The classes of the ``SocialLSTM`` net, ``SocialLSTMPredictor`` and the generator's ``SocialGANPredictor``
(with ``sample``), are predictors.social_lstm_predictors.
"""

from __future__ import annotations

import copy
import math
import re
from typing import Any

import casadi as ca
import numpy as np
import torch

from predictors import base
from predictors.base import OBS_LEN, check_history, check_humans, check_rollout_inputs, robot_indices
from predictors.errors import PredictorError
from predictors.export import TensorSpec, export_function, output_shapes
from predictors.nets.contract import check_predictor_contract
from predictors.threads import single_threaded

# (humans, robots, horizon) of the check on first export: small, but with neighbours and a recursion.
PARITY_SIZE = (2, 1, 3)


def casadi_name(text: str) -> str:
    """A valid CasADi function name: a letter first, then letters, digits and single underscores."""
    name = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", text)).strip("_")
    return name if name[:1].isalpha() else f"predictor_{name}"


class LearnedPredictor:
    """Any net that keeps the step contract, as a ``Predictor``; ``kind`` names its model kind
    (``predictors.models``)."""

    def __init__(self, net: torch.nn.Module, *, name: str, obs_len: int = OBS_LEN, kind: str | None = None):
        if obs_len < 2:
            raise PredictorError(f"obs_len must be >= 2 (a displacement needs two steps), got {obs_len}")
        self.name = name
        self.obs_len = obs_len
        self.kind: str = str(kind or getattr(type(self), "default_kind", type(net).__name__))
        self.config: Any = net.config
        self.weights_sha256: str | None = None  # of the file load_checkpoint read them from, if it did
        # A private float64 copy in eval mode: training may go on with the original. Typed Any: the step
        # contract's methods (encode, decode_step) are not nn.Module's.
        self.net: Any = copy.deepcopy(net).to(torch.float64).eval()
        for p in self.net.parameters():
            p.requires_grad_(False)
        # A zoo entry of a net that breaks the step contract fails here, in one line, rather than predicting
        # broadcast nonsense, or NaN at every step, in a closed loop.
        check_predictor_contract(self.net, f"predictor {name!r} (model {self.kind!r})", obs_len=obs_len)
        self._functions: dict[tuple[int, int, int], ca.Function] = {}
        self._export_checked = False  # to_casadi's first build is checked against torch (_check_export)
        self._export_failure: PredictorError | None = None  # what that check raised: raised again
        self._encoders: dict[tuple[int, int], ca.Function] = {}
        self._steps: dict[int, ca.Function] = {}
        # Per agent: each state tensor's trailing dims, and the head output's width (``_layout``).
        self._layout_memo: tuple[tuple[tuple[int, ...], ...], int] | None = None
        # The iterative best response predicts many times from the same past: keep the last encoding
        # (torch state for ``rollout``, the context for ``encode``).
        self._last_encoding: tuple[bytes, tuple] | None = None
        self._last_context: tuple[bytes, np.ndarray] | None = None

    # ------------------------------------------------------------------------------------- numeric side
    def _prepare(self, history: np.ndarray, mask: np.ndarray, humans: np.ndarray, keep_robots: bool = True):
        """Agents reordered (humans, robots), the last ``obs_len`` steps, gaps zeroed, absent agents imputed.
        ``keep_robots=False`` (a rollout without a robot plan) drops robots never observed: nothing is known
        of them, and nothing of theirs is returned (dataset evaluation hands over only observed agents, all
        as humans: ``predictors.evaluate.observed_history``)."""
        history = np.asarray(history, dtype=np.float64)
        mask = np.asarray(mask, dtype=bool)
        shaped = history.ndim == 3 and history.shape[2] == 2 and mask.shape == history.shape[:2]
        if not shaped or len(history) < self.obs_len:  # a short one ran on the steps it had: 0.7-0.9 m off
            raise PredictorError(
                f"history (L, N, 2) and mask (L, N) with L >= {self.obs_len} (the steps {self.name!r} reads; "
                f"pad a short track, its padding False in mask) expected, got {history.shape}, {mask.shape}"
            )
        humans = np.asarray(humans, dtype=int)
        robots = robot_indices(history.shape[1], humans)
        if not keep_robots:
            robots = robots[mask[-self.obs_len :, robots].any(axis=0)]
        order = np.concatenate([humans, robots])
        pos = history[-self.obs_len :, order].copy()
        seen = mask[-self.obs_len :, order].copy()
        never = np.flatnonzero(~seen.any(axis=0))
        if never.size:
            raise PredictorError(
                f"agents {order[never].tolist()} are never observed in the last {self.obs_len} steps of the "
                f"history (the steps {self.name!r} reads); they cannot be predicted"
            )
        pos[~seen] = 0.0
        last_row = pos.shape[0] - 1
        for a in np.flatnonzero(~seen[-1]):
            last = np.flatnonzero(seen[:, a])[-1]
            velocity = pos[last, a] - pos[last - 1, a] if last >= 1 and seen[last - 1, a] else 0.0
            pos[-1, a] = pos[last, a] + (last_row - last) * velocity
        return pos, seen, len(humans)

    def _rollout_tensor(
        self,
        pos: torch.Tensor,
        seen: torch.Tensor,
        n_humans: int,
        robots_future: torch.Tensor | None,
        horizon: int,
        noise: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``pos`` (B, L, N, 2), ``seen`` (B, L, N), ``robots_future`` (B, H, M, 2) -> (B, H, N_h, 2)."""
        encoded = self._encode_torch(pos, seen, noise)
        return self._decode(encoded, pos, seen, n_humans, robots_future, horizon)

    def _encode_torch(self, pos: torch.Tensor, seen: torch.Tensor, noise: torch.Tensor | None = None):
        """``net.encode``: ``(*state, out)``; only a generator takes noise."""
        if noise is not None:
            return self._net_call("encode", pos, seen, noise)
        return self._net_call("encode", pos, seen)

    def _net_call(self, method: str, *args: Any) -> Any:
        """``net.<method>(*args)``. What a plugin's net raises is a one-line PredictorError naming the
        predictor, its model and the scene's size (the contract's check ran it on 3 agents; a net written for
        small scenes meets 10 in the closed loop), its traceback kept as the cause for a sweep's errors.jsonl;
        left alone, it ended simulate with a traceback through the MPC, as a bug in crowdmpc. A shipped net's
        exception is such a bug, and propagates as it is."""
        try:
            return getattr(self.net, method)(*args)
        except Exception as exc:
            # shipped: a class of this package's nets (a user's subclass of one lives in the user's module);
            # asked of the class, since the registry, which knows the kinds, imports this module
            if type(self.net).__module__.startswith("predictors.nets."):
                raise
            agents = args[0].shape[-2]  # positions (B, L, N, 2), or prev (B, N, 2) after the state
            if method == "decode_step":
                agents = args[-1].shape[-1]  # neighbours (B, N)
            raise PredictorError(
                f"predictor {self.name!r} (model {self.kind!r}): {method} raised {type(exc).__name__}: "
                f"{exc} (on a scene of {agents} agents)"
            ) from exc

    def _decode(self, encoded, pos, seen, n_humans, robots_future, horizon) -> torch.Tensor:
        """The recursion after the encoder: what the CasADi prediction function computes."""
        state, out = tuple(encoded[:-1]), encoded[-1]
        present = seen[:, -1]
        positions = [pos[:, -1]]

        def advance(mean: torch.Tensor, k: int) -> torch.Tensor:
            nxt = positions[-1] + mean
            if robots_future is not None:  # the robots go where they plan to; their predictions are dropped
                nxt = torch.cat([nxt[:, :n_humans], robots_future[:, k]], dim=1)
            return nxt

        positions.append(advance(out[..., :2], 0))
        for k in range(1, horizon):
            *state_list, out = self._net_call("decode_step", *state, positions[-2], positions[-1], present)
            state = tuple(state_list)
            positions.append(advance(out[..., :2], k))
        return torch.stack(positions[1:], dim=1)[:, :, :n_humans]

    def rollout_tensor(
        self,
        history: np.ndarray,
        mask: np.ndarray,
        robots_future: torch.Tensor | None,
        humans: np.ndarray,
        horizon: int | None = None,
    ) -> torch.Tensor:
        """``rollout`` as a differentiable float64 tensor function of ``robots_future`` (H, M, 2)."""
        # The checked horizon: robots_future's length, else ``horizon`` (which it requires then).
        horizon = check_rollout_inputs(
            np.asarray(history),
            np.asarray(mask),
            None if robots_future is None else robots_future.detach().numpy(),
            humans,
            horizon,
        )
        pos, seen, n_humans = self._prepare(history, mask, humans, keep_robots=robots_future is not None)
        future = None if robots_future is None else robots_future.to(torch.float64)[None]
        with single_threaded():
            out = self._rollout_tensor(
                torch.from_numpy(pos)[None], torch.from_numpy(seen)[None], n_humans, future, horizon
            )
        return out[0]

    def rollout(self, history, mask, robots_future, humans, horizon=None):
        future = None if robots_future is None else np.asarray(robots_future, dtype=np.float64)
        horizon = check_rollout_inputs(np.asarray(history), np.asarray(mask), future, humans, horizon)
        if np.size(humans) == 0:  # no one to predict (the net's reshape of zero agents raised)
            return np.zeros((horizon, 0, 2))
        pos, seen, n_humans, encoded = self._encoded(history, mask, humans, keep_robots=future is not None)
        with torch.no_grad(), single_threaded():
            return self._decode(
                encoded,
                torch.from_numpy(pos)[None],
                torch.from_numpy(seen)[None],
                n_humans,
                None if future is None else torch.from_numpy(future)[None],
                horizon,
            )[0].numpy()

    @staticmethod
    def _input_key(history, mask, humans, keep_robots: bool) -> bytes:
        """The exact inputs of an encoding, as bytes to compare with the memoised one."""
        history = np.ascontiguousarray(history, dtype=np.float64)
        mask = np.ascontiguousarray(mask, dtype=bool)
        humans = np.ascontiguousarray(humans, dtype=np.int64)
        return b"|".join(
            [str((history.shape, keep_robots)).encode(), history.tobytes(), mask.tobytes(), humans.tobytes()]
        )

    def _encoded(self, history, mask, humans, keep_robots: bool = True):
        """``_prepare`` and the torch encoder, memoised on the exact inputs of the previous call."""
        key = self._input_key(history, mask, humans, keep_robots)
        if self._last_encoding is None or self._last_encoding[0] != key:
            pos, seen, n_humans = self._prepare(history, mask, humans, keep_robots)
            with torch.no_grad(), single_threaded():
                state = self._encode_torch(torch.from_numpy(pos)[None], torch.from_numpy(seen)[None])
            self._last_encoding = (key, (pos, seen, n_humans, state))
        return self._last_encoding[1]

    def encode(self, history, mask, humans):
        """The context (layout: this module's docstring), computed by the exported encoder and memoised like
        ``_encoded``."""
        check_history(np.asarray(history), np.asarray(mask))  # as rollout
        humans = check_humans(humans, np.shape(history)[1])  # as rollout: a repeat or a mask is refused
        key = self._input_key(history, mask, humans, True)
        if self._last_context is None or self._last_context[0] != key:
            pos, seen, n_humans = self._prepare(history, mask, humans)
            length, n_agents, _ = pos.shape
            *state, out = self.casadi_encoder(n_agents, length)(pos.ravel(), seen.ravel().astype(np.float64))
            width = self._widths()[1]
            step = np.asarray(out).reshape(n_agents, width)[:n_humans, :2]
            context = np.concatenate(
                [
                    *[np.asarray(block).ravel() for block in state],
                    pos[-1].ravel(),
                    (pos[-1, :n_humans] + step).ravel(),
                    seen[-1].astype(float),
                ]
            )
            self._last_context = (key, context)
        # A copy: the caller may write into its context, the memo must stay what the encoder computed.
        return self._last_context[1].copy()

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

    # ------------------------------------------------------------------------------------ symbolic side
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

    def _check_export(self) -> None:
        """The first export of this predictor is checked against torch (values and Jacobians, 1e-6) at a
        small size: every size is built by the same symbolic run of the same methods, so an operation mapped
        wrongly shows at any size; ``crowdmpc export`` checks the size it writes."""
        from predictors.export.parity import require_parity

        require_parity(self, *PARITY_SIZE)

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
