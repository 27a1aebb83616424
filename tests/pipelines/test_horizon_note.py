"""The note on an MPC that plans further ahead than its learned predictor was trained to predict (simulate,
sweep): TrajNet++ trains 12 steps (4.8 s), and a horizon of 13 to 20 rolled the net out past that without a
word."""

import dataclasses

import pytest

from pipelines.cli import main
from pipelines.commands.simulate_checks import horizon_note
from pipelines.loop.controllers import ControllerSpec
from predictors import registry, zoo


def _spec(controller: str, predictor: str, horizon: int | None) -> ControllerSpec:
    overrides = () if horizon is None else (("horizon", horizon),)
    return ControllerSpec(controller, predictor, mpc_overrides=overrides)


def test_a_shipped_net_was_trained_for_12_steps_and_the_rules_learned_nothing():
    assert registry.trained_prediction_length("social_lstm_eth") == 12
    assert registry.trained_prediction_length("constant_velocity") is None
    assert registry.trained_prediction_length("orca_oracle") is None
    assert (
        registry.trained_prediction_length("no_such_model") is None
        and registry.trained_prediction_length(None) is None
    )


@pytest.mark.parametrize(
    "spec",
    [
        _spec("cmpc", "social_lstm_eth", None),  # Table I's 8
        _spec("dmpc", "social_lstm_eth", 12),  # its own length
        _spec("cmpc", "constant_velocity", 20),  # a rule: no length to exceed
    ],
)
def test_no_note_within_the_training_length(spec):
    assert horizon_note(spec) is None


def test_the_note_names_the_horizon_the_model_and_the_extrapolated_steps():
    assert horizon_note(_spec("dmpc", "social_lstm_eth", 13)) == (
        "note: the MPC plans 13 steps ahead and 'social_lstm_eth' was trained to predict 12 (4.8 s): its "
        "steps 13..13 are extrapolated"
    )


def test_a_recorded_training_length_is_the_one_compared(monkeypatch):
    shipped = zoo.locate("social_lstm_eth")
    assert shipped is not None
    for recorded, expected in ((8, 8), ("8", 12), (True, 12), (0, 12)):  # anything but a length reads as 12
        entry = dataclasses.replace(shipped.entry, training={**shipped.entry.training, "pred_len": recorded})
        monkeypatch.setattr(zoo, "locate", lambda name, *a, e=entry: dataclasses.replace(shipped, entry=e))
        assert registry.trained_prediction_length("social_lstm_eth") == expected, recorded
    assert horizon_note(_spec("cmpc", "social_lstm_eth", 10)) is None  # 12 again (the last: 0)
    entry = dataclasses.replace(shipped.entry, training={**shipped.entry.training, "pred_len": 8})
    monkeypatch.setattr(zoo, "locate", lambda name, *a: dataclasses.replace(shipped, entry=entry))
    assert "trained to predict 8 (3.2 s): its steps 9..10" in horizon_note(
        _spec("cmpc", "social_lstm_eth", 10)
    )


def test_a_sweep_says_it_once_naming_the_methods(tmp_path, capsys):
    argv = ["sweep", "--experiment", "table2", "--set", "mpc.horizon=14", "--dry-run", "--out", str(tmp_path)]
    assert main(argv) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "trained to predict" in line]
    assert notes == [
        "note: methods 'CMPC', 'DMPC': the MPC plans 14 steps ahead and 'social_lstm_eth' was trained to "
        "predict 12 (4.8 s): its steps 13..14 are extrapolated"
    ]
