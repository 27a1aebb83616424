"""A user's predictor as a plugin: a small net that keeps the step contract (``predictors.nets.contract``)
and lives outside the package. Registered as ``tests.plugins.toy_predictor:ToyNet``.

Per agent and step: its last displacement and the mean of its neighbours' positions relative to it, each
neighbour weighted by ``exp(-d**2 / radius**2)``, go through a tanh recurrent cell; a linear head gives the
next displacement (a point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import torch
from torch import nn


@dataclass(frozen=True)
class ToyConfig:
    hidden_dim: int = 8  # width of the recurrent state
    radius: float = 2.0  # m, the distance at which a neighbour's weight has fallen to 1/e

    def __post_init__(self):
        if isinstance(self.hidden_dim, bool) or not isinstance(self.hidden_dim, int):
            raise TypeError(f"hidden_dim must be an integer, got {self.hidden_dim!r}")
        if not 1 <= self.hidden_dim <= 4096:
            raise ValueError(f"hidden_dim must be in 1..4096, got {self.hidden_dim}")
        if isinstance(self.radius, bool) or not isinstance(self.radius, int | float):
            raise TypeError(f"radius must be a number, got {self.radius!r}")
        if not (math.isfinite(self.radius) and 0 < self.radius <= 100):
            raise ValueError(f"radius must be in (0, 100], got {self.radius}")


class ToyNet(nn.Module):
    config_class: ClassVar[type] = ToyConfig

    def __init__(self, config: ToyConfig = ToyConfig()):
        super().__init__()
        self.config = config
        self.embed = nn.Linear(4, config.hidden_dim)
        self.recur = nn.Linear(config.hidden_dim, config.hidden_dim)
        self.readout = nn.Linear(config.hidden_dim, 2)

    @property
    def head_type(self) -> str:  # the step contract: "gaussian" or "point"
        return "point"

    def encode(self, positions: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """The state after the last observed step: one step of the cell from a zero state."""
        batch, _, n, _ = positions.shape
        h = positions.new_zeros(batch, n, self.config.hidden_dim)
        both = (mask[:, -1] & mask[:, -2]).to(positions.dtype)[..., None]  # a displacement needs both steps
        prev = positions[:, -2] * both + positions[:, -1] * (1 - both)
        return self.decode_step(h, prev, positions[:, -1], mask[:, -1])

    def decode_step(
        self, h: torch.Tensor, prev: torch.Tensor, cur: torch.Tensor, neighbours: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        rel = cur[:, None, :, :] - cur[:, :, None, :]  # (B, N, N, 2): j relative to i (0 for j = i)
        weight = torch.exp(-(rel * rel).sum(-1) / self.config.radius**2)
        weight = weight * neighbours[:, None, :].to(cur.dtype)
        social = (weight[..., None] * rel).sum(2) / (weight.sum(2)[..., None] + 1.0)
        h = torch.tanh(self.embed(torch.cat([cur - prev, social], dim=-1)) + self.recur(h))
        return h, self.readout(h)
