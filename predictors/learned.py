"""Learned predictors (Social-LSTM, vanilla LSTM, Social-GAN-like) behind the ``Predictor`` protocol.

Each wraps a ``nets.SocialLSTM`` and computes the same map two ways:

* ``rollout`` (and ``rollout_tensor``, ``sample``): float64 torch, recursive (Eq. 1): at every step the
  humans' predictions are fed back and the robots' positions are taken from ``robots_future`` (their own
  predictions are discarded). Training uses torch, and this is the reference the CasADi twins are tested
  against;
* ``encode`` + ``to_casadi``: CasADi twins of the net's two halves, built from ``predictors.casadi_layers``
  with the model's own weights (agents as columns, one MX graph each, one step function ``_casadi_step``).
  ``encode`` evaluates the encoder's twin (``casadi_encoder``) numerically on the observed past, because
  torch's per-operation overhead on these tiny tensors cost milliseconds per control step; only the
  prediction horizon (``to_casadi``) is symbolic.

Context layout (``encode``), agents ordered humans (as given) then robots (increasing index), ``D`` hidden:
``h (N, D) | c (N, D) | now (N, 2) | first (N_h, 2) | present (N)``, each block row-major: the decoder's
LSTM state, the agents' current positions, the humans' predicted positions at ``t+1`` (these depend on the
past only) and 1/0 for agents observed at the current step (only those are pooled as neighbours).

An agent missing at the current step is extrapolated from its last observed step (constant velocity when its
last two steps were seen, else held), takes part in the recursion, but is never pooled; an agent never
observed cannot be predicted (``ValueError``).
"""

from __future__ import annotations

import copy
import re
from collections.abc import Iterator
from contextlib import contextmanager

import casadi as ca
import numpy as np
import torch

from predictors import casadi_layers as cl
from predictors.base import OBS_LEN, check_rollout_inputs, robot_indices
from predictors.errors import PredictorError
from predictors.nets.social_lstm import N_TAGS, SocialLSTM, SocialLSTMConfig

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


def casadi_name(text: str) -> str:
    """A valid CasADi function name: a letter first, then letters, digits and single underscores."""
    name = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9_]", "_", text)).strip("_")
    return name if name[:1].isalpha() else f"predictor_{name}"


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
        self._weights = {
            k: v.detach().cpu().numpy().astype(np.float64) for k, v in self.net.state_dict().items()
        }
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
        """The context (module docstring), computed by the CasADi encoder and memoised like ``_encoded``."""
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
        n_agents = n_humans + n_robots
        return n_agents * (2 * self.config.hidden_dim + 2 + 1) + 2 * n_humans

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
            self._functions[key] = self._build_casadi(*key)
        return self._functions[key]

    def _build_casadi(self, n_humans: int, n_robots: int, horizon: int) -> ca.Function:
        d = self.config.hidden_dim
        n = n_humans + n_robots
        context = ca.MX.sym("context", self.context_size(n_humans, n_robots))
        robots_future = ca.MX.sym("robots_future", horizon * n_robots * 2)
        blocks = np.cumsum([0, n * d, n * d, 2 * n, 2 * n_humans, n])
        h = ca.reshape(context[blocks[0] : blocks[1]], d, n)  # column j = agent j (row-major (N, D) input)
        c = ca.reshape(context[blocks[1] : blocks[2]], d, n)
        now = ca.reshape(context[blocks[2] : blocks[3]], 2, n)
        first = ca.reshape(context[blocks[3] : blocks[4]], 2, n_humans)
        present = ca.reshape(context[blocks[4] : blocks[5]], 1, n)
        plan = [
            ca.reshape(robots_future[2 * n_robots * k : 2 * n_robots * (k + 1)], 2, n_robots)
            for k in range(horizon)
        ]

        previous = now
        current = ca.horzcat(first, plan[0])
        outputs = [first]
        for k in range(1, horizon):
            h, c, mean = self._casadi_decode_step(h, c, previous, current, present, n_humans)
            humans_next = current[:, :n_humans] + mean
            outputs.append(humans_next)
            previous, current = current, ca.horzcat(humans_next, plan[k])
        humans_future = ca.vertcat(*[ca.reshape(o, 2 * n_humans, 1) for o in outputs])
        return ca.Function(
            casadi_name(f"{self.name}_h{n_humans}_r{n_robots}_H{horizon}"),
            [context, robots_future],
            [humans_future],
            ["context", "robots_future"],
            ["humans_future"],
        )

    def _casadi_decode_step(self, h, c, previous, current, present, n_humans):
        """The twin of ``SocialLSTM.decode_step``, agents as columns; returns the humans' mean step."""
        h, c = self._casadi_step("decoder", h, c, previous, current, neighbours=present)
        return h, c, self._casadi_mean(h[:, :n_humans])

    def _casadi_mean(self, h):
        """The head's mean step ``(2, N)``: the first two outputs of either head are the raw linear ones."""
        return cl.linear(h, self._weights["head.weight"][:2], self._weights["head.bias"][:2])

    def _casadi_lstm(self, cell: str, x, h, c, weight_ih: np.ndarray):
        w = self._weights
        return cl.lstm_cell(
            x, h, c, weight_ih, w[f"{cell}.weight_hh"], w[f"{cell}.bias_ih"], w[f"{cell}.bias_hh"]
        )

    def _casadi_tag_step(self, cell: str, h, c, slot: int):
        """The twin of ``SocialLSTM._tag_step``: every agent is updated."""
        column = self.config.embedding_dim - N_TAGS + slot
        # The one-hot tag times weight_ih is that weight's column; a (1, N) input of ones selects it exactly.
        weight_ih = self._weights[f"{cell}.weight_ih"][:, column : column + 1]
        return self._casadi_lstm(cell, ca.DM.ones(1, h.shape[1]), h, c, weight_ih)

    def _casadi_step(self, cell: str, h, c, previous, current, *, neighbours, active=None):
        """The twin of ``SocialLSTM.step`` (agents as columns): the new ``(h, c)``.

        ``neighbours`` (1, N) weights who may be pooled; ``active`` (1, N) of 0/1 marks the agents that move
        and are updated, None for all of them (a prediction step, whose graph then carries no masking).
        """
        w, cfg = self._weights, self.config
        displacement = current - previous
        if active is not None:
            displacement = displacement * ca.repmat(active, 2, 1)
        parts = [displacement]
        if cfg.pooling != "none":
            weights = cl.grid_cell_weights(
                current,
                cell_side=cfg.cell_side,
                grid_size=cfg.grid_size,
                soft=cfg.pooling == "soft",
                neighbour_weight=neighbours,
            )
            values = cl.linear(h, w["pool.hidden_encoding.weight"], w["pool.hidden_encoding.bias"])
            grid = cl.grid_pool(values, weights)
            parts.append(cl.relu(cl.linear(grid, w["pool.embedding.weight"], w["pool.embedding.bias"])))
        x = cl.relu(
            cl.linear(
                ca.vertcat(*parts) * cfg.input_scale, w["input_embedding.weight"], w["input_embedding.bias"]
            )
        )
        # The two tag slots of the embedding are zero at every step but the tag steps: drop their columns.
        h_new, c_new = self._casadi_lstm(
            cell, x, h, c, w[f"{cell}.weight_ih"][:, : cfg.embedding_dim - N_TAGS]
        )
        if active is None:
            return h_new, c_new
        # torch.where(active, new, old): with weights of exactly 0 and 1 the blend reproduces it bit for bit.
        keep = ca.repmat(active, h.shape[0], 1)
        return keep * h_new + (1 - keep) * h, keep * c_new + (1 - keep) * c

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
            self._encoders[key] = self._build_casadi_encoder(*key)
        return self._encoders[key]

    def _build_casadi_encoder(self, n: int, length: int) -> ca.Function:
        d = self.config.hidden_dim
        positions = ca.MX.sym("positions", 2 * n * length)
        seen = ca.MX.sym("seen", n * length)
        # Column t * N + j is agent j at step t (the row-major (L, N, 2) and (L, N) inputs).
        pos = ca.reshape(positions, 2, n * length)
        flags = ca.reshape(seen, 1, n * length)

        def at(t):
            return pos[:, t * n : (t + 1) * n]

        def seen_at(t):
            return flags[:, t * n : (t + 1) * n]

        h, c = self._casadi_tag_step("encoder", ca.DM.zeros(d, n), ca.DM.zeros(d, n), slot=0)
        for t in range(1, length):
            active = seen_at(t - 1) * seen_at(t)
            h, c = self._casadi_step("encoder", h, c, at(t - 1), at(t), neighbours=active, active=active)
        step = self._casadi_mean(h)
        h, c = self._casadi_tag_step("decoder", h, c, slot=1)
        if self.config.noise_dim:
            # The generator's first prediction comes from a decoder step (SocialLSTM.encode).
            if length > 1:
                active, previous = seen_at(length - 2) * seen_at(length - 1), at(length - 2)
            else:
                active, previous = ca.DM.zeros(1, n), at(length - 1)
            h, c = self._casadi_step(
                "decoder", h, c, previous, at(length - 1), neighbours=active, active=active
            )
            step = self._casadi_mean(h)
        return ca.Function(
            casadi_name(f"{self.name}_encoder_n{n}_L{length}"),
            [positions, seen],
            [ca.reshape(h, d * n, 1), ca.reshape(c, d * n, 1), ca.reshape(step, 2 * n, 1)],
            ["positions", "seen"],
            ["h", "c", "step"],
        )


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
