"""A net that breaks the step contract (``predictors.nets.contract``) is refused before training starts and
when its zoo entry is loaded, in one line naming the model kind and what was expected against what it gave;
every registered kind, shipped or plugin, passes the same check."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch

from pipelines.cli import main
from predictors import models
from predictors.base import OBS_LEN, PRED_LEN
from predictors.checkpoint import load_checkpoint, save_checkpoint
from predictors.errors import PredictorError
from predictors.models import load_plugin, model_kind, model_kinds
from predictors.nets.contract import check_step_contract, check_training_forward
from predictors.optim_config import OptimConfig
from predictors.training import PredictorModule, defines_forward, make_module
from tests.predictors.samples import write_walk_file

BROKEN = "tests.plugins.broken_nets"
SEE = "(see predictors/nets/contract.py)"
WINDOW_MLP = "window_mlp:WindowMLP"


@pytest.fixture(autouse=True)
def _fresh_plugins(monkeypatch):
    monkeypatch.setattr(models, "_PLUGINS", {})
    monkeypatch.delenv(models.PLUGINS_ENV, raising=False)
    # the guide's example, registered as a user would from docs/examples
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "docs" / "examples"))


def _registered(name: str) -> str:
    """``BROKEN:name`` registered as a plugin kind; its name."""
    return load_plugin(f"{BROKEN}:{name}").name


# --------------------------------------------------------------------------------------- the good nets
def _all_kinds() -> list[str]:
    load_plugin("tests.plugins.toy_predictor:ToyNet")
    load_plugin(WINDOW_MLP)
    return sorted(model_kinds())


def test_every_registered_kind_and_head_passes_without_touching_the_net_or_the_random_state():
    for name in _all_kinds():
        kind = model_kind(name)
        heads = [{}, {"head": "point"}] if kind.has_field("head") and not kind.adversarial else [{}]
        for overrides in heads:
            net = kind.build_net(kind.config(overrides)).train()
            before = torch.get_rng_state()
            check_step_contract(net, name, obs_len=OBS_LEN)
            check_step_contract(net.double(), name, obs_len=OBS_LEN)  # as LearnedPredictor runs it
            if defines_forward(net) and not kind.adversarial:
                check_training_forward(net.float(), name, obs_len=OBS_LEN, pred_len=PRED_LEN)
            # a seeded run trains the same weights with the check as without it, in the mode it asked for
            assert torch.equal(before, torch.get_rng_state()) and net.training, name


# ---------------------------------------------------------------------------------------- the bad nets
BAD_STEPS = [
    (
        "OneColumn",
        "encode's out must be of shape (B, N, K) with K >= 2 (out[..., :2] is the mean step) for a 'point' "
        "head, got (2, 3, 1) for B=2, N=3",
    ),
    (
        "FlatOut",
        "decode_step's out must be of shape (B, N, K) with K >= 2 (out[..., :2] is the mean step) for a "
        "'point' head, got (2, 3) for B=2, N=3",
    ),
    ("AgentsFirst", "encode's state tensor 0 must be of shape (B, N, ...), got (3, 2, 8) for B=2, N=3"),
    (
        "GaussianOfTwo",
        "encode's out must be of shape (B, N, 5) (mean step, sigmas, correlation) for a 'gaussian' head, "
        "got (2, 3, 2) for B=2, N=3",
    ),
    (  # passed the check of 3 agents and failed in training's first batch, in a 75-line traceback
        "ThreeAgentsOnly",
        "encode failed on a synthetic batch (B=2, N=5): RuntimeError: mat1 and mat2 shapes cannot be "
        "multiplied (4x5 and 3x3)",
    ),
]


@pytest.mark.parametrize("net, message", BAD_STEPS, ids=[net for net, _ in BAD_STEPS])
def test_a_net_breaking_the_step_contract_is_refused_before_training(net, message):
    model = _registered(net)
    with pytest.raises(PredictorError) as caught:
        make_module(model, None, OptimConfig())
    assert str(caught.value) == f"model {model!r}: {message} {SEE}"


@pytest.mark.parametrize(
    "net, message",
    [
        ("InFloat64", "parameters of torch.float64; training feeds float32 batches"),
        ("Frozen", "the net has no trainable parameters"),
    ],
)
def test_a_net_training_cannot_use_is_refused_before_training(net, message):
    """Both passed the step check (run in the net's own dtype), then failed in Lightning with a traceback."""
    model = _registered(net)
    with pytest.raises(PredictorError, match=f"model {model!r}: {message}"):
        make_module(model, None, OptimConfig())


def test_a_net_breaking_the_contract_only_in_float64_is_refused_before_training(tmp_path, capsys):
    """``out.float()`` in decode_step passed the check in the float32 training runs in; the whole training
    ran, and only then did train's evaluation, loading the weights in float64, refuse them."""
    model = _registered("CastsToFloat32")
    with pytest.raises(PredictorError) as caught:
        make_module(model, None, OptimConfig())
    assert str(caught.value) == (
        f"model {model!r} in float64 (as the closed loop and the export run it): encode's out must be "
        f"torch.float64 like the positions, got torch.float32 {SEE}"
    )
    code, err = _train_plugin(f"{BROKEN}:CastsToFloat32", tmp_path, capsys)
    assert code == 2 and "in float64" in err and not (tmp_path / "run").exists(), err


@pytest.mark.parametrize(
    "net, message",
    [
        ("CentresInPlace", "encode changed its argument positions in place"),
        ("StepsStateInPlace", "decode_step changed its argument state tensor 0 in place"),
        ("ForwardCentresInPlace", "forward changed its argument positions in place"),
    ],
)
def test_a_net_changing_its_inputs_in_place_is_refused_before_training(net, message):
    """``positions -= centre`` in encode changed the training batch itself: the net trained and validated
    on moved scenes without a word (only the export refused the in-place operation, after training)."""
    model = _registered(net)
    with pytest.raises(PredictorError) as caught:
        make_module(model, None, OptimConfig())
    assert str(caught.value).startswith(f"model {model!r}: {message}: ")
    assert "x = x - v" in str(caught.value)


def test_a_forward_by_torch_habit_names_the_training_signature():
    model = _registered("TorchHabitForward")
    with pytest.raises(PredictorError) as caught:
        PredictorModule(model)
    assert str(caught.value) == (
        f"model {model!r}: TorchHabitForward.forward(positions, mask) is not the training rollout "
        "forward(positions, mask, obs_len, pred_len, *, teacher_forcing) -> (outputs, predicted); give it "
        "that signature, or drop forward and the net is "
        "trained through the generic rollout of encode and decode_step (predictors/nets/rollout.py)"
    )


def test_a_forward_returning_only_positions_is_refused():
    model = _registered("ForwardReturnsPositions")
    with pytest.raises(PredictorError, match=r"forward must return \(outputs, predicted\), got Tensor"):
        PredictorModule(model)


def _train_plugin(model: str, tmp_path, capsys) -> tuple[int, str]:
    """``crowdmpc --plugin MODEL train --model MODEL`` on a small file into tmp_path/run: code, stderr."""
    data = write_walk_file(tmp_path / "walk.ndjson")
    argv = ["--plugin", model, "train", "--model", model, "--train", str(data), "--val", str(data)]
    capsys.readouterr()
    code = main([*argv, "--epochs", "1", "--out", str(tmp_path / "run"), "--no-progress"])
    return code, capsys.readouterr().err


def _refusal(err: str) -> list[str]:
    """The lines of ``err`` but train's notes (the data's: ``--val`` here is the training file, which train
    notes since d902089)."""
    return [line for line in err.strip().splitlines() if not line.startswith("note: ")]


def test_train_refuses_a_broken_net_in_one_line_before_writing_anything(tmp_path, capsys):
    model = f"{BROKEN}:OneColumn"
    code, err = _train_plugin(model, tmp_path, capsys)
    (line,) = _refusal(err)
    assert code == 2 and "Traceback" not in err
    assert line.startswith(f"crowdmpc train: error: model {model!r}: encode's out must be of shape (B, N, K)")
    assert not (tmp_path / "run").exists()


def test_train_refused_before_writing_removes_the_parents_of_out_it_made(tmp_path, capsys):
    """--out's folder was removed, but not the missing parents its lock had made (OUT's a/b stayed)."""
    model = f"{BROKEN}:OneColumn"
    data = write_walk_file(tmp_path / "walk.ndjson")
    argv = ["--plugin", model, "train", "--model", model, "--train", str(data), "--val", str(data)]
    code = main([*argv, "--epochs", "1", "--out", str(tmp_path / "a" / "b" / "run"), "--no-progress"])
    assert code == 2 and "encode's out must be of shape" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["walk.ndjson"]
    # an empty folder that was there, named through one not made yet: kept (judged as named, it went too)
    (tmp_path / "kept").mkdir()
    out = tmp_path / "x" / ".." / "kept" / "run"
    assert main([*argv, "--epochs", "1", "--out", str(out), "--no-progress"]) == 2
    assert (tmp_path / "kept").is_dir() and not (tmp_path / "kept" / "run").exists()


def test_a_head_type_property_that_raises_is_one_line_in_train_and_in_the_check(tmp_path, capsys):
    """It was a KeyError traceback: ``train`` reads the head (for its loss) before the contract check."""
    model = f"{BROKEN}:HeadTypeRaises"
    code, err = _train_plugin(model, tmp_path, capsys)
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert f"model {model!r}: reading head_type failed: KeyError: 'point' {SEE}" in err
    kind = model_kind(model)
    with pytest.raises(PredictorError) as caught:
        check_step_contract(kind.build_net(kind.config()), "model 'x'", obs_len=OBS_LEN)
    assert str(caught.value) == f"model 'x': reading head_type failed: KeyError: 'point' {SEE}"


def test_a_saved_broken_net_fails_at_load_not_in_the_closed_loop(tmp_path):
    model = _registered("OneColumn")
    kind = model_kind(model)
    weights, config = save_checkpoint(
        kind.build_net(kind.config()), model=model, name="one_column", out_dir=tmp_path, obs_len=OBS_LEN
    )
    with pytest.raises(PredictorError) as caught:
        load_checkpoint(weights)
    assert str(caught.value).startswith(
        f"{config}: predictor 'one_column' (model {model!r}): encode's out must be of shape (B, N, K) with "
        "K >= 2"
    )


def test_a_net_that_raises_on_a_wellformed_batch_is_one_line():
    class Crashes(torch.nn.Module):
        head_type = "point"

        def encode(self, positions, mask):
            return positions @ torch.ones(3, 3)  # (..., 2) @ (3, 3): torch's RuntimeError

    with pytest.raises(PredictorError) as caught:
        check_step_contract(Crashes(), "model 'crashes'", obs_len=OBS_LEN)
    message = str(caught.value)
    assert (
        message.startswith("model 'crashes': encode failed on a synthetic batch (B=2, N=3): RuntimeError: ")
        and "\n" not in message
    )


@pytest.mark.parametrize("head", ["Gaussian", None])
def test_a_head_type_that_is_neither_gaussian_nor_point_is_refused(head):
    net = torch.nn.Linear(2, 2)
    net.head_type = head  # type: ignore[assignment]
    with pytest.raises(PredictorError, match=r"model 'x': head_type must be one of \['gaussian', 'point'\]"):
        check_step_contract(net, "model 'x'", obs_len=OBS_LEN)


def _train_three_epochs(model: str, tmp_path, capsys) -> tuple[int, list[str]]:
    """``crowdmpc train`` of plugin ``model``, 3 epochs on a walk into tmp_path/run: exit code, stderr."""
    data = write_walk_file(tmp_path / "walk.ndjson")
    argv = ["--plugin", model, "train", "--model", model, "--train", str(data), "--val", str(data)]
    code = main([*argv, "--epochs", "3", "--out", str(tmp_path / "run"), "--no-progress"])
    return code, capsys.readouterr().err.strip().splitlines()


def test_a_training_whose_loss_is_nan_stops_after_that_epoch_in_one_line_and_writes_no_weights(
    tmp_path, capsys
):
    """It trained every epoch on NaN, wrote NaN weights as OUT/NAME.pt, and only then failed, on reading
    them back, with "tensor 'embed.weight' holds NaN or infinite values", which named neither the cause nor
    the epoch."""
    model = f"{BROKEN}:DividesByItsOwnDistance"
    code, err = _train_three_epochs(model, tmp_path, capsys)
    assert code == 2 and err[-1].startswith(
        f"crowdmpc train: error: model {model!r}: training diverged: the training loss was nan in epoch 0, "
        "and no epoch before it validated"
    ), err
    epochs = (tmp_path / "run" / "csv" / "version_0" / "metrics.csv").read_text().splitlines()[1:]
    # stopped after the first epoch ("": the learning rate's row, logged as the epoch starts, has no epoch)
    assert {line.split(",")[0] for line in epochs} - {""} == {"0"}
    assert not list((tmp_path / "run").glob("*.pt"))


def test_a_diverged_epoch_whose_validation_ade_is_finite_is_no_best_epoch(tmp_path, capsys):
    """A Gaussian head's negative sigmas make the loss NaN from the first step while the mean, and the
    validation ADE, stay finite: that epoch was saved as the best, said to be "the best epoch before" the
    divergence it was, and its weights written as a trained model's (exit 0)."""
    model = f"{BROKEN}:NegativeSigmas"
    code, err = _train_three_epochs(model, tmp_path, capsys)
    assert code == 2 and err[-1].startswith(
        f"crowdmpc train: error: model {model!r}: training diverged: the training loss was nan in epoch 0, "
        "and no epoch before it validated; no weights written"
    ), err
    rows = (tmp_path / "run" / "csv" / "version_0" / "metrics.csv").read_text().splitlines()
    column = rows[0].split(",").index("val_ade")
    ades = [float(row.split(",")[column]) for row in rows[1:] if row.split(",")[column]]
    assert ades and all(map(math.isfinite, ades))  # what made the diverged epoch look like a best one
    assert not list((tmp_path / "run").glob("*.pt"))
    assert not list((tmp_path / "run" / "checkpoints").glob("best*"))


def test_a_model_loads_and_an_in_place_change_is_still_refused_under_inference_mode():
    """The in-place check reads torch's count of a tensor's changes (``_version``), which tensors made under
    ``torch.inference_mode()`` do not keep: a notebook loading a zoo model inside it, which worked before the
    check, ended in "RuntimeError: Inference tensors do not track version counter". The check makes its own
    tensors outside inference mode, so it loads, and still sees an in-place change there."""
    from predictors.registry import load_predictor

    with torch.inference_mode():
        assert load_predictor("social_lstm_eth").name == "social_lstm_eth"
        model = _registered("CentresInPlace")
        with pytest.raises(PredictorError, match="encode changed its argument positions in place"):
            check_step_contract(model_kind(model).build_net({}), f"model {model!r}", obs_len=OBS_LEN)


def test_a_net_failing_on_a_real_batch_ends_train_in_one_line(tmp_path, capsys):
    """It passed the contract check and ended train in Lightning's 75-line traceback."""
    from tests.predictors.samples import write_crowds

    model = f"{BROKEN}:NoPadding"
    data = str(write_crowds(tmp_path / "crowds.ndjson"))  # scenes of 1 to 4 agents, padded in a batch of 5
    argv = ["--plugin", model, "train", "--model", model, "--train", data, "--val", data, "--batch-size", "5"]
    capsys.readouterr()
    code = main([*argv, "--epochs", "1", "--out", str(tmp_path / "run"), "--no-progress"])
    err = capsys.readouterr().err
    (line,) = _refusal(err)
    assert code == 2 and "Traceback" not in err
    assert line.startswith(
        f"crowdmpc train: error: model {model!r}: training failed in the net's code (broken_nets.py:"
    )
    assert "in decode_step): ValueError: an absent agent in the batch (the contract check's" in err


def test_a_predictor_whose_net_predicts_nan_for_observed_agents_is_refused_where_it_loads():
    """A plugin net predicting NaN loaded as a zoo predictor, and ``simulate`` with it fell back at every step
    and ended 0, its table saying "NaN predictions 98 of 98". Training keeps such a net: the epoch's loss
    tells its divergence (test_a_training_whose_loss_is_nan_stops_after_that_epoch...)."""
    from predictors.learned import LearnedPredictor
    from tests.plugins.broken_nets import DividesByItsOwnDistance
    from tests.plugins.toy_predictor import ToyConfig, ToyNet

    net = DividesByItsOwnDistance(ToyConfig())
    check_step_contract(net, "model 'x'", obs_len=OBS_LEN)  # its shapes keep the contract
    with pytest.raises(PredictorError) as caught:
        LearnedPredictor(net, name="divides", kind=f"{BROKEN}:DividesByItsOwnDistance")
    message = str(caught.value)
    expected = (
        f"predictor 'divides' (model '{BROKEN}:DividesByItsOwnDistance'): encode's out holds NaN or inf "
        "in 12 of 12 entries on a synthetic batch (B=2, N=3) where every agent is observed; a predictor "
        "must return finite outputs there"
    )
    assert message.startswith(expected) and "\n" not in message, message
    assert LearnedPredictor(ToyNet(ToyConfig()), name="toy").name == "toy"


@pytest.mark.parametrize("net", ["NoisySteps", "DrawsInPython"])
def test_a_predictor_whose_net_draws_random_numbers_is_refused_where_it_loads(net):
    """A plugin net adding noise to its steps in eval mode was added to a zoo, and `crowdmpc evaluate`
    scored it 4.305 / 7.405 m, then 4.306 / 7.406 m, without a word; the MPC, refused its export, planned
    with it in torch. Training keeps such a net (its noise may be wanted there). The toy net encodes by its
    decode_step, so encode is the call named."""
    import tests.plugins.broken_nets as broken
    from predictors.learned import LearnedPredictor
    from tests.plugins.toy_predictor import ToyConfig

    model = getattr(broken, net)(ToyConfig())
    check_step_contract(model, "model 'x'", obs_len=OBS_LEN)  # its shapes keep the contract
    with pytest.raises(PredictorError) as caught:
        LearnedPredictor(model, name="noisy", kind=f"{BROKEN}:{net}")
    message = str(caught.value)
    expected = (
        f"predictor 'noisy' (model '{BROKEN}:{net}'): encode is not deterministic: two calls on the "
        "same synthetic batch gave outs "
    )
    assert message.startswith(expected) and "only while training" in message and "\n" not in message
