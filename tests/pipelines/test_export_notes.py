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
