"""Social pooling's sparse path (training, evaluation) against the dense one (what the export traces).

Both compute the same weights bit for bit; the pooled sums may differ in the order of their additions. Each
pooled value sums at most N - 1 products ``weight * value`` (weights in [0, 1]), so reordering moves it by at
most about ``N * eps * sum |terms|``: below 1e-13 in float64 and 1e-5 in float32 for these scenes (N <= 14,
values and gradients of order 1-10). The tolerances below are those, far under any effect of a wrong cell or
a missing pair (a whole neighbour's value, order 1).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch

from predictors.export import TensorSpec, export_function
from predictors.export.symbolic import SymTensor
from predictors.nets import pooling
from predictors.nets.pooling import (
    GridPooling,
    cell_weights,
    dense_grid_pool,
    sparse_grid_pool,
    uses_sparse_pooling,
)
from predictors.nets.social_gru import SocialGRU, SocialGRUConfig
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig

# float64: N * eps * sum|terms| < 1e-13; float32: < 1e-5 (module docstring)
TOLERANCE = {torch.float64: {"rtol": 1e-12, "atol": 1e-12}, torch.float32: {"rtol": 1e-5, "atol": 1e-5}}
GRID = {"cell_side": 0.5, "grid_size": 6}  # binary fractions: u lands exactly on edges and centres below


def hostile_scene(seed: int, dtype: torch.dtype = torch.float64) -> tuple[torch.Tensor, torch.Tensor]:
    """(B=3, N=14) positions and neighbours: agents spread over +-3 m (some beyond the +-1.5 m grid),
    padding (scene 1 has 9 agents; the padded ones at the origin, as ``collate_scenes`` leaves them, and not
    neighbours), absent agents, two agents in one cell, two at the same place, and agents exactly on a hard
    cell's edge, on a soft cell's centre and on the soft grid's outer bound (u = -0.5)."""
    generator = torch.Generator().manual_seed(seed)
    positions = (torch.rand(3, 14, 2, generator=generator, dtype=torch.float64) * 6 - 3).to(dtype)
    neighbours = torch.rand(3, 14, generator=generator) > 0.15
    positions[1, 9:] = 0.0
    neighbours[1, 9:] = False
    neighbours[0, :4] = True
    positions[0, 1] = positions[0, 0] + torch.tensor([0.1, 0.1], dtype=dtype)  # same cell as agent 2
    positions[0, 2] = positions[0, 0] + torch.tensor([0.15, 0.2], dtype=dtype)
    positions[0, 3] = positions[0, 1]  # the same place as agent 1
    neighbours[2, :4] = True
    positions[2, 1] = positions[2, 0] + torch.tensor([0.5, -1.0], dtype=dtype)  # u = (4, 1): two edges
    positions[2, 2] = positions[2, 0] + torch.tensor([-1.25, 0.25], dtype=dtype)  # u = (0.5, 3.5): centres
    positions[2, 3] = positions[2, 0] + torch.tensor([-1.75, 1.0], dtype=dtype)  # u = (-0.5, 5): soft bound
    return positions, neighbours


def pooled_and_gradients(pool, values, positions, neighbours, soft: bool):
    """``pool``'s (B, N, C, F) output and the gradient of a fixed random projection of it with respect to
    the values and the positions."""
    values = values.detach().requires_grad_()
    positions = positions.detach().requires_grad_()
    out = pool(values, positions, neighbours, soft=soft, **GRID)
    projection = torch.randn(out.shape, generator=torch.Generator().manual_seed(7), dtype=torch.float64)
    grads = torch.autograd.grad(
        (out * projection.to(out.dtype)).sum(), (values, positions), allow_unused=True
    )
    return out, *grads


@pytest.mark.parametrize("soft", [False, True], ids=["grid", "soft"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sparse_pooling_uses_the_dense_weights_bit_for_bit(soft, seed):
    """With one-hot values (agent j's value is the j-th unit vector), each pooled entry is one weight alone:
    the sparse path's weights are ``cell_weights``' exactly, edges, centres and bounds included."""
    positions, neighbours = hostile_scene(seed)
    n_agents = positions.shape[1]
    one_hot = torch.eye(n_agents, dtype=positions.dtype).expand(3, -1, -1)
    pooled = sparse_grid_pool(one_hot, positions, neighbours, soft=soft, **GRID)  # (B, N_i, C, N_j)
    weights = cell_weights(positions, neighbours, soft=soft, **GRID)  # (B, N_i, N_j, C)
    assert torch.equal(pooled.transpose(2, 3), weights)
    assert weights.count_nonzero() > 20  # the scene has pairs in range


@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
@pytest.mark.parametrize("soft", [False, True], ids=["grid", "soft"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sparse_pooling_equals_dense_in_values_and_gradients(soft, seed, dtype):
    positions, neighbours = hostile_scene(seed, dtype)
    values = torch.randn(3, 14, 5, generator=torch.Generator().manual_seed(seed), dtype=dtype)
    dense = pooled_and_gradients(dense_grid_pool, values, positions, neighbours, soft)
    sparse = pooled_and_gradients(sparse_grid_pool, values, positions, neighbours, soft)
    for name, a, b in zip(("pooled", "d/dvalues", "d/dpositions"), dense, sparse, strict=True):
        if not soft and name == "d/dpositions":  # hard binning: positions only pick cells, no gradient
            assert a is None and b is None
            continue
        torch.testing.assert_close(b, a, **TOLERANCE[dtype], msg=name)
    assert dense[0].abs().max() > 0.5  # something was pooled
    if soft:
        assert dense[2].abs().max() > 0.5  # and the tents' slopes reach the positions


def test_a_pair_outside_the_grid_padding_and_oneself_are_never_pooled():
    """Hand-made: agent 0 at the origin; 1 just inside the hard grid's corner, 2 on its outer edge (out),
    3 padded at the origin, 4 inside but not a neighbour; only 1 lands in agent 0's grid."""
    positions = torch.tensor([[[0.0, 0.0], [-1.5, 1.25], [1.5, 0.0], [0.0, 0.0], [0.3, 0.3]]])
    neighbours = torch.tensor([[True, True, True, False, False]])
    values = torch.arange(1.0, 6.0)[None, :, None]  # agent j's value: j + 1
    pooled = sparse_grid_pool(values, positions, neighbours, soft=False, **GRID)
    expected = torch.zeros(6 * 6)
    expected[0 * 6 + 5] = 2.0  # agent 1: u = (0, 5.5), cell (0, 5)
    assert torch.equal(pooled[0, 0, :, 0], expected)
    # the padded agent 3 at the origin sees agent 0 (u = (3, 3)) and agent 1, as the dense path computes it
    torch.testing.assert_close(pooled, dense_grid_pool(values, positions, neighbours, soft=False, **GRID))


@pytest.mark.parametrize("soft", [False, True], ids=["grid", "soft"])
def test_grid_pooling_module_takes_the_sparse_path_with_the_same_gradients(soft, monkeypatch):
    """``GridPooling`` on plain tensors calls the sparse path, and its output and gradients with respect to
    the hidden states, the positions (soft) and its parameters equal the dense path's (``sparse = False``)."""
    torch.manual_seed(0)
    positions, neighbours = hostile_scene(0)
    hidden = torch.randn(3, 14, 8, dtype=torch.float64)
    pool = GridPooling(hidden_dim=8, latent_dim=3, out_dim=6, soft=soft, **GRID).double()
    calls = []
    monkeypatch.setattr(
        pooling, "sparse_grid_pool", lambda *a, **k: calls.append(1) or sparse_grid_pool(*a, **k)
    )
    results = []
    for sparse in (False, True):
        pool.sparse = sparse
        pool.zero_grad()
        h, p = hidden.clone().requires_grad_(), positions.clone().requires_grad_()
        out = pool(h, p, neighbours)
        (out * torch.linspace(-1, 1, out.numel(), dtype=out.dtype).reshape(out.shape)).sum().backward()
        results.append((out, h.grad, p.grad, *(q.grad.clone() for q in pool.parameters())))
    assert len(calls) == 1  # the sparse=True run, once
    for a, b in zip(*results, strict=True):
        if a is None:  # hard binning: no gradient reaches the positions on either path
            assert b is None and not soft
            continue
        torch.testing.assert_close(b, a, **TOLERANCE[torch.float64])


@pytest.mark.parametrize("soft", [False, True], ids=["grid", "soft"])
def test_the_sparse_path_keeps_nothing_of_pair_count_size_for_the_backward_pass(soft):
    """What autograd keeps for the backward pass lives through all 20 steps of a training batch: the dense
    path kept its (B, N, N, C) weights (B = 2, N = 300: 6.5 M numbers a step); the sparse path keeps per
    pair in range only (about 15 of the 299 others here), nothing of B·N·N numbers or more."""
    torch.manual_seed(0)
    batch, n_agents = 2, 300
    positions = torch.randn(batch, n_agents, 2) * (0.5 * n_agents**0.5)  # 0.6 agents per m², as the bench
    pool = GridPooling(hidden_dim=8, latent_dim=3, out_dim=6, soft=soft, cell_side=0.8, grid_size=6)
    sizes = []

    def keep(tensor):
        sizes.append(tensor.numel())
        return tensor

    with torch.autograd.graph.saved_tensors_hooks(keep, lambda t: t):
        pool(torch.randn(batch, n_agents, 8), positions.requires_grad_(soft), torch.ones(batch, n_agents) > 0)
    assert sizes and max(sizes) < batch * n_agents * n_agents


def padded_batch(dtype: torch.dtype = torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    """Two scenes of 21 steps, 25 and 10 agents (padded to 25), walking within a few metres of each other."""
    generator = torch.Generator().manual_seed(4)
    start = torch.rand(2, 1, 25, 2, generator=generator, dtype=dtype) * 5
    heading = torch.randn(2, 1, 25, 2, generator=generator, dtype=dtype) * 0.3
    positions = start + torch.arange(21, dtype=dtype)[None, :, None, None] * heading
    mask = torch.ones(2, 21, 25, dtype=torch.bool)
    mask[1, :, 10:] = False
    mask[0, :4, 20:] = False  # agents that appear late
    positions = positions * mask[..., None]  # padding at the origin, as collate_scenes leaves it
    return positions, mask


@pytest.mark.parametrize(
    "net",
    [
        lambda: SocialLSTM(SocialLSTMConfig(pooling="grid")),
        lambda: SocialLSTM(SocialLSTMConfig(pooling="soft")),
        lambda: SocialGRU(SocialGRUConfig(pooling="soft")),
    ],
    ids=["social_lstm_grid", "social_lstm_soft", "social_gru_soft"],
)
def test_a_training_step_on_a_padded_batch_is_the_same_on_both_paths(net):
    """Teacher-forced forward and backward, as training runs it: the outputs and every parameter's gradient
    agree (float32)."""
    torch.manual_seed(0)
    model = net().train()
    positions, mask = padded_batch()
    results = []
    for sparse in (False, True):
        for module in model.modules():
            if isinstance(module, GridPooling):
                module.sparse = sparse
        model.zero_grad()
        out, _ = model(positions, mask, 9, 12, teacher_forcing=True)
        out[..., :2].square().mean().backward()
        results.append((out, *(p.grad.clone() for p in model.parameters())))
    for a, b in zip(*results, strict=True):
        torch.testing.assert_close(b, a, **TOLERANCE[torch.float32])


def test_the_export_traces_the_dense_path(monkeypatch):
    """``export_function`` runs the net on SymTensors: the sparse path is never entered, and the exported
    function equals torch's eager (sparse) result, as the export's parity check holds it."""
    torch.manual_seed(0)
    pool = GridPooling(hidden_dim=4, latent_dim=3, out_dim=5, soft=True, **GRID).double().eval()
    positions, neighbours = hostile_scene(1)
    hidden = torch.randn(3, 14, 4, dtype=torch.float64)
    calls: list[str] = []
    real_sparse = pooling.sparse_grid_pool
    monkeypatch.setattr(
        pooling, "sparse_grid_pool", lambda *a, **k: calls.append("sparse") or real_sparse(*a, **k)
    )
    specs = [
        TensorSpec("hidden", tuple(hidden.shape)),
        TensorSpec("positions", tuple(positions.shape)),
        TensorSpec("neighbours", tuple(neighbours.shape), True),
    ]
    function = export_function(pool, pool.forward, specs, ["pooled"], "pool")
    assert calls == []  # traced on the dense path
    with torch.no_grad():
        eager = pool(hidden, positions, neighbours)
    assert calls == ["sparse"]
    exported = function(hidden.numpy().ravel(), positions.numpy().ravel(), neighbours.numpy().ravel())
    np.testing.assert_allclose(np.asarray(exported).ravel(), eager.numpy().ravel(), rtol=0, atol=1e-12)


@pytest.mark.filterwarnings("ignore:`torch.jit.trace` is deprecated")
def test_only_plain_tensors_outside_tracing_take_the_sparse_path():
    x = torch.zeros(1, 2, 2)
    assert uses_sparse_pooling(x, x, x)
    symbol = SymTensor.from_flat(ca.MX.sym("p", 4), (1, 2, 2))
    assert not uses_sparse_pooling(x, symbol, x)  # the exporter's tensor
    assert not uses_sparse_pooling(x, torch.nn.Parameter(x), x)  # any tensor subclass

    seen = []

    def record(t):
        seen.append(uses_sparse_pooling(t))
        return t * 2

    torch.jit.trace(record, (x,), check_trace=False)
    assert seen == [False]  # torch.jit.trace would keep the example's pairs as constants
