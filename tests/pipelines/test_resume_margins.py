"""The refusal to extend a cell whose margins changed names what changed: per-class modes plan with their
classes' margins alone and record [] as their common ones, so the refusal had read "planned with margins
[] m, but the cell's margins are now [] m (per motion class)"."""

import dataclasses
import json

import numpy as np

from pipelines.cli import main
from pipelines.experiments.log import episode_log
from pipelines.experiments.resume_checks import _margins_change
from predictors.calibration_store import save_calibration
from tests.calibration_blocks import class_errors, constant_velocity_block

NAMES = ["new", "standing", "slow", "walking"]


def _planned(margins_m, quantiles=None):
    classes = None if quantiles is None else {"names": NAMES, "quantiles": quantiles, "standing_speed": 0.1}
    return {"margins_m": margins_m, "classes": classes}


def test_common_margins_are_shown_as_recorded():
    assert _margins_change(_planned([0.18, 0.36]), _planned([0.36, 0.72])) == (
        "margins [0.18, 0.36] m, but the cell's margins are now [0.36, 0.72] m"
    )


def test_per_class_margins_name_the_first_class_that_changed_and_count_the_others():
    was = [[0.04, 0.11], [0.0, 0.0], [0.13584, 0.32], [0.0923061107, 0.23]]
    now = [[0.04, 0.11], [0.0, 0.0], [0.2, 0.4], [0.1, 0.3]]
    assert _margins_change(_planned([], was), _planned([], now)) == (
        "margins per motion class, slow [0.136, 0.32] m, but the cell's are now [0.2, 0.4] m "
        "(and 1 more class)"
    )
    assert _margins_change(_planned([], was), _planned([], [*was[:3], now[3]])).endswith("[0.1, 0.3] m")


def test_margins_are_shown_to_the_decimals_that_tell_them_apart():
    """The common margins were printed as recorded, a calibration's 17 digits, and the class margins to the
    millimetre, so a 1e-5 m move read as the same margins twice ("[0.183] m, but ... now [0.183] m")."""
    was, moved = [0.18000000000000002, 0.36000000000000004], [0.18001, 0.36000000000000004]
    assert _margins_change(_planned(was), _planned(moved)) == (
        "margins [0.18, 0.36] m, but the cell's margins are now [0.18001, 0.36] m"
    )
    assert _margins_change(_planned(was), _planned([0.2, 0.36])) == (
        "margins [0.18, 0.36] m, but the cell's margins are now [0.2, 0.36] m"
    )
    classes = [[0.04], [0.0], [0.18291234567891], [0.3]]
    nudged = [[0.04], [0.0], [0.18292234567891], [0.3]]
    assert _margins_change(_planned([], classes), _planned([], nudged)) == (
        "margins per motion class, slow [0.18291] m, but the cell's are now [0.18292] m"
    )
    # the same to 17 decimals: in full; a damaged record's rows (no numbers): as they are
    assert _margins_change(_planned([1e-18]), _planned([2e-18])) == (
        "margins [1e-18] m, but the cell's margins are now [2e-18] m"
    )
    assert _margins_change(_planned(["x"]), _planned([0.1])) == (
        "margins ['x'] m, but the cell's margins are now [0.1] m"
    )


def test_classes_that_changed_otherwise_are_said_so():
    quantiles = [[0.1], [0.0], [0.2], [0.3]]
    assert _margins_change(_planned([], quantiles), _planned([], None)) == (
        "margins per motion class, where the cell now plans with none"
    )
    assert _margins_change(_planned([], None), _planned([], quantiles)).startswith("no margins per motion")
    changed = _planned([], quantiles)
    changed["classes"]["standing_speed"] = 0.2
    assert _margins_change(_planned([], quantiles), changed) == "other motion classes than the cell's now"


SHORTFALL_ARGV = ["sweep", "--experiment", "controllers", "--controllers", "cmpc", "--predictor",
                  "constant_velocity", "--margins", "conformal-shortfall", "--humans", "1", "--robots", "1",
                  "--backend", "inline", "--no-progress", "--jit", "off"]  # fmt: skip


def _calibrate_classes(
    standing_error: float | None = None, created: str | None = None, added: int = 1
) -> None:
    """constant_velocity's closed-loop block at alpha 0.1 with class margins 0.18 (c + 1) k (19 samples a
    class), and a 20th standing sample of ``standing_error`` at every step where given: 0 moves the count and
    no margin (the 18th smallest of 19 is the 19th of 20 when the 20th is the least), 1 moves the standing
    margins to 0.38 k. ``added``: that many such samples (3 of 0: every class margin equal, and the plain
    conformal margins 0.56 k become 0.54 k). ``created``: the block's creation time (None: now)."""
    errors, motion = class_errors(4)
    if standing_error is not None:
        errors = np.concatenate([errors, np.full((added, 4), standing_error)])
        motion = np.concatenate([motion, np.ones(added, dtype=motion.dtype)])
    block = constant_velocity_block(errors, classes=motion, shortfall=errors)
    save_calibration(block if created is None else dataclasses.replace(block, created=created))


def test_a_recalibration_that_moved_a_class_count_and_no_margin_extends_the_cell(tmp_path, capsys):
    """The resume check compared the records' class margins with the cell's whole, sample counts included: a
    block remade with two more standing samples and every margin equal (constant_velocity's after a63500e)
    refused the safe configuration's folders as planned with "other motion classes", their episodes equal."""
    out = tmp_path / "sweep"
    _calibrate_classes()
    assert main([*SHORTFALL_ARGV, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    _calibrate_classes(standing_error=0.0)
    capsys.readouterr()
    assert main([*SHORTFALL_ARGV, "--episodes-per-cell", "4", "--out", str(out)]) == 0, (
        capsys.readouterr().err
    )
    classes = [r["config"]["margins"]["classes"] for r in episode_log(out).load().values()]
    assert sorted(c["n"][1][0] for c in classes) == [19, 19, 20, 20]  # each record names the block it used
    assert len({json.dumps(c["quantiles"]) for c in classes}) == 1
    _calibrate_classes(standing_error=1.0)  # a margin moved: refused as before
    capsys.readouterr()
    assert main([*SHORTFALL_ARGV, "--episodes-per-cell", "6", "--out", str(out)]) == 2
    assert "planned with margins per motion class, standing [0.36, 0.72" in capsys.readouterr().err


def test_a_calibration_remade_with_the_margins_planned_with_gives_no_note_of_other_episodes(tmp_path, capsys):
    """`config show --from-sweep` said a rerun "gives other episodes" of every folder whose calibration was
    made again (its creation time and data compared): the safe configuration's folders after
    constant_velocity's was remade at 89af3ce with two more standing samples and every class margin equal.
    The note now compares the margins planned with, as a resume does; a plain conformal folder, whose
    margins moved with that sample, is still told."""
    shortfall, plain = tmp_path / "cps", tmp_path / "cp"
    _calibrate_classes(created="2026-01-01T00:00:00+00:00")
    assert main([*SHORTFALL_ARGV, "--episodes-per-cell", "1", "--out", str(shortfall)]) == 0
    plain_argv = [("conformal" if a == "conformal-shortfall" else a) for a in SHORTFALL_ARGV]
    assert main([*plain_argv, "--episodes-per-cell", "1", "--out", str(plain)]) == 0
    _calibrate_classes(standing_error=0.0, created="2026-01-02T00:00:00+00:00", added=3)
    other = "so a rerun gives other episodes"
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(shortfall)]) == 0
    printed, err = capsys.readouterr()
    assert other not in printed + err
    assert err == (
        "note: constant_velocity's calibration was remade since with the margins this sweep planned with, so "
        "a rerun plans with the same margins (its records name the new calibration).\n"
    )
    assert main(["config", "show", "--from-sweep", str(plain)]) == 0
    assert other in capsys.readouterr().err
    _calibrate_classes(standing_error=1.0, created="2026-01-03T00:00:00+00:00")  # the standing margins moved
    assert main(["config", "show", "--from-sweep", str(shortfall)]) == 0
    assert capsys.readouterr().err.startswith(
        "note: The zoo no longer holds what this sweep ran with (constant_velocity's calibration changed "
        f"since), {other}"
    )


def test_the_note_is_of_the_printed_runs_cells(tmp_path, capsys):
    """A folder holds the cells of every run swept into it: `config show --from-sweep` noted every record's
    remade block, so a run with margins none, printed by default as the folder's last, was told "a rerun
    gives other episodes" because an earlier run's conformal block was remade. Each run's note is now of the
    records of the cells its run line planned."""
    out = tmp_path / "sweep"
    _calibrate_classes(created="2026-01-01T00:00:00+00:00")
    plain_argv = [("conformal" if a == "conformal-shortfall" else a) for a in SHORTFALL_ARGV]
    none_argv = [("none" if a == "conformal-shortfall" else a) for a in SHORTFALL_ARGV]
    assert main([*plain_argv, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    assert main([*none_argv, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    _calibrate_classes(standing_error=0.0, created="2026-01-02T00:00:00+00:00", added=3)  # plain ones moved
    capsys.readouterr()
    for run in ([], ["--run", "2"]):
        assert main(["config", "show", "--from-sweep", str(out), *run]) == 0
        printed, err = capsys.readouterr()
        assert (err, "no longer holds" in printed) == ("", False), run
    assert main(["config", "show", "--from-sweep", str(out), "--run", "1"]) == 0
    assert "so a rerun gives other episodes" in capsys.readouterr().err


def test_a_report_of_a_folder_whose_block_was_remade_says_so_and_writes_the_same_files(
    tmp_path, capsys, monkeypatch
):
    """`sweep --report-only` said nothing of a calibration remade since the folder was swept (constant
    velocity's conformal:0.1 before 89af3ce), where `config show --from-sweep` notes it: the report now
    says it on stderr, from the records it reads anyway (the log read once), its files as they were."""
    from pipelines.experiments.log import EpisodeLog

    out = tmp_path / "cp"
    _calibrate_classes(created="2026-01-01T00:00:00+00:00")
    plain_argv = [("conformal" if a == "conformal-shortfall" else a) for a in SHORTFALL_ARGV]
    assert main([*plain_argv, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    report = ["sweep", "--report-only", "--no-progress", "--out", str(out)]
    capsys.readouterr()
    assert main(report) == 0
    printed, err = capsys.readouterr()
    assert "note: The zoo" not in err
    files = {name: (out / name).read_bytes() for name in ("table.md", "cells.csv", "episodes.csv")}
    _calibrate_classes(standing_error=0.0, created="2026-01-02T00:00:00+00:00", added=3)  # plain ones moved
    scans = []
    scan = EpisodeLog.scan
    monkeypatch.setattr(EpisodeLog, "scan", lambda self, *a, **k: scans.append(1) or scan(self, *a, **k))
    assert main(report) == 0
    again, err = capsys.readouterr()
    assert again == printed and {name: (out / name).read_bytes() for name in files} == files
    notes = [line for line in err.splitlines() if "no longer holds" in line]
    assert notes == [
        "note: The zoo no longer holds what this sweep ran with (constant_velocity's calibration changed "
        "since), so a rerun gives other episodes; `crowdmpc compare OLD NEW` names what differs."
    ]
    assert len(scans) == 1


def test_a_folder_of_a_remade_plain_block_is_refused_naming_both_blocks_and_the_report(tmp_path, capsys):
    """A plain conformal folder of constant_velocity made before 89af3ce (its m_1 moved) is refused on a
    resume: the refusal guessed "(recalibrated?)" and said only "use another --out", where the folder's
    report still reads it. It names the block the records planned with and the one the zoo holds, and
    `sweep --report-only` of the folder, which then reports it."""
    out = tmp_path / "cp"
    _calibrate_classes(created="2026-01-01T00:00:00+00:00")
    plain_argv = [("conformal" if a == "conformal-shortfall" else a) for a in SHORTFALL_ARGV]
    assert main([*plain_argv, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    _calibrate_classes(standing_error=0.0, created="2026-01-02T00:00:00+00:00", added=3)  # plain ones moved
    capsys.readouterr()
    assert main([*plain_argv, "--episodes-per-cell", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.rstrip().endswith(
        ": constant_velocity's closed-loop calibration at alpha 0.1 was made again after the records "
        "(records: your calibration of 2026-01-01 00:00 UTC, now: your calibration of 2026-01-02 00:00 UTC); "
        f"use another --out for the new margins, or `crowdmpc sweep --report-only --out {out}` to report the "
        "episodes it holds"
    ), err
    assert main(["sweep", "--report-only", "--no-progress", "--out", str(out)]) == 0
