"""The learned predictors' coupling to the robot plan, agent layout, gaps, and the GAN's sampling."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch

from predictors.constant_velocity import ConstantVelocity
from predictors.errors import PredictorError
from predictors.learned import LearnedPredictor
from predictors.learned_casadi import casadi_name
from predictors.nets.social_gan import generator_config
from predictors.nets.social_lstm import SocialLSTM, SocialLSTMConfig
from predictors.registry import load_predictor
from predictors.social_lstm_predictors import SocialGANPredictor, SocialLSTMPredictor
from tests.predictors.test_contract import HORIZON, crossing_scene

ZOO_MODELS = [
    "social_lstm_eth",
    "social_lstm_soft_eth",
    "vanilla_lstm_eth",
    "social_gan_eth",
    "social_lstm_synth",
]


def social_lstm(pooling: str) -> SocialLSTMPredictor:
    torch.manual_seed(3)
    return SocialLSTMPredictor(SocialLSTM(SocialLSTMConfig(pooling=pooling)), name=f"sl_{pooling}")


def plan_jacobian(predictor, history, mask, humans, robots_future) -> np.ndarray:
    f = predictor.to_casadi(len(humans), robots_future.shape[1], robots_future.shape[0])
    ctx, plan = f.mx_in(0), f.mx_in(1)
    jac = ca.Function("plan_jacobian", [ctx, plan], [ca.jacobian(f(ctx, plan), plan)])
    return np.asarray(jac(predictor.encode(history, mask, humans), robots_future.reshape(-1)))


def test_soft_pooling_couples_humans_to_the_robot_plan():
    history, mask, humans, robots_future = crossing_scene()
    jac = plan_jacobian(social_lstm("soft"), history, mask, humans, robots_future)
    n_h = len(humans)
    # t+1 comes from the observed past alone; from t+2 on every step depends on the plan.
    assert not jac[: 2 * n_h].any()
    assert np.abs(jac[2 * n_h :]).max() > 1e-4
    # the last plan step (t+H) is never an input to the predictions up to t+H
    assert not jac[:, -2 * robots_future.shape[1] :].any()


def test_vanilla_lstm_ignores_the_robot_plan():
    history, mask, humans, robots_future = crossing_scene()
    predictor = social_lstm("none")
    assert not plan_jacobian(predictor, history, mask, humans, robots_future).any()
    np.testing.assert_array_equal(
        predictor.rollout(history, mask, robots_future, humans),
        predictor.rollout(history, mask, robots_future + 1.0, humans),
    )


def test_robot_plan_replaces_the_robots_own_prediction():
    history, mask, humans, robots_future = crossing_scene()
    predictor = social_lstm("soft")
    planned = predictor.rollout(history, mask, robots_future, humans)
    swerve = robots_future.copy()
    swerve[:, 0] += [0.0, 0.3]  # robot 0 swerves sideways
    assert not np.allclose(predictor.rollout(history, mask, swerve, humans), planned)
    assert np.array_equal(predictor.rollout(history, mask, swerve, humans)[0], planned[0])  # t+1 fixed


def test_output_follows_the_order_of_humans():
    history, mask, humans, robots_future = crossing_scene()
    predictor = social_lstm("grid")
    out = predictor.rollout(history, mask, robots_future, humans)
    flipped = predictor.rollout(history, mask, robots_future, humans[::-1])
    np.testing.assert_allclose(flipped, out[:, ::-1], rtol=0, atol=1e-12)


def test_agent_missing_now_is_extrapolated_and_not_pooled():
    history, mask, _, _ = crossing_scene()
    mask = mask.copy()
    mask[-2:, 5] = False  # agent 5 was last seen two steps ago, walking (-0.7, -0.2) m/s
    predictor = social_lstm("soft")
    pos, seen, _ = predictor._prepare(history, mask, np.arange(6), keep_robots=False)
    np.testing.assert_allclose(pos[-1, 5], history[-3, 5] + 2 * (history[-3, 5] - history[-4, 5]))
    context = predictor.encode(history, mask, np.arange(6))
    assert context[-6:].tolist() == [1, 1, 1, 1, 1, 0]  # present flags: agent 5 is not pooled
    # moving the absent agent's (never seen) current position changes nothing for the others
    other = history.copy()
    other[-2:, 5] += 50.0
    np.testing.assert_array_equal(
        predictor.rollout(history, mask, None, np.arange(6), horizon=5)[:, :5],
        predictor.rollout(other, mask, None, np.arange(6), horizon=5)[:, :5],
    )


def test_never_observed_human_is_refused_and_unseen_robot_without_plan_dropped():
    history, mask, _, _ = crossing_scene()
    mask = mask.copy()
    mask[:, 3] = False
    predictor = social_lstm("grid")
    with pytest.raises(ValueError, match=r"agents \[3\] are never observed"):
        predictor.rollout(history, mask, None, np.arange(6), horizon=3)
    out = predictor.rollout(history, mask, None, np.array([0, 1, 2, 4, 5]), horizon=3)  # 3 is a "robot"
    assert out.shape == (3, 5, 2)


def test_an_agent_seen_only_before_the_models_window_is_refused_as_such():
    # it was "never observed in the history", which it was: only not in the last obs_len steps
    history, mask, humans, robots_future = crossing_scene()
    predictor = SocialLSTMPredictor(social_lstm("grid").net, name="sl", obs_len=4)
    mask = mask.copy()
    mask[-4:, 3] = False
    with pytest.raises(
        ValueError, match=r"agents \[3\] are never observed in the last 4 steps of the history"
    ):
        predictor.rollout(history, mask, robots_future, humans)


def test_rollout_reuses_the_encoding_of_the_same_past():
    history, mask, humans, robots_future = crossing_scene()
    predictor = social_lstm("soft")
    first = predictor.rollout(history, mask, robots_future, humans)
    key = predictor._last_encoding[0]
    second = predictor.rollout(history, mask, robots_future * 1.01, humans)
    assert predictor._last_encoding[0] is key
    assert not np.array_equal(first, second)


def gappy_scene():
    """``crossing_scene`` with every kind of gap ``SocialLSTM.encode`` masks: a human missing mid-track
    (agent 2 at step 3), one absent now (agent 5, last seen three steps ago), one seen at a single step
    (agent 3, step 4 only), and a robot that enters late (agent 1)."""
    history, mask, humans, _ = crossing_scene()
    mask = mask.copy()
    mask[3, 2] = False
    mask[-3:, 5] = False
    mask[:, 3] = False
    mask[4, 3] = True
    mask[:2, 1] = False
    return history, mask, humans


def context_blocks(context: np.ndarray, n_humans: int, n_agents: int, hidden: int) -> dict[str, np.ndarray]:
    sizes = {"h": n_agents * hidden, "c": n_agents * hidden, "now": 2 * n_agents, "first": 2 * n_humans}
    sizes["present"] = n_agents
    ends = np.cumsum(list(sizes.values()))
    assert ends[-1] == context.size
    return dict(zip(sizes, np.split(context, ends[:-1]), strict=True))


def torch_context(predictor: LearnedPredictor, history, mask, humans) -> np.ndarray:
    """The context as ``encode`` computed it in torch: ``SocialLSTM.encode`` on the prepared past."""
    pos, seen, n_humans = predictor._prepare(history, mask, humans)
    with torch.no_grad():
        h, c, out = predictor.net.encode(torch.from_numpy(pos)[None], torch.from_numpy(seen)[None])
    first = pos[-1, :n_humans] + out[0, :n_humans, :2].numpy()
    parts = [h[0].numpy(), c[0].numpy(), pos[-1], first, seen[-1].astype(float)]
    return np.concatenate([part.ravel() for part in parts])


@pytest.mark.parametrize("name", ZOO_MODELS)
@pytest.mark.parametrize("length", [8, 2, 1], ids=["L8-gaps", "L2-gaps", "L1"])
def test_casadi_encoder_gives_the_torch_context(name, length):
    predictor = load_predictor(name)
    history, mask, humans = gappy_scene()
    history, mask = history[-length:], mask[-length:].copy()
    if length == 2:  # the start of an episode: agent 5 seen only before, agent 3 only now
        mask[:] = True
        mask[1, 5] = mask[0, 3] = False
    if length == 1:
        mask[:] = True  # a single step: everyone must be seen now
    # the steps before them padded, marked unobserved: a predictor reads obs_len steps (fewer are refused)
    pad = predictor.obs_len - length
    history = np.concatenate([np.zeros((pad, *history.shape[1:])), history])
    mask = np.concatenate([np.zeros((pad, mask.shape[1]), dtype=bool), mask])
    context = predictor.encode(history, mask, humans)
    reference = torch_context(predictor, history, mask, humans)
    n_agents, hidden = history.shape[1], predictor.config.hidden_dim
    got = context_blocks(context, len(humans), n_agents, hidden)
    for block, expected in context_blocks(reference, len(humans), n_agents, hidden).items():
        np.testing.assert_allclose(got[block], expected, rtol=0, atol=1e-9, err_msg=f"block {block}")
    if length > 1:
        # the gaps are not a no-op: the same past fully observed gives another state
        full = predictor.encode(history, np.ones_like(mask), humans)
        assert np.abs(full[: 2 * n_agents * hidden] - context[: 2 * n_agents * hidden]).max() > 1e-3


@pytest.mark.parametrize("method", ["rollout", "encode"])
def test_a_history_shorter_than_the_steps_read_is_refused(method):
    """3 rows given to a net that reads 9 ran on the 3 it had: a forecast 0.7-0.9 m from the one its 9
    steps give, without a word (docs/extending.md: L at least obs_len)."""
    predictor = load_predictor("social_lstm_eth")
    history, mask, humans = gappy_scene()
    args = (None, humans, 4) if method == "rollout" else (humans,)
    with pytest.raises(PredictorError, match=r"with L >= 9 \(the steps 'social_lstm_eth' reads; pad a short"):
        getattr(predictor, method)(history[-3:], mask[-3:], *args)


def test_encode_runs_without_torch_and_reuses_a_copy_of_the_context(monkeypatch):
    history, mask, humans = gappy_scene()
    predictor = social_lstm("grid")
    expected = torch_context(predictor, history, mask, humans)

    def no_torch(*args, **kwargs):
        raise AssertionError("encode called the torch encoder")

    predictor.encode(history + 1.0, mask, humans)  # exports the encoder (a symbolic run of net.encode)
    monkeypatch.setattr(predictor.net, "encode", no_torch)
    context = predictor.encode(history, mask, humans)
    np.testing.assert_allclose(context, expected, rtol=0, atol=1e-9)
    key = predictor._last_context[0]
    context[:] = 0.0  # the caller's copy, not the memo
    again = predictor.encode(history, mask, humans)
    assert predictor._last_context[0] is key
    np.testing.assert_allclose(again, expected, rtol=0, atol=1e-9)
    moved = history.copy()
    moved[-1, 2] += 0.5
    assert not np.allclose(predictor.encode(moved, mask, humans), expected)
    assert predictor._last_context[0] is not key


def test_casadi_encoder_is_built_once_per_size():
    predictor = social_lstm("soft")
    encoder = predictor.casadi_encoder(6, 8)
    assert predictor.casadi_encoder(6, 8) is encoder
    assert predictor.casadi_encoder(7, 8) is not encoder
    assert encoder.name_in() == ["positions", "seen"] and encoder.name_out() == ["state_0", "state_1", "out"]
    assert encoder.size1_in(0) == 8 * 6 * 2 and encoder.size1_out(0) == 6 * predictor.config.hidden_dim
    with pytest.raises(PredictorError, match="n_agents, length >= 1"):
        predictor.casadi_encoder(0, 8)


def test_gan_sample_shapes_reproducibility_and_spread():
    torch.manual_seed(0)
    net = SocialLSTM(generator_config(pooling="soft"))
    torch.nn.init.normal_(net.noise.weight)
    gan = SocialGANPredictor(net, name="gan")
    history, mask, humans, robots_future = crossing_scene()
    a = gan.sample(history, mask, robots_future, humans, None, 5, np.random.default_rng(1))
    b = gan.sample(history, mask, robots_future, humans, None, 5, np.random.default_rng(1))
    assert a.shape == (5, HORIZON, len(humans), 2)
    np.testing.assert_array_equal(a, b)
    assert a.std(axis=0).max() > 1e-3
    with pytest.raises(ValueError, match="k must be >= 1"):
        gan.sample(history, mask, robots_future, humans, None, 0, np.random.default_rng(1))
    # robots' plans as nested lists, as rollout takes them (sample raised AttributeError: list has no ndim)
    listed = gan.sample(history, mask, robots_future.tolist(), humans, None, 5, np.random.default_rng(1))
    np.testing.assert_array_equal(listed, a)


def test_casadi_name_is_always_valid():
    assert casadi_name("social_lstm_eth_h7_r3_H4") == "social_lstm_eth_h7_r3_H4"
    assert casadi_name("7-up__model") == "predictor_7_up_model"


def test_an_export_that_fails_its_check_is_never_handed_out(monkeypatch):
    """A failed parity check must not leave its function behind for the next call (the sweep worker keeps
    the controller after a failed episode: its next episode would plan with an unchecked export)."""
    from predictors.export import ExportError, parity

    predictor = social_lstm("soft")
    failures = {"n": 0}

    def failing(*args):
        failures["n"] += 1
        raise ExportError("the exported prediction differs from torch", predictor.name)

    monkeypatch.setattr(parity, "require_parity", failing)
    for size in ((3, 2), (3, 2), (5, 1)):
        with pytest.raises(ExportError, match="differs from torch"):
            predictor.to_casadi(*size, HORIZON)
    assert failures["n"] == 1  # every size is built the same way: checked once, not once a size


def test_an_interrupted_export_check_is_made_again(monkeypatch):
    from predictors.export import parity

    predictor = social_lstm("soft")
    calls = {"n": 0}
    original = parity.require_parity

    def interrupted_once(*args):
        calls["n"] += 1
        if calls["n"] == 1:
            raise KeyboardInterrupt
        return original(*args)

    monkeypatch.setattr(parity, "require_parity", interrupted_once)
    with pytest.raises(KeyboardInterrupt):
        predictor.to_casadi(3, 2, HORIZON)
    assert predictor.to_casadi(3, 2, HORIZON) is not None and calls["n"] == 2


def test_each_size_is_built_once(monkeypatch):
    predictor = social_lstm("soft")
    built: list[tuple[int, int, int]] = []
    original = predictor._prediction

    def counting(*key):
        built.append(key)
        return original(*key)

    monkeypatch.setattr(predictor, "_prediction", counting)
    first = predictor.to_casadi(3, 2, HORIZON)
    assert predictor.to_casadi(3, 2, HORIZON) is first
    predictor.to_casadi(1, 1, HORIZON)
    # the first call also builds the check's size (predictors.learned_casadi.PARITY_SIZE), once
    assert sorted(built) == sorted([(3, 2, HORIZON), (2, 1, 3), (1, 1, HORIZON)])


@pytest.mark.parametrize("kind", ["social_lstm", "constant_velocity"])
def test_a_non_finite_observed_position_is_refused_where_unobserved_ones_are_ignored(kind):
    predictor = social_lstm("grid") if kind == "social_lstm" else ConstantVelocity()
    # a NaN the mask marks observed was spread by pooling to every human's rollout, while the CasADi
    # context made finite numbers of it
    history, mask, humans, robots_future = crossing_scene()
    history = history.copy()
    history[3, 4] = np.nan
    for call in (
        lambda: predictor.rollout(history, mask, robots_future, humans),
        lambda: predictor.encode(history, mask, humans),
    ):
        with pytest.raises(ValueError, match=r"history\[3, 4\] is \[nan, nan\].*mask marks agent 4 observed"):
            call()
    mask = mask.copy()
    mask[3, 4] = False  # absent there: its value is not read
    assert np.isfinite(predictor.rollout(history, mask, robots_future, humans)).all()
    assert np.isfinite(predictor.encode(history, mask, humans)).all()
    with pytest.raises(ValueError, match="robots_future holds a non-finite position"):
        predictor.rollout(history, mask, np.where(robots_future > 0, np.inf, robots_future), humans)


def test_a_plugin_net_raising_on_a_scene_is_one_line_naming_the_predictor_and_a_shipped_one_is_a_bug(
    monkeypatch,
):
    """A plugin net's own exception in the closed loop ended simulate with a traceback through the MPC, as a
    bug in crowdmpc would: the controller plugins' exceptions were one line naming them, the nets' were not.
    A shipped net's exception is still a bug: its traceback."""
    from tests.plugins.broken_nets import RaisesOnCrowds
    from tests.plugins.toy_predictor import ToyConfig

    kind = "tests.plugins.broken_nets:RaisesOnCrowds"
    predictor = LearnedPredictor(RaisesOnCrowds(ToyConfig()), name="crowds", kind=kind)
    history, mask, humans, robots_future = crossing_scene()  # 6 agents
    with pytest.raises(PredictorError) as caught:
        predictor.rollout(history, mask, robots_future, humans)
    assert str(caught.value) == (
        f"predictor 'crowds' (model {kind!r}): encode raised ValueError: my pooling grid holds at most 5 "
        "agents, got 6 (on a scene of 6 agents)"
    )
    assert isinstance(caught.value.__cause__, ValueError)  # the traceback a sweep's errors.jsonl keeps

    def broken(*args):
        raise RuntimeError("a bug")

    shipped = social_lstm("soft")
    monkeypatch.setattr(shipped.net, "encode", broken)
    with pytest.raises(RuntimeError, match="a bug"):
        shipped.rollout(history, mask, robots_future, humans)
