"""What calibrate says about the blocks it makes, as a new user found it: seeds among the evaluation seeds,
a block made otherwise than the one it replaces, a dry run that stored nothing, and blocks lacking margins
per motion class; and what the runs and `zoo calibrations` say about the controller a block was made with."""

import dataclasses

import pytest

from pipelines.cli import main
from pipelines.commands.calibrate_store import _check_keeps_class_margins, evaluation_seeds_note
from pipelines.commands.calibration_notes import controller_note
from pipelines.commands.zoo_calibrations import calibration_table
from pipelines.errors import PipelineError
from predictors.calibration_store import calibrations_path, find_calibration, read_calibrations
from predictors.zoo import checkpoints_dir
from tests.calibration_blocks import class_errors, constant_velocity_block

CALIBRATE = ["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop", "--no-progress"]
SHIPPED = checkpoints_dir() / "calibrations.json"


@pytest.fixture(autouse=True)
def _private_zoo(tmp_path, monkeypatch):
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))


@pytest.fixture
def episodes(monkeypatch):
    """calibrate's closed-loop episodes replaced by ``class_errors(4)`` (19 per motion class, enough for
    alpha 0.1) with the details the real ones record of their plan."""
    from pipelines.experiments import calibrate as experiment

    def measured(plan, progress=True, check_weights=None):
        scores, motion = class_errors(4)
        recorded = ("episodes", "seed", "humans", "controller", "profile", "visibility", "near")
        details = {key: getattr(plan, key) for key in recorded}
        details |= {"seeds": [plan.seed, plan.seed + plan.episodes - 1]}
        return experiment.ClosedLoopErrors(scores, motion, scores, details, None)

    monkeypatch.setattr(experiment, "closed_loop_errors", measured)


# ---------------------------------------------------------------------------------- 1: evaluation seeds
def test_calibration_seeds_among_the_evaluation_seeds_are_named_with_the_overlap():
    assert evaluation_seeds_note(0, 4) == (
        "note: calibration seeds 0..3 overlap the evaluation seeds 0..99999 (simulate and sweep from their "
        "default --seed 0) at 0..3: the margins would be fitted on episodes they are later evaluated on (the "
        "default --seed 1000000 keeps them apart)"
    )
    assert "seeds 99998..100002 overlap the evaluation seeds 0..99999 " in (
        evaluation_seeds_note(99_998, 5) or ""
    )
    assert " at 99998..99999: " in (evaluation_seeds_note(99_998, 5) or "")
    assert evaluation_seeds_note(100_000, 5) is None  # past the last evaluation seed
    assert evaluation_seeds_note(1_000_000, 200) is None  # calibrate's default


def test_calibrate_on_evaluation_seeds_says_so_in_one_line_and_runs(episodes, capsys):
    """`calibrate --seed 0` ran without a word, though its help says its seeds are disjoint from every
    evaluation seed. Said, not refused: it may be meant."""
    assert main([*CALIBRATE, "--alpha", "0.3", "--episodes", "4", "--seed", "0", "--dry-run"]) == 0
    err = capsys.readouterr().err
    assert (
        err.startswith("note: calibration seeds 0..3 overlap the evaluation seeds") and err.count("\n") == 1
    )
    assert main([*CALIBRATE, "--alpha", "0.3", "--episodes", "4", "--dry-run"]) == 0
    assert capsys.readouterr().err == ""


# ----------------------------------------------------------------------------------------- 3: dry run
def test_a_dry_run_ends_saying_nothing_was_stored(episodes, capsys, tmp_path):
    assert main([*CALIBRATE, "--alpha", "0.3", "--episodes", "4", "--dry-run"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[-1] == "--dry-run: nothing stored; the calibrations in force are unchanged"
    assert not calibrations_path().exists()
    assert main([*CALIBRATE, "--alpha", "0.3", "--episodes", "4"]) == 0
    assert "--dry-run" not in capsys.readouterr().out


# ------------------------------------------------------------------------ 2a: the block a calibrate replaces
def test_replacing_a_block_made_with_another_controller_says_what_differs(episodes, capsys):
    """A trial with --controller dmpc replaced the CMPC block of its alpha without a word."""
    argv = [*CALIBRATE, "--alpha", "0.3", "--episodes", "4", "--humans", "5"]
    assert main(argv) == 0
    assert capsys.readouterr().err == ""  # nothing replaced
    assert main(argv) == 0
    assert capsys.readouterr().err == ""  # replaced by the same calibration made again
    assert main([*argv, "--controller", "dmpc", "--seed", "7"]) == 0
    assert capsys.readouterr().err == (
        f"{evaluation_seeds_note(7, 4)}\n"
        "note: this replaces the closed-loop block of constant_velocity at alpha 0.3 in force from "
        f"{calibrations_path()}, made with --seed 1000000 --controller cmpc; this one is made with --seed 7 "
        "--controller dmpc\n"
    )
    assert [b.details["controller"] for b in read_calibrations() if b.alpha == 0.3] == ["dmpc"]


def test_hiding_the_shipped_block_made_on_other_episodes_names_them(episodes, capsys):
    assert main([*CALIBRATE, "--alpha", "0.1", "--episodes", "4", "--humans", "5"]) == 0
    assert capsys.readouterr().err == (
        "note: this replaces the closed-loop block of constant_velocity at alpha 0.1 in force from "
        f"{SHIPPED}, made with --episodes 100 --humans 5,6,7,8,9; this one is made with --episodes 4 "
        "--humans 5\n"
    )


def test_replacing_a_real_block_of_another_horizon_says_so():
    """`calibrate --source real --horizon 3` replaced the block at Table I's 4 steps without a word, and
    every run at that horizon was then refused ("covers 3 steps")."""
    from pathlib import Path

    from pipelines.commands.calibrate_store import _replaced_note

    old = find_calibration("constant_velocity", "real", 0.1)
    new = dataclasses.replace(old, quantiles=old.quantiles[:3], n=old.n[:3])
    note = _replaced_note(new, [(Path("calibrations.json"), old)])
    assert note is not None and note.endswith("made with --horizon 4; this one is made with --horizon 3")
    assert _replaced_note(old, [(Path("calibrations.json"), old)]) is None  # the same again: nothing to say


# ------------------------------------------------------------------- 2b: a run planning with another's block
def test_a_run_planning_with_a_block_made_with_another_controller_gets_a_note():
    shipped = find_calibration("constant_velocity", "closed-loop", 0.1)
    assert shipped.details["controller"] == "cmpc" and controller_note(shipped, "cmpc") is None
    assert controller_note(shipped, "dmpc") == (
        "note: the closed-loop margins of 'constant_velocity' at alpha=0.1 were calibrated with controller "
        "cmpc, this run's is dmpc: their coverage here is not measured (crowdmpc calibrate --predictor "
        "constant_velocity --source closed-loop --alpha 0.1 --episodes 100 --seed 1000000 --humans 5,6,7,8,9 "
        "--controller dmpc --profile paper --visibility visible --near 3 measures it, replacing that block "
        "for every run; CROWDMPC_ZOO=DIR keeps it apart)"
    )
    behind = dataclasses.replace(shipped, details={**shipped.details, "sensor_range": 3.0})
    assert (controller_note(behind, "dmpc") or "").endswith(
        " --sensor-range 3 measures it, replacing that block for every run; CROWDMPC_ZOO=DIR keeps it apart)"
    )
    unrecorded = dataclasses.replace(shipped, details={})  # made before the controller was recorded
    assert controller_note(unrecorded, "dmpc") is None
    assert controller_note(find_calibration("constant_velocity", "real", 0.1), "dmpc") is None


def test_a_block_made_beyond_todays_sensor_bound_is_not_quoted_back_to_calibrate():
    """A block made behind a 2000 m sensor before calibrate bounded the range (1 km) is still planned with
    (by a run behind the nearest range); the notes quoted `--sensor-range 2000` for it, a command calibrate
    now refuses. They quote the run's view, whose block is planned with before it, and say why."""
    import shlex

    from pipelines.cli import build_parser
    from pipelines.commands.calibrate_checks import sensor_range_refusal
    from pipelines.commands.calibration_notes import calibration_controller_note, calibration_world_note
    from pipelines.loop.margins import parse_margins
    from pipelines.loop.spec import ControllerSpec

    shipped = find_calibration("constant_velocity", "closed-loop", 0.1)
    old = dataclasses.replace(shipped, details={**shipped.details, "sensor_range": 2000.0})
    why = (
        "; the block was made behind a 2000 m sensor before calibrate bounded the range (the sensor range "
        "must be at most 1000 m, got 2000.0) and cannot be made again: the command makes one of the view "
        "asked for, planned with before it; CROWDMPC_ZOO=DIR keeps it apart)"
    )
    spec = ControllerSpec("dmpc", "constant_velocity", margins=parse_margins("conformal:0.1"))
    notes = [
        calibration_controller_note(spec, 900, as_read=old),
        calibration_world_note(spec, "v1", "visible", "orca", 900, as_read=old),
    ]
    for note in notes:
        assert note is not None and "--sensor-range 2000" not in note and note.endswith(why)
        command = note[note.index("(crowdmpc ") + 1 : note.index(" measures it")]
        args = build_parser().parse_args(shlex.split(command)[1:])
        assert args.sensor_range == 900 and sensor_range_refusal(args.predictor, args.sensor_range) is None
    assert (controller_note(old, "dmpc", view=(3.0, False)) or "").endswith(
        f"--near 3 --sensor-range 3 --no-sensor-tracks measures it{why}"
    )
    assert (controller_note(old, "dmpc") or "").endswith(f"--near 3 measures it{why}")  # every human seen


# -------------------------------------------------------------------- 2c: zoo calibrations, the episodes
def test_zoo_calibrations_shows_each_blocks_controller_and_episodes():
    header, *rows = calibration_table(None, "constant_velocity")
    columns = [
        header.index(name) for name in ("controller", "crowd (humans, profile, robots)", "episodes (seeds)")
    ]
    made = {(r[1], r[2]): [r[i] for i in columns] for r in rows}
    assert made["closed-loop", "0.1"] == ["cmpc", "5..9, paper, visible", "100 (1000000..1000099)"]
    assert made["real", "0.1"] == ["-", "-", "-"]  # recorded scenes
    shipped = find_calibration("constant_velocity", "closed-loop", 0.1)
    older = {k: v for k, v in shipped.details.items() if k != "seeds"} | {"controller": "dmpc", "seed": 5}
    older |= {"humans": [5, 7], "profile": "v1", "visibility": "invisible"}
    from predictors.calibration_store import save_calibration

    save_calibration(dataclasses.replace(shipped, details=older))  # made before the seed range was recorded
    header, *rows = calibration_table(None, "constant_velocity")
    assert [r[i] for r in rows if r[1:3] == ["closed-loop", "0.1"] for i in columns] == [
        "dmpc",
        "5,7, v1, invisible",
        "100 (5..104)",
    ]
    # a hand-edited block's sizes as they stand: int() of them ended the whole listing in a traceback
    save_calibration(dataclasses.replace(shipped, details=older | {"humans": [5.0, 7.0]}))
    header, *rows = calibration_table(None, "constant_velocity")
    assert [r[columns[1]] for r in rows if r[1:3] == ["closed-loop", "0.1"]] == ["5.0,7.0, v1, invisible"]


# ----------------------------------------------------------------- 4: blocks lacking margins per class
def test_blocks_lacking_margins_per_class_are_named_with_the_command_that_makes_them(monkeypatch):
    """It read "calibration at alpha 0.1 (in force: ...), alpha 0.05 (in force: ...) has margins per motion
    class and these blocks have none"."""
    from types import SimpleNamespace

    errors, motion = class_errors(4)
    made = {"episodes": 4, "seed": 1_000_000, "humans": [5], "controller": "cmpc", "near": 3.0}
    few = [
        dataclasses.replace(
            constant_velocity_block(errors[motion != 0], classes=motion[motion != 0]),
            alpha=alpha,
            details=made,
        )
        for alpha in (0.1, 0.05)
    ]
    args = SimpleNamespace(predictor="constant_velocity", source="closed-loop")
    with pytest.raises(PipelineError) as refused:
        _check_keeps_class_margins(few, args)
    assert str(refused.value) == (
        "not stored: the new closed-loop blocks of constant_velocity at alpha 0.1, 0.05 have no margins per "
        "motion class (a class had too few samples in 4 episodes), and runs plan now with blocks that have "
        f"them (in {SHIPPED}); make them with more episodes: crowdmpc calibrate --predictor "
        "constant_velocity --source closed-loop --alpha 0.1,0.05 --episodes 200 --seed 1000000 --humans 5 "
        "--controller cmpc --near 3, or measure without storing with --dry-run"
    )
    with pytest.raises(
        PipelineError, match=r"new closed-loop block of .* at alpha 0\.05 has no margins .* a "
    ):
        _check_keeps_class_margins(few[1:], args)


def test_a_block_of_other_weights_does_not_keep_a_retrained_models_block_out():
    """A model retrained under its name could not store a block without margins per motion class over its
    old weights' block, "runs plan now with a block that has them": every run refuses that block."""
    from types import SimpleNamespace

    errors, motion = class_errors(4)
    few = constant_velocity_block(errors[motion != 0], classes=motion[motion != 0])
    retrained = dataclasses.replace(few, predictor_sha256="a" * 64)
    args = SimpleNamespace(predictor="constant_velocity", source="closed-loop")
    with pytest.raises(PipelineError, match="runs plan now with a block that has them"):
        _check_keeps_class_margins([few], args)  # the shipped block is of these (no) weights
    _check_keeps_class_margins([retrained], args)  # it is of other weights than these


def test_simulate_and_sweep_say_when_a_run_plans_with_another_controllers_block(capsys, tmp_path):
    """The note was written but no command printed it: a DMPC run planned with the shipped CMPC-made block
    silently. A sweep says it once, of the DMPC method alone."""
    argv = [
        "sweep",
        "--experiment",
        "table2",
        "--predictor",
        "constant_velocity",
        "--margins",
        "conformal:0.1",
    ]
    argv += ["--humans", "1", "--episodes-per-cell", "1", "--dry-run", "--out", str(tmp_path / "s")]
    assert main(argv) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "calibrated with controller" in line]
    assert len(notes) == 1 and notes[0].startswith(
        "note: method 'DMPC': the closed-loop margins of 'constant_velocity' at alpha=0.1 were calibrated "
        "with controller cmpc, this run's is dmpc"
    )
    from pipelines.commands.calibration_notes import calibration_controller_note
    from pipelines.loop.margins import parse_margins
    from pipelines.loop.spec import ControllerSpec

    margins = parse_margins("conformal:0.1")
    assert calibration_controller_note(ControllerSpec("cmpc", "constant_velocity", margins=margins)) is None
    note = calibration_controller_note(ControllerSpec("dmpc", "constant_velocity", margins=margins))
    assert note is not None and note.startswith("note: the closed-loop margins of 'constant_velocity'")


# --------------------------------------------------------------- 5: real scenes the model was trained on
def test_real_calibration_on_the_models_own_training_files_says_so(tmp_path, monkeypatch, capsys):
    """`calibrate --source real` of a model trained on the validation scenes it calibrates on (a run of
    one's own --train files) stored margins fitted to its training data without a word, where `evaluate`
    notes such a file: they cover less than 1 - alpha of people the model has not seen."""
    from predictors.data import locate
    from predictors.hashing import sha256_file
    from predictors.zoo_edit import add_to_zoo
    from tests.predictors.samples import write_crowds

    seen, unseen = write_crowds(tmp_path / "seen.ndjson"), write_crowds(tmp_path / "unseen.ndjson")
    unseen.write_text(unseen.read_text() + "\n")  # other bytes, the same scenes
    files = {"train": {"train/seen.ndjson": sha256_file(seen)}, "val": {}, "test": {}}
    add_to_zoo(
        checkpoints_dir() / "vanilla_lstm_eth.pt",
        name="lstm_of_seen",
        protocol="paper",
        training_data={"protocol": "paper", "files": files},
        metrics={},
    )
    split = {"train": [seen], "val": [seen], "test": [unseen]}
    monkeypatch.setattr(locate, "protocol_files", lambda *args, **kwargs: split)
    monkeypatch.setattr(locate, "prepared_dir", lambda *args, **kwargs: tmp_path)
    real = ["calibrate", "--predictor", "lstm_of_seen", "--source", "real", "--alpha", "0.5", "--dry-run"]
    assert main([*real, "--holdout", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"note: the margins are calibrated on {seen}, which holds data lstm_of_seen was trained on" in err
    assert "held-out coverage is measured" not in err  # the test file it never saw
    split["val"], split["test"] = [unseen], [seen]
    assert main([*real, "--holdout", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "the margins are calibrated on" not in err
    assert f"note: held-out coverage is measured on {seen}, which holds data lstm_of_seen" in err


# ---------------------------------------------------------------------- 6: margins no plan can keep
def test_calibrate_says_which_margins_no_plan_can_keep(monkeypatch, capsys):
    """A block with margins past the 5 m any plan in the paper's scene can keep was stored without a word,
    in the place of its key's block; the first run planning with it at that horizon was refused."""
    from pipelines.experiments import calibrate as experiment

    def measured(plan, progress=True, check_weights=None):
        scores, motion = class_errors(4)  # walking's 0.9 margins 0.72 k m: 1.44 k m when doubled
        return experiment.ClosedLoopErrors(2 * scores, motion, scores, {"humans": list(plan.humans)}, None)

    monkeypatch.setattr(experiment, "closed_loop_errors", measured)
    assert main([*CALIBRATE, "--alpha", "0.1", "--episodes", "4", "--dry-run"]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "5 m any plan" in line]
    assert notes == [
        "note: alpha 0.1: the conformal-motion margins pass the 5 m any plan in the paper's scene can keep "
        "from horizon step 4 on (5.76 m at the widest): runs planning with them at a horizon of 4 or more "
        "refuse this block"
    ]
