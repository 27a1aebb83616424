"""Social-GRU, Social-Attention and the shared rollout: the step contract, masking, hand-checked pieces,
training gradients and config validation."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from predictors.errors import PredictorError
from predictors.export import TensorSpec, export_function
from predictors.nets.contract import StepNet
from predictors.nets.losses import gaussian_nll, l2_loss
from predictors.nets.pooling import POOLINGS
from predictors.nets.rollout import teacher_forced_rollout
from predictors.nets.social_attention import (
    NeighbourAttention,
    SocialAttention,
    SocialAttentionConfig,
    self_mask,
)
from predictors.nets.social_gru import SocialGRU, SocialGRUConfig, tag_input
from predictors.nets.social_lstm import HEADS, SocialLSTM, SocialLSTMConfig, pooled_rnn_parameter_count
from tests.predictors.test_nets import walking_batch

NETS = {
    "gru_soft": lambda: SocialGRU(),
    "gru_grid": lambda: SocialGRU(SocialGRUConfig(pooling="grid")),
    "gru_none_point": lambda: SocialGRU(SocialGRUConfig(pooling="none", head="point")),
    "attention": lambda: SocialAttention(),
    "attention_2heads_point": lambda: SocialAttention(SocialAttentionConfig(heads=2, head="point")),
}
SOCIAL = ["gru_soft", "gru_grid", "attention", "attention_2heads_point"]


def build(name: str) -> torch.nn.Module:
    torch.manual_seed(0)
    return NETS[name]()


def primary_prediction(net, positions, mask):
    with torch.no_grad():
        return net.eval()(positions, mask, 9, 12, teacher_forcing=False)[1][:, :, 0]


# ------------------------------------------------------------------------------------------- contract
@pytest.mark.parametrize("name", NETS)
@pytest.mark.parametrize("teacher_forcing", [True, False])
def test_forward_shapes(name, teacher_forcing):
    net = build(name)
    positions, mask = walking_batch()
    outputs, predicted = net(positions, mask, 9, 12, teacher_forcing=teacher_forcing)
    k = 5 if net.head_type == "gaussian" else 2
    assert outputs.shape == (2, 12, 3, k)
    assert predicted.shape == (2, 12, 3, 2)
    assert torch.isfinite(outputs).all() and torch.isfinite(predicted).all()


@pytest.mark.parametrize("name", NETS)
def test_step_contract(name):
    net = build(name).eval()
    assert isinstance(net, StepNet)
    assert net.config_class is type(net.config)
    assert net.head_type == net.config.head
    assert type(net)(net.config_class.from_dict(net.config.to_dict())).config == net.config
    positions, mask = walking_batch(batch=2, agents=4, steps=8)
    *state, out = net.encode(positions, mask)
    assert len(state) == (1 if isinstance(net, SocialGRU) else 2)  # GRU (h,), LSTM (h, c)
    for tensor in state:
        assert tensor.shape[:2] == (2, 4)  # one row of state per agent
    assert out.shape == (2, 4, 5 if net.head_type == "gaussian" else 2)
    cur = positions[:, -1] + out[..., :2]
    *next_state, next_out = net.decode_step(*state, positions[:, -1], cur, mask[:, -1])
    assert [s.shape for s in next_state] == [s.shape for s in state]
    assert next_out.shape == out.shape
    assert torch.isfinite(next_out).all()


@pytest.mark.parametrize("name", NETS)
def test_noise_is_refused(name):
    positions, mask = walking_batch(batch=1)
    with pytest.raises(ValueError, match="takes no noise"):
        build(name)(positions, mask, 9, 12, teacher_forcing=False, noise=torch.zeros(1, 3, 4))


# -------------------------------------------------------------------------------------------- masking
@pytest.mark.parametrize("name", NETS)
def test_an_unseen_agent_does_not_change_the_others(name):
    net = build(name)
    positions, mask = walking_batch(batch=1)
    alone = primary_prediction(net, positions[:, :, :2], mask[:, :, :2])
    unseen_mask = mask.clone()
    unseen_mask[:, :, 2] = False
    junk = positions.clone()
    junk[:, :, 2] = 1e3 * torch.randn(21, 2)  # an unseen agent's positions may be anything
    assert torch.allclose(primary_prediction(net, junk, unseen_mask), alone, atol=1e-6)


@pytest.mark.parametrize("name", NETS)
def test_decode_step_ignores_an_agent_that_is_not_a_neighbour(name):
    net = build(name).eval()
    positions, mask = walking_batch(batch=1, agents=3, steps=8)
    *state, out = net.encode(positions, mask)
    cur = positions[:, -1] + out[..., :2]
    neighbours = torch.tensor([[True, True, False]])
    moved = cur.clone()
    moved[:, 2] += torch.tensor([0.3, -0.2])  # close to agent 0 (inside every grid), but not a neighbour
    with torch.no_grad():
        *_, a = net.decode_step(*state, positions[:, -1], cur, neighbours)
        *_, b = net.decode_step(*state, positions[:, -1], moved, neighbours)
    assert torch.allclose(a[:, :2], b[:, :2], atol=1e-6)
    assert not torch.allclose(a[:, 2], b[:, 2])  # the agent itself is still updated


@pytest.mark.parametrize("name", SOCIAL)
def test_in_eval_mode_a_neighbours_past_reaches_the_primary_gradient(name):
    net = build(name).eval()
    positions, mask = walking_batch(batch=1)
    positions.requires_grad_(True)
    _, predicted = net(positions, mask, 9, 12, teacher_forcing=False)
    (grad,) = torch.autograd.grad(predicted[:, -1, 0].sum(), positions)
    assert grad[:, :9, 1].abs().sum() > 0


@pytest.mark.parametrize("name", ["gru_soft", "gru_grid", "attention_2heads_point"])
def test_encode_and_decode_step_run_on_the_exporters_symbols(name):
    """Both methods use only what ``predictors.export`` supports, and its CasADi twin gives torch's values
    (float64), with a partly seen agent in ``encode`` and a non-neighbour in ``decode_step``."""
    net = build(name).double().eval()
    n, length = 4, 5
    positions = torch.randn(1, length, n, 2, dtype=torch.float64)
    mask = torch.ones(1, length, n, dtype=torch.bool)
    mask[0, :2, 3] = False
    neighbours = torch.tensor([[True, True, False, True]])
    with torch.no_grad():
        *state, out = net.encode(positions, mask)
        cur = positions[:, -1] + out[..., :2]
        expected = [*state, out, *net.decode_step(*state, positions[:, -1], cur, neighbours)]
    names = [f"state{i}" for i in range(len(state))] + ["out"]
    encode = export_function(
        net,
        net.encode,
        [TensorSpec("positions", (1, length, n, 2)), TensorSpec("mask", (1, length, n), True)],
        names,
        "encode",
    )
    specs = [TensorSpec(f"in_{k}", tuple(s.shape)) for k, s in zip(names, state, strict=False)]
    specs += [
        TensorSpec("prev", (1, n, 2)),
        TensorSpec("cur", (1, n, 2)),
        TensorSpec("neighbours", (1, n), True),
    ]
    decode = export_function(net, net.decode_step, specs, names, "decode_step")

    def flat(*tensors):
        return [t.to(torch.float64).numpy().reshape(-1) for t in tensors]

    got = encode(*flat(positions, mask)) + decode(*flat(*state, positions[:, -1], cur, neighbours))
    for value, reference in zip(got, expected, strict=True):
        np.testing.assert_allclose(np.asarray(value).reshape(-1), reference.numpy().reshape(-1), atol=1e-12)


# ---------------------------------------------------------------------------------------- hand-checked
def test_self_mask_is_the_identity():
    like = torch.zeros(1, dtype=torch.float64)
    for n in (1, 2, 5):
        assert torch.equal(self_mask(like, n), torch.eye(n, dtype=torch.bool))


def test_tag_input_is_one_hot_on_the_spare_slots():
    like = torch.zeros(1)
    assert tag_input(like, 2, 5, slot=0).tolist() == [[0, 0, 0, 1, 0]] * 2
    assert tag_input(like, 1, 5, slot=1).tolist() == [[0, 0, 0, 0, 1]]


def test_attention_with_flat_scores_averages_the_allowed_values():
    """Zero key weights give every allowed neighbour the same score, so agent i's attended vector is the
    plain mean of the values it may see: with only agent 0 a neighbour, agent 0 sees itself alone and the
    others see themselves and agent 0; with everyone a neighbour, all three."""
    torch.manual_seed(0)
    block = NeighbourAttention(hidden_dim=4, model_dim=4, heads=2, ff_dim=8, position_scale=0.5)
    torch.nn.init.zeros_(block.key.weight)
    torch.nn.init.zeros_(block.key.bias)
    torch.nn.init.zeros_(block.ff_out.weight)  # block output = stream + attention + ff_out.bias
    hidden = torch.randn(1, 3, 4)
    positions = torch.tensor([[[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]]])
    with torch.no_grad():
        # values[i, j] = value(LN(proj(h_j)) + gelu(embed(0.5 * (p_j - p_i)))): j as seen from i
        relative = (positions[0, None, :, :] - positions[0, :, None, :]) * 0.5
        normed = block.attention_norm(block.hidden_projection(hidden[0]))
        values = block.value(normed[None] + torch.nn.functional.gelu(block.position_embedding(relative)))
        stream = block.hidden_projection(hidden[0])

        def expected(attended):
            return stream + block.attention_output(attended) + block.ff_out.bias

        only_zero = torch.stack([values[0, 0], values[1, :2].mean(0), values[2, ::2].mean(0)])
        got = block(hidden, hidden, positions, torch.tensor([[True, False, False]]))
        assert torch.allclose(got[0], expected(only_zero), atol=1e-6)
        got = block(hidden, hidden, positions, torch.tensor([[True, True, True]]))
        assert torch.allclose(got[0], expected(values.mean(dim=1)), atol=1e-6)
        got = block(hidden, hidden, positions, torch.tensor([[False, False, False]]))
        assert torch.allclose(got[0], expected(values.diagonal().T), atol=1e-6)


@pytest.mark.parametrize("training", [True, False])
def test_rollout_reproduces_social_lstm_forward(training):
    """The shared rollout is Social-LSTM's: identical with its masked step, and for the primary (always
    updated) also with the generic ``torch.where`` one; agents come and go during the prediction."""
    torch.manual_seed(0)
    net = SocialLSTM(SocialLSTMConfig(pooling="soft")).train(training)
    positions, mask = walking_batch(batch=2, agents=4)
    positions = positions + 0.1 * torch.randn_like(positions)
    mask[:, 10:14, 2] = False
    mask[:, :5, 3] = False
    reference = net(positions, mask, 9, 12, teacher_forcing=True)

    def masked(h, c, prev, cur, active, neighbours):
        return net.step(net.decoder, h, c, prev, cur, active, neighbours)

    own = teacher_forced_rollout(net, positions, mask, 9, 12, teacher_forcing=True, masked_step=masked)
    generic = teacher_forced_rollout(net, positions, mask, 9, 12, teacher_forcing=True)
    assert torch.equal(own[0], reference[0]) and torch.equal(own[1], reference[1])
    assert torch.equal(generic[0][:, :, 0], reference[0][:, :, 0])


# -------------------------------------------------------------------------------------------- training
@pytest.mark.parametrize("name", NETS)
def test_training_forward_gives_a_finite_loss_and_gradients(name):
    net = build(name).train()
    positions, mask = walking_batch(batch=2, agents=3)
    positions = positions + 0.05 * torch.randn_like(positions)
    mask[1, 12:, 2] = False  # a neighbour leaving during the teacher-forced steps
    outputs, _ = net(positions, mask, 9, 12, teacher_forcing=True)
    truth = positions[:, 9:, 0]
    target = truth - positions[:, 8:-1, 0]
    valid = mask[:, 9:, 0]
    if net.head_type == "gaussian":
        loss = gaussian_nll(outputs[:, :, 0], target, valid)
    else:
        loss = l2_loss(outputs[:, :, 0, :2], target, valid)
    loss.backward()
    assert torch.isfinite(loss)
    grads = [p.grad for p in net.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert sum(float(g.abs().sum()) for g in grads if g is not None) > 0


# ------------------------------------------------------------------------------------------ validation
def test_default_parameter_counts_are_computed_without_allocating():
    for config, net_class in ((SocialGRUConfig(), SocialGRU), (SocialAttentionConfig(), SocialAttention)):
        for variant in (config, type(config)(head="point")):
            net = net_class(variant)
            assert variant.parameter_count() == sum(p.numel() for p in net.parameters())
    assert SocialGRUConfig().parameter_count() == 12_483
    assert SocialAttentionConfig().parameter_count() == 19_909
    assert SocialGRUConfig(pooling="none").parameter_count() < SocialGRUConfig().parameter_count()


@pytest.mark.parametrize("pooling", POOLINGS)
@pytest.mark.parametrize("head", HEADS)
def test_social_lstm_and_gru_count_their_layout_once(pooling, head):
    """Both configs count Social-LSTM's layout with one function, the cells' gates apart (the Social-GRU had
    a copy of the Social-LSTM's count with 3 for 4): each variant's count is its net's."""
    gru = SocialGRUConfig(pooling=pooling, head=head)
    assert pooled_rnn_parameter_count(gru, gates=3) == gru.parameter_count()
    assert gru.parameter_count() == sum(p.numel() for p in SocialGRU(gru).parameters())
    for noise_dim in (0, 3):
        lstm = SocialLSTMConfig(pooling=pooling, head=head, noise_dim=noise_dim)
        assert (
            pooled_rnn_parameter_count(lstm, gates=4) + noise_dim * lstm.hidden_dim == lstm.parameter_count()
        )
        assert lstm.parameter_count() == sum(p.numel() for p in SocialLSTM(lstm).parameters())


@pytest.mark.parametrize(
    ("config_class", "values", "message"),
    [
        (SocialGRUConfig, {"pooling": "max"}, r"Social-GRU pooling 'max' is not one of"),
        (SocialGRUConfig, {"head": 5}, r"head must be a string, got 5"),
        (SocialGRUConfig, {"embedding_dim": 2}, r"embedding_dim must be in 3\.\.4096, got 2"),
        (SocialGRUConfig, {"hidden_dim": 32.0}, r"hidden_dim must be an integer, got 32\.0"),
        (SocialGRUConfig, {"grid_size": True}, r"grid_size must be an integer, got True"),
        (SocialGRUConfig, {"cell_side": float("nan")}, r"cell_side must be a finite number"),
        (SocialGRUConfig, {"input_scale": 0}, r"input_scale must be in \(0, 1000\]"),
        (SocialGRUConfig, {"hidden_dim": 4096, "embedding_dim": 4096}, r"parameters, more than"),
        (SocialAttentionConfig, {"heads": 3}, r"heads must divide model_dim, got heads 3"),
        (SocialAttentionConfig, {"heads": 0}, r"heads must be in 1\.\.64, got 0"),
        (SocialAttentionConfig, {"position_scale": -1.0}, r"position_scale must be in \(0, 1000\]"),
        (SocialAttentionConfig, {"model_dim": "16"}, r"model_dim must be an integer, got '16'"),
        (SocialAttentionConfig, {"head": "mixture"}, r"head 'mixture' is not one of"),
        (SocialAttentionConfig, {"hidden_dim": 4096, "ff_dim": 4096}, r"parameters, more than"),
    ],
)
def test_config_validation_names_the_bad_field(config_class, values, message):
    with pytest.raises(PredictorError, match=message):
        config_class(**values)


@pytest.mark.parametrize("config_class", [SocialGRUConfig, SocialAttentionConfig])
def test_from_dict_refuses_unknown_keys_and_non_objects(config_class):
    with pytest.raises(PredictorError, match=r"unknown .* config keys \['hidden'\]"):
        config_class.from_dict({"hidden": 3})
    with pytest.raises(PredictorError, match="must be a JSON object"):
        config_class.from_dict([1, 2])
    assert config_class.from_dict(config_class().to_dict()) == config_class()
