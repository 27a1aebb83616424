"""Learned predictors (Social-LSTM, vanilla LSTM, Social-GAN-like) behind the ``Predictor`` protocol.

Each wraps a ``nets.SocialLSTM`` and computes the same map two ways:

* ``rollout`` (and ``rollout_tensor``, ``sample``): float64 torch, recursive (Eq. 1): at every step the
  humans' predictions are fed back and the robots' positions are taken from ``robots_future`` (their own
  predictions are discarded). Training uses torch, and this is the reference the CasADi twins are tested
  against;
* ``encode`` + ``to_casadi``: the net's CasADi twin (``predictors.casadi_twin``, which also has the context
  layout), the encoder's evaluated numerically and the decoder's symbolic.

An agent missing at the current step is extrapolated from its last observed step (constant velocity when its
last two steps were seen, else held), takes part in the recursion, but is never pooled; an agent never
observed cannot be predicted (``ValueError``).
"""

from __future__ import annotations

import copy
from collections.abc import Iterator
from contextlib import contextmanager

import casadi as ca
import numpy as np
import torch

from predictors.base import OBS_LEN, check_rollout_inputs, robot_indices
from predictors.casadi_twin import SocialLSTMTwin
from predictors.errors import PredictorError
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

MODEL_KINDS = ("social_lstm", "vanilla_lstm", "social_gan")


@contextmanager
def single_threaded() -> Iterator[None]:
    """Run torch on one thread: these tensors are tiny, and on a shared CPU torch's thread pool spin-waits
    (a 64x40 linear layer took 1-1.7 ms on 2 threads against 0.1 ms on one, measured on the 2-core box)."""
    before = torch.get_num_threads()
    if before != 1:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        if before != 1:
            torch.set_num_threads(before)


class LearnedPredictor:
    """Common machinery; use ``SocialLSTMPredictor`` or ``SocialGANPredictor``."""

    kind: str  # set by each subclass; SocialLSTMPredictor refines it per instance (vanilla or social)

    def __init__(self, net: SocialLSTM, *, name: str, obs_len: int = OBS_LEN):
        if obs_len < 2:
            raise PredictorError(f"obs_len must be >= 2 (a displacement needs two steps), got {obs_len}")
        self.name = name
        self.obs_len = obs_len
        self.config: SocialLSTMConfig = net.config
        # A private float64 copy in eval mode: training may go on with the original.
        self.net = copy.deepcopy(net).to(torch.float64).eval()
        for p in self.net.parameters():
            p.requires_grad_(False)
        self._twin = SocialLSTMTwin(
            {k: v.detach().cpu().numpy().astype(np.float64) for k, v in self.net.state_dict().items()},
            self.config,
        )
        self._functions: dict[tuple[int, int, int], ca.Function] = {}
        self._encoders: dict[tuple[int, int], ca.Function] = {}
        # The iterative best response predicts many times from the same past: keep the last encoding
        # (torch state for ``rollout``, the context for ``encode``).
        self._last_encoding: tuple[bytes, tuple] | None = None
        self._last_context: tuple[bytes, np.ndarray] | None = None

    # ------------------------------------------------------------------------------------- numeric side
    def _prepare(self, history: np.ndarray, mask: np.ndarray, humans: np.ndarray, keep_robots: bool = True):
        """Agents reordered (humans, robots), the last ``obs_len`` steps, gaps zeroed, absent agents imputed.

        ``keep_robots=False`` (a rollout without a robot plan) drops robots never observed: nothing is known
        of them, and dataset evaluation passes agents that appear only later as such "robots".
        """
        history = np.asarray(history, dtype=np.float64)
        mask = np.asarray(mask, dtype=bool)
        if history.ndim != 3 or history.shape[2] != 2 or mask.shape != history.shape[:2]:
            raise ValueError(
                f"history (L, N, 2) and mask (L, N) expected, got {history.shape} and {mask.shape}"
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
            raise ValueError(
                f"agents {order[never].tolist()} are never observed in the history; they cannot be predicted"
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
        h, c, out = self.net.encode(pos, seen, noise)
        return self._decode(h, c, out, pos, seen, n_humans, robots_future, horizon)

    def _decode(self, h, c, out, pos, seen, n_humans, robots_future, horizon) -> torch.Tensor:
        """The recursion after the encoder: the torch twin of the CasADi function."""
        present = seen[:, -1]
        positions = [pos[:, -1]]

        def advance(mean: torch.Tensor, k: int) -> torch.Tensor:
            nxt = positions[-1] + mean
            if robots_future is not None:  # the robots go where they plan to; their predictions are dropped
                nxt = torch.cat([nxt[:, :n_humans], robots_future[:, k]], dim=1)
            return nxt

        positions.append(advance(out[..., :2], 0))
        for k in range(1, horizon):
            h, c, out = self.net.decode_step(h, c, positions[-2], positions[-1], present)
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
        pos, seen, n_humans, (h, c, out) = self._encoded(
            history, mask, humans, keep_robots=future is not None
        )
        with torch.no_grad(), single_threaded():
            return self._decode(
                h,
                c,
                out,
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
                state = self.net.encode(torch.from_numpy(pos)[None], torch.from_numpy(seen)[None])
            self._last_encoding = (key, (pos, seen, n_humans, state))
        return self._last_encoding[1]

    def encode(self, history, mask, humans):
        """The context (layout: ``predictors.casadi_twin``), computed by the CasADi encoder and memoised like
        ``_encoded``."""
        key = self._input_key(history, mask, humans, True)
        if self._last_context is None or self._last_context[0] != key:
            pos, seen, n_humans = self._prepare(history, mask, humans)
            length, n_agents, _ = pos.shape
            h, c, step = self.casadi_encoder(n_agents, length)(pos.ravel(), seen.ravel().astype(np.float64))
            first = pos[-1, :n_humans] + np.asarray(step).reshape(n_agents, 2)[:n_humans]
            context = np.concatenate(
                [
                    np.asarray(h).ravel(),
                    np.asarray(c).ravel(),
                    pos[-1].ravel(),
                    first.ravel(),
                    seen[-1].astype(float),
                ]
            )
            self._last_context = (key, context)
        # A copy: the caller may write into its context, the memo must stay what the encoder computed.
        return self._last_context[1].copy()

    def context_size(self, n_humans: int, n_robots: int) -> int:
        return self._twin.context_size(n_humans, n_robots)

    # ------------------------------------------------------------------------------------ symbolic side
    def to_casadi(self, n_humans: int, n_robots: int, horizon: int) -> ca.Function:
        """``f(context, robots_future) -> humans_future`` (see ``predictors.base``); built once per size."""
        if n_humans < 0 or n_robots < 0 or horizon < 1:
            raise PredictorError(
                "to_casadi needs n_humans, n_robots >= 0 and horizon >= 1, "
                f"got {n_humans}, {n_robots}, {horizon}"
            )
        key = (n_humans, n_robots, horizon)
        if key not in self._functions:
            self._functions[key] = self._twin.prediction(self.name, *key)
        return self._functions[key]

    def casadi_encoder(self, n_agents: int, length: int) -> ca.Function:
        """``encoder(positions, seen) -> (h, c, step)``: ``SocialLSTM.encode``'s twin, built once per size.

        Inputs are ``_prepare``'s arrays, flattened row-major: ``positions`` (L, N, 2) and ``seen`` (L, N) as
        0/1 floats. Outputs, row-major: the decoder's state ``h``, ``c`` (N, D) and ``step`` (N, 2), the mean
        of the head output that predicts the first future position (``positions[-1] + step``). A generator's
        noise is zero, as in ``encode``.
        """
        if n_agents < 1 or length < 1:
            raise PredictorError(f"casadi_encoder needs n_agents, length >= 1, got {n_agents}, {length}")
        key = (n_agents, length)
        if key not in self._encoders:
            self._encoders[key] = self._twin.encoder(self.name, *key)
        return self._encoders[key]


class SocialLSTMPredictor(LearnedPredictor):
    """Social-LSTM (``pooling`` "grid" or "soft") or, with ``pooling="none"``, the vanilla LSTM."""

    kind = "social_lstm"

    def __init__(self, net: SocialLSTM, *, name: str, obs_len: int = OBS_LEN):
        if net.config.noise_dim:
            raise PredictorError("SocialLSTMPredictor takes a net without noise; use SocialGANPredictor")
        super().__init__(net, name=name, obs_len=obs_len)
        self.kind = "vanilla_lstm" if net.config.pooling == "none" else "social_lstm"


class SocialGANPredictor(LearnedPredictor):
    """Social-GAN-like generator: deterministic (zero noise) ``rollout``/``to_casadi``, plus ``sample``."""

    kind = "social_gan"

    def __init__(self, net: SocialLSTM, *, name: str, obs_len: int = OBS_LEN):
        if not net.config.noise_dim:
            raise PredictorError("SocialGANPredictor needs a generator net (noise_dim >= 1)")
        super().__init__(net, name=name, obs_len=obs_len)

    def sample(
        self,
        history: np.ndarray,
        mask: np.ndarray,
        robots_future: np.ndarray | None,
        humans: np.ndarray,
        horizon: int | None,
        k: int,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """``k`` futures, each with its own standard normal noise: ``(k, H, N_h, 2)``."""
        if k < 1:
            raise ValueError(f"k must be >= 1, got {k}")
        horizon = check_rollout_inputs(np.asarray(history), np.asarray(mask), robots_future, humans, horizon)
        pos, seen, n_humans = self._prepare(history, mask, humans, keep_robots=robots_future is not None)
        noise = torch.from_numpy(rng.standard_normal((k, pos.shape[1], self.config.noise_dim)))
        future = None
        if robots_future is not None:
            future = torch.as_tensor(np.asarray(robots_future, dtype=np.float64))[None].expand(k, -1, -1, -1)
        with torch.no_grad(), single_threaded():
            out = self._rollout_tensor(
                torch.from_numpy(pos)[None].expand(k, -1, -1, -1),
                torch.from_numpy(seen)[None].expand(k, -1, -1),
                n_humans,
                future,
                horizon,
                noise,
            )
        return out.numpy()


PREDICTOR_CLASSES: dict[str, type[LearnedPredictor]] = {
    "SocialLSTMPredictor": SocialLSTMPredictor,
    "SocialGANPredictor": SocialGANPredictor,
}


def predictor_class_for(model: str) -> type[LearnedPredictor]:
    """The predictor class of a ``--model`` choice."""
    if model not in MODEL_KINDS:
        raise PredictorError(f"unknown model {model!r}; choose from {list(MODEL_KINDS)}")
    return SocialGANPredictor if model == "social_gan" else SocialLSTMPredictor
