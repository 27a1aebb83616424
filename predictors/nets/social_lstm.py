"""Social-LSTM as TrajNet++ builds it (Alahi et al. 2016; Kothari et al. 2021, ``trajnetbaselines/lstm``).

Per agent: the displacement since the last step and the pooled neighbours' hidden states are scaled by 4,
embedded (``Linear + ReLU``) and fed to an LSTM cell (one difference from TrajNet++, which embeds the
displacement alone and appends the pooled vector to that embedding; the shipped weights use this layout,
so changing it means retraining); a linear head gives the next displacement as a
bivariate Gaussian (mean, sigmas, correlation) or as a point. Separate encoder and decoder cells, start tags
on two spare embedding slots, single-step prediction applied recursively: the encoder's last step predicts
the first future position, each decoder step the next one from the previous prediction. ``pooling="none"``
is the vanilla LSTM (the ablation); ``"grid"`` TrajNet++'s hard social grid; ``"soft"`` its differentiable
twin. ``noise_dim > 0`` makes it the generator of the Social-GAN-like model (``nets.social_gan``).

Shapes: ``B`` scenes, ``N`` agents, positions in metres, tensors ``(B, N, ...)`` per step. Missing entries
are masked, never NaN. ``predictors.export`` turns ``encode`` and ``decode_step`` into CasADi functions.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Protocol

import torch
from torch import nn

from predictors.errors import PredictorError, short_repr
from predictors.net_size import MAX_PARAMETERS
from predictors.nets.config_checks import config_from_dict, config_to_dict, wrong_type
from predictors.nets.pooling import POOLINGS, GridPooling, pooling_for
from predictors.nets.rollout import teacher_forced_rollout

HEADS = ("gaussian", "point")
N_TAGS = 2  # TrajNet++ InputEmbedding keeps two embedding slots for the encoder/decoder start tags

# Bounds on a config, checked before any tensor is allocated: a zoo config is a file anyone can edit, and one
# hidden size of 4e6 asked torch for 256 TB. TrajNet++'s defaults are hidden 128, embedding 64, grid 12,
# latent 16, pool 256 (0.8 M parameters); the shipped nets have 13 k to 16 k. Each width may be 4096
# (32x TrajNet++'s hidden size), the grid 64 cells a side, and the whole net at most 10 M parameters (80 MB
# in float64, the predictor's copy; 12x TrajNet++'s; net_size.MAX_PARAMETERS, every kind's bound): far more
# than the MPC's CasADi twin can evaluate at control rate, so no net that could be used is refused, and no
# file can make us allocate more.
SIZE_BOUNDS: dict[str, tuple[int, int]] = {
    "hidden_dim": (1, 4096),
    "embedding_dim": (N_TAGS + 1, 4096),
    "grid_size": (1, 64),  # 64 x 64 cells of cell_side
    "latent_dim": (1, 4096),
    "pool_dim": (1, 4096),
    "noise_dim": (0, 4096),
}
# Upper bounds of the positive float settings: a cell of 100 m spans any scene; inputs scaled by more than
# 1000 saturate every unit.
FLOAT_BOUNDS: dict[str, float] = {"cell_side": 100.0, "input_scale": 1000.0}
LABEL = "Social-LSTM"


@dataclass(frozen=True)
class SocialLSTMConfig:
    """Hyper-parameters; TrajNet++'s defaults in brackets. Ours are small so that one CPU epoch on ETH takes
    seconds and the CasADi twin stays cheap inside the MPC: the pooling's ``grid_size**2 * latent_dim``
    inputs dominate its cost (10 agents, 3 symbolic steps: 8x8x8 cells/latent cost 1.1 ms an evaluation and
    11 ms a Jacobian, 6x6x4 cost 0.5 ms and 3.7 ms)."""

    pooling: str = "grid"  # "none" (vanilla LSTM) | "grid" (hard, TrajNet++) | "soft" (bilinear)
    hidden_dim: int = 32  # LSTM hidden size D [128]
    embedding_dim: int = 16  # input embedding incl. the 2 tag slots [64]
    cell_side: float = 0.8  # m, side of one pooling cell [0.6]; the grid spans +-2.4 m around the agent
    grid_size: int = 6  # cells per side of the pooling grid [12]
    latent_dim: int = 4  # neighbours' hidden states are compressed to this before pooling [16]
    pool_dim: int = 16  # pooled interaction vector [256]
    input_scale: float = 4.0  # inputs (displacement and pooled vector) are multiplied by this [4.0]
    noise_dim: int = 0  # > 0: generator of the GAN, noise added to the decoder's initial hidden state
    head: str = "gaussian"  # "gaussian" (5 outputs, TrajNet++ Hidden2Normal) | "point" (2 outputs)

    def __post_init__(self):
        # Types first: a config comes from a JSON file that anyone can edit, and a float, bool or string size
        # would otherwise reach torch (a traceback) or a comparison (a TypeError).
        for name in ("pooling", "head"):
            if not isinstance(getattr(self, name), str):
                raise wrong_type(LABEL, name, "a string", getattr(self, name))
        if self.pooling not in POOLINGS:
            raise PredictorError(f"pooling {short_repr(self.pooling)} is not one of {list(POOLINGS)}")
        if self.head not in HEADS:
            raise PredictorError(f"head {short_repr(self.head)} is not one of {list(HEADS)}")
        for name, (low, high) in SIZE_BOUNDS.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral):
                raise wrong_type(LABEL, name, "an integer", value)
            if not low <= value <= high:
                if name == "embedding_dim" and value <= N_TAGS:
                    raise PredictorError(f"embedding_dim must be > {N_TAGS} (start-tag slots), got {value}")
                raise PredictorError(f"{name} must be in {low}..{high}, got {value}")
        for name, high_f in FLOAT_BOUNDS.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise wrong_type(LABEL, name, "a number", value)
            if not math.isfinite(value):
                raise PredictorError(f"{name} must be a finite number, got {value!r}")
            if not 0 < value <= high_f:
                raise PredictorError(f"{name} must be in (0, {high_f:g}], got {value}")
        count = self.parameter_count()
        if count > MAX_PARAMETERS:
            raise PredictorError(
                f"this net would have {count:,} parameters, more than the {MAX_PARAMETERS:,} allowed "
                "(hidden_dim, embedding_dim, grid_size**2 * latent_dim * pool_dim too large)"
            )

    def parameter_count(self) -> int:
        """The number of parameters ``SocialLSTM(self)`` has, computed without allocating them."""
        noise = self.noise_dim * self.hidden_dim  # the generator's noise projection, no bias
        return pooled_rnn_parameter_count(self, gates=4) + noise

    def to_dict(self) -> dict:
        return config_to_dict(self)

    @classmethod
    def from_dict(cls, values: dict) -> SocialLSTMConfig:
        return config_from_dict(cls, values, LABEL)


class PooledRNNSizes(Protocol):
    """The sizes of a net laid out as Social-LSTM (``SocialLSTMConfig``, ``nets.social_gru``'s config)."""

    @property
    def pooling(self) -> str: ...
    @property
    def hidden_dim(self) -> int: ...
    @property
    def embedding_dim(self) -> int: ...
    @property
    def grid_size(self) -> int: ...
    @property
    def latent_dim(self) -> int: ...
    @property
    def pool_dim(self) -> int: ...
    @property
    def head(self) -> str: ...


def pooled_rnn_parameter_count(sizes: PooledRNNSizes, gates: int) -> int:
    """The parameters of Social-LSTM's layout with recurrent cells of ``gates`` gates (LSTM 4, GRU 3): the
    pooling, the input embedding, the encoder and decoder cells and the head (a GAN generator's noise
    projection not included), counted without allocating them."""

    def linear(n_in: int, n_out: int) -> int:
        return n_in * n_out + n_out

    count = 0
    pooled = 0
    if sizes.pooling != "none":
        count += linear(sizes.hidden_dim, sizes.latent_dim)
        count += linear(sizes.grid_size**2 * sizes.latent_dim, sizes.pool_dim)
        pooled = sizes.pool_dim
    count += linear(2 + pooled, sizes.embedding_dim - N_TAGS)
    # encoder and decoder cells: weight_ih, weight_hh and two biases, for each gate
    count += 2 * gates * sizes.hidden_dim * (sizes.embedding_dim + sizes.hidden_dim + 2)
    return count + linear(sizes.hidden_dim, 5 if sizes.head == "gaussian" else 2)


def gaussian_head(raw: torch.Tensor) -> torch.Tensor:
    """TrajNet++ ``Hidden2Normal``: bounded sigmas and correlation for numerical stability."""
    return torch.cat(
        [
            raw[..., :2],
            0.01 + 0.2 * torch.sigmoid(raw[..., 2:4]),
            0.7 * torch.sigmoid(raw[..., 4:5]),
        ],
        dim=-1,
    )


class SocialLSTM(nn.Module):
    config_class = SocialLSTMConfig  # the step contract (predictors/nets/contract.py)

    def __init__(self, config: SocialLSTMConfig = SocialLSTMConfig()):
        super().__init__()
        self.config = config
        cfg = config
        self.pool: GridPooling | None
        self.pool, pooled = pooling_for(cfg)
        self.input_embedding = nn.Linear(2 + pooled, cfg.embedding_dim - N_TAGS)
        self.encoder = nn.LSTMCell(cfg.embedding_dim, cfg.hidden_dim)
        self.decoder = nn.LSTMCell(cfg.embedding_dim, cfg.hidden_dim)
        self.head = nn.Linear(cfg.hidden_dim, 5 if cfg.head == "gaussian" else 2)
        self.noise = nn.Linear(cfg.noise_dim, cfg.hidden_dim, bias=False) if cfg.noise_dim else None

    @property
    def head_type(self) -> str:  # the contract's name: ``head`` is the output layer, as in TrajNet++
        return self.config.head

    # ------------------------------------------------------------------------------------------ pieces
    def output(self, hidden: torch.Tensor) -> torch.Tensor:
        """Head on hidden states: (..., 5) Gaussian parameters or (..., 2) a step; the mean is [..., :2]."""
        raw = self.head(hidden)
        return gaussian_head(raw) if self.config.head == "gaussian" else raw

    def _tag_step(self, cell: nn.LSTMCell, h: torch.Tensor, c: torch.Tensor, slot: int):
        batch, n_agents, _ = h.shape
        tag = h.new_zeros(batch * n_agents, self.config.embedding_dim)
        tag[:, self.config.embedding_dim - N_TAGS + slot] = 1
        h, c = cell(tag, (h.reshape(batch * n_agents, -1), c.reshape(batch * n_agents, -1)))
        return h.reshape(batch, n_agents, -1), c.reshape(batch, n_agents, -1)

    def step(
        self,
        cell: nn.LSTMCell,
        h: torch.Tensor,
        c: torch.Tensor,
        prev: torch.Tensor,
        cur: torch.Tensor,
        active: torch.Tensor,
        neighbours: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One step for every agent: (h, c) updated where ``active``; returns (h, c, head output).

        ``prev``/``cur`` (B, N, 2) positions at the last two steps; ``active`` (B, N) bool: the agent is seen
        at both; ``neighbours`` (B, N): who may be pooled (TrajNet++ pools only agents present at the step).
        """
        batch, n_agents, _ = cur.shape
        active_f = active.to(cur.dtype)[..., None]
        parts = [(cur - prev) * active_f]
        if self.pool is not None:
            # TrajNet++ detaches the pooled hidden states while training; a rollout keeps them attached so
            # that autograd gives the full Jacobian with respect to the robots' plan.
            pooled_hidden = h.detach() if self.training else h
            parts.append(self.pool(pooled_hidden, cur, neighbours))
        x = torch.relu(self.input_embedding(torch.cat(parts, dim=-1) * self.config.input_scale))
        x = torch.cat([x, x.new_zeros(batch, n_agents, N_TAGS)], dim=-1)
        h_new, c_new = cell(
            x.reshape(batch * n_agents, -1),
            (h.reshape(batch * n_agents, -1), c.reshape(batch * n_agents, -1)),
        )
        h = torch.where(active[..., None], h_new.reshape(batch, n_agents, -1), h)
        c = torch.where(active[..., None], c_new.reshape(batch, n_agents, -1), c)
        return h, c, self.output(h)

    # ---------------------------------------------------------------------------------------- phases
    def encode(
        self, positions: torch.Tensor, mask: torch.Tensor, noise: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Observed past -> decoder state and the head output that predicts the first future position.

        ``positions`` (B, L, N, 2) with ``mask`` (B, L, N); the first future position of agent ``n`` is
        ``positions[:, -1, n] + out[..., n, :2]``. ``noise`` (B, N, noise_dim) only for a generator
        (None = zeros, the deterministic prediction).
        """
        batch, length, n_agents, _ = positions.shape
        h = positions.new_zeros(batch, n_agents, self.config.hidden_dim)
        c = torch.zeros_like(h)
        h, c = self._tag_step(self.encoder, h, c, slot=0)
        out = self.output(h)
        for t in range(1, length):
            active = mask[:, t - 1] & mask[:, t]
            h, c, out = self.step(self.encoder, h, c, positions[:, t - 1], positions[:, t], active, active)
        if self.noise is not None and noise is not None:
            h = h + self.noise(noise)
        h, c = self._tag_step(self.decoder, h, c, slot=1)
        if self.noise is not None:
            # The generator's first prediction comes from the decoder, so that the noise shapes it too.
            active = mask[:, -2] & mask[:, -1] if length > 1 else torch.zeros_like(mask[:, -1])
            prev = positions[:, -2] if length > 1 else positions[:, -1]
            h, c, out = self.step(self.decoder, h, c, prev, positions[:, -1], active, active)
        return h, c, out

    def decode_step(self, h, c, prev, cur, neighbours):
        """A prediction step: every agent is updated; ``neighbours`` (B, N) marks who may be pooled."""
        active = torch.ones(cur.shape[:2], dtype=torch.bool, device=cur.device)
        return self.step(self.decoder, h, c, prev, cur, active, neighbours)

    def decode_step_masked(self, h, c, prev, cur, active, neighbours):
        """``decode_step`` updating only the ``active`` agents (teacher-forced training)."""
        return self.step(self.decoder, h, c, prev, cur, active, neighbours)

    def forward(
        self,
        positions: torch.Tensor,
        mask: torch.Tensor,
        obs_len: int,
        pred_len: int,
        *,
        teacher_forcing: bool,
        noise: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Scenes (B, T, N, 2) with the primary agent at index 0 -> (outputs, predicted positions).

        Returns head outputs (B, pred_len, N, 5|2) for the displacements into steps ``obs_len ..`` and the
        predicted positions (B, pred_len, N, 2). With ``teacher_forcing`` (TrajNet++ training), the
        neighbours' inputs are their true positions and only the primary is fed its own predictions;
        without it (evaluation) every agent is fed its own predictions and agents present at the last
        observed step are pooled.
        """
        encoded = self.encode(positions[:, :obs_len], mask[:, :obs_len], noise)
        return teacher_forced_rollout(
            self,
            positions,
            mask,
            obs_len,
            pred_len,
            teacher_forcing=teacher_forcing,
            encoded=encoded,
            masked_step=self.decode_step_masked,
        )
