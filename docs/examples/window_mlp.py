"""A complete user predictor in one file, outside the crowdmpc package (docs/extending.md walks through it).

WindowMLP predicts each agent's next step from its last K steps and a summary of its neighbours: the sum of
their relative positions, each weighted by exp(-d^2 / r^2), so that near neighbours count most. The state it
carries between steps is the window of the last K displacements, one row per agent.

Use it with ``crowdmpc --plugin window_mlp:WindowMLP ...`` from the directory that holds this file (or put
the directory on PYTHONPATH, or declare an entry point in the group ``crowdmpc.predictors``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class WindowMLPConfig:
    window: int = 4  # displacements the MLP sees
    hidden: int = 32
    radius: float = 1.5  # metres: neighbours much farther than this barely count

    def __post_init__(self):  # a config comes from a JSON file: refuse what would build a useless net
        if not (isinstance(self.window, int) and 1 <= self.window <= 16):
            raise ValueError(f"window must be an integer in 1..16, got {self.window!r}")
        if not (isinstance(self.hidden, int) and 1 <= self.hidden <= 1024):
            raise ValueError(f"hidden must be an integer in 1..1024, got {self.hidden!r}")
        if not (isinstance(self.radius, (int, float)) and 0 < self.radius <= 20):
            raise ValueError(f"radius must be a number in (0, 20], got {self.radius!r}")


class WindowMLP(nn.Module):
    config_class = WindowMLPConfig
    head_type = "point"  # out is the mean step itself; trained with the L2 loss

    def __init__(self, config: WindowMLPConfig = WindowMLPConfig()):
        super().__init__()
        self.config = config
        self.mlp = nn.Sequential(
            nn.Linear(2 * config.window + 2, config.hidden), nn.Tanh(), nn.Linear(config.hidden, 2)
        )

    def _out(self, window, cur, neighbours):
        relative = cur[:, None, :, :] - cur[:, :, None, :]  # (B, N, N, 2): j's position seen from i
        weight = torch.exp(-(relative**2).sum(-1) / self.config.radius**2)
        others = 1 - torch.eye(cur.shape[1], dtype=cur.dtype)  # never one's own neighbour
        weight = weight * others * neighbours.to(cur.dtype)[:, None, :]
        social = (weight[..., None] * relative).sum(2)
        return self.mlp(torch.cat([window * 4.0, social], dim=-1))

    def encode(self, positions, mask):
        batch, length, n_agents, _ = positions.shape
        window = positions.new_zeros(batch, n_agents, 2 * self.config.window)
        for t in range(1, length):
            seen = (mask[:, t - 1] & mask[:, t])[..., None]
            step = (positions[:, t] - positions[:, t - 1]) * seen.to(positions.dtype)
            window = torch.cat([window[..., 2:], step], dim=-1)
        return window, self._out(window, positions[:, -1], mask[:, -1])

    def decode_step(self, window, prev, cur, neighbours):
        window = torch.cat([window[..., 2:], cur - prev], dim=-1)
        return window, self._out(window, cur, neighbours)
