"""Sweeps: the experiments as data, durable resumable records (killed for real), the report's numbers."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pipelines.cli import main
from pipelines.errors import DroppedLineWarning, PipelineError
from pipelines.experiments.cells import (
    EXPERIMENTS,
    PAPER_TABLE_II,
    PAPER_TABLE_III,
    PaperFigures,
    get_experiment,
)
from pipelines.experiments.log import EPISODES_FILE, ERRORS_FILE, EpisodeLog, error_keys, mcap_path
from pipelines.experiments.paired import mcnemar_exact
from pipelines.experiments.report import CELLS_CSV, write_report
from pipelines.experiments.summary import _half_width, summarize, t95, wilson_interval
from pipelines.experiments.sweep import run_sweep
from pipelines.experiments.sweep_config import SweepConfig
from pipelines.experiments.sweep_folder import sweep_lock
from pipelines.experiments.tables import markdown_table, paired_success
from pipelines.experiments.tasks import World, scenario_schedule
from pipelines.experiments.worker import EpisodeOutcome, EpisodeWorker, is_failure
from pipelines.loop.controllers import ControllerSpec, make_controller
from pipelines.loop.margins import MarginSpec

REPO = Path(__file__).resolve().parents[2]

# ----------------------------------------------------------------------------------------------------------
# Experiments as data
# ----------------------------------------------------------------------------------------------------------


def test_schedule_alternates_scenarios_and_counts_seeds_per_scenario():
    assert scenario_schedule(5, seed=10) == [
        ("circle", 10),
        ("perpendicular", 10),
        ("circle", 11),
        ("perpendicular", 11),
        ("circle", 12),
    ]
    with pytest.raises(PipelineError, match="at least 1"):
        scenario_schedule(0)


@pytest.mark.parametrize("name", sorted(EXPERIMENTS))
def test_every_cell_of_an_experiment_runs_the_same_crowds(name):
    experiment = EXPERIMENTS[name]
    tasks = experiment.tasks(6, seed=3)
    cells = experiment.cells()
    assert len(tasks) == 6 * len(cells) == 6 * len(experiment.methods) * len(experiment.humans)
    by_cell: dict[str, list[tuple[str, int]]] = {}
    for task in tasks:
        by_cell.setdefault(task.cell.key, []).append((task.scenario, task.seed))
    assert all(episodes == scenario_schedule(6, 3) for episodes in by_cell.values())
    assert len({t.key for t in tasks}) == len(tasks)  # record keys never collide


def test_experiment_cells():
    table2 = get_experiment("table2")
    assert table2.method_labels == ("CMPC", "DMPC") and table2.humans == (5, 6, 7, 8, 9)
    assert [c.spec.controller for c in table2.cells()[:2]] == ["cmpc", "dmpc"]
    f, nf = get_experiment("table3").cells(humans=(7,))
    assert (f.spec.flocking, nf.spec.flocking) == (True, False) and f.key != nf.key
    assert f.key == "cmpc-social_lstm_eth-F-ibr-m=none-paper-visible-h7-r3"
    predictors = get_experiment("predictors")
    assert predictors.humans == (7,)
    assert [s.predictor for _, s in predictors.methods] == [
        "constant_velocity",
        "vanilla_lstm_eth",
        "social_lstm_eth",
        "social_lstm_soft_eth",
        "social_gan_eth",
        "social_lstm_synth",
        "orca_oracle",
    ]
    coupling = get_experiment("coupling").cells()
    assert [c.spec.coupling for c in coupling] == ["ibr", "nlp", "nlp"]
    assert [c.method for c in coupling] == ["IBR", "NLP exact", "NLP first-order"]
    assert coupling[1].key == "cmpc-social_lstm_soft_eth-F-nlp-coupled_mode=exact-m=none-paper-visible-h7-r3"
    cv = table2.with_predictor("constant_velocity")
    assert {s.predictor for _, s in cv.methods} == {"constant_velocity"}
    assert cv.cells()[0].key == "cmpc-constant_velocity-F-ibr-m=none-paper-visible-h5-r3"
    with pytest.raises(PipelineError, match="fixes each method's predictor"):
        predictors.with_predictor("constant_velocity")
    with pytest.raises(PipelineError, match="unknown experiment 'table4'"):
        get_experiment("table4")


def test_margins_profile_and_visibility_are_part_of_every_cell():
    table2 = get_experiment("table2")
    cp = table2.with_margins(MarginSpec("conformal", alpha=0.05))
    assert {s.margins.label for _, s in cp.methods} == {"cp0.05"}
    assert cp.cells((7,))[0].key == "cmpc-social_lstm_eth-F-ibr-m=cp0.05-paper-visible-h7-r3"
    v1 = table2.with_world(World("v1", "invisible"))
    assert v1.cells((7,))[1].key == "dmpc-social_lstm_eth-F-ibr-m=none-v1-invisible-h7-r3"
    assert v1.cells((7,))[1].world.env_config().robots_visible is False
    # Every cell of the convention ablation differs, on the same crowds; its settings are not overridable.
    conventions = get_experiment("conventions")
    keys = [c.key for c in conventions.cells()]
    assert len(keys) == len(set(keys)) == 8
    with pytest.raises(PipelineError, match="fixes each method's profile"):
        conventions.with_world(World("v1"))
    with pytest.raises(PipelineError, match="fixes each method's margins"):
        get_experiment("safety").with_margins(MarginSpec())
    safety = get_experiment("safety")
    alphas = ("alpha=0.5", "alpha=0.2", "alpha=0.1", "alpha=0.05", "alpha=0.01")
    families = (*alphas, *(f"motion {a}" for a in alphas), *(f"shortfall {a}" for a in alphas))
    assert safety.method_labels == ("none", *families)
    motion = {s.margins.label for _, s in safety.methods[6:11]}
    assert motion == {"cpm0.5", "cpm0.2", "cpm0.1", "cpm0.05", "cpm0.01"}
    with pytest.raises(PipelineError, match="unknown profile 'crowdnav'"):
        World("crowdnav")


def test_margins_go_to_the_methods_that_predict_and_are_refused_where_none_does(tmp_path, capsys):
    """The controllers experiment gave --margins to ORCA and the straight line too (in their cell keys), and
    a run then refused them with "conformal margins need a predictor; this controller uses none", naming
    neither the option nor the method: with the default list (cmpc, dmpc, orca, straight) always."""
    controllers = get_experiment("controllers").with_margins(MarginSpec("conformal", alpha=0.1))
    labels = {label: spec.margins.label for label, spec in controllers.methods}
    assert labels == {"cmpc": "cp0.1", "dmpc": "cp0.1", "orca": "none", "straight": "none"}
    argv = ["sweep", "--experiment", "controllers", "--humans", "3", "--margins", "conformal:0.1",
            "--dry-run", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    listed = capsys.readouterr().out
    assert "orca-none-F-ibr-m=none-paper-visible-h3-r3" in listed and "m=cp0.1-paper-visible-h3" in listed
    assert main([*argv, "--controllers", "orca,straight"]) == 2
    assert capsys.readouterr().err.strip() == (
        "crowdmpc sweep: error: --margins conformal:0.1: methods 'orca', 'straight' plan with no predictor; "
        "margins apply to the controllers that do (cmpc, dmpc, or a plugin with uses_predictor = True)"
    )


def test_paper_figures_as_printed():
    assert PAPER_TABLE_II[("CMPC", 7)] == PaperFigures(90.0, 19.1, 1.3, 1.3)
    assert PAPER_TABLE_II[("DMPC", 9)] == PaperFigures(83.9, 20.3, 1.9, 1.8)
    assert PAPER_TABLE_III[("NF", 5)] == PaperFigures(96.7, 17.6, 0.2, 1.4)
    assert PAPER_TABLE_III[("F", 8)].success == 86.6  # Table II prints 86.7 for the same configuration
    assert len(PAPER_TABLE_II) == len(PAPER_TABLE_III) == 10


# ----------------------------------------------------------------------------------------------------------
# Wilson intervals, checked by hand:
#   centre = (p + z^2/2n) / (1 + z^2/n),  half = z sqrt(p(1-p)/n + z^2/4n^2) / (1 + z^2/n),  z^2 = 3.841459
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("k", "n", "lo", "hi"),
    [
        (0, 10, 0.0, 0.2775),  # centre = half = 0.192073 / 1.384146 = 0.138767
        (10, 10, 0.7225, 1.0),
        (5, 10, 0.2366, 0.7634),  # half = 1.959964 * sqrt(0.025 + 0.009604) / 1.384146 = 0.263413
        (3, 4, 0.3006, 0.9544),  # centre 1.230182 / 1.960365 = 0.627527, half 0.326888
        (50, 100, 0.4038, 0.5962),
    ],
)
def test_wilson_interval_hand_values(k, n, lo, hi):
    assert wilson_interval(k, n) == pytest.approx((lo, hi), abs=5e-5)


@pytest.mark.parametrize(
    ("b", "c", "p"),
    [(0, 0, 1.0), (0, 6, 2 / 64), (1, 9, 2 * 11 / 1024), (5, 5, 1.0)],  # 2 * sum_{k<=min} C(n, k) / 2^n
)
def test_mcnemar_exact_hand_values(b, c, p):
    assert mcnemar_exact(b, c) == pytest.approx(p)
    assert mcnemar_exact(c, b) == pytest.approx(p)


def test_mcnemar_exact_takes_the_discordant_pairs_of_a_large_sweep():
    """From 1024 discordant pairs 2.0**n overflowed a float and the report of a sweep with a few thousand
    episodes a cell ended in OverflowError; the tail is now an exact integer ratio."""
    from fractions import Fraction
    from math import comb

    for b, c in ((500, 600), (1100, 1200), (3000, 3000)):
        n = b + c
        exact = min(Fraction(1), 2 * Fraction(sum(comb(n, k) for k in range(min(b, c) + 1)), 2**n))
        assert mcnemar_exact(b, c) == pytest.approx(float(exact), rel=1e-12)
    assert mcnemar_exact(0, 5000) == 0.0  # 2 / 2^5000: below the smallest float
    assert mcnemar_exact(2500, 2500) == 1.0


def test_mcnemar_exact_takes_numpy_counts_as_python_integers():
    """int64 counts overflowed in the exact terms and in 1 << n and gave p = 1.0 with a warning."""
    assert (
        mcnemar_exact(np.int64(30), np.int64(45)) == mcnemar_exact(30, 45) == pytest.approx(0.10534, abs=1e-5)
    )


@pytest.mark.parametrize(  # two-sided 95% quantiles of Student's t, from the standard tables
    ("dof", "t"),
    [(1, 12.7062), (2, 4.3027), (3, 3.1824), (4, 2.7764), (5, 2.5706), (10, 2.2281), (30, 2.0423),
     (120, 1.9799), (1000, 1.9623), (1001, 1.9623), (10**6, 1.9600)],
)  # fmt: skip
def test_t95_hand_values(dof, t):
    assert t95(dof) == pytest.approx(t, abs=5e-5)


def test_the_travel_time_interval_is_students_t():
    # two successes, 10 s and 20 s: standard error 5 s, times t95(1) = 12.706 (a normal one would say 9.8)
    assert _half_width([10.0, 20.0]) == pytest.approx(63.531, abs=1e-3)
    assert math.isnan(_half_width([10.0]))
    with pytest.raises(PipelineError, match="at least one degree of freedom"):
        t95(0)


def test_wilson_interval_edges():
    assert all(math.isnan(x) for x in wilson_interval(0, 0))
    with pytest.raises(PipelineError):
        wilson_interval(5, 4)


# ----------------------------------------------------------------------------------------------------------
# The record log
# ----------------------------------------------------------------------------------------------------------


def test_torn_last_line_is_dropped_and_the_log_goes_on(tmp_path):
    log = EpisodeLog(tmp_path / EPISODES_FILE)
    log.append({"key": "a", "x": float("nan")})
    log.append({"key": "b", "x": np.float64(2.0)})
    whole = log.path.read_bytes()
    with open(log.path, "ab") as f:
        f.write(b'{"key": "c", "x"')  # a kill in the middle of a write
    assert list(log.load(repair=False)) == ["a", "b"]
    assert log.path.read_bytes() != whole  # repair=False leaves the file alone
    records = log.load()
    assert records == {"a": {"key": "a", "x": None}, "b": {"key": "b", "x": 2.0}}
    assert log.path.read_bytes() == whole
    log.append({"key": "c", "x": 3})
    assert list(log.load()) == ["a", "b", "c"]


def test_a_garbled_last_line_counts_as_torn_but_one_in_the_middle_is_refused(tmp_path):
    path = tmp_path / EPISODES_FILE
    path.write_bytes(b'{"key": "a"}\n{"key": \x00\x00\n')
    # a whole line, newline and all, may be a crash's (its blocks written out of order) or an edit: cut off,
    # but kept beside the log and said (it was dropped without a word)
    with pytest.warns(DroppedLineWarning, match=r":2: the last line is no JSON record .*kept in .*\.cut$"):
        assert list(EpisodeLog(path).load()) == ["a"]
    assert path.read_bytes() == b'{"key": "a"}\n'
    assert path.with_name(f"{EPISODES_FILE}.cut").read_bytes() == b'{"key": \x00\x00\n'
    path.write_bytes(b'{"key": "a"}\nnot json\n{"key": "b"}\n')
    with pytest.raises(PipelineError, match=":2: not a JSON record"):
        EpisodeLog(path).load()
    path.write_bytes(b'{"key": "a"}\n{"key": "a"}\n')
    with pytest.raises(PipelineError, match="a second record for 'a'"):
        EpisodeLog(path).load()
    path.write_bytes(b'{"key": "a"}\nnot json\n{"key": "b"')  # a bad line, then a torn one: both the tail
    with pytest.warns(DroppedLineWarning):
        assert list(EpisodeLog(path).load()) == ["a"]
    assert path.read_bytes() == b'{"key": "a"}\n'
    assert path.with_name(f"{EPISODES_FILE}.cut").read_bytes().endswith(b'not json\n{"key": "b"')


def test_the_kept_cut_line_is_never_written_through_a_link_or_into_a_folder(tmp_path):
    """episodes.jsonl.cut is the sweep's own file: a link planted there had the cut line appended to its
    target, and a folder of that name stopped every resume with the OS's "Is a directory"."""
    from pipelines.experiments.sweep_folder import check_sweep_directory

    path = tmp_path / EPISODES_FILE
    path.write_bytes(b'{"key": "a"}\n')
    (tmp_path / "target").write_text("precious\n")
    cut = tmp_path / f"{EPISODES_FILE}.cut"
    cut.symlink_to(tmp_path / "target")
    with pytest.raises(PipelineError, match="is a symbolic link"):
        check_sweep_directory(tmp_path)
    path.write_bytes(b'{"key": "a"}\nnot json\n')
    with pytest.raises(PipelineError, match=r"episodes.jsonl.cut: cannot write there \(.*\); remove it"):
        EpisodeLog(path).load()  # the library's own guard, for a caller that skipped the folder's check
    assert (tmp_path / "target").read_text() == "precious\n"
    cut.unlink()
    cut.mkdir()
    with pytest.raises(PipelineError, match="is a directory where the sweep keeps a file; remove it"):
        check_sweep_directory(tmp_path)


def test_load_checks_each_record_naming_its_line(tmp_path):
    seen = []
    log = EpisodeLog(tmp_path / EPISODES_FILE, check=lambda record, where: seen.append((dict(record), where)))
    log.append({"key": "a", "config": {"mpc": {"horizon": 4}}, "x": 1})
    log.append({"key": "b", "config": {}, "x": 2})
    assert log.load()["a"] == {"key": "a", "config": {"mpc": {"horizon": 4}}, "x": 1}
    assert [where.rsplit(":", 1)[1] for _, where in seen] == ["1", "2"]
    assert seen[0][0]["config"] == {"mpc": {"horizon": 4}}


def test_the_report_holds_no_record_but_columns_of_what_it_reads(tmp_path):
    """A record held whole (its config left out) was 3.7 KB an episode, 4.1 GB at a million: the report
    keeps, of each, its summary's fields in machine arrays and where its line lies in the log."""
    from array import array

    from pipelines.commands.sweep_log_read import read_log

    config = SweepConfig(
        get_experiment("baselines"), tmp_path, 2, humans=(3,), backend="inline", progress=False
    )
    run_sweep(config)
    cells = config.experiment.cells(config.humans, config.n_robots)
    log = read_log(config, cells, config.tasks())
    assert log.held == log.planned == 4 and log.cells == {c.key for c in cells}
    assert sorted(log.columns) == sorted(c.key for c in cells)
    for columns in log.columns.values():
        assert len(columns) == 2
        for column in (columns.seeds, *columns.metrics.values(), *columns.solver.values()):
            assert isinstance(column.values, array)


# ----------------------------------------------------------------------------------------------------------
# Running sweeps (in this process: the inline backend, the same worker as the pools)
# ----------------------------------------------------------------------------------------------------------


def _config(out: Path, episodes: int, **kw) -> SweepConfig:
    kw = {"humans": (5,), "backend": "inline", "progress": False} | kw
    return SweepConfig(get_experiment("baselines"), out, episodes, **kw)


def test_a_rerun_planning_fewer_episodes_says_its_report_leaves_some_out(tmp_path, capsys):
    """A rerun with fewer episodes per cell, or other crowd sizes, reports its own plan: the episodes of the
    earlier plan dropped out of table.md and cells.csv without a word. It says so now, once per run."""
    run_sweep(_config(tmp_path, 3))
    capsys.readouterr()
    run_sweep(_config(tmp_path, 3))
    assert "this run does not plan" not in capsys.readouterr().err  # the same plan: nothing left out
    run_sweep(_config(tmp_path, 2))
    err = capsys.readouterr().err
    assert f"note: {tmp_path / EPISODES_FILE} holds 2 episode(s) this run does not plan (e.g. " in err
    assert "table.md, cells.csv and episodes.csv report this run's plan only" in err
    run_sweep(_config(tmp_path, 1, humans=(3,)))
    assert "holds 6 episode(s) this run does not plan" in capsys.readouterr().err


def test_a_rerun_runs_only_what_is_missing_and_extends(tmp_path):
    first = run_sweep(_config(tmp_path, 2))
    assert (first.planned, first.already_done, first.ran, first.errors) == (4, 0, 4, [])
    again = run_sweep(_config(tmp_path, 2))
    assert (again.planned, again.already_done, again.ran) == (4, 4, 0)
    more = run_sweep(_config(tmp_path, 3))
    assert (more.planned, more.already_done, more.ran) == (6, 4, 2)
    records = EpisodeLog(tmp_path / EPISODES_FILE).load()
    assert set(records) == {t.key for t in _config(tmp_path, 3).tasks()}
    record = records["orca-none-F-ibr-m=none-paper-visible-h5-r3/perpendicular/0"]
    assert (record["method"], record["predictor"], record["scenario"], record["seed"]) == (
        "ORCA",
        None,
        "perpendicular",
        0,
    )
    assert record["metrics"]["n_steps"] == record["solver"]["steps"] > 0
    assert record["wall_s"] > 0 and record["cpu_s"] > 0
    meta = json.loads((tmp_path / "sweep.json").read_text())
    assert meta["experiment"] == "baselines" and len(meta["runs"]) == 3


def test_a_sweep_called_as_a_worker_imports_the_script_says_to_guard_it(tmp_path, monkeypatch):
    """A script that runs a sweep outside ``if __name__ == "__main__":`` runs it again in every pool worker as
    the worker imports it (multiprocessing's spawn sets ``_inheriting`` meanwhile): each worker failed on the
    driver's lock, "another sweep is writing to ...", a sweep that was not there."""
    import multiprocessing

    monkeypatch.setattr(multiprocessing.current_process(), "_inheriting", True, raising=False)
    with pytest.raises(PipelineError, match=r'run_sweep under if __name__ == "__main__":'):
        run_sweep(_config(tmp_path / "out", 1))
    assert not (tmp_path / "out").exists()


def test_a_worker_builds_each_controller_once_per_cell():
    worker = EpisodeWorker()
    tasks = get_experiment("baselines").tasks(3, humans=(5,))
    outcomes = [worker.run(t) for t in tasks]
    assert all(o.error is None for o in outcomes)
    assert worker.builds == 2


def test_record_failures_keeps_the_mcap_logs_of_failed_episodes(tmp_path):
    run_sweep(_config(tmp_path, 2, record="failures"))
    records = EpisodeLog(tmp_path / EPISODES_FILE).load()
    tasks = {t.key: t for t in _config(tmp_path, 2).tasks()}
    kept = {key for key in records if mcap_path(tmp_path, tasks[key]).exists()}
    assert kept == {key for key, r in records.items() if is_failure(r["metrics"])}
    assert kept  # straight robots crossing 5 humans violate personal space
    assert all(mcap_path(tmp_path, tasks[k]).read_bytes().startswith(b"\x89MCAP") for k in kept)


def test_episodes_that_raise_go_to_errors_and_a_broken_setup_stops_early(tmp_path, monkeypatch):
    def broken(spec, env_config=None, *, jit=False, read=None):
        raise RuntimeError("no solver here")

    monkeypatch.setattr("pipelines.experiments.worker.make_controller", broken)
    with pytest.raises(PipelineError, match=r"first 4 episodes all raised \(RuntimeError: no solver here\)"):
        run_sweep(_config(tmp_path, 5))
    errors = (tmp_path / ERRORS_FILE).read_text().splitlines()
    assert len(errors) == 4 and "no solver here" in json.loads(errors[0])["error"]
    assert EpisodeLog(tmp_path / EPISODES_FILE).load() == {}


def test_an_error_after_a_torn_entry_of_errors_jsonl_is_an_entry_of_its_own(tmp_path, monkeypatch):
    """errors.jsonl is appended to and never cut: an entry torn by a kill or a full disk took the next
    entry into its line, whose traceback could not be read again, nor its key, which a rerun retries last."""

    def broken(spec, env_config=None, *, jit=False, read=None):
        raise RuntimeError("no solver here")

    monkeypatch.setattr("pipelines.experiments.worker.make_controller", broken)
    with pytest.raises(PipelineError, match="first 4 episodes all raised"):
        run_sweep(_config(tmp_path, 5))
    errors = (tmp_path / ERRORS_FILE).read_bytes()
    (tmp_path / ERRORS_FILE).write_bytes(errors[:-20])  # the last entry torn
    with pytest.raises(PipelineError, match="first 4 episodes all raised"):
        run_sweep(_config(tmp_path, 5))
    lines = (tmp_path / ERRORS_FILE).read_bytes().splitlines()
    assert len(lines) == 8 and lines[3] == errors.splitlines()[3][:-19]
    assert all("no solver here" in json.loads(line)["error"] for line in lines[:3] + lines[4:])
    assert len(error_keys(tmp_path)) == 7  # the torn entry's key alone is lost


def test_an_out_whose_file_system_does_not_lock_is_one_line(tmp_path, monkeypatch, capsys):
    """On an NFS mount without its lock daemon flock fails with ENOLCK ("No locks available"): the sweep
    ended in that OSError's traceback."""
    import errno
    import fcntl

    def no_locks(fd, operation):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(fcntl, "flock", no_locks)
    out = tmp_path / "runs"
    args = ["sweep", "--experiment", "baselines", "--episodes-per-cell", "1", "--humans", "5"]
    assert main([*args, "--backend", "inline", "--no-progress", "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc sweep: error: cannot lock {out / '.sweep.lock'} (No locks available): the file system of "
        "--out does not lock files (an NFS mount without its lock daemon?), which keeps a second sweep from "
        "writing the same directory; choose an --out on one that does\n"
    )


def test_one_directory_one_sweep_at_a_time_and_one_experiment(tmp_path):
    with sweep_lock(tmp_path), pytest.raises(PipelineError, match="another sweep is writing"):
        run_sweep(_config(tmp_path, 1))
    run_sweep(_config(tmp_path, 1))
    other = SweepConfig(get_experiment("table2"), tmp_path, 1, backend="inline", progress=False)
    with pytest.raises(PipelineError, match="holds a sweep of experiment 'baselines'"):
        run_sweep(other)


def test_a_cell_is_not_extended_with_other_weights(tmp_path):
    experiment = get_experiment("baselines")
    config = SweepConfig(experiment, tmp_path, 1, humans=(3,), backend="inline", progress=False)
    run_sweep(config)
    path = tmp_path / EPISODES_FILE
    records = [json.loads(line) for line in path.read_text().splitlines()]
    for r in records:  # as if run with a predictor whose weights have changed since
        r["predictor"], r["predictor_sha256"] = "constant_velocity", "0123"
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    with pytest.raises(PipelineError, match="sha256 0123, but the zoo's 'constant_velocity' is now None"):
        run_sweep(dataclasses.replace(config, episodes_per_cell=2))


FAILING = "tests.plugins.failing_controllers"


@pytest.fixture
def plugins(monkeypatch):
    """Register ``failing_controllers``' plugins here and for the worker processes; none left after."""
    from pipelines.loop import spec as registry

    monkeypatch.setattr(registry, "_PLUGINS", {})

    def register(*names: str) -> list[str]:
        specs = [f"{FAILING}:{name}" for name in names]
        registry.register_controller_plugins(specs)
        return specs

    return register


def _controllers(out: Path, episodes: int, controllers: list[str], **kw) -> SweepConfig:
    experiment = get_experiment("controllers").with_controllers(controllers)
    kw = {"humans": (1,), "backend": "inline", "progress": False} | kw
    return SweepConfig(experiment, out, episodes, **kw)


def _sweep_cli(out: Path, controllers: list[str], *options: str) -> list[str]:
    return ["sweep", "--experiment", "controllers", "--controllers", ",".join(controllers), "--humans", "1",
            "--jit", "off", "--no-progress", "--out", str(out), *options]  # fmt: skip


@pytest.mark.parametrize(
    "backend, said",
    [("process", "worker process died ("), ("ray", "Ray actor died while this episode was on it")],
)
def test_a_worker_that_dies_is_an_episode_error_and_the_sweep_goes_on(
    backend, said, tmp_path, plugins, capsys
):
    """A worker killed (SIGKILL here; a segfault, the OOM killer) ended the sweep in a traceback (the process
    pool's BrokenProcessPool, Ray's ActorDiedError), losing the episodes in flight, writing no error and no
    report."""
    if backend == "ray":
        pytest.importorskip("ray")  # the [cluster] extra
    (dies,) = plugins("Dies")
    argv = _sweep_cli(tmp_path, ["straight", dies], "--episodes-per-cell", "1", "--workers", "1")
    assert main([*argv, "--backend", backend]) == 1  # some episodes raised
    err = capsys.readouterr().err
    assert "Traceback" not in err and "1 episode raised; see" in err
    records = EpisodeLog(tmp_path / EPISODES_FILE).load()
    errors = [json.loads(line) for line in (tmp_path / ERRORS_FILE).read_text().splitlines()]
    # straight's episode finished before the other killed the worker: kept; the other is retried by a rerun
    assert [r["controller"] for r in records.values()] == ["straight"]
    assert [e["key"].split("/")[0].split("-")[0] for e in errors] == [dies]
    assert said in errors[0]["error"]  # the process pool's says the exit code, when known
    assert (tmp_path / "table.md").exists()


class _FakeActorDied(Exception):
    pass


def _fake_ray(monkeypatch, dies: set[str], code: dict | None = None) -> list[int]:
    """A Ray whose actors run an episode at once, each dying on a task whose key is in ``dies`` (and failing
    every task it held), and running ``code`` (default: the driver's); returns the list of actor ids made, in
    order."""
    import types

    from pipelines.plugins import code_with_plugins

    made: list[int] = []
    killed: list[int] = []

    class Ref:
        def __init__(self, actor, task):
            self.actor, self.task = actor, task

    class Actor:
        def __init__(self):
            self.id, self.dead = len(made), False
            made.append(self.id)
            self.run_unless_stopped = types.SimpleNamespace(remote=lambda task: Ref(self, task))
            self.code = types.SimpleNamespace(remote=lambda: Ref(self, None))

    def get(ref):
        if ref.task is None:  # the actor's code
            return "node-7", code_with_plugins() if code is None else code
        if ref.actor.dead or ref.task.key in dies:
            ref.actor.dead = True
            raise _FakeActorDied("The actor died unexpectedly before finishing this task.\n\tpid: 1")
        return EpisodeOutcome(ref.task.key, record={"key": ref.task.key})

    fake = types.ModuleType("ray")
    fake.is_initialized = lambda: True  # type: ignore[attr-defined]
    flag = types.SimpleNamespace()  # the backend's StopFlag: no stop said in these tests
    fake.remote = lambda **_: (
        lambda cls: types.SimpleNamespace(  # type: ignore[attr-defined]
            remote=lambda *a: flag if cls.__name__ == "StopFlag" else Actor()
        )
    )
    fake.wait = lambda refs, num_returns: (refs[:1], refs[1:])  # type: ignore[attr-defined]
    fake.get = get  # type: ignore[attr-defined]
    fake.exceptions = types.SimpleNamespace(RayActorError=_FakeActorDied)  # type: ignore[attr-defined]
    fake.kill = lambda actor: actor is flag or killed.append(actor.id)  # type: ignore[attr-defined]
    fake.killed = killed  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", fake)
    return made


def test_a_dead_ray_actor_fails_its_episodes_and_a_new_one_takes_its_place(monkeypatch):
    """Without Ray installed too: each episode the dead actor held is an error, the others run, a new actor
    replaces the dead one once, and actors dying again and again with nothing finishing stop the sweep."""
    import types

    from pipelines.errors import SweepStopped
    from pipelines.experiments.backends import RayBackend

    tasks = [types.SimpleNamespace(key=k) for k in "abcdef"]  # all a backend reads of a task
    made = _fake_ray(monkeypatch, dies={"b"})
    outcomes = list(RayBackend(1, "none", address=None).run(tasks))
    assert sorted(o.key for o in outcomes) == list("abcdef")
    # "a" finished before "b" killed the actor; "c", queued behind "b" on it, is lost with it
    assert sorted(o.key for o in outcomes if o.error) == ["b", "c"]
    assert "Ray actor died while this episode was on it (The actor died unexpectedly" in next(
        o.error for o in outcomes if o.error
    )
    assert made == [0, 1]
    _fake_ray(monkeypatch, dies=set("abcdef"))
    with pytest.raises(SweepStopped, match="the Ray actors died 3 times in a row"):
        list(RayBackend(1, "none", address=None).run(tasks))


def test_a_ray_worker_running_other_code_is_refused(monkeypatch, capsys):
    """A cluster node with another checkout, other libraries or another plugin file ran its episodes into the
    driver's table, which sweep.json names by the driver's code alone: the backend now asks every actor for
    its code as it starts (a replacement too) and refuses, naming the node and what differs."""
    import types

    from pipelines.experiments.backends import RayBackend
    from pipelines.plugins import code_with_plugins

    other = {**code_with_plugins(), "commit": "0123456789abcdef", "numpy": "1.0.0"}
    made = _fake_ray(monkeypatch, dies=set(), code=other)
    with pytest.raises(
        PipelineError, match=r"^a Ray worker on node-7 does not run this driver's code \(commit "
    ):
        RayBackend(2, "none", address=None)
    assert sys.modules["ray"].killed == made == [0, 1]  # type: ignore[attr-defined]
    with pytest.raises(PipelineError) as refused:
        RayBackend(1, "none", address=None)
    assert "numpy " in str(refused.value) and "-> 1.0.0" in str(refused.value)
    assert str(refused.value).endswith(
        "install the same crowdmpc commit, libraries and plugins on every node"
    )
    # a plugin only the actor loaded (its variables list it; the driver never ran it) is no code of the run,
    # one the driver registered and the actor lacks is
    _fake_ray(monkeypatch, dies=set(), code={**code_with_plugins(), "plugins": {"x:Y": "a" * 64}})
    RayBackend(1, "none", address=None)
    from pipelines.plugins import register

    register("tests.plugins.toy_controller:StraightLine")
    _fake_ray(monkeypatch, dies=set(), code={k: v for k, v in code_with_plugins().items() if k != "plugins"})
    with pytest.raises(
        PipelineError, match=r"\(plugin tests.plugins.toy_controller:StraightLine [0-9a-f]{12} -> "
    ):
        RayBackend(1, "none", address=None)
    # a node installed from the wheel names no commit: compared by the rest, said once a node
    wheel = {**code_with_plugins(), "commit": None, "dirty": None, "diff_sha256": None}
    _fake_ray(monkeypatch, dies=set(), code=wheel)
    capsys.readouterr()
    RayBackend(2, "none", address=None)
    assert capsys.readouterr().err.count("note: the Ray worker on node-7 or the driver names no commit") == 1
    _fake_ray(monkeypatch, dies=set(), code={**wheel, "numpy": "1.0.0"})
    with pytest.raises(PipelineError, match=r"\(numpy .* -> 1.0.0; the driver's -> the worker's\)"):
        RayBackend(1, "none", address=None)
    _fake_ray(monkeypatch, dies={"b"})  # the driver's code: runs, and the replacement is asked too
    tasks = [types.SimpleNamespace(key=k) for k in "abc"]
    assert sorted(o.key for o in RayBackend(1, "none", address=None).run(tasks)) == list("abc")


def test_a_sweep_whose_every_episode_kills_its_worker_stops(tmp_path, plugins, capsys, monkeypatch):
    """Fresh, the first episodes all failing stop it (fail fast); short of fail fast's 4 episodes, the pool
    breaking again and again with nothing finishing does, and the report of what is there is written."""
    (dies,) = plugins("Dies")
    fresh = _sweep_cli(tmp_path / "fresh", [dies], "--episodes-per-cell", "4", "--workers", "2")
    assert main([*fresh, "--backend", "process"]) == 2  # one break: the 4 episodes in flight
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("crowdmpc sweep: error: the first 4 episodes all raised (worker process died")
    out = tmp_path / "resumed"
    assert main(_sweep_cli(out, ["straight"], "--episodes-per-cell", "3", "--backend", "inline")) == 0
    (out / "table.md").unlink()
    monkeypatch.setattr("pipelines.experiments.process_backend.MAX_BREAKS_IN_A_ROW", 2)
    resumed = _sweep_cli(out, ["straight", dies], "--episodes-per-cell", "3", "--workers", "1")
    assert main([*resumed, "--backend", "process"]) == 2  # only the 3 new episodes, each killing its worker
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("crowdmpc sweep: error: the worker processes died 2 times in a row with no ")
    assert len((out / ERRORS_FILE).read_text().splitlines()) == 3  # the two tasks in flight, then the last
    assert "| straight |" in (out / "table.md").read_text()


def test_a_rerun_runs_new_episodes_before_retrying_those_that_raised(tmp_path, plugins, capsys):
    """Extending a sweep with 4 episodes that raise every time (retried first) stopped it before any new
    episode ran ("the first 4 episodes all raised"), and wrote no report: old failures run after the new
    episodes and do not count towards fail fast."""
    (raises,) = plugins("RaisesOnCircles")
    first = run_sweep(_controllers(tmp_path, 8, [raises]))
    assert (first.ran, len(first.errors)) == (4, 4)  # the perpendicular crossings, the circles
    more = run_sweep(_controllers(tmp_path, 10, [raises]))
    assert (more.ran, len(more.errors)) == (1, 5)  # the new perpendicular one ran, the new circle raised
    assert more.errors[0].endswith("/circle/4")  # the new episodes first
    assert main([*_sweep_cli(tmp_path, [raises], "--episodes-per-cell", "12", "--backend", "inline")]) == 1
    assert "| Episodes | 6 |" in (tmp_path / "table.md").read_text()


def test_a_broken_method_added_to_a_sweep_still_stops_early(tmp_path, plugins):
    """Fail fast counts this run's new episodes: a method that raises every time, added to a folder that holds
    records, stopped after 4 episodes before the last fix and ran every planned one after it."""
    (broken,) = plugins("AlwaysRaises")
    run_sweep(_controllers(tmp_path, 2, ["straight"]))
    with pytest.raises(
        PipelineError, match=r"first 4 episodes all raised \(.*reset\(\) raised RuntimeError: broken build\)"
    ):
        run_sweep(_controllers(tmp_path, 50, [broken]))
    assert len((tmp_path / ERRORS_FILE).read_text().splitlines()) == 4


def test_a_record_that_is_no_json_is_an_episode_error_naming_the_controller(tmp_path, plugins):
    """A plugin's describe() holding a set stopped the driver at the write (json.dumps), with a traceback
    and the rest of the sweep lost."""
    (bad,) = plugins("SetInDescribe")
    outcome = run_sweep(_controllers(tmp_path, 2, ["straight", bad]))
    assert outcome.ran == 2 and len(outcome.errors) == 2
    error = json.loads((tmp_path / ERRORS_FILE).read_text().splitlines()[0])["error"]
    assert "PipelineError: controller 'set_in_describe' (SetInDescribe): describe() must return JSON" in error
    assert "Object of type set is not JSON serializable" in error
    with pytest.raises(PipelineError, match=r"cannot write the record of 'k' as JSON \(Object of type set"):
        EpisodeLog(tmp_path / "log.jsonl").append({"key": "k", "modes": {"a"}})


@pytest.mark.slow
def test_the_ray_backend_runs_the_same_sweep(tmp_path):
    pytest.importorskip("ray")  # the [cluster] extra
    outcome = run_sweep(_config(tmp_path, 3, backend="ray", workers=2))
    assert (outcome.backend, outcome.ran, outcome.complete) == ("ray", 6, True)
    inline = tmp_path / "inline"
    run_sweep(_config(inline, 3))
    ray_records = EpisodeLog(tmp_path / EPISODES_FILE).load()
    inline_records = EpisodeLog(inline / EPISODES_FILE).load()
    assert {k: r["metrics"] for k, r in ray_records.items()} == {
        k: r["metrics"] for k, r in inline_records.items()
    }


# ----------------------------------------------------------------------------------------------------------
# Killed for real: a sweep process killed twice by SIGKILL, a torn line, then run to the end
# ----------------------------------------------------------------------------------------------------------

EPISODES_PER_CELL = 60  # x 2 cells: ~0.05 s each at 9 humans, so a run lasts long enough to be killed


def _sweep_command(out: Path) -> list[str]:
    return [
        sys.executable,
        "-m",
        "pipelines.cli",
        "sweep",
        "--experiment",
        "baselines",
        "--humans",
        "9",
        "--episodes-per-cell",
        str(EPISODES_PER_CELL),
        "--workers",
        "2",
        "--backend",
        "process",
        "--no-progress",
        "--out",
        str(out),
    ]


def _lines(path: Path) -> int:
    return path.read_bytes().count(b"\n") if path.exists() else 0


def _group_alive(pgid: int) -> bool:
    """Whether a live (not zombie) process of the group remains; zombies wait for a reaper, not for us."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        with contextlib.suppress(OSError):
            fields = stat.read_text().rsplit(")", 1)[1].split()  # after "pid (comm)": state, ppid, pgrp, ...
            if int(fields[2]) == pgid and fields[0] != "Z":
                return True
    return False


def _start_and_kill(out: Path, at_least: int) -> int:
    """Start a sweep, SIGKILL its driver once ``at_least`` records exist; the number recorded at the kill."""
    log = out / EPISODES_FILE
    proc = subprocess.Popen(
        _sweep_command(out),
        cwd=REPO,
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 120
        while _lines(log) < at_least:
            if proc.poll() is not None:
                pytest.fail(
                    f"the sweep ended before it could be killed: {proc.stderr.read().decode()[-2000:]}"
                )
            assert time.monotonic() < deadline, "the sweep made no progress"
            time.sleep(0.01)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        recorded = _lines(log)
        # The pool workers notice that their driver is gone and exit on their own (no orphans left running).
        deadline = time.monotonic() + 30
        while _group_alive(proc.pid):
            assert time.monotonic() < deadline, "pool workers outlived their killed driver"
            time.sleep(0.05)
        return recorded
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.stderr.close()


def test_killed_twice_then_rerun_gives_every_episode_once(tmp_path):
    planned = 2 * EPISODES_PER_CELL
    first = _start_and_kill(tmp_path, at_least=10)
    second = _start_and_kill(tmp_path, at_least=first + 20)
    assert first < second < planned
    with open(tmp_path / EPISODES_FILE, "ab") as f:
        f.write(b'{"key": "straight-none-F-ibr-h9-r3/circle/5')  # and a write torn by a third kill
    done = subprocess.run(_sweep_command(tmp_path), cwd=REPO, capture_output=True, timeout=300)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    lines = (tmp_path / EPISODES_FILE).read_bytes().splitlines()
    keys = [json.loads(line)["key"] for line in lines]
    assert len(keys) == planned and len(set(keys)) == planned
    tasks = get_experiment("baselines").tasks(EPISODES_PER_CELL, humans=(9,))
    assert set(keys) == {t.key for t in tasks}
    assert f"{planned}/{planned} episodes recorded ({planned - second} this run" in done.stderr.decode()


# ----------------------------------------------------------------------------------------------------------
# The report
# ----------------------------------------------------------------------------------------------------------


def _records(
    experiment,
    outcomes: dict[tuple[str, int], list[tuple[bool, float, bool, bool]]],
    n_robots: int = 3,
    humans: tuple[int, ...] | None = None,
):
    """Synthetic records: (method, humans) -> per episode (success, travel time, collision, discomfort)."""
    records = []
    for cell in experiment.cells(humans, n_robots=n_robots):
        for i, (success, time_s, collision, discomfort) in enumerate(
            outcomes.get((cell.method, cell.n_humans), [])
        ):
            records.append(
                {
                    "key": f"{cell.key}/{i}",
                    "cell": cell.key,
                    "method": cell.method,
                    "n_humans": cell.n_humans,
                    "scenario": ("circle", "perpendicular")[i % 2],
                    "seed": i // 2,
                    "metrics": {
                        "success": success,
                        "travel_time": time_s if success else None,
                        "collision": collision,
                        "contact": False,
                        "discomfort": discomfort,
                        "min_distance": 1.0,
                        "n_steps": 50,
                    },
                    "solver": {
                        "steps": 50,
                        "total_ms": 500.0,
                        "median_ms": 10.0,
                        "p95_ms": 20.0,
                        "max_ms": 30.0,
                        "mean_iterations": 2.0,
                        "max_iterations": 3,
                        "fallback_steps": 1,
                        "statuses": {"ok": 50},
                    },
                    "wall_s": 1.0,
                }
            )
    return records


TABLE2_EPISODES = {
    ("CMPC", 5): [
        (True, 18.0, False, False),
        (True, 20.0, True, False),
        (True, 19.0, False, True),
        (False, 0, False, False),
    ],
    ("DMPC", 5): [
        (True, 21.0, False, False),
        (False, 0, False, False),
        (False, 0, True, True),
        (False, 0, False, False),
    ],
    ("CMPC", 6): [(True, 18.0, False, False)] * 4,
    ("DMPC", 6): [(True, 18.0, False, False)] * 4,
}


def test_markdown_table_is_laid_out_like_the_paper():
    table2 = get_experiment("table2")
    summaries = summarize(table2, table2.cells(), _records(table2, TABLE2_EPISODES))
    lines = markdown_table(table2, summaries).splitlines()
    assert lines[0] == "## Table II: centralized (CMPC) vs distributed (DMPC) MPC"
    table = lines[lines.index("| Metrics \\ Methods | CMPC | DMPC | CMPC | DMPC |") :]
    assert table[1] == "|---|---|---|---|---|"
    assert table[2] == "| Numbers of pedestrians | 5 | 5 | 6 | 6 |"
    # 3/4 -> 75.0 [30.1, 95.4]; 1/4 -> 25.0 [4.6, 69.9]; 4/4 -> 100.0 [51.0, 100.0]: ties are left unmarked.
    assert table[3] == (
        "| Success rate (%) | **75.0 [30.1, 95.4]** | 25.0 [4.6, 69.9] "
        "| 100.0 [51.0, 100.0] | 100.0 [51.0, 100.0] |"
    )
    assert table[4] == "| &nbsp;&nbsp;paper | **94.0** | 93.4 | **91.9** | 91.8 |"
    # Mean of 18, 20, 19 = 19.0; sample sd 1.0 -> t95(2) / sqrt(3) = 4.303 / 1.732 = 2.5. One success: no
    # interval.
    assert (
        table[5]
        == "| Average travel time (s) | **19.0 ± 2.5** | 21.0 (1 success) | 18.0 ± 0.0 | 18.0 ± 0.0 |"
    )
    assert table[6] == "| &nbsp;&nbsp;paper | **17.9** | 18.1 | **18.6** | 18.7 |"
    # Collision and discomfort tie in both groups (1/4 and 0/4): unmarked. The paper's differ, and the lower
    # is the better: 0.2 < 0.3 and 0.6 < 0.8; 0.5 < 0.6 and 1.2 < 1.5 (test_fewer_collisions_... below has
    # our own rates differ).
    assert table[7] == (
        "| Collision rate (%) | 25.0 [4.6, 69.9] | 25.0 [4.6, 69.9] | 0.0 [0.0, 49.0] | 0.0 [0.0, 49.0] |"
    )
    assert table[8] == "| &nbsp;&nbsp;paper | **0.2** | 0.3 | 0.8 | **0.6** |"
    assert table[9] == (
        "| Discomfort rate (%) | 25.0 [4.6, 69.9] | 25.0 [4.6, 69.9] | 0.0 [0.0, 49.0] | 0.0 [0.0, 49.0] |"
    )
    assert table[10] == "| &nbsp;&nbsp;paper | **0.5** | 0.6 | **1.2** | 1.5 |"
    assert "| Episodes | 4 | 4 | 4 | 4 |" in table
    # DMPC at 5 failed on crowds 1 and 2 where CMPC succeeded, and won none: 2 * (1/2)^2 = 0.5.
    assert (
        "| Success, paired with the group's first method | reference | +0 / −2 (p = 0.5) | reference |"
        in "\n".join(table)
    )
    assert (
        "| Success circle / perpendicular (%) | 100.0 / 50.0 | 50.0 / 0.0 | 100.0 / 100.0 | 100.0 / 100.0 |"
        in table
    )


def test_fewer_collisions_and_discomforts_are_the_better_method():
    """Collision and discomfort rates are to be kept low: bold on the method with fewer.
    CMPC 0 of 4 -> 0.0 [0.0, 49.0]; DMPC 2 of 4 -> 50.0 [15.0, 85.0] (Wilson: centre (0.5 + 1.96^2 / 8) /
    (1 + 1.96^2 / 4) = 0.5, half width 1.96 sqrt(1/16 + 1.96^2 / 64) / 1.9604 = 0.35)."""
    table2 = get_experiment("table2")
    episodes = {
        ("CMPC", 5): [(True, 18.0, False, False)] * 4,
        ("DMPC", 5): [(True, 18.0, True, True)] * 2 + [(True, 18.0, False, False)] * 2,
    }
    lines = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes))).splitlines()
    assert "| Collision rate (%) | **0.0 [0.0, 49.0]** | 50.0 [15.0, 85.0] |" in lines
    assert "| Discomfort rate (%) | **0.0 [0.0, 49.0]** | 50.0 [15.0, 85.0] |" in lines


def test_success_per_scenario_below_100_percent_never_reads_100():
    """200 circle crowds, 199 successes: 99.5 %, which the row printed without decimals as "100", the figure
    of a scenario without a failure (at the paper's 500 circle episodes, 2 failures read "100" too). One
    decimal, as every other rate of the table: 99.5 / 100.0."""
    table2 = get_experiment("table2")
    won, lost = (True, 18.0, False, False), (False, 0, False, False)
    episodes = {("CMPC", 5): [lost] + [won] * 399}  # episode 0 is circle crowd 0
    table = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes)))
    assert "| Success circle / perpendicular (%) | 99.5 / 100.0 |" in table


def test_success_is_paired_only_with_a_column_of_the_same_profile():
    """The conventions experiment's paper profile draws other crowds from a seed than v1 (its spawn separation
    and crossing band: seed 1, 7 humans, circle), so "paper/visible/none" is no pair of "v1/visible/none"
    (the group's first column): each profile has its own reference, and visibility and margins, which do
    not change the crowds, are paired within it. Hand-made outcomes, 4 crowds each: v1/visible/none and
    paper/visible/cp0.1 succeed on all, paper/visible/none fails crowds 0 and 1. Paired with v1/visible/none,
    paper/visible/none read "+0 / −2 (p = 0.5)" and paper/visible/cp0.1 "+0 / −0 (p = 1)"; with
    paper/visible/none, the latter is "+2 / −0 (p = 0.5)"."""
    from crowdsim.scenarios import make_layout

    paper, v1 = (
        make_layout("circle", 7, 3, np.random.default_rng(1), crossing=crossing).human_starts
        for crossing in ("paper", "v1")
    )
    assert not np.allclose(paper, v1)
    conventions = get_experiment("conventions")
    won, lost = (True, 18.0, False, False), (False, 0, False, False)
    episodes = {(label, 7): [won] * 4 for label in conventions.method_labels}
    episodes["paper/visible/none", 7] = [lost, lost, won, won]
    records = _records(conventions, episodes)
    lines = markdown_table(conventions, summarize(conventions, conventions.cells(), records)).splitlines()
    header = next(line for line in lines if line.startswith("| Metrics"))
    assert header.startswith("| Metrics \\ Methods | v1/visible/none | v1/visible/cp0.1 | v1/invisible/")
    paired = next(line for line in lines if line.startswith("| Success, paired"))
    assert paired.split(" | ")[1:] == [
        "reference",
        "+0 / −0 (p = 1)",
        "+0 / −0 (p = 1)",
        "+0 / −0 (p = 1)",
        "reference",
        "+2 / −0 (p = 0.5)",
        "+2 / −0 (p = 0.5)",
        "+2 / −0 (p = 0.5) |",
    ]


def test_paired_success_counts_only_the_crowds_both_methods_ran():
    """CMPC succeeded on 4 crowds, DMPC has run 2 of them so far and succeeded on both: no crowd was lost,
    (0, 0, p = 1); the 2 crowds DMPC has not run are no failures of it."""
    table2 = get_experiment("table2")
    episodes = {("CMPC", 5): [(True, 18.0, False, False)] * 4, ("DMPC", 5): [(True, 18.0, False, False)] * 2}
    reference, other = summarize(table2, table2.cells(), _records(table2, episodes))
    assert (reference.cell.method, other.cell.method) == ("CMPC", "DMPC")
    assert paired_success(reference, other) == (0, 0, 1.0)
    table = markdown_table(table2, [reference, other])
    assert "| Success, paired with the group's first method | reference | +0 / −0 (p = 1) |" in table


def test_crowd_sizes_with_and_without_the_papers_figures_share_one_table():
    """Table II at 4 and 5 humans: the paper has a column at 5 only. Its rows stay, "—" under the 4-human
    columns, and the note says what the 'paper' rows are; one predictor is "predictor", not "predictors"."""
    table2 = get_experiment("table2")
    cells = table2.cells(humans=(4, 5))
    outcomes = {(m, n): [(True, 18.0, False, False)] * 2 for m in ("CMPC", "DMPC") for n in (4, 5)}
    markdown = markdown_table(table2, summarize(table2, cells, _records(table2, outcomes, humans=(4, 5))))
    lines = markdown.splitlines()
    assert "| Numbers of pedestrians | 4 | 4 | 5 | 5 |" in lines
    assert "| &nbsp;&nbsp;paper | — | — | **94.0** | 93.4 |" in lines  # success
    assert "| &nbsp;&nbsp;paper | — | — | **17.9** | 18.1 |" in lines  # travel time
    assert "Paper ('paper' rows): 1000 episodes per cell (500 + 500)," in markdown
    assert "have no column at these crowd sizes" not in markdown
    assert "; predictor social_lstm_eth. Rates" in markdown


def test_a_method_alone_at_its_crowd_size_has_no_reference_to_pair_with():
    """Only CMPC has episodes: no group of two, "—" in the paired row (not "reference")."""
    table2 = get_experiment("table2")
    episodes = {("CMPC", 5): [(True, 18.0, False, False)] * 2}
    table = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes)))
    assert "| Success, paired with the group's first method | — |" in table


def test_the_paired_p_value_has_two_significant_digits():
    """CMPC failed once where DMPC succeeded (crowd 4) and succeeded where DMPC failed four times: b = 1,
    c = 4, p = 2 (C(5, 0) + C(5, 1)) / 2^5 = 12 / 32 = 0.375, printed 0.38."""
    table2 = get_experiment("table2")
    episodes = {
        ("CMPC", 5): [(True, 18.0, False, False)] * 4 + [(False, 0, False, False)],
        ("DMPC", 5): [(False, 0, False, False)] * 4 + [(True, 18.0, False, False)],
    }
    table = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes)))
    assert "| Success, paired with the group's first method | reference | +1 / −4 (p = 0.38) |" in table


def test_the_contact_row_counts_contacts_not_collisions():
    """Both episodes are collisions (< 0.8 m) without contact (< 0.6 m): 2/2 -> 100.0 [34.2, 100.0] in the
    collision row, 0/2 -> 0.0 [0.0, 65.8] in the contact row (Wilson: 1.96^2 / (2 + 1.96^2) = 0.658)."""
    table2 = get_experiment("table2")
    episodes = {("CMPC", 5): [(True, 18.0, True, False)] * 2}
    lines = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes))).splitlines()
    assert "| Collision rate (%) | 100.0 [34.2, 100.0] |" in lines
    assert "| Contact rate (%) (< 0.6 m) | 0.0 [0.0, 65.8] |" in lines


def test_the_note_names_a_method_without_a_predictor_none():
    """The baselines plan with no predictor: the note says "predictor none", not an empty name."""
    baselines = get_experiment("baselines")
    episodes = {(m, 5): [(True, 18.0, False, False)] * 2 for m in ("straight", "ORCA")}
    markdown = markdown_table(
        baselines, summarize(baselines, baselines.cells(), _records(baselines, episodes))
    )
    assert "; predictor none. Rates" in markdown


def test_the_note_gives_the_range_of_episodes_per_cell():
    """Cells of 4 and 3 episodes: "3–4" (an en dash), not the largest count alone."""
    table2 = get_experiment("table2")
    episodes = {("CMPC", 5): [(True, 18.0, False, False)] * 4, ("DMPC", 5): [(True, 18.0, False, False)] * 3}
    markdown = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes)))
    assert (
        "\nOurs: 3\u20134 episodes per cell, circle and perpendicular crossings in turn, the circle first,"
        in (markdown)
    )


def test_the_papers_figures_stand_beside_its_own_team_size_only(tmp_path):
    """With --robots 2 Table II printed the paper's 3-robot figures under each column, in bold, as if
    comparable (they are looked up by method and humans)."""
    table2 = get_experiment("table2")
    cells = table2.cells(n_robots=2)
    records = _records(table2, TABLE2_EPISODES, n_robots=2)
    summaries = summarize(table2, cells, records)
    assert summaries and not any(s.paper for s in summaries)
    markdown = markdown_table(table2, summaries)
    assert "paper |" not in markdown and "Robots: 2 per episode (the paper's tables: 3)." in markdown
    assert "Table II) are for 3 robots: not shown beside these." in markdown
    write_report(tmp_path, table2, cells, records)
    assert "paper_success" in (tmp_path / CELLS_CSV).read_text().splitlines()[0]
    assert (tmp_path / CELLS_CSV).read_text().splitlines()[1].endswith(",,,,")  # no paper figures
    # the paper's own team: its figures, and no word on robots
    three = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, TABLE2_EPISODES)))
    assert "| &nbsp;&nbsp;paper | **94.0** |" in three and "Robots:" not in three
    # the paper's team at crowd sizes it has no column for: that is the reason, not the robots
    two = table2.cells(humans=(2,))
    outcomes = {(c.method, 2): [(True, 15.0, False, False)] for c in two}
    small = markdown_table(table2, summarize(table2, two, _records(table2, outcomes, humans=(2,))))
    assert "have no column at these crowd sizes" in small and "are for 3 robots" not in small


def test_episode_rows_are_made_as_they_are_written(tmp_path):
    """A list of every row beside the records was 85 MB more at 100,000 episodes; the file is the same."""
    import collections.abc

    from pipelines.experiments.report import episode_rows, write_csv

    table2 = get_experiment("table2")
    records = _records(table2, TABLE2_EPISODES)
    rows = episode_rows(records, table2.cells())
    assert isinstance(rows, collections.abc.Iterator)
    write_csv(tmp_path / "made.csv", rows)
    write_csv(tmp_path / "listed.csv", list(episode_rows(records, table2.cells())))
    text = (tmp_path / "made.csv").read_text()
    assert text == (tmp_path / "listed.csv").read_text() and len(text.splitlines()) == 1 + len(records)
    write_csv(tmp_path / "none.csv", iter([]))
    assert (tmp_path / "none.csv").read_text() == ""


def test_report_files(tmp_path):
    table2 = get_experiment("table2")
    report = write_report(tmp_path, table2, table2.cells(), _records(table2, TABLE2_EPISODES))
    assert {p.name for p in report.files} == {
        "cells.csv",
        "episodes.csv",
        "table.md",
        "success_vs_humans.png",
        "travel_time_vs_humans.png",
        "collision_vs_humans.png",
        "contact_vs_humans.png",
        "discomfort_vs_humans.png",
        "control_step_vs_humans.png",
        "min_distance_hist.csv",
        "min_distance_hist.png",
        "safety_tradeoff.png",
    }
    rows = (tmp_path / CELLS_CSV).read_text().splitlines()
    header = rows[0].split(",")
    first = dict(zip(header, rows[1].split(","), strict=True))
    assert len(rows) == 1 + 4  # cells with records only
    assert (first["method"], first["n_humans"], first["success_count"], first["paper_success"]) == (
        "CMPC",
        "5",
        "3",
        "94.0",
    )
    assert float(first["success_ci_lo"]) == pytest.approx(30.064, abs=1e-3)
    assert (tmp_path / "success_vs_humans.png").read_bytes().startswith(b"\x89PNG")


def test_a_travel_time_plot_says_when_a_method_has_no_success_or_no_error_bar():
    """Every episode failed: the legend named both methods as drawn, and the title promised Student's t error
    bars, over an empty plot; one success a cell: the title promised the bars none of its cells has."""
    from pipelines.experiments.report_plots import OUTCOMES, outcome_figure

    table2 = get_experiment("table2")
    travel = next(o for o in OUTCOMES if o.name == "travel_time")

    def figure(outcomes):
        summaries = summarize(table2, table2.cells(), _records(table2, outcomes))
        fig = outcome_figure(table2, summaries, travel)
        ax = fig.axes[0]
        return [t.get_text() for t in fig.legends[0].get_texts()], ax.get_title()

    failed = {(m, h): [(False, 0.0, False, False)] * 2 for m in ("CMPC", "DMPC") for h in (5, 6)}
    labels, title = figure(failed)
    assert "CMPC (ours, no success)" in labels and "DMPC (ours, no success)" in labels
    assert title.endswith("no error bars: fewer than two successes")
    once = {(m, h): [(True, 20.0, False, False), (False, 0.0, False, False)] for m, h in failed}
    labels, title = figure(once)
    assert "CMPC (ours)" in labels and title.endswith("no error bars: fewer than two successes")
    labels, title = figure(TABLE2_EPISODES)
    assert title.endswith("error bars: our 95% Student's t interval of the mean")


def test_a_report_at_one_crowd_size_leaves_no_plot_of_the_earlier_ones(tmp_path):
    """`--report-only --humans 5` after a sweep at 5 and 6 humans wrote *_by_method.png and a table of 5,
    and left the five *_vs_humans.png of 5 and 6 beside them."""
    table2 = get_experiment("table2")
    records = _records(table2, TABLE2_EPISODES)
    write_report(tmp_path, table2, table2.cells(), records)
    cells = [cell for cell in table2.cells() if cell.n_humans == 5]
    report = write_report(
        tmp_path, table2, cells, [r for r in records if r["cell"] in {c.key for c in cells}]
    )
    pngs = sorted(p.name for p in tmp_path.glob("*.png"))
    assert pngs == sorted(p.name for p in report.files if p.suffix == ".png")
    assert "success_by_method.png" in pngs and "success_vs_humans.png" not in pngs


# ----------------------------------------------------------------------------------------------------------
# The command line
# ----------------------------------------------------------------------------------------------------------


def test_cli_dry_run_lists_the_cells(tmp_path, capsys):
    assert (
        main(
            [
                "sweep",
                "--experiment",
                "table3",
                "--episodes-per-cell",
                "10",
                "--dry-run",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert (
        "10 cells x 10 episodes = 100" in out
        and "cmpc-social_lstm_eth-NF-ibr-m=none-paper-visible-h9-r3" in out
    )


def test_cli_user_errors_are_one_line(tmp_path, capsys):
    args = ["sweep", "--experiment", "baselines", "--out", str(tmp_path)]
    assert main([*args, "--episodes-per-cell", "0"]) == 2
    assert "--episodes-per-cell must be at least 1" in capsys.readouterr().err
    assert main([*args, "--predictor", "constant_velocity"]) == 2
    assert "fixes each method's predictor" in capsys.readouterr().err
    assert main(["sweep", "--experiment", "table2", "--predictor", "nope", "--out", str(tmp_path)]) == 2
    assert "needs predictors ['nope']" in capsys.readouterr().err
    assert main([*args, "--report-only"]) == 2


def test_cli_runs_a_small_sweep_and_reports(tmp_path, capsys):
    args = ["sweep", "--experiment", "baselines", "--humans", "5,6", "--episodes-per-cell", "2"]
    assert main([*args, "--backend", "inline", "--no-progress", "--out", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    assert "8/8 episodes recorded" in captured.err
    # a projection of seconds reads in seconds, not "0.00 CPU-hours"
    # inline runs one episode at a time, whatever --workers says
    assert re.search(
        r"the 8 planned episodes take (\d+\.\d) s of CPU: \1 s for 1 worker on 1 free core\n", captured.err
    )
    assert "| Numbers of pedestrians | 5 | 5 | 6 | 6 |" in captured.out
    # ORCA and the straight line run no solver: their solver figures are not applicable, not 0.00
    assert "| IBR iterations per step (mean) | n/a | n/a | n/a | n/a |" in captured.out
    assert "| Fallback steps (%) | n/a | n/a | n/a | n/a |" in captured.out
    assert (tmp_path / "table.md").exists()


def test_a_resumed_sweep_scans_its_log_once_and_reports_as_its_log_reads(tmp_path, monkeypatch, capsys):
    """A resume scanned episodes.jsonl to find what it holds, and its report scanned it again after the run
    (JSON and checks of every record twice). The report now takes what the resume read and the run appended:
    one scan, and the same files as a report of the log read afresh (--report-only)."""
    args = ["sweep", "--experiment", "baselines", "--humans", "5", "--backend", "inline", "--no-progress"]
    args += ["--out", str(tmp_path)]
    assert main([*args, "--episodes-per-cell", "1"]) == 0
    scans, scan = [], EpisodeLog.scan

    def counted(log, repair=True):
        scans.append(log.path.name)
        yield from scan(log, repair)

    monkeypatch.setattr(EpisodeLog, "scan", counted)
    assert main([*args, "--episodes-per-cell", "3"]) == 0
    assert scans == [EPISODES_FILE]
    written = {name: (tmp_path / name).read_bytes() for name in ("cells.csv", "episodes.csv", "table.md")}
    assert written["episodes.csv"].count(b"\n") == 1 + 2 * 3
    capsys.readouterr()
    assert main([*args, "--episodes-per-cell", "3", "--report-only"]) == 0
    assert {name: (tmp_path / name).read_bytes() for name in written} == written


def test_controller_spec_of_cells_is_validated():
    with pytest.raises(PipelineError):
        ControllerSpec("nope")


def test_jit_is_a_worker_setting_that_leaves_the_cell_alone():
    spec = ControllerSpec("cmpc", "constant_velocity")
    assert make_controller(spec, jit=True).cfg.jit is True
    assert make_controller(spec).cfg.jit is False
    assert make_controller(dataclasses.replace(spec, coupling="nlp"), jit=True).cfg.jit is False
    # the baselines solve no NLP: nothing to compile, and nothing breaks
    assert make_controller(ControllerSpec("orca"), jit=True) is not None
    cell = get_experiment("table2").with_predictor("constant_velocity").cells((5,))[0]
    assert "jit" not in cell.key


def test_ray_workers_get_the_drivers_crowdmpc_environment(monkeypatch):
    """Actors on a cluster node start from that node's environment: the driver's plugins and zoo must travel
    in the runtime_env, with the single-thread settings."""
    from pipelines.experiments.backends import worker_environment
    from pipelines.experiments.worker import SINGLE_THREAD_ENV
    from pipelines.loop import spec as controllers
    from predictors import models

    monkeypatch.setattr(models, "_PLUGINS", {})  # none registered by an earlier test
    monkeypatch.setattr(controllers, "_PLUGINS", {})
    monkeypatch.delenv(controllers.PLUGINS_ENV, raising=False)
    monkeypatch.setenv("CROWDMPC_PLUGINS", "my_pkg.nets:MyNet")
    monkeypatch.setenv("CROWDMPC_ZOO", "/shared/zoo")
    monkeypatch.setenv("UNRELATED_VARIABLE", "x")
    env = worker_environment()
    assert env["CROWDMPC_PLUGINS"] == "my_pkg.nets:MyNet" and env["CROWDMPC_ZOO"] == "/shared/zoo"
    assert "UNRELATED_VARIABLE" not in env and controllers.PLUGINS_ENV not in env
    assert all(env[k] == v for k, v in SINGLE_THREAD_ENV.items())
    # one registered from Python (load_controller_plugin lists it nowhere) travels as well
    controllers.load_controller_plugin("tests.plugins.toy_controller:StraightLine")
    assert worker_environment()[controllers.PLUGINS_ENV] == "tests.plugins.toy_controller:StraightLine"


def test_the_ray_backend_starts_ray_with_that_environment(monkeypatch):
    import socket
    import types

    from pipelines.experiments.backends import RayBackend, worker_environment
    from pipelines.plugins import code_with_plugins

    calls: list[dict] = []
    fake = types.ModuleType("ray")
    fake.is_initialized = lambda: False  # type: ignore[attr-defined]
    fake.init = lambda **kwargs: calls.append(kwargs)  # type: ignore[attr-defined]
    actor = types.SimpleNamespace(code=types.SimpleNamespace(remote=lambda: "ref"))
    fake.remote = lambda **_: lambda cls: types.SimpleNamespace(remote=lambda *a: actor)  # type: ignore[attr-defined]
    fake.get = lambda ref: ("node", code_with_plugins())  # type: ignore[attr-defined]
    fake.wait = lambda refs, num_returns, timeout=None: (refs[:1], refs[1:])  # type: ignore[attr-defined]
    fake.exceptions = types.SimpleNamespace(RayActorError=RuntimeError)  # type: ignore[attr-defined]
    fake.available_resources = lambda: {"CPU": 2.0}  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", fake)
    monkeypatch.setenv("CROWDMPC_CONTROLLERS", "my_pkg.ctl:MyController")
    # the plugins earlier tests registered in this process travel too (plugin_environment): none here
    from pipelines.loop import spec as controllers

    kept = {name: p for name, p in controllers._PLUGINS.items() if p.source != "plugin"}
    monkeypatch.setattr(controllers, "_PLUGINS", kept)
    with socket.create_server(("127.0.0.1", 0)) as head:  # the join tries the address's port first
        address = f"ray://127.0.0.1:{head.getsockname()[1]}"
        RayBackend(2, "none", address=address)
    assert calls == [
        {
            "address": address,
            "runtime_env": {"env_vars": worker_environment()},
            "log_to_driver": False,
        }
    ]
    assert calls[0]["runtime_env"]["env_vars"]["CROWDMPC_CONTROLLERS"] == "my_pkg.ctl:MyController"


@pytest.mark.parametrize(
    ("failure", "shown"),
    [
        (ConnectionError("Failed to connect to Ray cluster at 10.0.0.9:6379"), "Failed to connect"),
        (ValueError("Invalid address format: head"), "Invalid address format"),
    ],
)
def test_a_ray_address_with_no_cluster_is_one_line_naming_it(monkeypatch, failure, shown):
    """What Ray 2.60 raises for an address with no cluster behind it, and for one it cannot parse (both met
    with the real Ray): the user's input, so a PipelineError naming it rather than Ray's traceback. (A port
    nothing listens at is refused before Ray: tests/pipelines/test_ray_join.py.)"""
    import types

    from pipelines.experiments.backends import RayBackend

    def init(**_):
        raise failure

    fake = types.ModuleType("ray")
    fake.is_initialized = lambda: False  # type: ignore[attr-defined]
    fake.init = init  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", fake)
    with pytest.raises(PipelineError, match=f"--ray-address 'head' .*{shown}.*ray start --head"):
        RayBackend(2, "none", address="head")  # no port: left to Ray


def test_a_tables_title_follows_the_predictors_it_runs():
    """The controllers table says which predictor it ran with, not "the paper's" after --predictor; the
    predictor swap mentions the oracle only when the oracle is one of its columns."""
    controllers = get_experiment("controllers")
    # ORCA and the straight line use no predictor: the title does not say they do
    assert controllers.title.endswith(
        "each controller, those that predict the humans with the paper's predictor"
    )
    assert controllers.with_predictor("my_net_eth").title.endswith(
        "those that predict the humans with my_net_eth"
    )
    conventions = get_experiment("conventions").with_predictor("constant_velocity")
    assert conventions.title.endswith("(CMPC, constant_velocity)")
    swap = get_experiment("predictors")
    assert swap.with_predictors(["constant_velocity", "orca_oracle"]).title == swap.title
    assert swap.with_predictors(["constant_velocity"]).title == "Predictor swap: CMPC with each predictor"


def test_each_run_records_its_code_and_a_resume_by_other_code_says_so(tmp_path, capsys):
    """The version stays 0.1.0 while results change from commit to commit: each run line of sweep.json keeps
    the commit and the libraries' versions, and a resume by other code says its episodes are mixed in."""
    from pipelines.plugins import code_with_plugins

    run_sweep(_config(tmp_path, 1))
    meta = json.loads((tmp_path / "sweep.json").read_text())
    assert meta["runs"][0]["code"] == code_with_plugins() and set(code_with_plugins()) >= {"commit", "casadi"}
    run_sweep(_config(tmp_path, 1))
    assert "note:" not in capsys.readouterr().err  # the same code: nothing to say
    other = {**code_with_plugins(), "commit": "0123456789abcdef", "casadi": "3.6.0"}
    meta = json.loads((tmp_path / "sweep.json").read_text())
    meta["runs"][1]["code"] = other  # the second run recorded no episode: no other code in the folder
    (tmp_path / "sweep.json").write_text(json.dumps(meta))
    run_sweep(_config(tmp_path, 1))
    assert "note:" not in capsys.readouterr().err
    meta["runs"][0]["code"] = other  # the run that made the episodes
    (tmp_path / "sweep.json").write_text(json.dumps(meta))
    run_sweep(_config(tmp_path, 2))
    err = capsys.readouterr().err
    assert f"note: {tmp_path} holds episodes made by other code (commit 0123456789ab -> " in err
    assert f"casadi 3.6.0 -> {code_with_plugins()['casadi']}" in err
    run_sweep(_config(tmp_path, 2))  # the mix stays in the directory: every later resume says so
    assert "note: " in capsys.readouterr().err


def test_each_record_names_the_run_that_made_it(tmp_path):
    """A resume by other code keeps the earlier episodes (above), so each line must say which run of
    sweep.json, and with it which code, made it: before, only the order of the lines hinted at it."""
    run_sweep(_config(tmp_path, 1))
    run_sweep(_config(tmp_path, 1))  # nothing to run: a run line, no record
    run_sweep(_config(tmp_path, 2))
    runs = json.loads((tmp_path / "sweep.json").read_text())["runs"]
    records = EpisodeLog(tmp_path / EPISODES_FILE).load().values()
    assert len(runs) == 3
    made_by = sorted((r["scenario"], r["run"]) for r in records)
    assert made_by == [("circle", 1)] * 2 + [("perpendicular", 3)] * 2  # as config show --run counts them
    assert all(runs[r["run"] - 1]["code"]["commit"] == runs[0]["code"]["commit"] for r in records)


def test_a_resume_of_a_sweep_whose_code_went_unrecorded_says_so(tmp_path, capsys):
    """A run line from before 4a16d16 holds no "code": its episodes were made by code that cannot be told
    apart from this run's, so a resume mixed them in without a word (a sweep of that era, resumed by the
    current code, printed no note); it says the earlier code is unknown."""
    run_sweep(_config(tmp_path, 1))
    meta = json.loads((tmp_path / "sweep.json").read_text())
    del meta["runs"][0]["code"]  # as such a version wrote it
    (tmp_path / "sweep.json").write_text(json.dumps(meta))
    capsys.readouterr()
    run_sweep(_config(tmp_path, 2))
    err = capsys.readouterr().err
    assert f"note: {tmp_path} holds episodes made by other code (code not recorded -> commit " in err


def test_a_sweep_json_moved_away_leaves_its_runs_unknown_not_credited_to_the_next(tmp_path, capsys):
    """The damaged-sweep.json refusal said "move it away to start afresh": a rerun then kept every episode
    and numbered itself run 1, so the old records' "run": 1 named its code (table.md's Code line too)."""
    run_sweep(_config(tmp_path, 1))
    (tmp_path / "sweep.json").rename(tmp_path / "sweep.json.bad")
    capsys.readouterr()
    run_sweep(_config(tmp_path, 2))
    err = capsys.readouterr().err
    assert f"note: {tmp_path / EPISODES_FILE} holds episodes of 1 run(s) sweep.json does not list" in err
    runs = json.loads((tmp_path / "sweep.json").read_text())["runs"]
    assert runs[0] == {"lost": "not listed in sweep.json when run 2 began"} and "code" in runs[1]
    made_by = sorted((r["scenario"], r["run"]) for r in EpisodeLog(tmp_path / EPISODES_FILE).load().values())
    assert made_by == [("circle", 1)] * 2 + [("perpendicular", 2)] * 2
    run_sweep(_config(tmp_path, 2))  # listed now: nothing more to pad, and the lost run named as such
    err = capsys.readouterr().err
    assert "does not list" not in err and "1 run(s) sweep.json lost, code unknown" in err
    assert "code not recorded" not in err  # that is a run from before the code was kept
    assert len(json.loads((tmp_path / "sweep.json").read_text())["runs"]) == 3
    assert main(["config", "show", "--from-sweep", str(tmp_path), "--run", "1"]) == 2
    assert (
        "(run 1) was lost from the file (not listed in sweep.json when run 2 began)"
        in capsys.readouterr().err
    )


def test_lost_runs_are_found_past_records_without_a_run_and_bounded(tmp_path, capsys):
    """A record older than its run number turned the search off (the next run took number 1 again), and a
    damaged record's run of 200000 padded sweep.json with as many lines."""
    from pipelines.experiments.resume_checks import ResumeChecks
    from pipelines.experiments.run_lines import lost_runs

    checks = ResumeChecks(tmp_path, [])
    for run in (None, 3, 2):
        checks.add({"key": "k", "run": run} if run else {"key": "k"})
    assert checks.runs_recorded is None and checks.last_run == 3
    assert (
        lost_runs(tmp_path, 1, checks.last_run) == [{"lost": "not listed in sweep.json when run 4 began"}] * 2
    )
    assert lost_runs(tmp_path, 3, 3) == []
    with pytest.raises(PipelineError, match="a record names run 200000, 199999 past the 1 sweep.json lists"):
        lost_runs(tmp_path, 1, 200_000)


def test_the_note_says_one_episode_per_cell_in_the_singular():
    """A sweep of --episodes-per-cell 1 said "Ours: 1 episodes per cell"."""
    table2 = get_experiment("table2")
    episodes = {("CMPC", 5): [(True, 18.0, False, False)], ("DMPC", 5): [(True, 18.0, False, False)]}
    markdown = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes)))
    assert "\nOurs: 1 episode per cell, the circle crossing, the same seeds" in markdown


@pytest.mark.parametrize(
    ("count", "words"),
    [
        (1, "the circle crossing"),
        (2, "half circle and half perpendicular crossing"),
        (3, "2 circle and 1 perpendicular crossings"),
        (4, "half circle and half perpendicular crossing"),
    ],
)
def test_the_note_says_which_crossings_the_episodes_are(count, words):
    """Episode i of a cell is circle for even i, perpendicular for odd: the note said "half circle and half
    perpendicular crossing" of every count, of one episode (the circle alone) and of three (two circles)."""
    table2 = get_experiment("table2")
    episodes = {(m, 5): [(True, 18.0, False, False)] * count for m in ("CMPC", "DMPC")}
    markdown = markdown_table(table2, summarize(table2, table2.cells(), _records(table2, episodes)))
    assert f" per cell, {words}, the same seeds in every cell;" in markdown


def test_the_help_names_the_experiments_that_refuse_margins_and_conventions(capsys):
    """sweep --help said --margins, --profile and --visibility apply to table2, table3, predictors and
    coupling (and controllers), as if the others refused them: sensing takes all three, safety and baselines
    --profile and --visibility; only baselines, conventions and safety refuse --margins, and conventions
    alone --profile and --visibility. The help names exactly the experiments that refuse each."""
    from pipelines.experiments.tasks import World
    from pipelines.loop.margins import parse_margins

    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    said = re.search(r"; ([\w, ]+) fix their methods' margins and refuse it\. .*?; (\w+) fixes them", text)
    assert said is not None, "sweep --help does not say which experiments refuse --margins and --profile"

    def refuses(change) -> bool:
        try:
            change()
        except PipelineError:
            return True
        return False

    margins = parse_margins("conformal:0.1")
    no_margins = {name for name, e in EXPERIMENTS.items() if refuses(lambda e=e: e.with_margins(margins))}
    fixed = {name for name, e in EXPERIMENTS.items() if refuses(lambda e=e: e.with_world(World("v1")))}
    assert set(re.split(r", | and ", said.group(1))) == no_margins
    assert {said.group(2)} == fixed


@pytest.mark.parametrize(
    ("lost_first", "local"),
    [(True, False), (False, False), (False, True)],
    ids=["actor-lost-too", "cluster-alone", "own-local-ray"],
)
def test_a_ray_cluster_that_stops_answering_stops_the_sweep_in_one_line(lost_first, local, monkeypatch):
    """`ray stop` on the cluster's head mid-sweep: Ray's driver waited on the lost GCS (for a replacement
    actor's code check, or for episodes), then ended the process after 60 s (exit 1, a C++ log line, no
    report). The backend now tries the GCS's port while nothing comes back and stops the sweep itself
    (SweepStopped: the command reports what was recorded) once it has not answered for GCS_GONE_S.
    local: the sweep's own Ray (no --ray-address, no $RAY_ADDRESS), whose line said to wait for "the
    cluster" to be back; there is none, and the same command starts a new local Ray."""
    import socket
    import types

    from pipelines.errors import SweepStopped
    from pipelines.experiments import backends
    from pipelines.plugins import code_with_plugins

    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]  # closed below: nothing answers there, as after `ray stop`
    monkeypatch.setattr(backends, "GCS_PROBE_S", 0.01, raising=False)
    monkeypatch.setattr(backends, "GCS_GONE_S", 0.05, raising=False)
    dead: set[int] = set()  # the actors lost (lost_first: the first, with its episode)
    actors: list[types.SimpleNamespace] = []

    def actor(*_):
        n = len(actors)
        actors.append(types.SimpleNamespace(
            code=types.SimpleNamespace(remote=lambda: ("code", n)),
            run_unless_stopped=types.SimpleNamespace(remote=lambda task: ("run", n)),
        ))  # fmt: skip
        return actors[-1]

    def wait(refs, num_returns, timeout=None):
        assert timeout is not None, "a wait on a lost GCS never ends"
        done = [r for r in refs if r[1] == 0 and (r[0] == "code" or (lost_first and not dead))]
        return done[:1], [r for r in refs if r not in done[:1]]

    def get(ref):
        if ref[0] == "code":
            return "node", code_with_plugins()
        dead.add(ref[1])
        raise _FakeActorDied("The actor died unexpectedly before finishing this task.")

    fake = types.ModuleType("ray")
    fake.is_initialized = lambda: not local  # type: ignore[attr-defined]
    fake.init = lambda address, **_: address == "local" or pytest.fail(address)  # type: ignore[attr-defined]
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    fake.remote = lambda **_: (
        lambda cls: types.SimpleNamespace(  # type: ignore[attr-defined]
            remote=(lambda *a: types.SimpleNamespace()) if cls.__name__ == "StopFlag" else actor
        )
    )
    fake.wait, fake.get = wait, get  # type: ignore[attr-defined]
    fake.exceptions = types.SimpleNamespace(RayActorError=_FakeActorDied)  # type: ignore[attr-defined]
    gcs = types.SimpleNamespace(gcs_address=f"127.0.0.1:{port}")
    fake.get_runtime_context = lambda: gcs  # type: ignore[attr-defined]
    fake.kill = lambda a: pytest.fail("Ray's kill waits on the lost GCS")  # type: ignore[attr-defined]
    fake.shutdown = lambda: pytest.fail("Ray's shutdown waits on the lost GCS")  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", fake)
    backend = backends.RayBackend(1, "none", address=None)
    tasks = [types.SimpleNamespace(key=k) for k in "ab"]
    said = (
        r"^this sweep's own local Ray stopped answering \(its GCS at 127\.0\.0\.1:\d+, for 0\.05 s: "
        r"`ray stop` on this machine, or its processes killed\); the episodes recorded stay, and the same "
        r"command runs the rest on a new local Ray$"
        if local
        else r"^the Ray cluster stopped answering \(its GCS at 127\.0\.0\.1.*once the cluster is back$"
    )
    with pytest.raises(SweepStopped, match=said):
        list(backend.run(tasks))
    backend.close()
    assert len(actors) == (2 if lost_first else 1)
