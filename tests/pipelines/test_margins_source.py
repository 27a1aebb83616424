"""Where a run's calibrated margins came from: a user's calibration (the user zoo's, ``crowdmpc calibrate``)
hides the shipped block of its key and shares its label ("cp0.1"), so the records name the zoo, and
simulate's header and a sweep's table.md say it."""

from __future__ import annotations

import pytest

from pipelines.cli import main
from pipelines.experiments.cell_columns import CellColumns
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.summary import summarize, summarize_columns
from pipelines.experiments.tables import markdown_table
from pipelines.logs.identity import run_identity
from pipelines.loop.margins import MarginSpec, calibration_text, parse_margins
from predictors.calibration_store import save_calibration
from tests.calibration_blocks import class_errors, constant_velocity_block
from tests.pipelines.test_compare import BASE, _record, _sweep

SHIPPED = {"created": "2026-11-30T20:08:48+00:00", "data_sha256": "a" * 64, "zoo": "shipped"}


@pytest.mark.parametrize(
    ("created", "said"),
    [
        ("2026-11-30T20:08:48+00:00", "calibration of 2026-11-30 20:08 UTC"),
        ("2026-12-01T01:38:48+05:30", "calibration of 2026-11-30 20:08 UTC"),  # said in UTC
        ("2026-11-30T20:08:48", "calibration of 2026-11-30 20:08"),  # no zone given: none invented
        ("yesterday", "calibration of yesterday"),  # a record written by hand: as it is
    ],
)
def test_where_a_calibration_came_from_in_words(created, said):
    assert calibration_text({"created": created, "zoo": "shipped"}) == f"shipped {said}"
    assert calibration_text({"created": created, "zoo": "user"}) == f"your {said}"
    assert calibration_text({"created": created}) == said  # recorded before the zoo was


def test_a_users_block_is_recorded_as_the_user_zoos():
    shipped = MarginSpec("conformal").calibration("constant_velocity", None)
    assert shipped is not None and shipped["zoo"] == "shipped"
    errors, motion = class_errors(4)
    save_calibration(constant_velocity_block(errors, classes=motion, shortfall=errors))
    mine = MarginSpec("conformal").calibration("constant_velocity", None)
    assert mine is not None and mine["zoo"] == "user" and mine["data_sha256"] == "0" * 64
    # another alpha's block is still the shipped one
    other = MarginSpec("conformal", alpha=0.05).calibration("constant_velocity", None)
    assert other is not None and other["zoo"] == "shipped"


def _cell_records(cells, calibration):
    records = []
    for cell in cells:
        for i in range(2):
            record = _record(i, True, False, 20.0)
            margins = {"mode": "conformal", "label": "cp0.1", "margins_m": [0.1] * 4}
            config = record["config"] | {
                "margins": margins | ({"calibration": calibration} if calibration else {})
            }
            records.append(record | {"cell": cell.key, "key": f"{cell.key}/{i}", "config": config})
    return records


def test_a_sweeps_table_says_where_its_margins_came_from():
    experiment = get_experiment("table2").with_margins(parse_margins("conformal"))
    cells = [c for c in experiment.cells() if c.n_humans == 5]
    records = _cell_records(cells, SHIPPED)
    table = markdown_table(experiment, summarize(experiment, cells, records))
    line = "Calibrated margins from: social_lstm_eth cp0.1: shipped calibration of 2026-11-30 20:08 UTC."
    assert line in table.splitlines()
    # the report of a large sweep reads its records as columns: the same table
    columns: dict[str, CellColumns] = {}
    for record in records:
        columns.setdefault(record["cell"], CellColumns()).add(record)
    assert markdown_table(experiment, summarize_columns(experiment, cells, columns)) == table
    mine = _cell_records(cells, SHIPPED | {"zoo": "user", "created": "2026-12-05T10:00:00+00:00"})
    table = markdown_table(experiment, summarize(experiment, cells, mine))
    assert (
        "Calibrated margins from: social_lstm_eth cp0.1: your calibration of 2026-12-05 10:00 UTC." in table
    )
    # margins without a calibration (none, fixed) or records without their config: no such line
    bare = markdown_table(experiment, summarize(experiment, cells, _cell_records(cells, None)))
    assert "Calibrated margins from" not in bare


def test_where_a_block_is_stored_tells_no_run_apart():
    """Its creation time and data tell the block: a rerun of a run recorded before the zoo was kept replaces
    its recordings, and compare lists no difference, while another block is another run."""
    episode = {"controller": "cmpc", "predictor": "constant_velocity", "n_robots": "3", "n_humans": "7"}
    old = {k: v for k, v in SHIPPED.items() if k != "zoo"}

    def config(calibration):
        return {"margins": {"label": "cp0.1", "calibration": calibration}}

    assert run_identity(episode, config(old)) == run_identity(episode, config(SHIPPED))
    assert run_identity(episode, config(old)) != run_identity(
        episode, config(old | {"data_sha256": "b" * 64})
    )


def test_compare_lists_no_difference_in_where_a_block_is_stored(tmp_path, capsys):
    def with_calibration(calibration):
        records = [_record(i, *o) for i, o in enumerate(BASE)]
        for r in records:
            r["config"]["margins"] = {"label": "cp0.1", "calibration": calibration}
        return records

    a = _sweep(tmp_path / "a", with_calibration({k: v for k, v in SHIPPED.items() if k != "zoo"}))
    b = _sweep(tmp_path / "b", with_calibration(SHIPPED))
    assert main(["compare", str(a), str(b), "--no-progress"]) == 0
    assert "b ran with the settings of a." in capsys.readouterr().out
    c = _sweep(tmp_path / "c", with_calibration(SHIPPED | {"created": "2026-12-05T10:00:00+00:00"}))
    assert main(["compare", str(a), str(c), "--no-progress"]) == 0
    assert "margins.calibration.created" in capsys.readouterr().out


@pytest.mark.parametrize("margins", ["conformal", "conformal-motion"])
def test_a_controller_plans_with_the_block_its_records_name(margins, monkeypatch):
    """Its margins, their classes and the record of their block each read the calibrations files as the
    controller was built: a calibrate run that replaced the block between those reads had the controller
    plan with one block while every record named the other."""
    import dataclasses

    import predictors.calibration_store as store
    from pipelines.loop.controllers import ControllerSpec, make_controller

    errors, motion = class_errors(4)
    planned = constant_velocity_block(errors, classes=motion, shortfall=errors)
    save_calibration(planned)
    later = dataclasses.replace(
        constant_velocity_block(2 * errors, classes=motion, shortfall=2 * errors), data_sha256="1" * 64
    )
    real = store.read_calibration_file
    read: list[object] = []  # the files the controller's build read
    saving = []  # while the calibrate run reads the file it writes: not the build's

    def read_then_recalibrate(path):
        blocks = real(path)
        if not saving:
            read.append(path)
        if len(read) == 2 and not saving:  # the user zoo's file and the shipped: the block is replaced
            saving.append(True)
            save_calibration(later)
            saving.clear()
        return blocks

    monkeypatch.setattr(store, "read_calibration_file", read_then_recalibrate)
    controller = make_controller(ControllerSpec("cmpc", margins=parse_margins(margins)))
    assert len(read) == len(set(read)) == 2  # the user zoo's file, then the shipped one
    assert controller.calibration is not None and controller.calibration["data_sha256"] == "0" * 64
    if margins == "conformal":
        assert controller.cfg.human_margins == tuple(planned.quantiles[:4])
    else:
        assert controller.class_margins == planned.classes
