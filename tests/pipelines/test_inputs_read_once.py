"""A command reads each of its inputs (a zoo's manifest, a checkpoint, a calibrations file) once: the bytes
checked are the bytes used. Read again, a `zoo add --replace` or a calibrate run in between had one check
pass files the next one, or the run, never saw."""

from __future__ import annotations

import builtins
import collections
import io
import os
from pathlib import Path


def count_opens(monkeypatch, *suffixes: str) -> collections.Counter:
    """How often each file whose name ends in one of ``suffixes`` is opened from now on, by path."""
    real_open, opened = io.open, collections.Counter()

    def opening(file, *args, **kwargs):
        if isinstance(file, str | os.PathLike) and str(file).endswith(suffixes):
            opened[Path(file).resolve()] += 1
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(io, "open", opening)
    monkeypatch.setattr(builtins, "open", opening)
    return opened


def test_a_sweeps_checks_read_the_manifest_weights_and_calibrations_once(monkeypatch):
    """check_predictors, check_couplings and check_margins each read the zoo's manifest (the couplings' the
    weights too, and the margins' the calibrations once a method): the coupling experiment's three methods
    of one predictor read the manifest six times and its weights twice."""
    from pipelines.commands.sweep_checks import check_plan
    from pipelines.experiments.cells import get_experiment
    from pipelines.loop.margins import MarginSpec
    from predictors.zoo import checkpoints_dir

    experiment = get_experiment("coupling").with_margins(MarginSpec("conformal", alpha=0.1))
    shipped = checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json", ".pt")
    check_plan(experiment)
    name = experiment.methods[0][1].predictor
    read = {path.name: n for path, n in opened.items() if path.parent == shipped}
    assert read == {"manifest.json": 1, f"{name}.json": 1, f"{name}.pt": 1, "calibrations.json": 1}


def test_zoo_add_shipped_reads_the_config_it_checks_the_kind_of_once(tmp_path, monkeypatch):
    """`zoo add --shipped` read the config for its model kind, then again as the pair loaded: a config
    replaced between the reads had its kind checked and another one added to the shipped zoo."""
    import shutil

    from predictors import zoo, zoo_edit

    src, shipped = tmp_path / "src", tmp_path / "clone" / "checkpoints"
    src.mkdir()
    shipped.mkdir(parents=True)
    for suffix in (".pt", ".json"):
        shutil.copyfile(zoo.shipped_checkpoints_dir() / f"social_lstm_eth{suffix}", src / f"mine{suffix}")
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(shipped))
    opened = count_opens(monkeypatch, ".json")
    entry = zoo_edit.add_to_zoo(
        src / "mine.pt", name="mine", protocol="p", training_data={}, metrics={}, shipped=True
    )
    assert entry.model == "social_lstm" and zoo.locate("mine").source == zoo.SHIPPED
    assert opened[(src / "mine.json").resolve()] == 1


def test_zoo_add_checks_the_metrics_against_the_bytes_it_adds(tmp_path, monkeypatch):
    """`zoo add` hashed the weights and the config and parsed the config for its metrics check, then loaded
    the pair, and took the weights' size_kb from a stat apart: a pair replaced between the reads had its
    metrics checked against other bytes than the zoo keeps."""
    import hashlib
    import json
    import shutil

    from pipelines.cli import main
    from predictors import zoo

    src = tmp_path / "src"
    src.mkdir()
    for suffix in (".pt", ".json"):
        shutil.copyfile(zoo.shipped_checkpoints_dir() / f"social_lstm_eth{suffix}", src / f"mine{suffix}")
    weights, config = src / "mine.pt", src / "mine.json"
    metrics = src / "mine.metrics.json"
    recorded = {
        "weights_sha256": hashlib.sha256(weights.read_bytes()).hexdigest(),
        "config_sha256": hashlib.sha256(config.read_bytes()).hexdigest(),
    }
    metrics.write_text(json.dumps({**recorded, "model": "social_lstm", "metrics": {}}))
    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    opened = count_opens(monkeypatch, ".pt", ".json")
    assert main(["zoo", "add", str(weights)]) == 0
    assert opened[weights.resolve()] == 1 and opened[config.resolve()] == 1
    added = zoo.read_manifest(tmp_path / "zoo")["mine"]
    assert added.training["size_kb"] == round(len(weights.read_bytes()) / 1024, 1)


def test_the_notes_of_a_sweep_read_the_manifest_once(monkeypatch):
    """horizon_note and zoo_notes each located the predictor's entry, once a method: the coupling
    experiment's three methods of one predictor read the manifest six times for their notes, and a `zoo add
    --replace` between the reads had the notes describe two models."""
    from pipelines.commands.sweep_checks import method_notes
    from pipelines.experiments.cells import get_experiment
    from predictors.zoo import checkpoints_dir

    manifest = (checkpoints_dir() / "manifest.json").resolve()
    opened = count_opens(monkeypatch, ".json")
    method_notes(get_experiment("coupling").cells((5,), 3))
    assert opened[manifest] == 1


def test_export_reads_the_manifest_once(tmp_path, monkeypatch, capsys):
    """export located the entry for its plugin and quick-check notes, for its load and for its horizon note:
    the manifest read three times, and a `zoo add --replace` between the reads had the notes describe other
    weights than were exported."""
    from pipelines.cli import main
    from predictors.zoo import checkpoints_dir

    manifest = (checkpoints_dir() / "manifest.json").resolve()
    opened = count_opens(monkeypatch, ".json")
    small = ["--humans", "2", "--robots", "1", "--horizon", "2"]
    assert main(["export", "social_lstm_eth", "--out", str(tmp_path / "f.casadi"), *small]) == 0
    assert opened[manifest] == 1


def test_simulate_reads_the_manifest_weights_and_calibrations_once(tmp_path, monkeypatch):
    """simulate's world check loaded the predictor, its notes located the entry again and looked the
    calibration block up once a note, and its controller loaded the predictor and looked the block up once
    more: the manifest read 8 times, the weights twice and calibrations.json 6 times, and a `zoo add
    --replace` or a calibrate run between the reads had the notes and the checks describe other files than
    the episodes planned with."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json", ".pt")
    run = ["--humans", "2", "--robots", "1", "--episodes", "1", "--no-progress", "--margins", "conformal:0.1"]
    world = ["--set", "world.obs_len=10", "--set", "env.time_limit=2"]  # obs_len: the world's check loads
    assert main(["simulate", "--controller", "cmpc", "--predictor", "social_lstm_eth", *run, *world]) == 0
    read = {path.name: n for path, n in opened.items() if path.parent == shipped}
    name = "social_lstm_eth"
    assert read == {"manifest.json": 1, f"{name}.json": 1, f"{name}.pt": 1, "calibrations.json": 1}


def test_a_sweep_reads_the_manifest_once_for_its_notes_and_its_checks(tmp_path, monkeypatch):
    """A sweep's notes located their predictors' entries (method_notes) and then check_plan read the
    manifests again for the models it loads: a `zoo add --replace` between the reads had the notes describe
    other models than were checked and run."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    manifest = (zoo.checkpoints_dir() / "manifest.json").resolve()
    opened = count_opens(monkeypatch, ".json")
    plan = ["--experiment", "coupling", "--humans", "5", "--episodes", "1", "--set", "mpc.horizon=14"]
    assert main(["sweep", *plan, "--dry-run", "--out", str(tmp_path / "sweep")]) == 0
    assert opened[manifest] == 1


def test_a_refused_sweep_plan_says_its_notes_first(tmp_path, capsys):
    """The plan's predictors are checked before the notes, which are printed before any refusal, as when
    the whole check followed them."""
    from pipelines.cli import main

    plan = ["--experiment", "table2", "--predictor", "social_lstm_eth", "--humans", "5", "--episodes", "1"]
    refused = ["--set", "mpc.horizon=14", "--margins", "conformal:0.1"]  # calibrated for 4 steps
    assert main(["sweep", *plan, *refused, "--dry-run", "--out", str(tmp_path / "sweep")]) == 2
    err = capsys.readouterr().err
    assert err.index("trained to predict 12") < err.index("covers 4 steps"), err


def test_a_sweeps_calibration_notes_read_the_blocks_its_margins_check_read(tmp_path, monkeypatch, capsys):
    """Each calibration note looked its block up again (the manifest for the weights' sha256, then the
    calibrations), once a method, beside check_margins' own lookup: a calibrate run between the reads had
    the notes describe another block than was checked and planned with."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json")
    plan = ["--experiment", "coupling", "--humans", "5,40", "--episodes", "1", "--margins", "conformal:0.1"]
    assert main(["sweep", *plan, "--dry-run", "--out", str(tmp_path / "sweep")]) == 0
    assert "were calibrated with 3 robots among 5-9 humans" in capsys.readouterr().err  # of that block
    assert opened[shipped / "manifest.json"] == 1
    assert opened[shipped / "calibrations.json"] == 1


def test_the_calibrate_commands_the_notes_quote_read_no_manifest_again(tmp_path, monkeypatch, capsys):
    """A note quoting a `crowdmpc calibrate` command read the manifest again to tell whether the command
    needs --plugin: Table II's dry run under profile v1 behind a sensor read it six times (once for the
    checks, then for each method's world and sensor notes and DMPC's controller note), simulate's run three
    times, and a `zoo add --replace` between the reads had a command register another model than was run."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    manifest = (zoo.checkpoints_dir() / "manifest.json").resolve()
    quoted = "crowdmpc calibrate --predictor social_lstm_eth --source closed-loop"
    opened = count_opens(monkeypatch, ".json")
    plan = ["--experiment", "table2", "--predictor", "social_lstm_eth", "--humans", "5", "--episodes", "1"]
    views = ["--margins", "conformal-shortfall:0.1", "--profile", "v1", "--sensor-range", "3"]
    assert main(["sweep", *plan, *views, "--dry-run", "--out", str(tmp_path / "sweep")]) == 0
    assert capsys.readouterr().err.count(quoted) == 3  # the world, sensor and controller notes
    assert opened.pop(manifest) == 1
    run = ["--humans", "2", "--robots", "1", "--episodes", "1", "--no-progress", "--set", "env.time_limit=2"]
    run += ["--controller", "dmpc", "--predictor", "social_lstm_eth", *views[:4]]
    assert main(["simulate", *run]) == 0
    assert capsys.readouterr().err.count(quoted) == 2  # the world and controller notes
    assert opened[manifest] == 1


def test_a_refused_simulate_reads_the_manifest_and_calibrations_once(tmp_path, monkeypatch, capsys):
    """A lookup of the calibration block that refused was left to the controller: each calibration note
    looked it up again (the manifest for the weights' sha256, then calibrations.json), each refusal's
    calibrate command located the entry again, and the controller looked it up once more, so `simulate
    --margins conformal:0.37` (no block at that alpha) read the manifest 13 times and calibrations.json 7
    times before its one line."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json", ".pt")
    run = ["--humans", "2", "--robots", "1", "--episodes", "1", "--no-progress"]
    name = "social_lstm_eth"
    assert (
        main(["simulate", "--controller", "cmpc", "--predictor", name, *run, "--margins", "conformal:0.37"])
        == 2
    )
    err = capsys.readouterr().err
    assert f"no closed-loop calibration at alpha=0.37 for predictor {name!r}" in err
    assert err.strip().endswith(
        f"run: crowdmpc calibrate --predictor {name} --source closed-loop --alpha 0.37"
    )
    read = {path.name: n for path, n in opened.items() if path.parent == shipped}
    assert read == {"manifest.json": 1, f"{name}.json": 1, f"{name}.pt": 1, "calibrations.json": 1}


def test_a_simulate_refused_a_blocks_horizon_notes_that_block_reading_it_once(tmp_path, monkeypatch, capsys):
    """A block of too few steps for the MPC's horizon is refused by the controller, after the notes on that
    block (which looked it up themselves, five times): they are printed as before, of the block read once."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json")
    run = ["--humans", "2", "--robots", "1", "--episodes", "1", "--no-progress", "--set", "mpc.horizon=14"]
    run += ["--margins", "conformal:0.1"]  # calibrated for 4 steps
    assert main(["simulate", "--controller", "cmpc", "--predictor", "social_lstm_eth", *run]) == 2
    err = capsys.readouterr().err
    assert err.index("were calibrated with 3 robots among 5-9 humans") < err.index("covers 4 steps"), err
    assert opened[shipped / "manifest.json"] == 1
    assert opened[shipped / "calibrations.json"] == 1


def test_a_refused_sweep_plan_reads_the_manifest_and_calibrations_once(tmp_path, monkeypatch, capsys):
    """check_margins refused before the notes were printed, so each of the notes looked the block up again
    (once a note and method) and check_plan's own check_margins once more: the coupling experiment's dry run
    with --margins conformal:0.37 read the manifest 33 times and calibrations.json 17 times."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json")
    plan = ["--experiment", "coupling", "--humans", "5", "--episodes", "1", "--margins", "conformal:0.37"]
    assert main(["sweep", *plan, "--dry-run", "--out", str(tmp_path / "sweep")]) == 2
    assert "no closed-loop calibration at alpha=0.37" in capsys.readouterr().err
    assert opened[shipped / "manifest.json"] == 1
    assert opened[shipped / "calibrations.json"] == 1


def test_a_plugin_controller_loads_the_zoo_entry_simulate_located(tmp_path, monkeypatch, capsys):
    """A plugin controller that loads the run's predictor itself (docs/extending.md) located its zoo entry
    again, after simulate had for its notes and the unknown-name check before it had read both zoos'
    manifests: one run read manifest.json three times, and a `zoo add --replace` between the reads had the
    notes describe another model than the plugin planned with. It now loads the entry simulate located."""
    import json

    from pipelines.cli import main
    from predictors import zoo
    from predictors.registry import load_predictor

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    plugin, name, out = (
        "tests.plugins.toy_controller:LoadingItsPredictor",
        "social_lstm_eth",
        tmp_path / "r.json",
    )
    opened = count_opens(monkeypatch, ".json", ".pt")
    run = ["--humans", "2", "--robots", "1", "--episodes", "1", "--no-progress", "--json", str(out)]
    assert main(["--plugin", plugin, "simulate", "--controller", plugin, "--predictor", name, *run]) == 0
    read = {path.name: n for path, n in opened.items() if path.parent == shipped}
    assert read == {"manifest.json": 1, f"{name}.json": 1, f"{name}.pt": 1}
    recorded = json.loads(out.read_text())["episodes"][0]["predictor_sha256"]
    assert recorded == zoo.locate(name).entry.sha256
    opened.clear()
    load_predictor(name)  # handed for the plugin's build alone: a later load locates the entry again
    assert opened[shipped / "manifest.json"] == 1


def corrupt_shipped_copy(tmp_path, monkeypatch, name: str = "social_lstm_eth") -> Path:
    """A copy of the shipped zoo, as $CROWDMPC_CHECKPOINTS, whose ``name``.pt has a byte flipped (a model
    that does not load: its sha256 is not the manifest's); its folder, resolved."""
    import shutil

    from predictors import zoo

    root = tmp_path / "checkpoints"
    shutil.copytree(zoo.shipped_checkpoints_dir(), root)
    weights = root / f"{name}.pt"
    data = bytearray(weights.read_bytes())
    data[-10] ^= 0x01
    weights.write_bytes(bytes(data))
    monkeypatch.setenv(zoo.CHECKPOINTS_ENV, str(root))
    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    return root.resolve()


def test_a_simulate_whose_predictor_does_not_load_reads_each_input_once(tmp_path, monkeypatch, capsys):
    """A load that refused was dropped: each calibration note looked the block up itself (the manifest for
    the weights' sha256, then calibrations.json) and the controller loaded the predictor again, so a corrupt
    social_lstm_eth.pt had `simulate --margins conformal:0.1` read the manifest 7 times, calibrations.json 5
    times and the weights and config twice before its line. The refusal is kept and raised by the
    controller, after the notes, as before."""
    from pipelines.cli import main

    name = "social_lstm_eth"
    shipped = corrupt_shipped_copy(tmp_path, monkeypatch, name)
    opened = count_opens(monkeypatch, ".json", ".pt")
    run = ["--humans", "2", "--robots", "1", "--episodes", "1", "--no-progress", "--margins", "conformal:0.1"]
    assert main(["simulate", "--controller", "cmpc", "--predictor", name, *run]) == 2
    note, error = capsys.readouterr().err.splitlines()
    assert note.startswith(f"note: the closed-loop margins of {name!r} at alpha=0.1 were calibrated with 3")
    assert error.startswith(f"crowdmpc simulate: error: checkpoint {shipped / name}.pt has sha256 ")
    assert "but the manifest expects" in error
    read = {path.name: n for path, n in opened.items() if path.parent == shipped}
    assert read == {"manifest.json": 1, f"{name}.json": 1, f"{name}.pt": 1, "calibrations.json": 1}


def test_a_sweep_whose_predictor_does_not_load_reads_each_input_once(tmp_path, monkeypatch, capsys):
    """check_predictors' refusal of a model that does not load left the notes printed before it to locate
    the entries again and look each method's block up once a note: a corrupt social_lstm_eth.pt had Table
    II's dry run with --margins conformal:0.1 read the manifest 12 times and calibrations.json 10 times. The
    notes now describe what the check located, then its refusal follows, as before."""
    from pipelines.cli import main

    name = "social_lstm_eth"
    shipped = corrupt_shipped_copy(tmp_path, monkeypatch, name)
    opened = count_opens(monkeypatch, ".json", ".pt")
    plan = [
        "--experiment",
        "table2",
        "--predictor",
        name,
        "--humans",
        "2",
        "--robots",
        "1",
        "--episodes",
        "1",
    ]
    assert (
        main(["sweep", *plan, "--margins", "conformal:0.1", "--dry-run", "--out", str(tmp_path / "s")]) == 2
    )
    *notes, error = capsys.readouterr().err.splitlines()
    assert notes[0].startswith(f"note: methods 'CMPC', 'DMPC': the closed-loop margins of {name!r} at alpha")
    assert error.startswith(f"crowdmpc sweep: error: checkpoint {shipped / name}.pt has sha256 ")
    read = {path.name: n for path, n in opened.items() if path.parent == shipped}
    assert read == {"manifest.json": 1, f"{name}.json": 1, f"{name}.pt": 1, "calibrations.json": 1}


def test_a_sweep_of_a_predictor_no_zoo_holds_reads_the_manifest_once(tmp_path, monkeypatch, capsys):
    """The notes printed before the refusal of a name no zoo holds located each name again: `sweep
    --experiment table2 --predictor nope --dry-run` read the manifest twice (22 times, and calibrations.json
    10 times, with --margins conformal:0.1). Its one line is as it was."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json")
    plan = ["--experiment", "table2", "--predictor", "nope", "--margins", "conformal:0.1", "--dry-run"]
    assert main(["sweep", *plan, "--out", str(tmp_path / "s")]) == 2
    error = capsys.readouterr().err.splitlines()[-1]
    assert error.startswith("crowdmpc sweep: error: experiment 'table2' needs predictors ['nope'] that are")
    assert error.endswith("(check the names --predictor gives, or train or fetch the zoo models)")
    assert opened[shipped / "manifest.json"] == 1 and opened[shipped / "calibrations.json"] <= 1


def test_a_sweep_of_two_predictors_reads_the_calibrations_once(tmp_path, monkeypatch):
    """planned_margins looked each predictor's block up with a read of calibrations.json of its own: the
    predictors experiment of social_lstm_eth and social_gan_eth read the file twice, and a calibrate run
    between the reads had the two predictors' margins checked against two contents of it."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    opened = count_opens(monkeypatch, ".json")
    plan = ["--experiment", "predictors", "--predictors", "social_lstm_eth,social_gan_eth", "--humans", "5"]
    plan += ["--episodes-per-cell", "1", "--margins", "conformal:0.1", "--vary", "mpc.horizon=3,4"]
    assert main(["sweep", *plan, "--dry-run", "--out", str(tmp_path / "sweep")]) == 0
    assert opened[shipped / "calibrations.json"] == 1


def test_a_resume_checks_every_cells_margins_against_one_read_of_the_calibrations(tmp_path, monkeypatch):
    """The resume check looked each recorded cell's margins up with a read of calibrations.json of its own:
    four cells of two predictors read it four times, and a calibrate run between the reads had the cells
    checked against two contents of the file."""
    from pipelines.experiments.cells import get_experiment
    from pipelines.experiments.resume_checks import ResumeChecks, planned_margins
    from pipelines.loop.margins import MarginSpec
    from predictors import zoo
    from predictors.registry import checkpoint_sha256

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    names = ("social_lstm_eth", "social_gan_eth")
    experiment = get_experiment("predictors").with_predictors(names).with_margins(MarginSpec("conformal"))
    tasks = experiment.tasks(1, humans=(5, 6), n_robots=1)
    checks = ResumeChecks(tmp_path, tasks)
    for task in tasks:  # each cell's record, of the margins it plans with now
        name = task.cell.spec.predictor_name
        margins = {"mode": "conformal", "alpha": 0.1, **planned_margins(task.cell)}
        record = {
            "predictor": name,
            "predictor_sha256": checkpoint_sha256(name),
            "config": {"margins": margins},
        }
        checks.add({"key": task.key, **record})
    opened = count_opens(monkeypatch, ".json")
    checks.check()
    assert len(tasks) == 4
    assert opened[zoo.checkpoints_dir().resolve() / "calibrations.json"] == 1


def test_a_resume_and_a_reuse_read_the_manifest_and_calibrations_once(tmp_path, monkeypatch):
    """A resume's check read the manifest again for the weights' sha256, and --reuse's checks the manifest
    (once a folder and once a cell) and calibrations.json again, after the plan's checks had read both:
    with nothing left to run, a resume read the manifest twice, and a --reuse that took every episode five
    times and calibrations.json twice. They now check the records against what the plan's checks read."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    plan = ["sweep", "--experiment", "controllers", "--controllers", "cmpc,dmpc", "--humans", "2"]
    plan += ["--predictor", "social_lstm_eth", "--margins", "conformal:0.1", "--robots", "1", "--backend"]
    plan += [
        "inline",
        "--no-progress",
        "--jit",
        "off",
        "--set",
        "env.time_limit=2",
        "--episodes-per-cell",
        "1",
    ]
    other = tmp_path / "other"
    assert main([*plan, "--out", str(other)]) == 0
    opened = count_opens(monkeypatch, "manifest.json", "calibrations.json")
    assert main([*plan, "--out", str(other)]) == 0  # every episode recorded: no worker loads the model
    assert opened == {shipped / "manifest.json": 1, shipped / "calibrations.json": 1}
    opened.clear()
    assert main([*plan, "--reuse", str(other), "--out", str(tmp_path / "sweep")]) == 0  # takes them all
    assert opened == {shipped / "manifest.json": 1, shipped / "calibrations.json": 1}


def test_a_dry_runs_preview_of_a_resume_and_a_reuse_reads_the_manifest_and_calibrations_once(
    tmp_path, monkeypatch, capsys
):
    """`sweep --dry-run` over a folder (and with --reuse) checks the records as the run would, but against
    reads of the manifest and calibrations.json of its own, after the plan's checks had read both: here the
    preview read the manifest 4 times and calibrations.json twice, with --reuse 10 and 4 times, and a `zoo
    add --replace` or calibrate run between the reads had it refuse records the run would take, or pass
    records the run refuses."""
    from pipelines.cli import main
    from predictors import zoo

    monkeypatch.setenv(zoo.ZOO_ENV, str(tmp_path / "zoo"))
    shipped = zoo.checkpoints_dir().resolve()
    plan = ["sweep", "--experiment", "controllers", "--controllers", "cmpc,dmpc", "--humans", "2"]
    plan += ["--predictor", "social_lstm_eth", "--margins", "conformal:0.1", "--robots", "1", "--backend"]
    plan += ["inline", "--no-progress", "--jit", "off", "--set", "env.time_limit=2"]
    other, out = tmp_path / "other", tmp_path / "sweep"
    assert main([*plan, "--episodes-per-cell", "2", "--out", str(other)]) == 0
    assert main([*plan, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    capsys.readouterr()
    opened = count_opens(monkeypatch, "manifest.json", "calibrations.json")
    assert main([*plan, "--episodes-per-cell", "2", "--dry-run", "--out", str(out)]) == 0
    assert "2 of 4 planned episodes recorded" in capsys.readouterr().out
    assert opened == {shipped / "manifest.json": 1, shipped / "calibrations.json": 1}, opened
    opened.clear()
    reuse = ["--episodes-per-cell", "2", "--dry-run", "--reuse", str(other), "--out", str(out)]
    assert main([*plan, *reuse]) == 0
    assert "takes 2 with --reuse" in capsys.readouterr().out  # OTHER's second of each cell
    assert opened == {shipped / "manifest.json": 1, shipped / "calibrations.json": 1}, opened
