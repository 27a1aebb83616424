"""The note on an MPC that plans further ahead than its learned predictor was trained to predict (simulate,
sweep): TrajNet++ trains 12 steps (4.8 s), and a horizon of 13 to 20 rolled the net out past that without a
word."""

import dataclasses

import pytest

from pipelines.cli import main
from pipelines.commands import simulate_checks
from pipelines.loop.controllers import ControllerSpec
from predictors import registry, zoo


def _spec(controller: str, predictor: str, horizon: int | None) -> ControllerSpec:
    overrides = () if horizon is None else (("horizon", horizon),)
    return ControllerSpec(controller, predictor, mpc_overrides=overrides)


def horizon_note(spec: ControllerSpec) -> str | None:
    """The note as simulate and sweep make it, of the entry the spec's predictor loads."""
    return simulate_checks.horizon_note(spec, simulate_checks.zoo_entry(spec.predictor_name))


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
        "step 13 is extrapolated"
    )  # one step past: not "steps 13..13"
    assert horizon_note(_spec("dmpc", "social_lstm_eth", 15)).endswith("its steps 13..15 are extrapolated")


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


def test_an_nlp_that_takes_long_to_build_and_solve_is_said_so():
    """A horizon of 100 among 50 humans ran minutes in one CasADi call, deaf to Ctrl-C, without a word."""
    from pipelines.commands.simulate_checks import size_note

    assert size_note(_spec("cmpc", "constant_velocity", None), 7, 3) is None  # Table I
    assert size_note(_spec("cmpc", "constant_velocity", None), 50, 12) is None  # 4 x 50 x 12 = 2400
    assert size_note(_spec("dmpc", "constant_velocity", 12), 7, 3) is None
    assert size_note(_spec("orca", "constant_velocity", 30), 50, 12) is None  # no NLP
    assert size_note(_spec("cmpc", "constant_velocity", 13), 7, 3) == (
        "note: an NLP of 3 robots among 7 humans over 13 steps is large (here 11 s to build and 0.6 s a "
        "first step for 12 robots, 50 humans, 8 steps; 2.5 s and 0.9 s for 3, 7 and 30): steps may pass "
        "mpc.time_limit_s, and an interrupt waits for CasADi to return"
    )
    assert size_note(_spec("dmpc", "constant_velocity", 8), 50, 12) is not None  # 4800


def test_a_sweep_says_it_of_each_methods_largest_crowd(tmp_path, capsys):
    """simulate said it; a sweep of the same NLPs said nothing."""
    argv = ["sweep", "--experiment", "table2", "--humans", "7,50", "--robots", "12", "--set", "mpc.horizon=8",
            "--dry-run", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "is large" in line]
    assert notes == [
        "note: methods 'CMPC', 'DMPC': an NLP of 12 robots among 50 humans over 8 steps is large (here 11 s "
        "to build and 0.6 s a first step for 12 robots, 50 humans, 8 steps; 2.5 s and 0.9 s for 3, 7 and "
        "30): steps may pass mpc.time_limit_s, and an interrupt waits for CasADi to return"
    ]
    assert main([*argv[:7], "--dry-run", "--out", str(tmp_path)]) == 0  # horizon 4: 4 x 50 x 12 = 2400
    assert "is large" not in capsys.readouterr().err


def test_a_cost_scale_below_the_solver_tolerance_is_said_so(tmp_path, capsys):
    """The solvers stop at an error of solver_tol in cost_scale * F: cost_scale = 1e-9 with the default
    tolerance reported every step "ok" while the robots stood still. A note, not a refusal (a rule between the
    two would refuse recorded configs, and solver_tol = 1 with cost_scale = 0.01 ran well)."""
    from pipelines.commands.simulate_checks import tolerance_note

    said = tolerance_note(ControllerSpec("cmpc", "constant_velocity", mpc_overrides=(("cost_scale", 1e-9),)))
    assert said == (
        "note: mpc.cost_scale 1e-09 is below mpc.solver_tol 1e-06: the solvers stop at an error of "
        "solver_tol in cost_scale * F, and may return plans that hardly move"
    )
    for overrides in ((), (("cost_scale", 0.01),), (("cost_scale", 1e-9), ("solver_tol", 1e-9))):
        assert tolerance_note(ControllerSpec("dmpc", "constant_velocity", mpc_overrides=overrides)) is None
    assert tolerance_note(ControllerSpec("orca")) is None
    argv = ["sweep", "--experiment", "table2", "--set", "mpc.cost_scale=1e-9", "--dry-run"]
    assert main([*argv, "--out", str(tmp_path / "s")]) == 0
    assert "note: methods 'CMPC', 'DMPC': mpc.cost_scale 1e-09 is below" in capsys.readouterr().err
