"""Social-Attention: each agent's LSTM reads its displacement and a self-attention over its neighbours.

At every step (observed or predicted) a pre-norm Transformer block mixes the agents' hidden states: agent
``i``'s query comes from its own hidden state, the key and value of neighbour ``j`` from ``j``'s hidden
state plus an embedding of ``j``'s position relative to ``i`` (so ``i`` may weigh who is close or ahead),
``scaled_dot_product_attention`` runs over the neighbours (``i`` always attends to itself, so no row is
empty), then a residual and a GELU feed-forward with a residual. The block's output joins the embedded
displacement as the LSTM cell's input. Separate encoder and decoder cells as in TrajNet++'s LSTMs (no start
tags: the decoder starts from the encoder's state), one shared attention block, and TrajNet++'s Gaussian
head (``nets.social_lstm.gaussian_head``) or a point head.

Unlike the social grid there is no range: everyone present may be attended to, and the relative-position
embedding has to learn to ignore the far ones. That embedding and the feed-forward use GELU, so the map
from the robots' plan to the predictions is smooth for the NLP.

Both ``encode`` and ``decode_step`` are run on symbolic tensors by the CasADi exporter: only the ops it
knows (no ``torch.eye``, no in-place writes, no branching on tensor values).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch
import torch.nn.functional as F
from torch import nn

from predictors.errors import PredictorError
from predictors.net_size import MAX_PARAMETERS
from predictors.nets.config_checks import (
    check_choice,
    check_int,
    check_parameter_count,
    check_positive_float,
    config_from_dict,
    config_to_dict,
)
from predictors.nets.contract import Head
from predictors.nets.rollout import TeacherForcedForward
from predictors.nets.social_lstm import HEADS, gaussian_head

LABEL = "Social-Attention"
# Widths may be 4096 as in nets.social_lstm.SIZE_BOUNDS (where the bounds are explained); 64 heads is more
# than any model_dim this net could afford at control rate.
SIZE_BOUNDS: dict[str, tuple[int, int]] = {
    "hidden_dim": (1, 4096),
    "embedding_dim": (1, 4096),
    "model_dim": (1, 4096),
    "heads": (1, 64),
    "ff_dim": (1, 4096),
}
# Upper bounds of the positive float settings: inputs scaled by more than 1000 saturate every unit.
FLOAT_BOUNDS: dict[str, float] = {"input_scale": 1000.0, "position_scale": 1000.0}


@dataclass(frozen=True)
class SocialAttentionConfig:
    """Hyper-parameters; small, so that the CasADi twin (``N**2 * model_dim`` pair terms a step) stays
    cheap inside the MPC."""

    hidden_dim: int = 32  # LSTM hidden size D
    embedding_dim: int = 16  # displacement embedding (Linear + ReLU)
    model_dim: int = 16  # width of the attention block (queries, keys, values, residual stream)
    heads: int = 1  # attention heads; must divide model_dim
    ff_dim: int = 32  # hidden width of the block's feed-forward
    input_scale: float = 4.0  # displacements are multiplied by this, as in TrajNet++ [4.0]
    position_scale: float = 0.5  # 1/m: relative positions are multiplied by this (2 m -> 1) before embedding
    head: str = "gaussian"  # "gaussian" (5 outputs, TrajNet++ Hidden2Normal) | "point" (2 outputs)

    def __post_init__(self):
        check_choice(LABEL, "head", self.head, HEADS)
        for name, (low, high) in SIZE_BOUNDS.items():
            check_int(LABEL, name, getattr(self, name), low, high)
        if self.model_dim % self.heads:
            raise PredictorError(
                f"{LABEL} heads must divide model_dim, got heads {self.heads} and model_dim {self.model_dim}"
            )
        for name, high_f in FLOAT_BOUNDS.items():
            check_positive_float(LABEL, name, getattr(self, name), high_f)
        check_parameter_count(
            LABEL, self.parameter_count(), MAX_PARAMETERS, "hidden_dim, model_dim or ff_dim too large"
        )

    def parameter_count(self) -> int:
        """The number of parameters ``SocialAttention(self)`` has, computed without allocating them."""

        def linear(n_in: int, n_out: int) -> int:
            return n_in * n_out + n_out

        d = self.model_dim
        count = linear(2, self.embedding_dim)  # displacement embedding
        count += linear(self.hidden_dim, d) + linear(2, d)  # hidden -> residual stream; relative position
        count += 2 * 2 * d  # two LayerNorms (weight, bias)
        count += 4 * linear(d, d)  # queries, keys, values, output
        count += linear(d, self.ff_dim) + linear(self.ff_dim, d)  # feed-forward
        # encoder and decoder LSTMCells: weight_ih, weight_hh and two biases, 4 gates each
        count += 2 * 4 * self.hidden_dim * (self.embedding_dim + d + self.hidden_dim + 2)
        count += linear(self.hidden_dim, 5 if self.head == "gaussian" else 2)
        return count

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, values: dict) -> SocialAttentionConfig:
        return config_from_dict(cls, values, LABEL)


def self_mask(like: torch.Tensor, n: int) -> torch.Tensor:
    """(n, n) bool identity from the ops the exporter knows (it has no ``torch.eye``): the rows
    ``[1, 0, ..., 0]`` (n + 1 long) read back n at a time move the 1 one place right on each row."""
    rows = torch.cat([like.new_ones(n, 1), like.new_zeros(n, n)], dim=1)
    return rows.flatten()[: n * n].reshape(n, n) > 0.5


class NeighbourAttention(nn.Module):
    """A pre-norm Transformer block over each agent's neighbours with a relative-position term."""

    def __init__(self, *, hidden_dim: int, model_dim: int, heads: int, ff_dim: int, position_scale: float):
        super().__init__()
        self.heads = heads
        self.position_scale = position_scale
        self.hidden_projection = nn.Linear(hidden_dim, model_dim)
        self.position_embedding = nn.Linear(2, model_dim)
        self.attention_norm = nn.LayerNorm(model_dim)
        self.query = nn.Linear(model_dim, model_dim)
        self.key = nn.Linear(model_dim, model_dim)
        self.value = nn.Linear(model_dim, model_dim)
        self.attention_output = nn.Linear(model_dim, model_dim)
        self.ff_norm = nn.LayerNorm(model_dim)
        self.ff_in = nn.Linear(model_dim, ff_dim)
        self.ff_out = nn.Linear(ff_dim, model_dim)

    def forward(
        self, hidden: torch.Tensor, source: torch.Tensor, positions: torch.Tensor, neighbours: torch.Tensor
    ) -> torch.Tensor:
        """``hidden`` (B, N, D) the queries' states, ``source`` (B, N, D) the keys' and values' (the same,
        or detached while training), ``positions`` (B, N, 2), ``neighbours`` (B, N) bool -> (B, N, model_dim).
        """
        batch, n_agents, _ = hidden.shape
        d = self.query.out_features
        head_dim = d // self.heads
        stream = self.hidden_projection(hidden)
        queries = self.query(self.attention_norm(stream))  # (B, N, d)
        # relative[b, i, j] = p_j - p_i: where neighbour j is seen from agent i
        relative = (positions[:, None, :, :] - positions[:, :, None, :]) * self.position_scale
        pair = self.attention_norm(self.hidden_projection(source))[:, None, :, :] + F.gelu(
            self.position_embedding(relative)
        )  # (B, N, N, d): neighbour j as seen from agent i
        keys, values = self.key(pair), self.value(pair)
        # Keys differ per (i, j), so each agent is its own attention batch with a single query.
        q = queries.reshape(batch * n_agents, 1, self.heads, head_dim).transpose(1, 2)
        k = keys.reshape(batch * n_agents, n_agents, self.heads, head_dim).transpose(1, 2)
        v = values.reshape(batch * n_agents, n_agents, self.heads, head_dim).transpose(1, 2)
        allowed = neighbours[:, None, :] | self_mask(positions, n_agents)[None]  # (B, N, N)
        attended = F.scaled_dot_product_attention(
            q, k, v, attn_mask=allowed.reshape(batch * n_agents, 1, 1, n_agents)
        )  # (B * N, heads, 1, head_dim)
        attended = attended.transpose(1, 2).reshape(batch, n_agents, d)
        stream = stream + self.attention_output(attended)
        return stream + self.ff_out(F.gelu(self.ff_in(self.ff_norm(stream))))


class SocialAttention(TeacherForcedForward, nn.Module):
    config_class: ClassVar[type] = SocialAttentionConfig

    def __init__(self, config: SocialAttentionConfig = SocialAttentionConfig()):
        super().__init__()
        self.config = config
        cfg = config
        self.input_embedding = nn.Linear(2, cfg.embedding_dim)
        self.attention = NeighbourAttention(
            hidden_dim=cfg.hidden_dim,
            model_dim=cfg.model_dim,
            heads=cfg.heads,
            ff_dim=cfg.ff_dim,
            position_scale=cfg.position_scale,
        )
        self.encoder = nn.LSTMCell(cfg.embedding_dim + cfg.model_dim, cfg.hidden_dim)
        self.decoder = nn.LSTMCell(cfg.embedding_dim + cfg.model_dim, cfg.hidden_dim)
        self.head = nn.Linear(cfg.hidden_dim, 5 if cfg.head == "gaussian" else 2)

    @property
    def head_type(self) -> Head:  # the step contract (predictors/nets/contract.py)
        return "gaussian" if self.config.head == "gaussian" else "point"

    # ------------------------------------------------------------------------------------------ pieces
    def output(self, hidden: torch.Tensor) -> torch.Tensor:
        """Head on hidden states: (..., 5) Gaussian parameters or (..., 2) a step; the mean is [..., :2]."""
        raw = self.head(hidden)
        return gaussian_head(raw) if self.config.head == "gaussian" else raw

    def step(
        self,
        cell: nn.LSTMCell,
        h: torch.Tensor,
        c: torch.Tensor,
        prev: torch.Tensor,
        cur: torch.Tensor,
        active: torch.Tensor | None,
        neighbours: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One step: (h, c) (B, N, D) updated where ``active`` (B, N) bool, everywhere when None.

        ``prev``/``cur`` (B, N, 2) positions at the last two steps; ``neighbours`` (B, N) bool: who may be
        attended to. Returns (h, c, head output).
        """
        batch, n_agents, _ = cur.shape
        displacement = cur - prev
        if active is not None:
            # an inactive agent's positions may be fill values: keep them out of its (discarded) update
            displacement = displacement * active.to(cur.dtype)[..., None]
        embedded = torch.relu(self.input_embedding(displacement * self.config.input_scale))
        # As TrajNet++ detaches the pooled hidden states while training, the neighbours' keys and values
        # are detached then; a rollout keeps them attached for the Jacobian with respect to the robots' plan.
        source = h.detach() if self.training else h
        social = self.attention(h, source, cur, neighbours)
        x = torch.cat([embedded, social], dim=-1).reshape(batch * n_agents, -1)
        h_new, c_new = cell(x, (h.reshape(batch * n_agents, -1), c.reshape(batch * n_agents, -1)))
        h_new = h_new.reshape(batch, n_agents, -1)
        c_new = c_new.reshape(batch, n_agents, -1)
        if active is not None:
            h_new = torch.where(active[..., None], h_new, h)
            c_new = torch.where(active[..., None], c_new, c)
        return h_new, c_new, self.output(h_new)

    # ---------------------------------------------------------------------------------------- phases
    def encode(
        self, positions: torch.Tensor, mask: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Observed past (B, L, N, 2) with ``mask`` (B, L, N) -> decoder state (h, c) and the head output
        that predicts the first future position (``positions[:, -1] + out[..., :2]``)."""
        batch, length, n_agents, _ = positions.shape
        h = positions.new_zeros(batch, n_agents, self.config.hidden_dim)
        c = torch.zeros_like(h)
        out = self.output(h)
        for t in range(1, length):
            active = mask[:, t - 1] & mask[:, t]
            h, c, out = self.step(self.encoder, h, c, positions[:, t - 1], positions[:, t], active, active)
        return h, c, out

    def decode_step(
        self,
        h: torch.Tensor,
        c: torch.Tensor,
        prev: torch.Tensor,
        cur: torch.Tensor,
        neighbours: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """A prediction step: every agent is updated; ``neighbours`` (B, N) marks who may be attended to."""
        return self.step(self.decoder, h, c, prev, cur, None, neighbours)

    def decode_step_masked(
        self,
        h: torch.Tensor,
        c: torch.Tensor,
        prev: torch.Tensor,
        cur: torch.Tensor,
        active: torch.Tensor,
        neighbours: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``decode_step`` updating only the ``active`` agents (teacher-forced training)."""
        return self.step(self.decoder, h, c, prev, cur, active, neighbours)
