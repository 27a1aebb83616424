"""Predictor nets that break the step contract (``predictors.nets.contract``) as a researcher's first try
might: each is ``ToyNet`` with one mistake. Registered as ``tests.plugins.broken_nets:NAME``; training,
loading from a zoo and the closed loop refuse each in one line."""

from __future__ import annotations

import random
from dataclasses import dataclass

import torch
from torch import nn

from tests.plugins.toy_predictor import ToyConfig, ToyNet


class OneColumn(ToyNet):
    """A 1-column head: ``out`` (B, N, 1), which ``cur + out[..., :2]`` would broadcast to x and y alike."""

    def __init__(self, config: ToyConfig):
        super().__init__(config)
        self.readout = nn.Linear(config.hidden_dim, 1)


class FlatOut(ToyNet):
    """``decode_step``'s ``out`` of shape (B, N): the step's two values folded into one per agent (its
    ``encode`` is right)."""

    def encode(self, positions, mask):
        h = positions.new_zeros(positions.shape[0], positions.shape[2], self.config.hidden_dim)
        return ToyNet.decode_step(self, h, positions[:, -2], positions[:, -1], mask[:, -1])

    def decode_step(self, h, prev, cur, neighbours):
        h, out = super().decode_step(h, prev, cur, neighbours)
        return h, out.sum(-1)


class AgentsFirst(ToyNet):
    """Its state laid out (N, B, H), as ``nn.LSTM`` lays out its hidden state, not (B, N, H)."""

    def decode_step(self, h, prev, cur, neighbours):
        h, out = super().decode_step(h.transpose(0, 1), prev, cur, neighbours)
        return h.transpose(0, 1), out

    def encode(self, positions, mask):
        h = positions.new_zeros(positions.shape[2], positions.shape[0], self.config.hidden_dim)
        return self.decode_step(h, positions[:, -2], positions[:, -1], mask[:, -1])


class GaussianOfTwo(ToyNet):
    """Says it has a Gaussian head (5 values: mean, sigmas, correlation) but outputs only the mean."""

    @property
    def head_type(self) -> str:
        return "gaussian"


class TorchHabitForward(ToyNet):
    """A ``forward(positions, mask)`` by torch habit, not the training rollout's signature."""

    def forward(self, positions: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return self.encode(positions, mask)


class ForwardReturnsPositions(ToyNet):
    """The training signature, but ``forward`` returns only the predicted positions."""

    def forward(self, positions, mask, obs_len, pred_len, *, teacher_forcing):
        from predictors.nets.rollout import teacher_forced_rollout

        args = (positions, mask, obs_len, pred_len)
        return teacher_forced_rollout(self, *args, teacher_forcing=teacher_forcing)[1]


class InFloat64(ToyNet):
    """Kept in float64 (``.double()``): its step keeps the contract in its own dtype, but training feeds
    float32 batches."""

    def __init__(self, config: ToyConfig):
        super().__init__(config)
        self.double()


class Frozen(ToyNet):
    """Every parameter frozen: nothing for the optimiser to train."""

    def __init__(self, config: ToyConfig):
        super().__init__(config)
        for p in self.parameters():
            p.requires_grad_(False)


class HeadTypeRaises(ToyNet):
    """A ``head_type`` property with a bug: it looks its head up in a table that lacks the key."""

    @property
    def head_type(self) -> str:
        return {"gaussian": "gaussian"}["point"]


class CastsToFloat32(ToyNet):
    """Its step output cast with ``.float()`` (a habit from float32 training): it keeps the contract in the
    float32 it trains in, and breaks it in the float64 the closed loop and the export run it in."""

    def decode_step(self, h, prev, cur, neighbours):
        h, out = super().decode_step(h, prev, cur, neighbours)
        return h, out.float()


class SqrtDistance(ToyNet):
    """Weighs its neighbours by their distance, ``sqrt`` of the squared one: 0 for an agent and itself,
    where sqrt's derivative is infinite. Its values are right; its Jacobian with respect to the robots' plan
    is NaN in torch and in its CasADi twin alike."""

    def decode_step(self, h, prev, cur, neighbours):
        rel = cur[:, None, :, :] - cur[:, :, None, :]
        weight = torch.exp(-torch.sqrt((rel * rel).sum(-1)) / self.config.radius)
        weight = weight * neighbours[:, None, :].to(cur.dtype)
        social = (weight[..., None] * rel).sum(2) / (weight.sum(2)[..., None] + 1.0)
        h = torch.tanh(self.embed(torch.cat([cur - prev, social], dim=-1)) + self.recur(h))
        return h, self.readout(h)


class DividesByItsOwnDistance(ToyNet):
    """Repels each agent from everyone by ``1 / d^2``, itself included (``d = 0``): its steps are NaN, its
    loss NaN from the first batch, its weights NaN after the first optimiser step."""

    def decode_step(self, h, prev, cur, neighbours):
        rel = cur[:, None, :, :] - cur[:, :, None, :]
        push = (rel / (rel * rel).sum(-1, keepdim=True)).sum(2)
        h = torch.tanh(self.embed(torch.cat([cur - prev, push], dim=-1)) + self.recur(h))
        return h, self.readout(h)


class CentresInPlace(ToyNet):
    """``encode`` centres the scene on its agents' mean last position in place (``positions -= c``): the
    caller's tensor changes with it. In training that is the batch itself, so the net was trained and
    validated against moved scenes (val ADE 9.3 m where the same net without it reaches 3.5 m), silently."""

    def encode(self, positions, mask):
        positions -= positions[:, -1:].mean(dim=2, keepdim=True)
        return super().encode(positions, mask)


class StepsStateInPlace(ToyNet):
    """``decode_step`` adds to its state in place (``h += ...``): the state the caller handed it changes."""

    def decode_step(self, h, prev, cur, neighbours):
        h += 0.0
        return super().decode_step(h, prev, cur, neighbours)


class ForwardCentresInPlace(ToyNet):
    """Its own training ``forward`` centres the batch in place before the generic rollout."""

    def forward(self, positions, mask, obs_len, pred_len, *, teacher_forcing):
        from predictors.nets.rollout import teacher_forced_rollout

        positions -= positions[:, obs_len - 1 : obs_len].mean(dim=2, keepdim=True)
        args = (positions, mask, obs_len, pred_len)
        return teacher_forced_rollout(self, *args, teacher_forcing=teacher_forcing)


class RaisesOnCrowds(ToyNet):
    """Written for small scenes: refuses more than 5 agents with its own ValueError. The contract's check
    (3 agents) passes it; the closed loop, with 7 humans and 3 robots, meets it."""

    def decode_step(self, h, prev, cur, neighbours):
        if cur.shape[1] > 5:
            raise ValueError(f"my pooling grid holds at most 5 agents, got {cur.shape[1]}")
        return super().decode_step(h, prev, cur, neighbours)


@dataclass(frozen=True)
class NoDefaultsConfig:
    """A config whose field has no default: the kind's defaults cannot build one."""

    width: int
    hidden_dim: int = 8
    radius: float = 2.0


class NoDefaults(ToyNet):
    """``ToyNet`` under a config that ``train`` cannot build without ``--net-config``."""

    config_class = NoDefaultsConfig


class ThreeAgentsOnly(ToyNet):
    """Mixes the agents with an ``nn.Linear(3, 3)``: it fits a batch of 3 agents and no other."""

    def __init__(self, config: ToyConfig):
        super().__init__(config)
        self.mix = nn.Linear(3, 3)

    def decode_step(self, h, prev, cur, neighbours):
        h, out = super().decode_step(h, prev, cur, neighbours)
        return h, self.mix(out.transpose(1, 2)).transpose(1, 2)


class NoPadding(ToyNet):
    """Takes every agent as present: the contract check's batches pass (all observed), a real batch padded to
    its largest scene (absent agents masked) fails."""

    def decode_step(self, h, prev, cur, neighbours):
        if not bool(neighbours.all()):
            raise ValueError("an absent agent in the batch")
        return super().decode_step(h, prev, cur, neighbours)


class NegativeSigmas(ToyNet):
    """A Gaussian head whose sigma_x is negative (a raw linear output, here made so for every seed): the
    NLL's log of sigma_x * sigma_y is NaN from the first step, while the mean, and so every validation ADE,
    is finite."""

    head_type = "gaussian"

    def __init__(self, config: ToyConfig):
        super().__init__(config)
        self.readout = nn.Linear(config.hidden_dim, 5)

    def decode_step(self, h, prev, cur, neighbours):  # ToyNet's encode steps through it too
        h, out = super().decode_step(h, prev, cur, neighbours)
        return h, self._gaussian(out)

    @staticmethod
    def _gaussian(raw):
        sigma_x = -0.1 - torch.nn.functional.softplus(raw[..., 2:3])  # with sigma_y > 0: log(sx sy) is NaN
        sigma_y = 0.1 + torch.nn.functional.softplus(raw[..., 3:4])
        return torch.cat([raw[..., :2], sigma_x, sigma_y, 0.5 * torch.tanh(raw[..., 4:5])], dim=-1)


class NaNFromItsThirdStep(ToyNet):
    """A net that trains, then diverges: its third training step on (the walk file's one batch an epoch: the
    third epoch) and every later one are NaN, as a learning rate that overshoots late does."""

    def __init__(self, config: ToyConfig):
        super().__init__(config)
        self.steps = 0  # training steps taken, per net (the contract check builds its own)

    def encode(self, positions, mask):
        h, out = super().encode(positions, mask)
        if self.training and torch.is_grad_enabled():
            self.steps += 1
            if self.steps >= 3:
                out = out * float("nan")
        return h, out


class DetachesItsPosition(ToyNet):
    """Steps from a detached copy of the current positions, a stop-gradient CasADi has no counterpart for:
    its exported values are torch's, its Jacobian with respect to the robots' plan is not."""

    def decode_step(self, h, prev, cur, neighbours):
        return super().decode_step(h, prev, cur.detach(), neighbours)


class VelocityWithoutGradients(ToyNet):
    """Takes its velocity under ``torch.no_grad()``, which a symbolic run (itself without gradients) cannot
    see: as ``DetachesItsPosition`` for the export, without a detach() to name."""

    def decode_step(self, h, prev, cur, neighbours):
        with torch.no_grad():
            velocity = cur - prev
        return super().decode_step(h, cur - velocity, cur, neighbours)


class NaNWhenEvaluated(ToyNet):
    """Trains as ``ToyNet`` does, and steps NaN in eval mode, as a predictor runs it (a dropout or a norm
    layer whose eval branch is wrong): its loss is finite, the net it leaves cannot predict."""

    def decode_step(self, h, prev, cur, neighbours):
        h, out = super().decode_step(h, prev, cur, neighbours)
        return h, out if self.training else out * float("nan")


class DrawsInPython(ToyNet):
    """Adds a draw of Python's ``random`` to each step: a constant to the exporter, which traces the net once,
    and another number at each torch rollout."""

    def decode_step(self, h, prev, cur, neighbours):
        h, out = super().decode_step(h, prev, cur, neighbours)
        return h, out + 0.01 * random.random()


class NoisySteps(ToyNet):
    """Adds torch's noise to each step, in eval mode too: another prediction at each call."""

    def decode_step(self, h, prev, cur, neighbours):
        h, out = super().decode_step(h, prev, cur, neighbours)
        return h, out + 0.01 * torch.randn_like(out)
