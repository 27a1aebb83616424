"""The registry of model kinds (``predictors.models``): shipped kinds, plugins by ``module:NetClass`` and by
entry point, and what it refuses (bad specs, classes that break the contract, bad configs, oversized nets),
each as one PredictorError line."""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from importlib import metadata

import numpy as np
import pytest
import torch

from predictors import models
from predictors.errors import PredictorError
from predictors.kinds import MAX_PARAMETERS, ModelKind
from predictors.learned import LearnedPredictor
from predictors.models import (
    ENTRY_POINT_GROUP,
    PLUGINS_ENV,
    UnknownModel,
    load_plugin,
    model_kind,
    model_kinds,
    model_names,
    register_plugins,
)
from predictors.social_lstm_predictors import SocialGANPredictor
from tests.plugins.toy_predictor import ToyConfig, ToyNet
from tests.predictors.test_contract import HORIZON, crossing_scene

TOY = "tests.plugins.toy_predictor:ToyNet"
NEVER = "tests.plugins.never_imported:Net"  # importing that module raises
SHIPPED = {"social_lstm", "vanilla_lstm", "social_gan", "social_gru", "social_attention"}


@pytest.fixture
def no_plugins(monkeypatch):
    """A registry without the plugins other tests of this process registered."""
    monkeypatch.setattr(models, "_PLUGINS", {})


def fake_entry_points(monkeypatch, **entries: str) -> None:
    """Installed entry points of the group ``crowdmpc.predictors``: name -> ``module:Class``."""
    points = [metadata.EntryPoint(name=n, value=v, group=ENTRY_POINT_GROUP) for n, v in entries.items()]

    def entry_points(*, group: str):
        return [p for p in points if p.group == group]

    monkeypatch.setattr(models.metadata, "entry_points", entry_points)


# ------------------------------------------------------------------------------------------------ shipped
def test_the_shipped_kinds(no_plugins):
    assert SHIPPED <= set(model_names())
    assert set(model_kinds()) >= SHIPPED
    gan = model_kind("social_gan")
    assert gan.adversarial and gan.source == "shipped" and gan.predictor_class_name == "SocialGANPredictor"
    assert gan.config().noise_dim == 8 and gan.config().head == "point"
    assert model_kind("vanilla_lstm").config().pooling == "none"
    assert model_kind("social_lstm").predictor_class_name == "LearnedPredictor"
    assert model_kind("social_lstm").has_field("pooling") and not model_kind("social_attention").has_field(
        "pooling"
    )


def test_a_kind_defining_value_cannot_be_changed(no_plugins):
    """vanilla_lstm is SocialLSTM without pooling: {"pooling": "grid"} used to train a grid Social-LSTM named
    vanilla_lstm_eth. Refused from overrides, from a stored "net" that leaves pooling to the class's default
    (grid), and from a pooled net handed over as it is; a stored config may repeat the defining value."""
    vanilla, social = model_kind("vanilla_lstm"), model_kind("social_lstm")
    message = re.escape(
        "pooling 'grid' is not a vanilla_lstm: the kind is defined by pooling 'none' "
        "(it has no social pooling)"
    )
    with pytest.raises(PredictorError, match=message):
        vanilla.config({"pooling": "grid"})
    with pytest.raises(PredictorError, match=message):
        vanilla.build_net({"hidden_dim": 8})
    assert vanilla.config({"pooling": "none", "hidden_dim": 8}).pooling == "none"
    pooled = social.build_net(social.config({"hidden_dim": 8}))
    with pytest.raises(PredictorError, match=message):
        vanilla.build_net(pooled.config)
    with pytest.raises(PredictorError, match=message):
        vanilla.config_dict(pooled.config)  # what save_checkpoint writes
    with pytest.raises(PredictorError, match=message):
        vanilla.predictor(pooled, name="pooled", obs_len=9)
    # a default only: social_lstm pools either way
    assert social.config({"pooling": "soft"}).pooling == "soft"


@pytest.mark.parametrize(
    ("model", "values", "message"),
    [
        (
            "social_lstm",
            {"pooling": "none"},
            "pooling 'none' is not a social_lstm (without social pooling it is",
        ),
        ("social_lstm", {"noise_dim": 4}, "noise_dim 4 is not a social_lstm (noise makes it the social_gan"),
        (
            "vanilla_lstm",
            {"noise_dim": 2},
            "noise_dim 2 is not a vanilla_lstm (noise makes it a GAN generator)",
        ),
        (
            "social_gan",
            {"noise_dim": 0},
            "noise_dim 0 is not a social_gan (the generator draws its variety from",
        ),
        ("social_gan", {"head": "gaussian"}, "head 'gaussian' is not a social_gan (its discriminator judges"),
    ],
)
def test_a_new_config_that_makes_another_kind_is_refused_and_a_stored_one_still_loads(
    no_plugins, model, values, message, tmp_path
):
    """`train --model social_lstm --pooling none` trained a vanilla LSTM named social_lstm_eth, and with
    noise_dim 4 a social_lstm carried a noise layer fed zeros; a social_gan without noise or with a Gaussian
    head got through the config and was refused only once the data were read (with the config's repr). A
    checkpoint trained before the rule keeps loading under its kind (its user zoo entry stays usable); no new
    one is written."""
    kind = model_kind(model)
    with pytest.raises(PredictorError, match=re.escape(message)):
        kind.config(values)
    assert kind.config({key: kind.config().to_dict()[key] for key in values}) == kind.config()
    stored = kind.build_net({**kind.config().to_dict(), **values})  # a checkpoint's config, as stored
    assert all(getattr(stored.config, key) == value for key, value in values.items())
    with pytest.raises(PredictorError, match=re.escape(message)):
        kind.config_dict(stored.config)  # what save_checkpoint writes


def test_a_kind_whose_defaults_take_a_refused_value_is_refused(no_plugins):
    with pytest.raises(
        PredictorError, match=r"model 'odd': its defaults take refused values of \['pooling'\]"
    ):
        ModelKind(
            "odd",
            type(model_kind("social_lstm").build_net({})),
            {"pooling": "none"},
            refused={"pooling": (lambda value: value == "none", "")},
        )


@pytest.mark.parametrize("name", ["gpt", "", "Social_LSTM", "social_lstm ", None, 3, ["social_lstm"]])
def test_an_unknown_name_lists_the_choices(no_plugins, name):
    with pytest.raises(UnknownModel) as refused:
        model_kind(name)
    message = str(refused.value)
    assert message.startswith(f"unknown model {name!r}; choose from [")
    assert "'social_lstm'" in message and "--plugin module:NetClass" in message and "\n" not in message


def test_an_unregistered_plugin_name_says_how_to_register_it_and_imports_nothing(no_plugins):
    with pytest.raises(UnknownModel) as refused:
        model_kind(NEVER)
    assert str(refused.value) == (
        f"model {NEVER!r} is a plugin that is not registered; register it with "
        f"`crowdmpc --plugin {NEVER} COMMAND ...` or {PLUGINS_ENV}={NEVER}"
    )
    assert "tests.plugins.never_imported" not in sys.modules


# ------------------------------------------------------------------------------------------------ plugins
def test_a_plugin_by_module_and_class(no_plugins):
    kind = load_plugin(TOY)
    assert kind.name == TOY and kind.net_class is ToyNet and kind.source == "plugin"
    assert model_kind(TOY) is kind and TOY in model_names() and TOY in model_kinds()
    assert load_plugin(TOY) is kind  # loaded once
    config = kind.config({"hidden_dim": 4})
    assert config == ToyConfig(hidden_dim=4) and kind.config_dict(config) == {"hidden_dim": 4, "radius": 2.0}
    predictor = kind.predictor(kind.build_net(config), name="toy", obs_len=9)
    assert type(predictor) is LearnedPredictor and predictor.kind == TOY and predictor.name == "toy"


def test_register_plugins_records_them_for_child_processes(no_plugins, monkeypatch):
    monkeypatch.setenv(PLUGINS_ENV, "some.module:Other")
    monkeypatch.setattr(models, "load_plugin", lambda spec: spec)  # record only: some.module is not real
    register_plugins([TOY, TOY])
    assert os.environ[PLUGINS_ENV] == f"some.module:Other,{TOY}"  # kept, and each listed once


def test_one_plugin_given_alone_is_refused_naming_it(no_plugins):
    # register_plugins("m:C") iterated the str: "plugin 'w' is not of the form module:NetClass"
    with pytest.raises(PredictorError, match=r"list of 'module:NetClass' strings, got the str 'tests\."):
        register_plugins(TOY)


def test_plugins_from_the_environment(no_plugins, monkeypatch):
    monkeypatch.setenv(PLUGINS_ENV, f" {TOY} ,")
    assert TOY in model_names()
    assert model_kind(TOY).source == "plugin"


@pytest.mark.parametrize(
    "spec, message",
    [
        ("../x", "plugin '../x' is not of the form module:NetClass"),
        ("/tmp/x.py:Net", "is not of the form module:NetClass"),
        ("toy_predictor", "is not of the form module:NetClass"),
        ("a:b:c", "is not of the form module:NetClass"),
        ("a b:C", "is not of the form module:NetClass"),
        ("mödule:Net", "is not of the form module:NetClass"),
        ("a." * 150 + "b:C", "is not of the form module:NetClass"),
        ("", "is not of the form module:NetClass"),
        (None, "plugin None is not of the form module:NetClass"),
        ("os:system", "model 'os:system': <built-in function system> is not a torch.nn.Module subclass"),
        ("os:nope", "plugin 'os:nope': module 'os' has no 'nope'"),
        (
            "no_such_module_q:Net",
            "plugin 'no_such_module_q:Net': importing 'no_such_module_q' failed: ModuleNotFoundError",
        ),
        (NEVER, "importing 'tests.plugins.never_imported' failed: AssertionError"),
        ("torch.nn:Linear", "Linear.config_class must be a dataclass of hyper-parameters"),
        ("tests.plugins.toy_predictor:ToyConfig", "is not a torch.nn.Module subclass"),
    ],
)
def test_bad_plugins_are_refused_in_one_line(no_plugins, spec, message):
    with pytest.raises(PredictorError) as refused:
        load_plugin(spec)
    assert message in str(refused.value) and "\n" not in str(refused.value)
    assert spec not in models._PLUGINS


def test_a_class_without_the_step_methods_is_refused(no_plugins, monkeypatch):
    class NoStep(torch.nn.Module):
        config_class = ToyConfig
        head_type = "point"

    monkeypatch.setattr(sys.modules["tests.plugins.toy_predictor"], "NoStep", NoStep, raising=False)
    with pytest.raises(PredictorError, match=r"NoStep has no encode\(\)"):
        load_plugin("tests.plugins.toy_predictor:NoStep")


# ------------------------------------------------------------------------------------------- entry points
def test_a_plugin_by_entry_point(no_plugins, monkeypatch):
    fake_entry_points(monkeypatch, toy_ep=TOY)
    assert "toy_ep" in model_names()
    kind = model_kind("toy_ep")
    assert kind.net_class is ToyNet and kind.source.startswith("entry point") and kind.name == "toy_ep"
    assert model_kinds()["toy_ep"] is kind
    assert model_kind("social_lstm").source == "shipped"


def test_an_installed_entry_point_named_as_a_shipped_kind_is_refused(
    no_plugins, monkeypatch, tmp_path, capsys
):
    """An installed package declaring ``social_lstm = module:Net`` was ignored without a word (the shipped
    kind trained in its place), where ``--plugin`` refuses to shadow one: refused in one line naming the
    distribution and the entry point, wherever kinds are listed or loaded."""
    from pipelines.cli import main
    from tests.plugins import install_distribution

    install_distribution(
        monkeypatch, tmp_path / "site", f"[{ENTRY_POINT_GROUP}]\ntoy_ep = {TOY}\nsocial_lstm = {TOY}\n"
    )
    message = (
        f"entry point 'social_lstm' ({TOY}) of distribution 'shadow-pkg' would shadow a shipped model; "
        f"rename it in shadow-pkg's '{ENTRY_POINT_GROUP}' entry points or uninstall shadow-pkg"
    )
    for call in (lambda: model_kind("social_lstm"), lambda: model_kind("toy_ep"), model_names, model_kinds):
        with pytest.raises(PredictorError) as refused:
            call()
        assert str(refused.value) == message
    capsys.readouterr()
    with pytest.raises(SystemExit) as exited:
        main(["train", "--model", "social_lstm", "--epochs", "1"])
    assert exited.value.code == 2
    assert capsys.readouterr().err == (
        f"crowdmpc train: error: argument --model: {message}; see 'crowdmpc train --help'\n"
    )


def test_an_entry_point_that_does_not_load_is_one_line(no_plugins, monkeypatch):
    fake_entry_points(monkeypatch, broken="no_such_module_q:Net")
    with pytest.raises(PredictorError) as refused:
        model_kind("broken")
    message = str(refused.value)
    assert message.startswith(
        "entry point 'broken' (no_such_module_q:Net) does not load: ModuleNotFoundError"
    )


# ------------------------------------------------------------------------------------------------ configs
@pytest.mark.parametrize(
    "kind, values, message",
    [
        (
            TOY,
            {"bogus": 1},
            f"unknown {TOY} config keys ['bogus']; expected a subset of ['hidden_dim', 'radius']",
        ),
        (TOY, {"hidden_dim": 0}, f"{TOY} config: ValueError: hidden_dim must be in 1..4096, got 0"),
        (TOY, {"hidden_dim": "8"}, f"{TOY} config: TypeError: hidden_dim must be an integer, got '8'"),
        (TOY, {"radius": float("nan")}, "radius must be in (0, 100], got nan"),
        (TOY, [1, 2], f"a {TOY} config must be a JSON object, got [1, 2]"),
        ("social_lstm", {"pooling": "max"}, "pooling 'max' is not one of"),
        ("social_lstm", {"hidden": 3}, "unknown social_lstm config keys ['hidden']"),
        ("social_gru", {"hidden_dim": True}, "hidden_dim must be an integer, got True"),
        ("social_attention", {"pooling": "soft"}, "unknown social_attention config keys ['pooling']"),
    ],
)
def test_bad_configs_are_refused(no_plugins, kind, values, message):
    load_plugin(TOY)
    with pytest.raises(PredictorError) as refused:
        model_kind(kind).config(values)
    assert message in str(refused.value) and "\n" not in str(refused.value)
    if isinstance(values, dict):  # a dict given to build_net is validated the same way
        with pytest.raises(PredictorError, match=re.escape(message)):
            model_kind(kind).build_net({**values})


@dataclass(frozen=True)
class UncheckedConfig:  # a newcomer's config: annotated, and no __post_init__ checking anything
    hidden_dim: int = 8
    radius: float = 2.0
    tag: str | None = None


class Unchecked(ToyNet):
    config_class = UncheckedConfig


@pytest.mark.parametrize(
    "values, message",
    [
        ({"hidden_dim": "8"}, "hidden_dim must be an integer (UncheckedConfig.hidden_dim: int), got '8'"),
        ({"hidden_dim": True}, "hidden_dim must be an integer (UncheckedConfig.hidden_dim: int), got True"),
        ({"hidden_dim": 8.0}, "hidden_dim must be an integer (UncheckedConfig.hidden_dim: int), got 8.0"),
        ({"radius": "2"}, "radius must be a number (UncheckedConfig.radius: float), got '2'"),
        ({"radius": None}, "radius must be a number (UncheckedConfig.radius: float), got None"),
        ({"tag": 3}, "tag must be a string or null (UncheckedConfig.tag: str | None), got 3"),
    ],
)
def test_a_plugin_config_value_of_another_type_than_its_annotation_is_refused(values, message):
    """A plugin whose config class checks nothing: a string size failed in torch ("empty(): argument 'size'
    ... must be tuple of ints", no key named) and ``true`` built a net of width 1; each is now one line
    naming the key, the type it is annotated with and the value."""
    kind = ModelKind(name="mine:Unchecked", net_class=Unchecked, source="plugin")
    with pytest.raises(PredictorError) as refused:
        kind.config(values)
    assert str(refused.value) == f"mine:Unchecked config holds a value of the wrong type: {message}"
    assert kind.config({"radius": 3, "tag": None}).radius == 3  # JSON's 3 for 3.0; a union takes null
    assert kind.config({"tag": "x"}).tag == "x"
    stored = kind.build_net({"hidden_dim": 4, "radius": 2.0, "tag": 7})  # a stored config keeps loading
    assert stored.config.tag == 7


def test_an_oversized_net_is_refused_before_memory_is_taken(no_plugins, monkeypatch):
    kind = load_plugin(TOY)
    devices = []
    original = ToyNet.__init__

    def spy(self, config):
        devices.append(torch.empty(()).device.type)  # the default device the net is built on
        original(self, config)

    monkeypatch.setattr(ToyNet, "__init__", spy)
    config = kind.config({"hidden_dim": 4096})  # 4096 x 4096 recurrent weights alone: 16.8 M
    with pytest.raises(PredictorError) as refused:
        kind.build_net(config)
    assert re.fullmatch(
        rf"{re.escape(TOY)}: this config makes a net of [\d,]+ parameters, more than the "
        rf"{MAX_PARAMETERS:,} allowed",
        str(refused.value),
    )
    assert devices == ["meta"]
    kind.build_net(kind.config({"hidden_dim": 64}))
    assert devices == ["meta", "meta", "cpu"]


def test_the_gan_kind_makes_a_sampling_predictor(no_plugins):
    kind = model_kind("social_gan")
    torch.manual_seed(0)
    predictor = kind.predictor(kind.build_net(kind.config()), name="g", obs_len=9)
    assert isinstance(predictor, SocialGANPredictor) and predictor.kind == "social_gan"
    check_sampling(predictor)


def check_sampling(predictor: SocialGANPredictor) -> None:
    """``sample`` on the crossing scene (2 robots, 4 humans, H = 4): k = 5 finite futures (k, H, N_h, 2),
    each different from the others and from the zero-noise rollout, the same again from the same seed and
    others from another seed; without a plan, the horizon asked for."""
    history, mask, humans, robots_future = crossing_scene()

    def draw(seed: int) -> np.ndarray:
        return predictor.sample(history, mask, robots_future, humans, None, 5, np.random.default_rng(seed))

    samples = draw(1)
    assert samples.shape == (5, HORIZON, 4, 2) and np.isfinite(samples).all()
    gaps = [np.abs(samples[i] - samples[j]).max() for i in range(5) for j in range(i + 1, 5)]
    assert min(gaps) > 1e-3  # no two samples alike: each has its own noise
    rollout = predictor.rollout(history, mask, robots_future, humans)
    assert np.abs(samples - rollout[None]).max(axis=(1, 2, 3)).min() > 1e-3
    np.testing.assert_array_equal(draw(1), samples)
    assert np.abs(draw(2) - samples).max() > 1e-3
    unplanned = predictor.sample(history, mask, None, humans, 3, 2, np.random.default_rng(1))
    assert unplanned.shape == (2, 3, 4, 2) and np.isfinite(unplanned).all()


def test_model_kind_stays_importable_from_the_registry():
    """ModelKind lived in predictors.models before predictors.kinds: code written then still imports it."""
    from predictors import kinds

    assert models.ModelKind is kinds.ModelKind
