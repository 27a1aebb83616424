"""`crowdmpc export` says what its printout would not: a horizon past the net's training length, and that a
generator's function is its zero-noise future."""

from __future__ import annotations

from pipelines.cli import main


def test_export_notes_a_horizon_past_training_and_a_generators_zero_noise(tmp_path, capsys):
    out = tmp_path / "gan.casadi"
    small = ["--humans", "2", "--robots", "1"]
    assert main(["export", "social_gan_eth", "--out", str(out), *small, "--horizon", "14"]) == 0
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if line.startswith("note:")]
    assert notes == [
        "note: --horizon 14 is past the 12 steps (4.8 s) 'social_gan_eth' was trained to predict: the "
        "function's steps 13..14 are extrapolated",
        "note: 'social_gan_eth' is a generator: the function is its zero-noise future, as the MPC plans on "
        "it; its sampled futures (SocialGANPredictor.sample) stay in torch",
    ]
    assert "note:" not in captured.out  # the printout itself is unchanged: a script reading stdout
    # within the trained length, of a net without noise, or of a predictor that learned nothing: no note
    for name, horizon in (("social_lstm_eth", "12"), ("constant_velocity", "30")):
        out = tmp_path / f"{name}.casadi"
        assert main(["export", name, "--out", str(out), *small, "--horizon", horizon]) == 0
        assert "note:" not in capsys.readouterr().err


def test_one_step_past_the_training_length_is_said_as_one_step(tmp_path, capsys):
    """--horizon 13 of a net trained on 12 steps said "steps 13..13 are extrapolated"."""
    out = tmp_path / "lstm.casadi"
    argv = [
        "export",
        "social_lstm_eth",
        "--out",
        str(out),
        "--humans",
        "2",
        "--robots",
        "1",
        "--horizon",
        "13",
    ]
    assert main(argv) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note:")]
    assert notes == [
        "note: --horizon 13 is past the 12 steps (4.8 s) 'social_lstm_eth' was trained to predict: the "
        "function's step 13 is extrapolated"
    ]


def test_the_printout_counts_one_human_and_one_robot_in_the_singular(tmp_path, capsys):
    """`export constant_velocity --humans 1 --robots 1` printed "for 1 humans, 1 robots"."""
    out = tmp_path / "cv.casadi"
    assert main(["export", "constant_velocity", "--out", str(out), "--humans", "1", "--robots", "1"]) == 0
    assert " for 1 human, 1 robot, horizon 4 (exported in " in capsys.readouterr().out.splitlines()[0]
    assert main(["export", "constant_velocity", "--out", str(out), "--humans", "2", "--robots", "0"]) == 0
    assert " for 2 humans, 0 robots, horizon 4 (exported in " in capsys.readouterr().out.splitlines()[0]


def test_a_large_export_of_a_net_is_said_to_take_long_before_it_starts(tmp_path, capsys, monkeypatch):
    """50 humans and 12 robots over 100 steps ran for 8 minutes in one CasADi call, deaf to Ctrl-C, unsaid."""
    from pipelines.commands import export

    monkeypatch.setattr(export, "LONG_EXPORT", 4)  # 3 agents x 2 steps: the note without the long wait
    small = ["--humans", "2", "--robots", "1", "--horizon", "2"]
    assert main(["export", "social_lstm_eth", "--out", str(tmp_path / "a.casadi"), *small]) == 0
    assert capsys.readouterr().err.startswith(
        "note: a net's twin for 3 agents over 2 steps takes long to build and check (here 9 s at 62 agents "
        "over 5 steps, 78 s over 20, 8 minutes over 100); an interrupt waits for CasADi to return\n"
    )
    assert main(["export", "constant_velocity", "--out", str(tmp_path / "b.casadi"), *small]) == 0
    assert "note:" not in capsys.readouterr().err  # a rule's twin builds in a moment at any size
    monkeypatch.setattr(export, "LONG_EXPORT", 7)
    assert main(["export", "social_lstm_eth", "--out", str(tmp_path / "c.casadi"), *small]) == 0
    assert "note:" not in capsys.readouterr().err
