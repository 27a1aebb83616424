"""What ``nets.rollout.teacher_forced_rollout`` feeds a net at each prediction step, by hand: with teacher
forcing the neighbours get their true positions at the step's two times and only agents seen at both are
pooled (the primary always is); without it every agent gets its own predictions and the agents present at
the last observed step are pooled. A recording net shows the inputs exactly."""

from __future__ import annotations

import torch

from predictors.nets.rollout import teacher_forced_rollout

OBS, PRED = 3, 3
STEP = torch.tensor([0.5, 0.0])  # every agent's predicted step, metres


class Recorder:
    """A step-contract net whose mean step is always ``STEP`` and which keeps what each step is given."""

    head_type = "point"

    def __init__(self):
        self.calls: list[tuple[torch.Tensor, ...]] = []

    def encode(self, positions, mask):
        batch, _, n, _ = positions.shape
        return positions.new_zeros(batch, n, 1), STEP.expand(batch, n, 2)

    def decode_step(self, state, prev, cur, neighbours):
        self.calls.append((prev, cur, neighbours))
        return state, STEP.expand(*cur.shape[:2], 2)


def scene() -> tuple[torch.Tensor, torch.Tensor]:
    """One scene, 3 agents, ``OBS + PRED`` steps; agent ``a`` at step ``t`` is at ``(t, 10 a)``; agent 2 is
    absent at step 4 (its entry the data's fill value 0)."""
    t = torch.arange(OBS + PRED, dtype=torch.float32)
    positions = torch.stack([torch.stack([t, torch.full_like(t, 10.0 * a)], -1) for a in range(3)], 1)[None]
    mask = torch.ones(1, OBS + PRED, 3, dtype=torch.bool)
    mask[0, 4, 2] = False
    positions = torch.where(mask[..., None], positions, torch.zeros(()))
    return positions, mask


def test_teacher_forcing_feeds_the_neighbours_true_positions_and_pools_only_those_seen_at_both():
    positions, mask = scene()
    mask[0, 4, 0] = False  # the primary's truth missing: it is fed its own predictions, so it stays active
    net = Recorder()
    _, predicted = teacher_forced_rollout(net, positions, mask, OBS, PRED, teacher_forcing=True)
    assert len(net.calls) == PRED - 1
    for k, (prev, cur, neighbours) in enumerate(net.calls, start=1):
        t = OBS - 1 + k  # the step's current time: it predicts t + 1
        assert torch.equal(prev[0, 1:], positions[0, t - 1, 1:]) and torch.equal(
            cur[0, 1:], positions[0, t, 1:]
        )
        # the primary is fed its own predictions: from (2, 0), 0.5 m a step
        assert torch.equal(cur[0, 0], torch.tensor([2.0 + 0.5 * k, 0.0]))
        seen = (mask[0, t - 1] & mask[0, t]).tolist()
        assert neighbours[0].tolist() == [True, *seen[1:]]
    # agent 2, absent at step 4: pooled at t = 3 (seen at 2 and 3), not at t = 4
    assert [c[2][0].tolist() for c in net.calls] == [[True, True, True], [True, True, False]]
    assert torch.equal(predicted[0, :, 1], positions[0, OBS - 1 : -1, 1] + STEP)  # one step from the truth


def test_free_rollout_feeds_every_agent_its_own_predictions_and_pools_those_present_when_observed_last():
    positions, mask = scene()
    mask[0, OBS - 1, 1] = False  # agent 1 unseen at the last observed step: never pooled
    net = Recorder()
    _, predicted = teacher_forced_rollout(net, positions, mask, OBS, PRED, teacher_forcing=False)
    now = positions[0, OBS - 1]
    for k, (prev, cur, neighbours) in enumerate(net.calls, start=1):
        assert torch.equal(prev[0], now + (k - 1) * STEP) and torch.equal(cur[0], now + k * STEP)
        assert neighbours[0].tolist() == [True, False, True]
    assert torch.equal(predicted[0], now + torch.arange(1, PRED + 1)[:, None, None] * STEP)
