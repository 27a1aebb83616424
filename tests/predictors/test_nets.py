"""The torch networks: shapes, masking, who influences whom, heads and losses with hand-computed numbers."""

from __future__ import annotations

import math

import pytest
import torch

from predictors.errors import PredictorError
from predictors.nets.losses import VARIETY_ERRORS, gaussian_nll, l2_loss, variety_loss
from predictors.nets.pooling import cell_weights
from predictors.nets.social_gan import Discriminator, generator_config
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig, gaussian_head


def walking_batch(batch: int = 2, agents: int = 3, steps: int = 21) -> tuple[torch.Tensor, torch.Tensor]:
    """Agents walking in parallel 0.6 m apart (inside each other's pooling grid), 0.4 m per step."""
    t = torch.arange(steps, dtype=torch.float32)[:, None]
    positions = torch.stack(
        [torch.cat([0.4 * t, torch.full_like(t, 0.6 * a)], dim=1) for a in range(agents)], 1
    )
    return positions[None].repeat(batch, 1, 1, 1), torch.ones(batch, steps, agents, dtype=torch.bool)


@pytest.mark.parametrize("pooling", ["none", "grid", "soft"])
@pytest.mark.parametrize("teacher_forcing", [True, False])
def test_forward_shapes(pooling, teacher_forcing):
    net = SocialLSTM(SocialLSTMConfig(pooling=pooling))
    positions, mask = walking_batch()
    outputs, predicted = net(positions, mask, 9, 12, teacher_forcing=teacher_forcing)
    assert outputs.shape == (2, 12, 3, 5)
    assert predicted.shape == (2, 12, 3, 2)
    assert torch.isfinite(predicted).all()


def test_gaussian_head_bounds():
    params = gaussian_head(torch.tensor([[0.3, -0.2, -100.0, 100.0, 100.0]]))
    assert params[0, :2].tolist() == pytest.approx([0.3, -0.2])
    assert params[0, 2].item() == pytest.approx(0.01)  # 0.01 + 0.2 * sigmoid(-100)
    assert params[0, 3].item() == pytest.approx(0.21)
    assert params[0, 4].item() == pytest.approx(0.7)
    # TrajNet++'s Hidden2Normal bounds the correlation to (0, 0.7): never negative (a tanh would allow -0.7)
    low = gaussian_head(torch.tensor([[0.0, 0.0, 100.0, -100.0, -100.0]]))
    assert low[0, 2:].tolist() == pytest.approx([0.21, 0.01, 0.0])


def test_hard_grid_bins_a_neighbour_on_a_cell_edge_as_trajnet_floors_it():
    """Grid 2 x 2 of 1 m cells around agent 0 (u = relative + 1, cell floor(ux) * 2 + floor(uy)): a neighbour
    on an inner edge goes to the upper cell only, one on the grid's outer edge is out of range."""
    positions = torch.tensor([[[0.0, 0.0], [0.0, 0.0], [-1.0, 0.0], [1.0, -0.5]]], dtype=torch.float64)
    weights = cell_weights(
        positions, torch.ones(1, 4, dtype=torch.bool), cell_side=1.0, grid_size=2, soft=False
    )
    assert weights[0, 0].tolist() == [
        [0.0, 0.0, 0.0, 0.0],  # itself: never pooled
        [0.0, 0.0, 0.0, 1.0],  # u = (1, 1): cell (1, 1)
        [0.0, 1.0, 0.0, 0.0],  # u = (0, 1): cell (0, 1)
        [0.0, 0.0, 0.0, 0.0],  # u = (2, 0.5): beyond the grid
    ]


def primary_prediction(net, positions, mask):
    with torch.no_grad():
        return net.eval()(positions, mask, 9, 12, teacher_forcing=False)[1][:, :, 0]


def test_neighbours_influence_only_through_pooling():
    torch.manual_seed(0)
    positions, mask = walking_batch(batch=1)
    moved = positions.clone()
    moved[:, :, 1, 1] += 0.3  # the neighbour walks 0.3 m further out
    vanilla = SocialLSTM(SocialLSTMConfig(pooling="none"))
    assert torch.equal(primary_prediction(vanilla, positions, mask), primary_prediction(vanilla, moved, mask))
    social = SocialLSTM(SocialLSTMConfig(pooling="soft"))
    assert not torch.allclose(
        primary_prediction(social, positions, mask), primary_prediction(social, moved, mask)
    )


def test_absent_and_distant_agents_do_not_influence_the_primary():
    torch.manual_seed(0)
    net = SocialLSTM(SocialLSTMConfig(pooling="soft"))
    positions, mask = walking_batch(batch=1)
    alone = primary_prediction(net, positions[:, :, :1], mask[:, :, :1])
    absent_mask = mask.clone()
    absent_mask[:, :, 1:] = False
    assert torch.allclose(primary_prediction(net, positions, absent_mask), alone, atol=1e-6)
    far = positions.clone()
    far[:, :, 1:, 1] += 10.0  # 10 m away: outside every grid
    assert torch.allclose(primary_prediction(net, far, mask), alone, atol=1e-6)


def test_in_eval_mode_a_neighbours_past_reaches_the_primary_gradient():
    torch.manual_seed(0)
    net = SocialLSTM(SocialLSTMConfig(pooling="soft"))
    positions, mask = walking_batch(batch=1)
    positions.requires_grad_(True)
    net.eval()
    _, predicted = net(positions, mask, 9, 12, teacher_forcing=False)
    (grad,) = torch.autograd.grad(predicted[:, -1, 0].sum(), positions)
    assert grad[:, :9, 1].abs().sum() > 0  # the neighbour's past reaches the primary


def test_generator_noise_changes_predictions_and_zero_noise_is_deterministic():
    torch.manual_seed(0)
    net = SocialLSTM(generator_config(pooling="soft"))
    torch.nn.init.normal_(net.noise.weight)
    positions, mask = walking_batch(batch=1)
    net.eval()
    zero = torch.zeros(1, 3, net.config.noise_dim)
    with torch.no_grad():
        a = net(positions, mask, 9, 12, teacher_forcing=False, noise=zero)[1]
        b = net(positions, mask, 9, 12, teacher_forcing=False, noise=None)[1]
        c = net(positions, mask, 9, 12, teacher_forcing=False, noise=torch.randn(1, 3, net.config.noise_dim))[
            1
        ]
    assert torch.equal(a, b)
    assert not torch.allclose(a, c)
    assert a.shape == (1, 12, 3, 2)


def test_discriminator_scores_each_trajectory():
    logits = Discriminator()(torch.randn(5, 21, 2))
    assert logits.shape == (5,)


def test_gaussian_nll_hand_computed():
    # target at the mean, sigma 0.1 and 0.2, rho 0: NLL = log(2 pi * 0.1 * 0.2)
    params = torch.tensor([[0.0, 0.0, 0.1, 0.2, 0.0]])
    nll = gaussian_nll(params, torch.zeros(1, 2), torch.ones(1))
    assert nll.item() == pytest.approx(math.log(2 * math.pi * 0.02), abs=1e-6)
    # one sigma off along x adds 1/2
    nll = gaussian_nll(params, torch.tensor([[0.1, 0.0]]), torch.ones(1))
    assert nll.item() == pytest.approx(math.log(2 * math.pi * 0.02) + 0.5, abs=1e-6)


def test_gaussian_nll_with_correlation_hand_computed():
    """The correlation terms: rho 0.5, the target one sigma off on both axes, z = (1, 1) or (1, -1).

    NLL = log(2 pi sx sy) + log(1 - rho^2) / 2 + (zx^2 + zy^2 - 2 rho zx zy) / (2 (1 - rho^2))."""
    params = torch.tensor([[0.0, 0.0, 0.1, 0.2, 0.5]], dtype=torch.float64)
    base = math.log(2 * math.pi * 0.02) + 0.5 * math.log(0.75)
    along = gaussian_nll(params, torch.tensor([[0.1, 0.2]], dtype=torch.float64), torch.ones(1))
    assert along.item() == pytest.approx(base + (2 - 1) / 1.5, abs=1e-12)  # 2/3: the correlation helps
    across = gaussian_nll(params, torch.tensor([[0.1, -0.2]], dtype=torch.float64), torch.ones(1))
    assert across.item() == pytest.approx(base + (2 + 1) / 1.5, abs=1e-12)  # 2: against the correlation


def test_l2_and_variety_loss_hand_computed():
    weight = torch.ones(1, 2)
    assert l2_loss(torch.tensor([[[3.0, 4.0]]]), torch.zeros(1, 1, 2), torch.ones(1, 1)).item() == 5.0
    target = torch.zeros(1, 2, 2)
    samples = torch.stack([torch.full((1, 2, 2), 3.0), torch.tensor([[[0.3, 0.4], [0.0, 0.0]]])])
    # sample 0: mean distance 3 sqrt 2; sample 1: (0.5 + 0) / 2 = 0.25 -> the best counts
    assert variety_loss(samples, target, weight).item() == pytest.approx(0.25)


def _variety_scenes() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Two scenes of five steps at the origin, two samples each, ``(samples, target, valid)``.

    Scene 0, steps 0-3 valid: sample 0 misses by 2 m once (distance 2 / 4 = 0.5, squared 4 / 4 = 1), sample
    1 by 0.6 m at each step (distance 2.4 / 4 = 0.6, squared 4 * 0.36 / 4 = 0.36) and by 100 m at the
    masked step 4. Scene 1, steps 0-1 valid: sample 0 misses by 0.5 m once (0.25, squared 0.125), sample 1
    by 1 m once (0.5, squared 0.5); both miss by 50 m at the masked steps."""
    samples = torch.zeros(2, 2, 5, 2, dtype=torch.float64)
    samples[0, 0, 0] = torch.tensor([1.2, 1.6], dtype=torch.float64)
    samples[1, 0, :4] = torch.tensor([0.36, 0.48], dtype=torch.float64)
    samples[1, 0, 4] = torch.tensor([60.0, 80.0], dtype=torch.float64)
    samples[0, 1, 1] = torch.tensor([0.3, 0.4], dtype=torch.float64)
    samples[1, 1, 0] = torch.tensor([0.6, 0.8], dtype=torch.float64)
    samples[:, 1, 2:] = torch.tensor([30.0, 40.0], dtype=torch.float64)
    valid = torch.tensor([[True] * 4 + [False], [True] * 2 + [False] * 3])
    return samples, torch.zeros(2, 5, 2, dtype=torch.float64), valid


def test_the_variety_errors_pick_different_samples_by_hand():
    """Scene 0's one large miss is the nearest sample by mean distance (0.5 < 0.6) and the farthest by mean
    squared error (1 > 0.36); scene 1 picks sample 0 either way. Each error over the valid steps only,
    divided by their count, the two scenes averaged: (0.5 + 0.25) / 2 and (0.36 + 0.125) / 2."""
    samples, target, valid = _variety_scenes()
    assert variety_loss(samples, target, valid, "distance").item() == pytest.approx(0.375, abs=1e-12)
    assert variety_loss(samples, target, valid, "squared").item() == pytest.approx(0.2425, abs=1e-12)
    # float weights weigh the steps as the mask does
    assert variety_loss(samples, target, valid.double(), "squared").item() == pytest.approx(0.2425, abs=1e-12)


def test_the_variety_loss_defaults_to_the_distance_every_shipped_gan_trained_on():
    samples, target, valid = _variety_scenes()
    assert variety_loss(samples, target, valid).item() == pytest.approx(0.375, abs=1e-12)
    assert VARIETY_ERRORS == ("distance", "squared")
    with pytest.raises(
        PredictorError, match=r"^variety error 'mse' is not one of \['distance', 'squared'\]$"
    ):
        variety_loss(samples, target, valid, "mse")


def test_config_validation_names_the_bad_value():
    with pytest.raises(PredictorError, match="pooling 'max' is not one of"):
        SocialLSTMConfig(pooling="max")
    with pytest.raises(PredictorError, match="embedding_dim must be > 2"):
        SocialLSTMConfig(embedding_dim=2)
    with pytest.raises(PredictorError, match=r"unknown Social-LSTM config keys \['hidden'\]"):
        SocialLSTMConfig.from_dict({"hidden": 3})
