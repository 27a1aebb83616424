"""Learned predictors: any net keeping the step contract (``predictors.nets.contract``) as a ``Predictor``.

One ``LearnedPredictor`` computes the same map two ways:

* ``rollout`` (and ``rollout_tensor``, ``sample``): float64 torch, recursive (Eq. 1): at every step the
  humans' predictions are fed back and the robots' positions are taken from ``robots_future`` (their own
  predictions are discarded). Training uses torch, and this is the reference the CasADi side is checked
  against;
* ``encode`` + ``to_casadi``: the net's own ``encode`` and ``decode_step`` exported to CasADi by
  ``predictors.export`` (no hand-written twin; predictors.learned_casadi builds them). The encoder's function
  is evaluated numerically; the decoder step is called ``H - 1`` times inside the symbolic prediction, so the
  MPC differentiates through it.

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
from typing import Any

import numpy as np
import torch

from predictors.base import OBS_LEN, check_history, check_humans, check_rollout_inputs, robot_indices
from predictors.errors import PredictorError
from predictors.learned_casadi import PARITY_SIZE, ExportedTwin
from predictors.nets.contract import check_predictor_contract
from predictors.threads import single_threaded


class LearnedPredictor(ExportedTwin):
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
        self._init_twin()  # the exported functions, built on first use (predictors.learned_casadi)
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

    # ------------------------------------------------------------------------------------ symbolic side
    def _check_export(self) -> None:
        """The first export of this predictor is checked against torch (values and Jacobians, 1e-6) at a
        small size: every size is built by the same symbolic run of the same methods, so an operation mapped
        wrongly shows at any size; ``crowdmpc export`` checks the size it writes."""
        from predictors.export.parity import require_parity

        require_parity(self, *PARITY_SIZE)
