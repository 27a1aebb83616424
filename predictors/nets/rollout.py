"""The training rollout of any net that keeps the step contract (``nets.contract``), TrajNet++ style.

``teacher_forced_rollout`` is ``SocialLSTM.forward`` written only in terms of ``encode`` / ``decode_step``:
the observed past is encoded, then each future step is predicted from the previous two positions. With
teacher forcing (TrajNet++ training) the neighbours' inputs are their true positions and only the primary
(index 0) is fed its own predictions; without it (evaluation) every agent is fed its own predictions and
the agents present at the last observed step may be attended to.

Under teacher forcing a neighbour is updated at a step only where it is seen at both of its positions, and
only such agents are pooled: that needs a ``masked_step(*state, prev, cur, active, neighbours)`` which
updates only the ``active`` agents. A net may pass its own; otherwise ``decode_step`` runs for everyone with
``neighbours = active`` and the state of the inactive agents is put back (``torch.where``), which gives the
same state and the same outputs for every active agent (the primary is always active).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch

from predictors.errors import PredictorError

MaskedStep = Callable[..., tuple[torch.Tensor, ...]]
# A net keeping ``nets.contract.StepNet``. Typed ``Any``: the protocol's variadic ``decode_step`` matches no
# concrete signature (``decode_step(h, c, prev, cur, neighbours)``), so mypy could not check it anyway.
Net = Any


def masked_by_where(net: Net) -> MaskedStep:
    """A ``masked_step`` from ``net.decode_step``: the inactive agents keep their state."""

    def step(*args: torch.Tensor) -> tuple[torch.Tensor, ...]:
        *state, prev, cur, active, neighbours = args
        *new_state, out = net.decode_step(*state, prev, cur, neighbours)
        kept = []
        for new, old in zip(new_state, state, strict=True):
            # state tensors are (B, N, ...): broadcast the (B, N) mask over the trailing dimensions
            where = active.reshape(*active.shape, *([1] * (old.dim() - 2)))
            kept.append(torch.where(where, new, old))
        return (*kept, out)

    return step


def teacher_forced_rollout(
    net: Net,
    positions: torch.Tensor,
    mask: torch.Tensor,
    obs_len: int,
    pred_len: int,
    *,
    teacher_forcing: bool,
    encoded: tuple[torch.Tensor, ...] | None = None,
    masked_step: MaskedStep | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Scenes (B, T, N, 2) with ``mask`` (B, T, N), primary at index 0 -> (outputs, predicted positions).

    ``outputs`` (B, pred_len, N, K) are the head outputs for the displacements into steps ``obs_len ..``,
    ``predicted`` (B, pred_len, N, 2) the positions. ``encoded`` replaces ``net.encode`` of the observed
    steps (a generator encodes with its noise); ``masked_step`` see the module docstring.
    """
    observed = positions[:, :obs_len]
    observed_mask = mask[:, :obs_len]
    *state, out = encoded if encoded is not None else net.encode(observed, observed_mask)
    step = masked_step if masked_step is not None else masked_by_where(net)
    now = observed[:, -1]
    outputs = [out]
    predicted = [now + out[..., :2]]
    present = observed_mask[:, -1]
    prev_model, cur_model = now, predicted[0]
    for k in range(1, pred_len):
        prev_in, cur_in = prev_model, cur_model
        if isinstance(net, torch.nn.Module) and net.training:
            # TrajNet++ "DETACH!!!": no gradient through the fed-back positions
            prev_in, cur_in = prev_in.detach(), cur_in.detach()
        if teacher_forcing:
            t = obs_len - 1 + k
            prev_in = torch.cat([prev_in[:, :1], positions[:, t - 1, 1:]], dim=1)
            cur_in = torch.cat([cur_in[:, :1], positions[:, t, 1:]], dim=1)
            active = mask[:, t - 1] & mask[:, t]
            active = torch.cat([torch.ones_like(active[:, :1]), active[:, 1:]], dim=1)
            *state, out = step(*state, prev_in, cur_in, active, active)
        else:
            *state, out = net.decode_step(*state, prev_in, cur_in, present)
        outputs.append(out)
        predicted.append(cur_in + out[..., :2])
        prev_model, cur_model = cur_in, predicted[-1]
    return torch.stack(outputs, dim=1), torch.stack(predicted, dim=1)


class TeacherForcedForward:
    """``forward`` for a step-contract net that has ``decode_step_masked``: ``teacher_forced_rollout`` with
    that step, the training and evaluation rollout ``SocialLSTM.forward`` does (no noise: not a GAN)."""

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
        if noise is not None:
            raise PredictorError(f"{type(self).__name__} takes no noise (it is not a GAN generator)")
        return teacher_forced_rollout(
            self,
            positions,
            mask,
            obs_len,
            pred_len,
            teacher_forcing=teacher_forcing,
            masked_step=self.decode_step_masked,  # type: ignore[attr-defined]
        )
