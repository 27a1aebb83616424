"""ONE contract test over every predictor: each registered name, each shipped zoo entry, and an untrained net
of every registered model kind (``predictors.models``: the shipped kinds, and the test plugin
``tests.plugins.toy_predictor:ToyNet``, so a user's predictor is held to the same contract), so the contract
holds even before a zoo exists. A new predictor, or a new kind, inherits it all.

Checks: shapes and finiteness (with and without a robot plan, robots first as in closed loop and
interleaved), torch rollout vs the CasADi function (values <= 1e-6 in float64), the Jacobian of the humans'
prediction with respect to the robot plan (CasADi vs torch autograd, or central differences for predictors
without torch), the CasADi function's save/load round trip (the export path), the checkpoint round trip,
refusal of a checkpoint whose sha256 differs from the manifest, and refusal of humans that are not distinct
integer indices and of a horizon below one step.
"""

from __future__ import annotations

import json

import casadi as ca
import numpy as np
import pytest
import torch

from predictors.base import OBS_LEN, Predictor
from predictors.checkpoint import load_checkpoint, save_checkpoint
from predictors.errors import CheckpointMismatch, PredictorError
from predictors.learned import LearnedPredictor
from predictors.models import load_plugin, model_kind, model_kinds
from predictors.oracle import ORACLE_PREDICTOR
from predictors.registry import PREDICTORS, load_predictor
from predictors.zoo import checkpoints_dir, load_zoo, zoo_names
from predictors.zoo_edit import add_to_zoo

HORIZON = 4
TOL = 1e-6
TOY = "tests.plugins.toy_predictor:ToyNet"

load_plugin(TOY)  # registered before the kinds are listed: the contract covers plugins


@pytest.fixture(autouse=True)
def _toy_registered():
    """Registered for each test too: the session drops the plugins its modules registered as they were
    imported (tests/conftest.py), and the test's own registration goes with the test."""
    load_plugin(TOY)


# Every kind with its own config, and the variants the MPC relies on (soft pooling: the coupled NLP).
UNTRAINED = [(name, {}) for name in sorted(model_kinds())] + [("social_lstm", {"pooling": "soft"})]


def _untrained(kind_name: str, overrides: dict) -> LearnedPredictor:
    torch.manual_seed(7)
    kind = model_kind(kind_name)
    return kind.predictor(
        kind.build_net(kind.config(overrides)), name=f"untrained_{kind_name}", obs_len=OBS_LEN
    )


def _label(kind_name: str, overrides: dict) -> str:
    return kind_name + (json.dumps(overrides, separators=(",", ":")) if overrides else "")


CASES = (
    # the ORCA oracle reads the simulator and has no CasADi twin: tests/pipelines/test_oracle.py
    [("registry", name, {}) for name in sorted(PREDICTORS) if name != ORACLE_PREDICTOR]
    # the shipped zoo only: collection must not read a user's zoo (tests get an empty one of their own)
    + [("zoo", name, {}) for name in zoo_names(checkpoints_dir())]
    + [("untrained", name, overrides) for name, overrides in UNTRAINED]
)


def _load(case: tuple[str, str, dict]) -> Predictor:
    source, name, overrides = case
    if source == "untrained":
        return _untrained(name, overrides)
    return load_zoo(name, checkpoints_dir()) if source == "zoo" else load_predictor(name)


@pytest.fixture(params=CASES, ids=[f"{source}:{_label(name, o)}" for source, name, o in CASES])
def predictor(request) -> Predictor:
    return _load(request.param)


# The cases with weights: the registry's built-ins have none. A case the contract's fixture would skip is
# never collected, so `pytest -ra` lists only skips that depend on the machine.
WEIGHTED = [case for case in CASES if case[0] != "registry"]


@pytest.fixture(params=WEIGHTED, ids=[f"{source}:{_label(name, o)}" for source, name, o in WEIGHTED])
def learned(request) -> LearnedPredictor:
    predictor = _load(request.param)
    assert isinstance(predictor, LearnedPredictor), f"{predictor.name} has no weights"
    return predictor


def crossing_scene(robots_first: bool = True):
    """obs_len (9) observed steps of 2 robots and 4 humans walking through each other within ~2 m (pooling).

    Returns history (L, 6, 2), mask, humans, robots_future (H, 2, 2). With ``robots_first`` the layout is
    the simulator's (robots 0, 1); otherwise robots sit at indices 1 and 4 and humans come unsorted.
    """
    L = 9
    t = np.arange(L)[:, None] * 0.4
    start = np.array([[-1.5, 0.3], [1.5, -0.2], [-1.0, -1.0], [0.8, 1.2], [0.0, -1.6], [1.2, 0.6]])
    velocity = np.array([[0.9, 0.0], [-0.9, 0.1], [0.5, 0.6], [-0.3, -0.8], [0.1, 0.9], [-0.7, -0.2]])
    history = start[None] + t[..., None] * velocity[None] - 0.4 * (L - 1) * velocity[None] / 2
    mask = np.ones((L, 6), dtype=bool)
    robots = np.array([0, 1])
    steps = np.arange(1, HORIZON + 1)[:, None, None] * 0.4
    robots_future = history[-1, robots][None] + steps * velocity[robots][None] * 1.1
    if robots_first:
        return history, mask, np.array([2, 3, 4, 5]), robots_future
    order = np.array([2, 0, 3, 5, 1, 4])  # old index at each new position: robots land at 1 and 4
    return history[:, order], mask[:, order], np.array([5, 0, 2, 3]), robots_future


def torch_jacobian(p: LearnedPredictor, history, mask, robots_future, humans) -> np.ndarray:
    plan = torch.tensor(robots_future, dtype=torch.float64)
    jac = torch.autograd.functional.jacobian(
        lambda r: p.rollout_tensor(history, mask, r, humans).reshape(-1), plan
    )
    return jac.reshape(-1, plan.numel()).numpy()


def finite_difference_jacobian(p: Predictor, history, mask, robots_future, humans, eps=1e-6) -> np.ndarray:
    columns = []
    for k in range(robots_future.size):
        step = np.zeros(robots_future.size)
        step[k] = eps
        up = p.rollout(history, mask, robots_future + step.reshape(robots_future.shape), humans)
        down = p.rollout(history, mask, robots_future - step.reshape(robots_future.shape), humans)
        columns.append((up - down).reshape(-1) / (2 * eps))
    return np.stack(columns, axis=1)


@pytest.mark.parametrize("robots_first", [True, False], ids=["robots-first", "interleaved"])
def test_rollout_casadi_values_and_jacobians(predictor, robots_first):
    history, mask, humans, robots_future = crossing_scene(robots_first)
    n_humans, n_robots = len(humans), robots_future.shape[1]

    out = predictor.rollout(history, mask, robots_future, humans)
    assert out.shape == (HORIZON, n_humans, 2)
    assert np.isfinite(out).all()

    context = predictor.encode(history, mask, humans)
    assert context.shape == (predictor.context_size(n_humans, n_robots),)
    assert context.dtype == np.float64 and np.isfinite(context).all()
    function = predictor.to_casadi(n_humans, n_robots, HORIZON)
    assert function.name_in() == ["context", "robots_future"] and function.name_out() == ["humans_future"]
    symbolic = np.asarray(function(context, robots_future.reshape(-1))).reshape(HORIZON, n_humans, 2)
    np.testing.assert_allclose(symbolic, out, rtol=0, atol=TOL)

    ctx, plan = function.mx_in(0), function.mx_in(1)
    jac_fn = ca.Function("plan_jacobian", [ctx, plan], [ca.jacobian(function(ctx, plan), plan)])
    jac_casadi = np.asarray(jac_fn(context, robots_future.reshape(-1)))
    if isinstance(predictor, LearnedPredictor):
        jac_reference = torch_jacobian(predictor, history, mask, robots_future, humans)
    else:
        jac_reference = finite_difference_jacobian(predictor, history, mask, robots_future, humans)
    np.testing.assert_allclose(jac_casadi, jac_reference, rtol=0, atol=TOL)
    if isinstance(predictor, LearnedPredictor) and getattr(predictor.config, "pooling", None) == "soft":
        # the differentiable pooling is what couples the humans to the plan inside the NLP
        assert np.abs(jac_casadi).max() > 1e-6


def test_rollout_without_robots(predictor):
    """Dataset evaluation: every agent is a human, no plan; partial tracks allowed."""
    history, mask, _, _ = crossing_scene()
    mask = mask.copy()
    mask[:3, 4] = False  # enters late
    mask[-2:, 5] = False  # left two steps ago
    humans = np.arange(6)
    out = predictor.rollout(history, mask, None, humans, horizon=12)
    assert out.shape == (12, 6, 2)
    assert np.isfinite(out).all()


@pytest.mark.parametrize(
    "humans, expected",
    [
        # agent 2 twice: it pooled with its own copy (social_lstm_eth moved it by 1.7 cm)
        (np.array([2, 2, 3]), "humans must be distinct agent indices; [2] repeated"),
        # a mask of agents 2..5, not indices: it was read as the agents [0, 0, 1, 1, 1, 1]
        (np.arange(6) >= 2, "humans must be integer agent indices, got dtype bool"),
        (np.array([2.0, 3.0]), "humans must be integer agent indices, got dtype float64"),
        (np.array([2, 6]), "humans must be indices into 6 agents (0..5), got [2, 6]"),
        (np.array([[2, 3]]), "humans must be a 1-D array of agent indices, got shape (1, 2)"),
    ],
    ids=["repeated", "bool-mask", "float", "out-of-range", "2-D"],
)
def test_rollout_refuses_humans_that_are_not_distinct_indices(predictor, humans, expected):
    history, mask, _, _ = crossing_scene()
    with pytest.raises(ValueError) as refused:
        predictor.rollout(history, mask, None, humans, horizon=HORIZON)
    assert str(refused.value).startswith(expected)


@pytest.mark.parametrize(
    "humans, expected",
    [
        (np.array([2, 2, 3]), "humans must be distinct agent indices; [2] repeated"),
        (np.arange(6) >= 2, "humans must be integer agent indices, got dtype bool"),
    ],
    ids=["repeated", "bool-mask"],
)
def test_encode_refuses_humans_that_are_not_distinct_indices(predictor, humans, expected):
    """The closed loop predicts through encode and the twin: rollout's refusal alone left that path reading a
    repeat as a neighbour on itself and a mask as indices."""
    history, mask, _, _ = crossing_scene()
    with pytest.raises(ValueError) as refused:
        predictor.encode(history, mask, humans)
    assert str(refused.value).startswith(expected)


@pytest.mark.parametrize("humans", [np.array([], dtype=int), np.array([])], ids=["int", "float"])
def test_rollout_of_no_humans(predictor, humans):
    """Every agent a robot: nothing to predict, from an empty int array or from ``np.array([])`` (float)."""
    history, mask, _, _ = crossing_scene()
    robots_future = history[-1][None] + np.zeros((HORIZON, 6, 2))
    assert predictor.rollout(history, mask, robots_future, humans).shape == (HORIZON, 0, 2)


def test_rollout_refuses_a_horizon_below_one(predictor):
    """As ``to_casadi`` does: the learned predictors returned one step for 0 or -2 and raised IndexError for
    a plan of no steps, constant velocity returned an empty array."""
    history, mask, humans, robots_future = crossing_scene()
    for horizon in (0, -2):
        with pytest.raises(ValueError, match=f"^horizon must be at least 1 step, got {horizon}$"):
            predictor.rollout(history, mask, None, np.arange(6), horizon=horizon)
    with pytest.raises(ValueError, match="^robots_future's length H must be at least 1 step, got 0$"):
        predictor.rollout(history, mask, robots_future[:0], humans)


def test_sizes_that_are_no_whole_numbers_are_refused_naming_them(predictor):
    """3.5 steps were 3 and True one; CasADi's refusals of a size named none ("Assertion nrow>=0"), and
    constant velocity's context of "2" humans was "2222"."""
    history, mask, humans, robots_future = crossing_scene()
    for horizon in (3.5, True, "3"):
        with pytest.raises(PredictorError, match="^horizon must be a whole number of steps, got "):
            predictor.rollout(history, mask, None, np.arange(6), horizon=horizon)
    for sizes, name in [((2.5, 2, 3), "n_humans"), ((2, "2", 3), "n_robots"), ((-1, 2, 3), "n_humans")]:
        with pytest.raises(PredictorError, match=f"^{name} must be a whole number >= 0, got "):
            predictor.to_casadi(*sizes)
    with pytest.raises(PredictorError, match="^horizon must be at least 1 step, got 0$"):
        predictor.to_casadi(2, 2, 0)
    with pytest.raises(PredictorError, match="^n_humans must be a whole number >= 0, got '2'$"):
        predictor.context_size("2", 2)


def test_lists_and_a_scene_of_no_one_are_taken_as_arrays(predictor):
    """Constant velocity raised AttributeError on lists where the nets took them; a net raised torch's
    reshape error on a scene of no agents at all, where constant velocity returned no forecast."""
    history, mask, humans, robots_future = crossing_scene()
    as_arrays = predictor.rollout(history, mask, robots_future, humans)
    as_lists = predictor.rollout(history.tolist(), mask.tolist(), robots_future.tolist(), humans.tolist())
    np.testing.assert_array_equal(as_lists, as_arrays)
    nobody = predictor.rollout(np.zeros((9, 0, 2)), np.zeros((9, 0), bool), None, np.array([], int), 3)
    assert nobody.shape == (3, 0, 2)


def test_casadi_function_save_load_round_trip(predictor, tmp_path):
    history, mask, humans, robots_future = crossing_scene()
    function = predictor.to_casadi(len(humans), robots_future.shape[1], HORIZON)
    path = tmp_path / "predictor.casadi"
    function.save(str(path))
    loaded = ca.Function.load(str(path))
    context = predictor.encode(history, mask, humans)
    np.testing.assert_array_equal(
        np.asarray(loaded(context, robots_future.reshape(-1))),
        np.asarray(function(context, robots_future.reshape(-1))),
    )


def test_checkpoint_round_trip_and_hash_refusal(learned, tmp_path):
    predictor = learned
    history, mask, humans, robots_future = crossing_scene()
    weights, _ = save_checkpoint(
        predictor.net,
        model=predictor.kind,
        name="roundtrip",
        out_dir=tmp_path / "run",
        obs_len=predictor.obs_len,
    )
    reloaded = load_checkpoint(weights)
    assert type(reloaded) is type(predictor) and reloaded.kind == predictor.kind
    # Checkpoints store float32 weights; a trained zoo entry is float32 already, an untrained one rounds.
    np.testing.assert_allclose(
        reloaded.rollout(history, mask, robots_future, humans),
        predictor.rollout(history, mask, robots_future, humans),
        rtol=0,
        atol=1e-5,
    )

    zoo = tmp_path / "zoo"
    add_to_zoo(weights, name="roundtrip", protocol="test", training_data={}, metrics={}, directory=zoo)
    assert load_zoo("roundtrip", zoo).name == "roundtrip"
    data = bytearray((zoo / "roundtrip.pt").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (zoo / "roundtrip.pt").write_bytes(bytes(data))
    with pytest.raises(CheckpointMismatch, match="roundtrip.pt has sha256"):
        load_zoo("roundtrip", zoo)
