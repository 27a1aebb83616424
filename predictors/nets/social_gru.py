"""Social-GRU: ``nets.social_lstm.SocialLSTM`` with GRU cells, so the state per agent is ``h`` alone.

Everything else is Social-LSTM's (TrajNet++ ``trajnetbaselines/lstm``): the displacement since the last
step and the pooled neighbours' hidden states, scaled by ``input_scale``, embedded (``Linear + ReLU``) and
fed to the cell; separate encoder and decoder cells with start tags on two spare embedding slots; a linear
head giving the next displacement as TrajNet++'s bivariate Gaussian or as a point; single-step prediction
applied recursively. A GRU has 3 gates to the LSTM's 4 and no cell state, so its CasADi twin is about a
quarter cheaper per step and its context a half smaller. The pooling defaults to ``"soft"`` (bilinear),
whose non-zero gradient with respect to the neighbours' positions the coupled NLP needs.

Both ``encode`` and ``decode_step`` are run on symbolic tensors by the CasADi exporter: only the ops it
knows, no in-place writes, no branching on tensor values (``nets.contract``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import nn

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
from predictors.nets.pooling import POOLINGS, GridPooling, pooling_for
from predictors.nets.rollout import TeacherForcedForward
from predictors.nets.social_lstm import FLOAT_BOUNDS, HEADS, N_TAGS, gaussian_head, pooled_rnn_parameter_count

LABEL = "Social-GRU"
# Social-LSTM's bounds (nets.social_lstm.SIZE_BOUNDS, where they are explained), without the noise.
SIZE_BOUNDS: dict[str, tuple[int, int]] = {
    "hidden_dim": (1, 4096),
    "embedding_dim": (N_TAGS + 1, 4096),  # two slots are the start tags
    "grid_size": (1, 64),
    "latent_dim": (1, 4096),
    "pool_dim": (1, 4096),
}


@dataclass(frozen=True)
class SocialGRUConfig:
    """Hyper-parameters, Social-LSTM's small defaults (TrajNet++'s in brackets): the pooling's
    ``grid_size**2 * latent_dim`` inputs dominate the CasADi twin's cost."""

    pooling: str = "soft"  # "none" (vanilla GRU) | "grid" (hard, TrajNet++) | "soft" (bilinear)
    hidden_dim: int = 32  # GRU hidden size D [128]
    embedding_dim: int = 16  # input embedding incl. the 2 tag slots [64]
    cell_side: float = 0.8  # m, side of one pooling cell [0.6]; the grid spans +-2.4 m around the agent
    grid_size: int = 6  # cells per side of the pooling grid [12]
    latent_dim: int = 4  # neighbours' hidden states are compressed to this before pooling [16]
    pool_dim: int = 16  # pooled interaction vector [256]
    input_scale: float = 4.0  # inputs (displacement and pooled vector) are multiplied by this [4.0]
    head: str = "gaussian"  # "gaussian" (5 outputs, TrajNet++ Hidden2Normal) | "point" (2 outputs)

    def __post_init__(self):
        check_choice(LABEL, "pooling", self.pooling, POOLINGS)
        check_choice(LABEL, "head", self.head, HEADS)
        for name, (low, high) in SIZE_BOUNDS.items():
            check_int(LABEL, name, getattr(self, name), low, high)
        for name, high_f in FLOAT_BOUNDS.items():
            check_positive_float(LABEL, name, getattr(self, name), high_f)
        check_parameter_count(
            LABEL,
            self.parameter_count(),
            MAX_PARAMETERS,
            "hidden_dim, embedding_dim, grid_size**2 * latent_dim * pool_dim too large",
        )

    def parameter_count(self) -> int:
        """The number of parameters ``SocialGRU(self)`` has, computed without allocating them."""
        return pooled_rnn_parameter_count(self, gates=3)

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, values: dict) -> SocialGRUConfig:
        return config_from_dict(cls, values, LABEL)


def tag_input(like: torch.Tensor, rows: int, embedding_dim: int, slot: int) -> torch.Tensor:
    """(rows, embedding_dim) one-hot start tags on spare slot ``slot``; built by concatenation, since the
    exporter has no in-place write (``tag[:, k] = 1``)."""
    first = embedding_dim - N_TAGS + slot
    return torch.cat(
        [
            like.new_zeros(rows, first),
            like.new_ones(rows, 1),
            like.new_zeros(rows, embedding_dim - first - 1),
        ],
        dim=1,
    )


class SocialGRU(TeacherForcedForward, nn.Module):
    config_class: ClassVar[type] = SocialGRUConfig

    def __init__(self, config: SocialGRUConfig = SocialGRUConfig()):
        super().__init__()
        self.config = config
        cfg = config
        self.pool: GridPooling | None
        self.pool, pooled = pooling_for(cfg)
        self.input_embedding = nn.Linear(2 + pooled, cfg.embedding_dim - N_TAGS)
        self.encoder = nn.GRUCell(cfg.embedding_dim, cfg.hidden_dim)
        self.decoder = nn.GRUCell(cfg.embedding_dim, cfg.hidden_dim)
        self.head = nn.Linear(cfg.hidden_dim, 5 if cfg.head == "gaussian" else 2)

    @property
    def head_type(self) -> Head:  # the step contract (predictors/nets/contract.py)
        return "gaussian" if self.config.head == "gaussian" else "point"

    # ------------------------------------------------------------------------------------------ pieces
    def output(self, hidden: torch.Tensor) -> torch.Tensor:
        """Head on hidden states: (..., 5) Gaussian parameters or (..., 2) a step; the mean is [..., :2]."""
        raw = self.head(hidden)
        return gaussian_head(raw) if self.config.head == "gaussian" else raw

    def _tag_step(self, cell: nn.GRUCell, h: torch.Tensor, slot: int) -> torch.Tensor:
        batch, n_agents, _ = h.shape
        tag = tag_input(h, batch * n_agents, self.config.embedding_dim, slot)
        return cell(tag, h.reshape(batch * n_agents, -1)).reshape(batch, n_agents, -1)

    def step(
        self,
        cell: nn.GRUCell,
        h: torch.Tensor,
        prev: torch.Tensor,
        cur: torch.Tensor,
        active: torch.Tensor | None,
        neighbours: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One step: ``h`` (B, N, D) updated where ``active`` (B, N) bool, everywhere when None.

        ``prev``/``cur`` (B, N, 2) positions at the last two steps; ``neighbours`` (B, N) who may be pooled.
        Returns (h, head output).
        """
        batch, n_agents, _ = cur.shape
        displacement = cur - prev
        if active is not None:
            # an inactive agent's positions may be fill values: keep them out of its (discarded) update
            displacement = displacement * active.to(cur.dtype)[..., None]
        parts = [displacement]
        if self.pool is not None:
            # TrajNet++ detaches the pooled hidden states while training; a rollout keeps them attached so
            # that autograd gives the full Jacobian with respect to the robots' plan.
            pooled_hidden = h.detach() if self.training else h
            parts.append(self.pool(pooled_hidden, cur, neighbours))
        x = torch.relu(self.input_embedding(torch.cat(parts, dim=-1) * self.config.input_scale))
        x = torch.cat([x, x.new_zeros(batch, n_agents, N_TAGS)], dim=-1)
        h_new = cell(x.reshape(batch * n_agents, -1), h.reshape(batch * n_agents, -1))
        h_new = h_new.reshape(batch, n_agents, -1)
        h = h_new if active is None else torch.where(active[..., None], h_new, h)
        return h, self.output(h)

    # ---------------------------------------------------------------------------------------- phases
    def encode(self, positions: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Observed past (B, L, N, 2) with ``mask`` (B, L, N) -> decoder state ``h`` and the head output
        that predicts the first future position (``positions[:, -1] + out[..., :2]``)."""
        batch, length, n_agents, _ = positions.shape
        h = positions.new_zeros(batch, n_agents, self.config.hidden_dim)
        h = self._tag_step(self.encoder, h, slot=0)
        out = self.output(h)
        for t in range(1, length):
            active = mask[:, t - 1] & mask[:, t]
            h, out = self.step(self.encoder, h, positions[:, t - 1], positions[:, t], active, active)
        h = self._tag_step(self.decoder, h, slot=1)
        return h, out

    def decode_step(
        self, h: torch.Tensor, prev: torch.Tensor, cur: torch.Tensor, neighbours: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """A prediction step: every agent is updated; ``neighbours`` (B, N) marks who may be pooled."""
        return self.step(self.decoder, h, prev, cur, None, neighbours)

    def decode_step_masked(
        self,
        h: torch.Tensor,
        prev: torch.Tensor,
        cur: torch.Tensor,
        active: torch.Tensor,
        neighbours: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``decode_step`` updating only the ``active`` agents (teacher-forced training)."""
        return self.step(self.decoder, h, prev, cur, active, neighbours)
