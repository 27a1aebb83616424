"""A sweep's workers plan with the calibration blocks its driver checked (pipelines.experiments
.checked_calibrations): each worker read calibrations.json again as it built a cell's controller, so a
`calibrate` run between the driver's check and a worker's build had episodes plan with, and record, margins
nobody checked, caught only by a later resume."""

from __future__ import annotations

import numpy as np
import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.experiments.log import episode_log
from predictors.calibration_store import save_calibration
from tests.calibration_blocks import class_errors, constant_velocity_block
from tests.pipelines.test_inputs_read_once import count_opens

SWEEP = ["sweep", "--experiment", "controllers", "--controllers", "cmpc,dmpc", "--predictor",
         "constant_velocity", "--margins", "conformal:0.1", "--humans", "1,2", "--robots", "1",
         "--backend", "inline", "--no-progress", "--jit", "off", "--set", "env.time_limit=2"]  # fmt: skip


def _recalibrate_at_start(monkeypatch, block) -> list:
    """``block`` saved (a `calibrate` run) as the sweep's run starts: after the driver's checks looked its
    margins up, before any worker builds a controller; in the list returned, once it is."""
    from pipelines.experiments import sweep

    real, saved = sweep.make_scratch_root, []

    def recalibrating():
        saved.append(save_calibration(block))
        return real()

    monkeypatch.setattr(sweep, "make_scratch_root", recalibrating)
    return saved


def test_a_sweeps_workers_plan_with_the_margins_its_driver_checked(tmp_path, monkeypatch):
    errors, _ = class_errors(4)
    checked = constant_velocity_block(errors)
    save_calibration(checked)
    saved = _recalibrate_at_start(monkeypatch, constant_velocity_block(2 * errors))
    out = tmp_path / "sweep"
    assert main([*SWEEP, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    assert saved
    records = list(episode_log(out).load().values())
    assert len(records) == 4  # 2 controllers x 2 crowd sizes, each cell's controller built after the save
    for record in records:
        margins = record["config"]["margins"]
        assert margins["margins_m"] == list(checked.quantiles[: len(margins["margins_m"])])
        assert margins["calibration"]["created"] == checked.created


def test_a_sweep_reads_the_calibrations_once(tmp_path, monkeypatch):
    """Its driver's checks read calibrations.json once for every method; each worker read it again for
    every cell it built (here, inline: four cells, five reads)."""
    from predictors import zoo

    save_calibration(constant_velocity_block(class_errors(4)[0]))
    user = zoo.user_zoo_dir().resolve()
    opened = count_opens(monkeypatch, "calibrations.json")
    assert main([*SWEEP, "--episodes-per-cell", "1", "--out", str(tmp_path / "sweep")]) == 0
    assert opened[user / "calibrations.json"] == 1


def test_a_resume_checks_the_records_against_the_margins_its_workers_plan_with(tmp_path, monkeypatch):
    """The resume check read calibrations.json again after the plan's checks: a calibrate run between the
    reads refused records of the margins the workers would plan with, or passed records of others."""
    errors, _ = class_errors(4)
    checked = constant_velocity_block(errors)
    save_calibration(checked)
    out = tmp_path / "sweep"
    assert main([*SWEEP, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    saved = _recalibrated_before(monkeypatch, "read_recorded", 2 * errors)  # the resume's check
    assert main([*SWEEP, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    records = list(episode_log(out).load().values())
    assert saved and len(records) == 8
    _planned_with(records, checked)


def _recalibrated_before(monkeypatch, step: str, errors: np.ndarray) -> list[object]:
    """A calibrate of ``errors`` run after the plan's checks, as ``pipelines.experiments.sweep.<step>``
    starts: the blocks it saved (one, once the step ran)."""
    from pipelines.experiments import sweep

    real, saved = getattr(sweep, step), []

    def recalibrating(*args, **kwargs):
        saved.append(save_calibration(constant_velocity_block(errors)))
        return real(*args, **kwargs)

    monkeypatch.setattr(sweep, step, recalibrating)
    return saved


def _planned_with(records: list[dict], checked) -> None:
    """Every record planned with the margins of the block the driver ``checked``."""
    for record in records:
        margins = record["config"]["margins"]
        assert margins["margins_m"] == list(checked.quantiles[: len(margins["margins_m"])])


def test_reuse_checks_the_others_records_against_the_margins_its_workers_plan_with(tmp_path, monkeypatch):
    """`sweep --reuse OTHER` checked OTHER's records against a read of calibrations.json of its own, after
    the plan's checks: a calibrate run between the reads refused records of the margins the workers plan
    with (or took records of others)."""
    errors, _ = class_errors(4)
    checked = constant_velocity_block(errors)
    save_calibration(checked)
    other, out = tmp_path / "other", tmp_path / "sweep"
    assert main([*SWEEP, "--episodes-per-cell", "1", "--out", str(other)]) == 0
    saved = _recalibrated_before(monkeypatch, "seed_from", 2 * errors)  # --reuse's check
    assert main([*SWEEP, "--episodes-per-cell", "2", "--reuse", str(other), "--out", str(out)]) == 0
    records = list(episode_log(out).load().values())
    assert saved and len(records) == 8
    assert sum(record["run"] == 1 for record in records) == 4  # OTHER's four, taken (its run, first)
    _planned_with(records, checked)


def test_a_resumes_refusal_names_the_block_its_workers_plan_with(tmp_path, monkeypatch, capsys):
    """A refused resume said the cell's margins now (the block its workers are handed) but named as "now"
    the block calibrations.json held when the refusal was made, read once more: a calibrate run between the
    plan's checks and the refusal had it give one block's margins and another's date."""
    import dataclasses

    from pipelines.experiments import sweep

    errors, _ = class_errors(4)
    made = dataclasses.replace(constant_velocity_block(errors), created="2026-01-01T10:00:00+00:00")
    save_calibration(made)
    out = tmp_path / "sweep"
    assert main([*SWEEP, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    checked = dataclasses.replace(constant_velocity_block(2 * errors), created="2026-01-02T10:00:00+00:00")
    save_calibration(checked)  # recalibrated after the records: the resume is refused
    real = sweep.read_recorded

    def recalibrating(*args, **kwargs):  # after the plan's checks, before the resume's
        save_calibration(dataclasses.replace(checked, created="2026-01-03T10:00:00+00:00"))
        return real(*args, **kwargs)

    monkeypatch.setattr(sweep, "read_recorded", recalibrating)
    capsys.readouterr()
    assert main([*SWEEP, "--episodes-per-cell", "2", "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert "but the cell's margins are now [1.12, 2.24, 3.36, 4.48] m" in error
    assert (
        "(records: your calibration of 2026-01-01 10:00 UTC, now: your calibration of 2026-01-02 10:00 UTC)"
        in error
    )


# ---- plugin controllers: built as Class(spec, env_config, jit=...), they take no block as an argument
PLUGIN = "tests.plugins.margin_controller:MarginMPC"  # CMPC wrapped, as a user's plugin would
WITH_PLUGIN = ["--plugin", PLUGIN, *SWEEP[:4], f"cmpc,{PLUGIN}", *SWEEP[5:]]


def test_a_plugin_wrapping_the_mpc_plans_with_the_margins_the_driver_checked(tmp_path, monkeypatch):
    """The shipped controllers were handed the checked block; a plugin wrapping MPCController looked its
    margins up again in the worker, and planned with (and recorded) the block a calibrate run saved after the
    driver's check: [1.12, 2.24, 3.36, 4.48] m where CMPC planned with [0.56, 1.12, 1.68, 2.24]."""
    errors, _ = class_errors(4)
    checked = constant_velocity_block(errors)
    save_calibration(checked)
    saved = _recalibrate_at_start(monkeypatch, constant_velocity_block(2 * errors))
    out = tmp_path / "sweep"
    assert main([*WITH_PLUGIN, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    records = list(episode_log(out).load().values())
    assert saved and sorted(r["controller"] for r in records) == ["cmpc", "cmpc", "margin_mpc", "margin_mpc"]
    _planned_with(records, checked)


def test_a_sweep_with_a_plugin_reads_the_calibrations_once(tmp_path, monkeypatch):
    """The driver's read, and none in the plugin's worker (inline here: its build read the file once a
    cell)."""
    from predictors import zoo

    save_calibration(constant_velocity_block(class_errors(4)[0]))
    user = zoo.user_zoo_dir().resolve()
    opened = count_opens(monkeypatch, "calibrations.json")
    assert main([*WITH_PLUGIN, "--episodes-per-cell", "1", "--out", str(tmp_path / "sweep")]) == 0
    assert opened[user / "calibrations.json"] == 1


def _plugin_spec(alpha: float = 0.1):
    from pipelines.loop.controllers import ControllerSpec, register_controller_plugins
    from pipelines.loop.margins import MarginSpec

    register_controller_plugins([PLUGIN])
    return ControllerSpec(PLUGIN, predictor="constant_velocity", margins=MarginSpec("conformal", alpha=alpha))


def test_make_controller_hands_a_plugin_the_block_read_for_its_margins(tmp_path):
    """``make_controller(spec, read=ControllerReads(calibration=...))`` (a sweep worker's call) hands a
    plugin's own lookup of ``spec``'s margins the block given, not calibrations.json's; the plugin's
    constructor is the documented one. Outside the build, and for other margins, the file is read."""
    from pipelines.loop.controllers import ControllerReads, make_controller

    errors, _ = class_errors(4)
    now = constant_velocity_block(2 * errors)
    save_calibration(now)
    read = (tmp_path / "calibrations.json", constant_velocity_block(errors))  # the command's, checked
    spec = _plugin_spec()
    controller = make_controller(spec, read=ControllerReads(calibration=read))
    margins = controller.describe()["config"]["margins"]
    assert margins["margins_m"] == list(read[1].quantiles[: len(margins["margins_m"])])
    assert spec.margins.located("constant_velocity", 4, None)[1].quantiles == now.quantiles
    other = make_controller(_plugin_spec(), read=ControllerReads())  # nothing read: the file's
    assert other.describe()["config"]["margins"]["margins_m"] == list(now.quantiles[:4])


def test_a_handed_block_is_still_checked_against_the_plugins_weights(tmp_path):
    """The block handed is found as the file's would be: one made for other weights is refused as such."""
    import dataclasses

    from pipelines.loop.controllers import ControllerReads, make_controller

    block = dataclasses.replace(constant_velocity_block(class_errors(4)[0]), predictor_sha256="ab" * 32)
    with pytest.raises(PipelineError, match="was made for weights sha256 abab"):
        make_controller(_plugin_spec(), read=ControllerReads(calibration=(tmp_path / "c.json", block)))


def test_a_plugins_lookup_of_other_margins_is_handed_nothing(tmp_path):
    """A block is handed only to the margins and predictor it was looked up for: a lookup at another alpha
    reads the files (here: the shipped zoo's block at 0.2)."""
    from pipelines.loop.margins import MarginSpec
    from pipelines.loop.margins_handed import handing_calibration
    from predictors.zoo import checkpoints_dir

    spec = _plugin_spec()
    read = (tmp_path / "calibrations.json", constant_velocity_block(class_errors(4)[0]))
    with handing_calibration(spec.margins, "constant_velocity", read):
        assert spec.margins.located("constant_velocity", 4, None) == read
        path, block = MarginSpec("conformal", alpha=0.2).located("constant_velocity", 4, None)
    assert path == checkpoints_dir() / "calibrations.json" and block.alpha == 0.2


def test_a_library_sweeps_refused_lookup_reads_the_manifest_once(tmp_path, monkeypatch):
    """``run_sweep`` without ``calibrations`` looks each method's block up as it starts, from the entries it
    located for the weights; a lookup that refused located its predictor's entry again, only to name the
    model in the calibrate command its refusal quotes: the coupling experiment (three methods of one
    predictor) at an alpha no block has read the manifest four times before any worker started."""
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.sweep import run_sweep
    from pipelines.experiments.sweep_config import SweepConfig
    from pipelines.loop.margins import MarginSpec
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    real, reads = zoo.read_manifest, []

    def reading(*args, **kwargs):
        reads.append(args)
        return real(*args, **kwargs)

    handed = []

    class NoEpisodes:  # what the workers would be handed, and no episode run
        name = "none"

        def run(self, tasks):
            handed.extend(tasks)
            return iter(())

        def close(self):
            pass

    monkeypatch.setattr(zoo, "read_manifest", reading)
    experiment = get_experiment("coupling").with_margins(MarginSpec("conformal", alpha=0.37))
    config = SweepConfig(experiment, tmp_path / "sweep", 1, humans=(5,), backend="inline", progress=False)
    run_sweep(config, backend_factory=lambda config, scratch: NoEpisodes())
    assert len({task.cell.method for task in handed}) == 3
    assert all(task.calibration is ... for task in handed)  # refused: each worker refuses it itself
    assert len(reads) == 1
