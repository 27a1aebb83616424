"""``crowdmpc config show --from-sweep DIR``: the TOML that reruns what a sweep directory recorded."""

from __future__ import annotations

import json
import math

import pytest

from mpc.config import MPC_BOUNDS, MPC_LEAST
from pipelines.cli import main
from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE
from tests.waits import within


def _metrics(out) -> dict:
    lines = (out / EPISODES_FILE).read_text().splitlines()
    return {r["key"]: r["metrics"] for r in map(json.loads, lines)}


def test_a_sweep_reruns_from_what_its_directory_records(tmp_path, capsys):
    """The helper of the reproducibility audit had to write a JSON-to-TOML converter for this."""
    first = tmp_path / "first"
    options = ["--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "2", "--seed", "5"]
    assert main(["sweep", *options, "--backend", "inline", "--no-progress", "--out", str(first)]) == 0
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(first)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith(f"# From {first / SWEEP_FILE}, run 1 of 1 (started ")
    assert 'experiment = "baselines"' in printed and "episodes_per_cell = 2" in printed
    rerun = tmp_path / "rerun.toml"
    rerun.write_text(printed)
    again = tmp_path / "again"
    rerun_args = [
        "--config",
        str(rerun),
        "sweep",
        "--backend",
        "inline",
        "--no-progress",
        "--out",
        str(again),
    ]
    assert main(rerun_args) == 0
    assert _metrics(again) == _metrics(first) and len(_metrics(first)) == 4  # 2 methods x 2 episodes
    capsys.readouterr()
    assert main(["config", "show", "--config", str(rerun)]) == 0  # it loads back to itself
    assert capsys.readouterr().out == printed.split("\n", 2)[2]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--from-sweep", "{tmp}"], "no sweep.json (not a sweep directory)"),
        (["--run", "2"], "--run goes with --from-sweep DIR"),
        (["--from-sweep", "{sweep}", "--run", "3"], "records runs 1..1"),
        (["--from-sweep", "{sweep}", "--set", "mpc.horizon=5"], "no --config or --set beside it"),
        (
            ["--from-sweep", "{old}"],
            "records no config (a sweep from before configs were kept, or one swept from",
        ),
        (["--from-sweep", "{damaged}"], "unknown config section 'mcp'; the file is damaged"),
        (["--from-sweep", "{flat}"], "config section 'mpc' is not a table of keys; the file is damaged"),
        (["--from-sweep", "{sweep}/sweep.json"], "sweep.json: that is a sweep's file; give its folder, "),
        (
            ["--from-sweep", "{tmp}/odd"],
            "odd/sweep.json is not a regular file (a folder, a device or a pipe)",
        ),
    ],
)
def test_what_it_refuses(tmp_path, capsys, args, message):
    sweep, old, damaged, flat = (tmp_path / name for name in ("sweep", "old", "damaged", "flat"))
    run = {"started": "2026-12-01T00:00:00+0000", "version": "0.1.0"}
    for folder, line in (
        (sweep, {**run, "config": {}}),
        (old, run),
        (damaged, {**run, "config": {"mcp": {}}}),
        (flat, {**run, "config": {"mpc": 4}}),
    ):
        folder.mkdir()
        (folder / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [line]}))
    (tmp_path / "odd" / SWEEP_FILE).mkdir(parents=True)
    names = {"tmp": tmp_path, "sweep": sweep, "old": old, "damaged": damaged, "flat": flat}
    assert main(["config", "show", *(a.format(**names) for a in args)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_a_sweep_of_an_experiment_swept_from_python_is_not_called_old(tmp_path, capsys):
    """docs/examples/own_experiment.py's folder (run_sweep records no config): the refusal said it was a
    sweep from before configs were kept and to rerun it from its options, none of which names its
    experiment."""
    run = {"started": "2026-12-07T18:40:22+00:00", "version": "0.1.0", "episodes_per_cell": 1}
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"experiment": "sensed_margins", "runs": [run]}))
    assert main(["config", "show", "--from-sweep", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and "(run 1) records no config: its experiment 'sensed_margins' is no --experiment" in err[0]
    )
    assert "from before configs were kept" not in err[0] and "rerun it with the code that swept it" in err[0]


def test_recorded_values_stay_inside_their_comment(tmp_path, capsys):
    """A line break in a recorded version or commit ended the comment: what followed was read as TOML."""
    run = {
        "started": "2026-12-01\n[mpc]",
        "version": "0.1.0",
        "code": {"commit": "abc\n[mpc]\nw_coll = 1.0"},
        "config": {"sweep": {"experiment": "baselines"}},
    }
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [run]}))
    assert main(["config", "show", "--from-sweep", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "at commit abc [mpc] w_coll = 1.0." in printed
    (tmp_path / "printed.toml").write_text(printed)
    assert main(["config", "show", "--config", str(tmp_path / "printed.toml")]) == 0


def test_the_plugins_a_sweep_ran_are_named_as_the_options_a_rerun_needs(tmp_path, capsys):
    """A sweep of a plugin's predictor (docs/extending.md, section 5) recorded the plugin in its code, and the
    printed file named none: its rerun stopped on "a plugin that is not registered" with nothing in the file
    saying which. A recorded name that is no module:Class (a hand-edited record) is left out."""
    plugins = {"mine_q:Net": "ab" * 32, "my_controller:GoStraight": "cd" * 32, "x\n[mpc]": "0"}
    run = {"started": "2026-12-01", "version": "0.1.0", "code": {"commit": "abc", "plugins": plugins}}
    run["config"] = {"sweep": {"experiment": "baselines"}}
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [run]}))
    assert main(["config", "show", "--from-sweep", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    said = " ".join(line[2:] for line in printed.splitlines()[2:4])  # a comment wrapped at the file's width
    assert said == (
        "It ran plugins' code: rerun it as `crowdmpc --plugin mine_q:Net --plugin my_controller:GoStraight "
        "--config FILE sweep --out NEW`."
    )
    (tmp_path / "printed.toml").write_text(printed)
    assert main(["config", "show", "--config", str(tmp_path / "printed.toml")]) == 0


def _recorded_sweep(directory, sets: list[str]) -> None:
    """A sweep.json whose run recorded the effective config of ``sets``, as `crowdmpc sweep` records it."""
    from pipelines.config import load

    run = {"started": "2026-12-01T00:00:00+0000", "version": "0.1.0", "config": load(sets=sets).effective()}
    directory.mkdir(parents=True)
    (directory / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [run]}))


def test_the_recorded_profiles_own_values_stay_unset_so_another_profile_takes_its_own(
    tmp_path, capsys, monkeypatch
):
    """A sweep records every [env] value (the paper profile's time limit, crossing ...); printed as settings,
    they ran under `--profile v1` as the paper's, and `sweep --profile v1` refused them."""
    from pipelines.config import load

    monkeypatch.chdir(tmp_path)
    _recorded_sweep(tmp_path / "sweep", ["sweep.experiment=baselines", "sweep.out=sweep", "sweep.humans=[3]"])
    assert main(["config", "show", "--from-sweep", "sweep"]) == 0
    printed = capsys.readouterr().out
    assert 'profile = "paper"' in printed
    assert "# time_limit = 40.0" in printed and '# crossing = "paper"' in printed  # unset: the profile's
    rerun = tmp_path / "rerun.toml"
    rerun.write_text(printed)
    v1 = ["env.profile=v1"]
    assert load(str(rerun), v1).env == load(sets=v1).env  # v1's 30 s limit and crossing, not the paper's
    assert main(["--config", str(rerun), "sweep", "--profile", "v1", "--dry-run"]) == 0
    assert "straight-none-F-ibr-m=none-v1-visible-h3-r3" in capsys.readouterr().out


def test_its_out_is_the_directory_given_wherever_the_sweep_ran_and_the_rerun_starts(
    tmp_path, capsys, monkeypatch
):
    """A sweep run with `--out rel` recorded "rel": the printed file said a rerun resumes there, but a rerun
    from another directory started a fresh sweep in that directory's rel."""
    from pipelines.config import load

    _recorded_sweep(tmp_path / "start" / "rel", ["sweep.experiment=baselines", "sweep.out=rel"])
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert main(["config", "show", "--from-sweep", "../start/rel"]) == 0
    rerun = elsewhere / "rerun.toml"
    rerun.write_text(capsys.readouterr().out)
    assert load(str(rerun)).sweep.out == str((tmp_path / "start" / "rel").resolve())


def test_a_record_of_more_workers_than_this_machine_takes_reads_back(tmp_path, capsys, monkeypatch):
    """`sweep --workers 32` on 16 CPUs, read back on 2: this machine's limit was applied to the record, so
    config show refused it. It prints it, saying so in a comment, and a sweep of the file here refuses."""
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(16)))
    sets = ["sweep.experiment=baselines", "sweep.humans=[3]", "sweep.workers=32", "sweep.backend=process"]
    _recorded_sweep(tmp_path / "sweep", sets)
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1})
    assert main(["config", "show", "--from-sweep", str(tmp_path / "sweep")]) == 0
    printed = capsys.readouterr().out
    assert "\nworkers = 32 " in printed
    assert (
        "# Its [sweep] workers = 32 is more than a local pool takes on this machine (at most 8: 4 per"
        in printed
    )
    rerun = tmp_path / "rerun.toml"
    rerun.write_text(printed)
    again = tmp_path / "again"
    assert main(["--config", str(rerun), "sweep", "--no-progress", "--out", str(again)]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc sweep: error: {rerun}: sweep.workers: workers 32: at most 8 here (4 per CPU this process "
        "may use, 2); more only queue for the same cores (a Ray cluster takes more)\n"
    )
    assert not again.exists()
    argv = ["--config", str(rerun), "sweep", "--workers", "2", "--dry-run", "--out", str(again)]
    assert main(argv) == 0  # --workers reruns it here


def test_a_changed_calibration_or_model_is_said_before_a_rerun(tmp_path, capsys):
    """A rerun from the printed file gave other episodes, silently, once the calibration the sweep planned
    with was made again (or a model replaced): the file says so in a comment, and a note on stderr."""
    import dataclasses

    import numpy as np

    from predictors.calibration_store import save_calibration
    from tests.calibration_blocks import constant_velocity_block
    from tests.pipelines.test_sweep_hostile import MARGINS_ARGV

    def calibrate(scale: float, created: str) -> None:
        block = constant_velocity_block(np.outer(np.arange(1, 20) / 100.0 * scale, [1.0, 2.0, 3.0, 4.0]))
        save_calibration(dataclasses.replace(block, created=created))

    out = tmp_path / "sweep"
    calibrate(1.0, "2026-01-01T00:00:00+00:00")
    assert main([*MARGINS_ARGV, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    assert "no longer holds" not in "".join(capsys.readouterr())  # the zoo holds what it ran with
    calibrate(2.0, "2026-01-02T00:00:00+00:00")  # the same key: it replaces the block the sweep used
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    printed, err = capsys.readouterr()
    said = "The zoo no longer holds what this sweep ran with (constant_velocity's calibration changed since)"
    assert said in " ".join(line.lstrip("# ") for line in printed.splitlines())
    assert err.startswith(f"note: {said}") and err.count("\n") == 1


def test_an_episode_log_that_is_a_pipe_is_not_waited_on(tmp_path, capsys):
    """The zoo note read episodes.jsonl whatever it was: a pipe there (nobody writing it) hung the command
    for good, and a link to /dev/zero read one endless line until the memory ran out."""
    import os

    sweep = tmp_path / "sweep"
    sweep.mkdir()
    run = {"started": "2026-12-01T00:00:00+0000", "version": "0.1.0", "config": {}}
    (sweep / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [run]}))
    os.mkfifo(sweep / EPISODES_FILE)

    with within(20, "config show --from-sweep waited on the pipe"):
        assert main(["config", "show", "--from-sweep", str(sweep)]) == 0
        assert capsys.readouterr().out.startswith(f"# From {sweep / SWEEP_FILE}, run 1 of 1")
        argv = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "1"]
        assert main([*argv, "--backend", "inline", "--no-progress", "--out", str(sweep)]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc sweep: error: {sweep / EPISODES_FILE} is not a regular file (a device or a pipe) where "
        "the sweep keeps a file; remove it\n"
    )


def test_a_sweep_run_at_a_small_delta_still_reads_back(tmp_path, capsys):
    """MPCConfig's least delta also refuses what sweep folders recorded: at 1e-12 a sweep that had run well at
    delta = 1e-13 (no fallback step) could no longer be shown or reported; only values near the NLP's
    overflow are refused."""
    run = {
        "started": "2026-12-01T00:00:00+0000",
        "version": "0.1.0",
        "config": {"sweep": {"experiment": "baselines"}, "mpc": {"delta": 1e-13}},
    }
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [run]}))
    assert main(["config", "show", "--from-sweep", str(tmp_path)]) == 0
    assert "delta = 1e-13" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("margins", "vary", "shown"),
    [
        ("conformal:", None, 'margins = "conformal:0.1"'),
        ("conformal::real", None, 'margins = "conformal:0.1:real"'),
        ("none:", None, 'margins = "none"'),
        (None, "controller.margins=conformal-motion:,fixed:0.1,0.2", 'vary = "controller.margins='),
    ],
)
def test_a_margins_spec_with_an_empty_part_reads_back_as_it_ran(tmp_path, capsys, margins, vary, shown):
    """An empty alpha or source ran at the default before it was refused where typed; the sweeps recorded
    with one (`--margins conformal:$ALPHA`, $ALPHA unset) could no longer be shown or reported."""
    from pipelines.loop.margins import parse_margins

    config = {"sweep": {"experiment": "baselines", "vary": vary}, "controller": {"margins": margins}}
    run = {"started": "2026-12-01T00:00:00+0000", "version": "0.1.0", "config": config}
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [run]}))
    assert main(["config", "show", "--from-sweep", str(tmp_path)]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.startswith(shown))
    if vary is not None:  # each value as it ran, the fixed margins' numbers kept
        assert line.startswith('vary = "controller.margins=conformal-motion:0.1,fixed:0.1,0.2"')
        assert parse_margins("conformal-motion:0.1") == parse_margins("conformal-motion")


def test_a_simulate_path_named_none_reads_back_as_the_file_it_was(tmp_path, capsys):
    """A config file's [simulate] record = "none" (off, as [sweep] record reads it) was a folder named none,
    and a sweep run with that file records it; refusing the word where typed refused the sweep's report."""
    config = {"sweep": {"experiment": "baselines"}, "simulate": {"record": "none", "json": "NULL"}}
    run = {"started": "2026-12-01T00:00:00+0000", "version": "0.1.0", "config": config}
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"experiment": "baselines", "runs": [run]}))
    assert main(["config", "show", "--from-sweep", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert 'record = "./none"' in printed and 'json = "./NULL"' in printed


@pytest.mark.parametrize(
    "bounds, key, lifted, ran, shown, limit, typed",
    [
        (MPC_LEAST, "delta", 0.0, "1e-200", "1e-200", "at least 1e-40", "1e-300"),
        (MPC_LEAST, "w_goal", 0.0, "1e-300", "1e-300", "at least 1e-40", "5e-324"),  # no guidance: it ran
        (MPC_BOUNDS, "rho", math.inf, "2000", "2000.0", "at most 1000 s^2", "1e+300"),
        (MPC_LEAST, "time_limit_s", 0.0, "1e-12", "1e-12", "at least 1e-09 s", "5e-324"),
        (MPC_LEAST, "d_flock", 0.0, "1e-12", "1e-12", "at least 1e-06 m", "5e-324"),
    ],
    ids=["least", "least_w_goal", "most", "least_time_limit_s", "least_d_flock"],
)
def test_a_sweep_run_beyond_a_bound_added_since_reads_back_and_does_not_rerun(
    tmp_path, capsys, monkeypatch, bounds, key, lifted, ran, shown, limit, typed
):
    """A sweep folder recorded before MPC_LEAST held delta to 1e-40 (delta = 1e-200 ran well with Table I's
    weights), or before MPC_BOUNDS held rho to 1000 s^2 (rho = 2000 ran), was refused by --report-only and
    config show --from-sweep, which run nothing, since MPCConfig checked the bounds; only a run is refused
    now, as its NLP would be."""
    out = tmp_path / "sweep"
    robots = "2" if key == "d_flock" else "1"  # a flock of one is refused its d_flock
    options = ["--experiment", "controllers", "--controllers", "cmpc", "--humans", "1", "--robots", robots]
    options += ["--episodes-per-cell", "1", "--set", "env.time_limit=2", "--backend", "inline"]
    options += ["--no-progress"]
    with monkeypatch.context() as before:  # the code before the bound
        before.setitem(bounds, key, (lifted, bounds[key][1]))
        assert main(["sweep", *options, "--set", f"mpc.{key}={ran}", "--out", str(out)]) == 0
    (out / "table.md").unlink()
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--out", str(out)]) == 0
    assert "cmpc" in (out / "table.md").read_text()  # the report written again
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"\n{key} = {shown} " in printed
    rerun = tmp_path / "rerun.toml"
    rerun.write_text(printed)
    assert main(["--config", str(rerun), "sweep", "--out", str(tmp_path / "again"), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err == f"crowdmpc sweep: error: {rerun}: mpc.{key}: must be {limit}, got {shown}\n"
    for command in (["config", "show"], ["simulate", "--controller", "cmpc"]):  # typed: refused as before
        assert main([*command, "--set", f"mpc.{key}={typed}"]) == 2
        err = capsys.readouterr().err
        assert err.endswith(f" error: --set mpc.{key}: must be {limit}, got {typed}\n")


def test_a_sweep_run_at_the_largest_sizes_of_the_work_reads_back(tmp_path, capsys):
    """MPCConfig refuses past mpc.sizes' bounds, which the config schema has held since sweeps recorded
    their configs: a folder that ran at each bound still reports and shows what it ran."""
    out = tmp_path / "sweep"
    largest = ["mpc.j_max=1000", "mpc.solver_max_iter=100000", "mpc.time_limit_s=3600.0"]
    options = ["--experiment", "controllers", "--controllers", "dmpc", "--humans", "1", "--robots", "1"]
    options += ["--episodes-per-cell", "1", "--set", "env.time_limit=2", "--backend", "inline"]
    options += ["--no-progress", *(item for setting in largest for item in ("--set", setting))]
    assert main(["sweep", *options, "--out", str(out)]) == 0
    (out / "table.md").unlink()
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--out", str(out)]) == 0
    assert "dmpc" in (out / "table.md").read_text()
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    printed = capsys.readouterr().out
    for line in ("j_max = 1000 ", "solver_max_iter = 100000 ", "time_limit_s = 3600.0 "):
        assert f"\n{line}" in printed


def test_an_unknown_predictor_is_refused_as_simulate_refuses_it_but_a_recorded_one_is_shown(tmp_path, capsys):
    """`config show --set controller.predictor=nosuch` printed the config without a word, where simulate and
    sweep refuse the name. What a sweep recorded is shown as it ran: a predictor that a plugin registered
    then (not loaded now), or a zoo held, is named by a rerun's own refusal."""
    typed = tmp_path / "typed.toml"
    typed.write_text('[controller]\npredictor = "nosuch"\n')
    for given in (["--set", "controller.predictor=nosuch"], ["--config", str(typed)]):
        assert main(["simulate", "--controller", "cmpc", *given]) == 2
        refused = capsys.readouterr().err
        assert main(["config", "show", *given]) == 2
        out, err = capsys.readouterr()
        assert (out, err) == ("", refused.replace("crowdmpc simulate:", "crowdmpc config show:", 1))
        assert err.count("\n") == 1 and "predictor: unknown predictor 'nosuch'; choose from [" in err
    assert main(["config", "show", "--set", 'sweep.predictors=["constant_velocity", "nosuch"]']) == 2
    assert "--set sweep.predictors: unknown predictor 'nosuch'; choose from [" in capsys.readouterr().err
    assert main(["config", "show", "--set", "controller.predictor=social_lstm_eth"]) == 0
    run = {
        "started": "2026-12-01T00:00:00+0000",
        "version": "0.1.0",
        "config": {"sweep": {"experiment": "table2"}, "controller": {"predictor": "my_plugin_net"}},
    }
    (tmp_path / SWEEP_FILE).write_text(json.dumps({"experiment": "table2", "runs": [run]}))
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(tmp_path)]) == 0
    assert '\npredictor = "my_plugin_net" ' in capsys.readouterr().out


def test_a_profile_value_the_sweep_asked_for_reads_back_for_the_cells_of_another_profile(tmp_path, capsys):
    """`--set env.time_limit=40.0` is the paper's limit, so the record could not tell it from the unset value
    and left it unset: the conventions experiment's v1 cells had run at 40 s, and `--report-only` and the
    printed file planned v1 cells of 30 s, which the folder does not hold (the report lost their columns)."""
    out = tmp_path / "sweep"
    options = ["--experiment", "conventions", "--predictor", "constant_velocity", "--humans", "1"]
    options += ["--robots", "1", "--episodes-per-cell", "1", "--backend", "inline", "--no-progress"]
    assert main(["sweep", *options, "--set", "env.time_limit=40.0", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--out", str(out)]) == 0
    assert "not recorded" not in (out / "table.md").read_text()
    assert "v1/visible/none" in (out / "table.md").read_text()
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "\ntime_limit = 40.0 " in printed and "\n# timeout_margin = 1.0 " in printed
    rerun = tmp_path / "rerun.toml"
    rerun.write_text(printed)
    assert main(["--config", str(rerun), "sweep", "--dry-run"]) == 0
    assert "8 of 8 planned episodes recorded" in capsys.readouterr().out


def test_an_infinite_orca_setting_reads_back_as_it_ran(tmp_path, capsys):
    """OrcaParams takes inf, which sweep.json writes as null (JSON has none): read back as unset, the report
    planned cells of the default 5 s horizon and refused ("none of them of the cells planned here")."""
    out = tmp_path / "sweep"
    options = ["--experiment", "baselines", "--humans", "1", "--episodes-per-cell", "1"]
    options += ["--backend", "inline", "--no-progress", "--out", str(out)]
    infinite = ["--set", "env.orca.time_horizon=inf", "--set", "env.orca.neighbor_dist=inf"]
    assert main(["sweep", *options, *infinite]) == 0
    assert "orca.time_horizon=inf" in (out / EPISODES_FILE).read_text()
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["config", "show", "--from-sweep", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "\nneighbor_dist = inf " in printed and "\ntime_horizon = inf " in printed


def test_the_keys_read_back_as_inf_are_those_that_take_it():
    """A recorded null is inf for these keys alone: one more that takes inf is recorded as null too."""
    from pipelines.config import ConfigError, load
    from pipelines.config.recorded import INFINITE_KEYS
    from pipelines.config.schema import SECTIONS

    def takes_inf(section: str, key: str) -> bool:
        try:
            load(sets=[f"{section}.{key}=inf"])
        except ConfigError:
            return False
        return True

    numbers = [
        (s.name, k.name) for s in SECTIONS for k in s.keys if k.kind == "float" and k.default is not None
    ]
    assert [pair for pair in numbers if takes_inf(*pair)] == list(INFINITE_KEYS)


@pytest.mark.parametrize(
    "bounds, key, lifted, ran, limit",
    [
        (MPC_LEAST, "w_goal", 0.0, "1e-60", "at least 1e-40"),
        (MPC_LEAST, "delta", 0.0, "1e-200", "at least 1e-40"),
        (MPC_BOUNDS, "rho", math.inf, "2000.0", "at most 1000 s^2"),
    ],
    ids=["w_goal", "delta", "rho"],
)
def test_a_rerun_of_a_sweep_beyond_a_bound_added_since_names_its_folder_and_report(
    tmp_path, capsys, monkeypatch, bounds, key, lifted, ran, limit
):
    """The same command again into a sweep folder that ran mpc.w_goal = 1e-60 before its least value, or
    --reuse of that folder, was refused as any typed value is, naming neither the folder that ran it nor that
    its report still reads back: the refusal says both, before any worker starts."""
    out, new = tmp_path / "sweep", tmp_path / "new"
    options = ["--experiment", "controllers", "--controllers", "cmpc", "--humans", "1", "--robots", "1"]
    options += ["--episodes-per-cell", "1", "--set", "env.time_limit=2", "--backend", "inline"]
    options += ["--no-progress", "--set", f"mpc.{key}={ran}"]
    with monkeypatch.context() as before:
        before.setitem(bounds, key, (lifted, bounds[key][1]))
        assert main(["sweep", *options, "--out", str(out)]) == 0
    held = sorted(p.name for p in out.iterdir()), (out / EPISODES_FILE).read_text()
    for folder, extra in ((out, []), (new, ["--reuse", str(out)])):
        capsys.readouterr()
        assert main(["sweep", *options, *extra, "--episodes-per-cell", "2", "--out", str(folder)]) == 2
        err = capsys.readouterr().err
        assert err == (
            f"crowdmpc sweep: error: --set mpc.{key}: must be {limit}, got {ran}; {out} ran with mpc.{key} = "
            f"{ran} before that bound: no more of it runs, and `crowdmpc sweep --report-only --out {out}` "
            "still reports it\n"
        )
    assert (sorted(p.name for p in out.iterdir()), (out / EPISODES_FILE).read_text()) == held
    assert not new.exists()


@pytest.mark.parametrize(
    "module, bound, lifted, ran, refusal, recorded",
    [
        (
            "crowdsim.world",
            "SENSOR_RANGE",
            (1e-6, math.inf),
            ["--sensor-range", "2000"],
            "--sensor-range: the sensor range must be at most 1000 m, got 2000.0",
            "simulate.sensor_range = 2000.0",
        ),
        (
            "crowdsim.orca",
            "LEAST_NEIGHBOR_DIST",
            0.0,
            ["--set", "env.orca.neighbor_dist=1e-12"],
            "--set env.orca.neighbor_dist: ORCA's neighbor_dist must be at least 1e-06 m, got 1e-12",
            "env.orca.neighbor_dist = 1e-12",
        ),
    ],
    ids=["sensor_range", "neighbor_dist"],
)
def test_a_rerun_of_a_sweep_beyond_a_world_bound_added_since_names_its_folder_and_report(
    tmp_path, capsys, monkeypatch, module, bound, lifted, ran, refusal, recorded
):
    """The sensor range's bounds and ORCA's least neighbor_dist came after the MPC's: the same command again
    into a folder that ran --sensor-range 2000 before them (or --reuse of it, or its dry run) was refused in
    their words alone, where the MPC's refusal names the folder and that its report still reads back."""
    import importlib

    out, new = tmp_path / "sweep", tmp_path / "new"
    options = ["--experiment", "controllers", "--controllers", "orca", "--humans", "2"]
    options += ["--episodes-per-cell", "1", "--backend", "inline", "--no-progress", *ran]
    with monkeypatch.context() as before:
        before.setattr(importlib.import_module(module), bound, lifted)
        assert main(["sweep", *options, "--out", str(out)]) == 0
    held = sorted(p.name for p in out.iterdir()), (out / EPISODES_FILE).read_text()
    for folder, extra in ((out, []), (out, ["--dry-run"]), (new, ["--reuse", str(out)])):
        capsys.readouterr()
        assert main(["sweep", *options, *extra, "--episodes-per-cell", "2", "--out", str(folder)]) == 2
        assert capsys.readouterr().err == (
            f"crowdmpc sweep: error: {refusal}; {out} ran with {recorded} before that bound: no more of it "
            f"runs, and `crowdmpc sweep --report-only --out {out}` still reports it\n"
        )
    assert (sorted(p.name for p in out.iterdir()), (out / EPISODES_FILE).read_text()) == held
    assert not new.exists()


@pytest.mark.parametrize(
    "bound, lifted, run, vary, refusal, recorded",
    [
        (
            ("crowdsim.world", "SENSOR_RANGE"),
            (1e-6, math.inf),
            ["--controllers", "orca", "--humans", "2"],
            "simulate.sensor_range=3,2000",
            "the sensor range must be at most 1000 m, got 2000.0",
            "simulate.sensor_range = 2000.0",
        ),
        (
            ("crowdsim.orca", "LEAST_NEIGHBOR_DIST"),
            0.0,
            ["--controllers", "orca", "--humans", "2"],
            "env.orca.neighbor_dist=10,1e-12",
            "ORCA's neighbor_dist must be at least 1e-06 m, got 1e-12",
            "env.orca.neighbor_dist = 1e-12",
        ),
        (
            (MPC_LEAST, "w_goal"),
            (0.0, MPC_LEAST["w_goal"][1]),
            ["--controllers", "cmpc", "--humans", "1", "--robots", "1", "--set", "env.time_limit=2"],
            "mpc.w_goal=1,1e-60",
            "method 'cmpc w_goal=1e-60' of experiment 'controllers': w_goal must be at least 1e-40, got "
            "1e-60",
            "mpc.w_goal = 1e-60",
        ),
    ],
    ids=["sensor_range", "neighbor_dist", "w_goal"],
)
def test_a_rerun_of_a_sweep_that_varied_a_value_beyond_a_bound_added_since_names_its_folder_and_report(
    tmp_path, capsys, monkeypatch, bound, lifted, run, vary, refusal, recorded
):
    """A sweep record keeps a --vary column's values only as typed in [sweep] vary, which ran_beyond_bound
    did not read: the same command again into a folder that ran --vary simulate.sensor_range=3,2000 before
    the bound (or its dry run, or --reuse of it) was refused in the bound's words alone, as if the folder held
    no such column. A fresh folder's refusal is the bound's words, as before."""
    import importlib

    out, new, fresh = tmp_path / "sweep", tmp_path / "new", tmp_path / "fresh"
    options = ["--experiment", "controllers", *run, "--episodes-per-cell", "1", "--backend", "inline"]
    options += ["--no-progress", "--vary", vary]
    holder, name = bound
    with monkeypatch.context() as before:
        if isinstance(holder, dict):
            before.setitem(holder, name, lifted)
        else:
            before.setattr(importlib.import_module(holder), name, lifted)
        assert main(["sweep", *options, "--out", str(out)]) == 0
    held = sorted(p.name for p in out.iterdir()), (out / EPISODES_FILE).read_text()
    note = (
        f"; {out} ran with {recorded} before that bound: no more of it runs, and `crowdmpc sweep "
        f"--report-only --out {out}` still reports it"
    )
    runs = ((out, [], note), (out, ["--dry-run"], note), (new, ["--reuse", str(out)], note), (fresh, [], ""))
    for folder, extra, said in runs:
        capsys.readouterr()
        assert main(["sweep", *options, *extra, "--episodes-per-cell", "2", "--out", str(folder)]) == 2
        assert capsys.readouterr().err == f"crowdmpc sweep: error: --vary: {refusal}{said}\n"
    assert (sorted(p.name for p in out.iterdir()), (out / EPISODES_FILE).read_text()) == held
    assert not new.exists() and not fresh.exists()
