"""`crowdmpc zoo calibrations`: the calibration blocks in force, one line each, with the zoo each comes from
and whether its weights are the zoo's."""

import dataclasses

import pytest

from pipelines.cli import main
from pipelines.commands.zoo_calibrations import calibration_table
from predictors.calibration_store import find_calibration, save_calibration


@pytest.fixture(autouse=True)
def _private_zoo(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))


def _rows(predictor: str = "social_lstm_eth") -> dict[tuple[str, str, str, str], list[str]]:
    """The table's rows by (source, alpha, view, zoo)."""
    header, *rows = calibration_table(None, predictor)
    assert header[:4] == ["predictor", "source", "alpha", "view"] and header[-1] == "zoo"
    return {(r[1], r[2], r[3], r[-1]): r for r in rows}


def test_the_shipped_blocks_are_listed_with_their_margins():
    rows = _rows()
    assert len(rows) == 10  # closed-loop and real, at five alphas each
    closed = rows["closed-loop", "0.1", "every human", "shipped"]
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    assert closed[4] == " / ".join(f"{q:.2f}" for q in shipped.quantiles)
    assert closed[5:8] == [str(min(shipped.n)), "motion, shortfall", "ok"]
    assert rows["real", "0.1", "recorded", "shipped"][6] == "-"  # no classes in recorded scenes


def test_user_blocks_come_first_hide_the_shipped_block_of_their_key_and_say_whose_weights_they_are():
    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    behind = {**shipped.details, "sensor_range": 3.0}
    save_calibration(dataclasses.replace(shipped, details=behind, quantiles=(0.5, 0.5, 0.5, 0.5)))
    save_calibration(dataclasses.replace(shipped, alpha=0.05, predictor_sha256="f" * 64))  # other weights
    save_calibration(dataclasses.replace(shipped, predictor="gone", predictor_sha256=None))
    header, *rows = calibration_table(None)
    assert [(r[0], r[2], r[3], r[7], r[-1]) for r in rows[:3]] == [
        ("gone", "0.1", "every human", "no model", "user"),
        ("social_lstm_eth", "0.05", "every human", "other", "user"),
        ("social_lstm_eth", "0.1", "3 m sensor", "ok", "user"),
    ]
    mine = _rows()
    assert mine["closed-loop", "0.1", "3 m sensor", "user"][4] == "0.50 / 0.50 / 0.50 / 0.50"
    assert ("closed-loop", "0.1", "every human", "shipped") in mine  # beside it: another view
    assert ("closed-loop", "0.05", "every human", "shipped") not in mine  # hidden by the user's block
    assert len(mine) == 11


def test_the_command_prints_the_table_and_refuses_an_unknown_predictor_in_one_line(capsys):
    assert main(["zoo", "calibrations", "--predictor", "constant_velocity"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("predictor ") and set(out[1]) <= {"-", " "}
    assert len(out) == 2 + 10 + 1 and all(line.startswith("constant_velocity ") for line in out[2:-1])
    assert main(["zoo", "calibrations", "--predictor", "social_lstm"]) == 2
    err = capsys.readouterr().err
    assert "unknown predictor 'social_lstm'; choose from" in err and err.count("\n") == 1


def test_the_plot_draws_each_block_of_the_predictor_by_alpha_and_view(tmp_path, capsys):
    from pipelines.commands.zoo_calibrations import plot_margins

    shipped = find_calibration("constant_velocity", "closed-loop", 0.1)
    behind = dataclasses.replace(shipped, details={**shipped.details, "sensor_range": 3.0})
    real = find_calibration("constant_velocity", "real", 0.1)
    figure = plot_margins([behind, real, shipped], "title")
    closed, recorded = figure.axes
    lines = {line.get_label(): line for line in closed.get_lines()}
    assert list(lines) == ["alpha 0.1", "alpha 0.1, 3 m sensor"]  # every human in view first
    assert [lines["alpha 0.1"].get_linestyle(), lines["alpha 0.1, 3 m sensor"].get_linestyle()] == ["-", "--"]
    assert tuple(lines["alpha 0.1"].get_ydata()) == shipped.quantiles
    assert [tuple(line.get_ydata()) for line in recorded.get_lines()] == [real.quantiles]
    save_calibration(behind)
    out = tmp_path / "margins.png"
    assert main(["zoo", "calibrations", "--predictor", "constant_velocity", "--plot", str(out)]) == 0
    assert out.read_bytes().startswith(b"\x89PNG") and f"wrote {out}" in capsys.readouterr().out
    assert main(["zoo", "calibrations", "--plot", str(out)]) == 2
    assert "--plot draws one predictor's blocks: add --predictor NAME" in capsys.readouterr().err


def test_a_plot_that_cannot_be_written_is_refused_before_the_table(tmp_path, capsys, monkeypatch):
    """A name matplotlib cannot write (or that has no suffix, for which savefig chose PNG and another name)
    is one line before anything is read; a missing folder is made; a predictor with no block to draw is an
    error, not a success without the file."""
    for name, message in [
        ("x.txt", "--plot " + str(tmp_path / "x.txt") + ": cannot write a figure of type 'txt'"),
        ("plain", "cannot write a figure of type '(no suffix)'"),
    ]:
        assert (
            main(["zoo", "calibrations", "--predictor", "constant_velocity", "--plot", str(tmp_path / name)])
            == 2
        )
        captured = capsys.readouterr()
        assert message in captured.err and captured.err.count("\n") == 1 and captured.out == ""
    nested = tmp_path / "new" / "folder" / "m.png"
    assert main(["zoo", "calibrations", "--predictor", "constant_velocity", "--plot", str(nested)]) == 0
    assert nested.read_bytes().startswith(b"\x89PNG")
    monkeypatch.setattr("pipelines.commands.zoo_calibrations.blocks_of", lambda *_: [])
    capsys.readouterr()
    empty = tmp_path / "none.png"
    assert main(["zoo", "calibrations", "--predictor", "constant_velocity", "--plot", str(empty)]) == 2
    err = capsys.readouterr().err
    assert (
        f"--plot {empty}: no calibrations of 'constant_velocity' to draw in" in err and err.count("\n") == 1
    )
    assert not empty.exists()


def test_a_user_zoo_set_to_the_shipped_one_lists_its_blocks(monkeypatch, capsys):
    """$CROWDMPC_ZOO at the shipped zoo is read as the one zoo (`zoo list` does), yet `zoo calibrations`,
    and every run planning with calibrated margins, failed: looking for a killed calibrate's blocks to take
    back, they asked for the user zoo to write, which the shipped one is not."""
    from predictors import zoo

    monkeypatch.setenv("CROWDMPC_ZOO", str(zoo.checkpoints_dir()))
    before = sorted(p.name for p in zoo.checkpoints_dir().iterdir())
    assert main(["zoo", "calibrations", "--predictor", "constant_velocity"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 2 + 10 + 1 and all(line.endswith(" shipped") for line in out[2:-1])
    assert sorted(p.name for p in zoo.checkpoints_dir().iterdir()) == before


def test_a_block_of_one_episode_lists_its_seed_once():
    """A block made on one closed-loop episode was listed "1 (7..7)"; a range is said of two seeds or more."""
    from pipelines.commands.zoo_calibrations import _episodes

    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    one = dataclasses.replace(shipped, details={**shipped.details, "seeds": [7]})
    two = dataclasses.replace(shipped, details={**shipped.details, "seeds": [7, 8]})
    assert _episodes(one, {"episodes": "1"}) == "1 (7)"
    assert _episodes(two, {"episodes": "2"}) == "2 (7..8)"


def test_a_removed_models_blocks_stay_said_so_and_go_when_asked(tmp_path, capsys):
    """`zoo remove mine` left mine's blocks in calibrations.json without a word, and `zoo calibrations` then
    listed them with weights "no model" and nothing on what they were or how they go. They stay (a re-add of
    the same weights plans with them again, and sweeps planned with them resume), and both commands say so
    and how they go: `zoo remove --calibrations mine`."""
    import json
    import shutil
    from pathlib import Path

    real = Path(__file__).resolve().parents[2] / "checkpoints"
    for suffix in (".pt", ".json"):
        shutil.copyfile(real / f"social_lstm_eth{suffix}", tmp_path / f"mine{suffix}")
    document = json.loads((tmp_path / "mine.json").read_text())
    (tmp_path / "mine.json").write_text(json.dumps({**document, "name": "mine"}))
    (tmp_path / "mine.metrics.json").write_text(json.dumps({"metrics": {"test": {"ade": 0.5}}}))
    assert main(["zoo", "add", str(tmp_path / "mine.pt")]) == 0
    from predictors.zoo import locate

    shipped = find_calibration("social_lstm_eth", "closed-loop", 0.1)
    sha = locate("mine").entry.sha256
    for alpha in (0.1, 0.05):
        save_calibration(dataclasses.replace(shipped, predictor="mine", alpha=alpha, predictor_sha256=sha))
    zoo = tmp_path / "zoo"
    capsys.readouterr()
    assert main(["zoo", "remove", "mine"]) == 0
    assert capsys.readouterr().out.splitlines()[1] == (
        f"its 2 calibration block(s) stay in {zoo / 'calibrations.json'} (`zoo calibrations`: weights 'no "
        "model'): a zoo add of the same weights plans with them again, and sweeps planned with them resume; "
        "`crowdmpc zoo remove --calibrations mine` removes them"
    )
    assert main(["zoo", "calibrations", "--predictor", "mine"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 2 + 2 + 2 and all(" no model " in row for row in out[2:4])
    assert out[-1].startswith("weights no model: blocks of mine, which no zoo holds (`zoo remove` keeps")
    assert out[-1].endswith("`crowdmpc zoo remove --calibrations NAME` removes them")
    assert main(["zoo", "add", str(tmp_path / "mine.pt")]) == 0  # the same weights: in force again
    assert [r[7] for r in calibration_table(None, "mine")[1:]] == ["ok", "ok"]
    assert main(["zoo", "remove", "mine"]) == 0
    capsys.readouterr()
    assert main(["zoo", "remove", "--calibrations", "mine"]) == 0
    assert (
        capsys.readouterr().out
        == f"removed the 2 calibration block(s) of mine from {zoo / 'calibrations.json'}\n"
    )
    assert calibration_table(None, "mine")[1:] == [] and len(_rows()) == 10  # the shipped ones untouched
    assert main(["zoo", "remove", "--calibrations", "mine"]) == 2  # none left: said, not a silent success
    assert "holds no calibration block of 'mine'; nothing removed" in capsys.readouterr().err
