"""benchmarks/sweep_log_scale.py: its log is the plan's and passes the log's checks; one small run."""

import json

from pipelines.experiments.cells import get_experiment
from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE, episode_log
from pipelines.experiments.sweep import run_sweep
from pipelines.experiments.sweep_config import SweepConfig
from tests.benchmark_modules import load_benchmark

sweep_log_scale = load_benchmark("sweep_log_scale")


def test_a_multiplied_log_holds_every_planned_episode_and_passes_the_checks(tmp_path):
    seed = tmp_path / "seed"
    experiment = get_experiment("baselines")
    run_sweep(SweepConfig(experiment, seed, 2, humans=(3,), backend="inline", progress=False))
    out = tmp_path / "big"
    size = sweep_log_scale.multiply(seed, out, 7)
    assert size == (out / EPISODES_FILE).stat().st_size
    records = episode_log(out).load(repair=False)  # every line checked
    config = SweepConfig(experiment, out, 7, humans=(3,), backend="inline", progress=False)
    assert set(records) == {t.key for t in config.tasks()}
    assert json.loads((out / SWEEP_FILE).read_text())["runs"][-1]["episodes_per_cell"] == 7
    assert run_sweep(config).ran == 0  # the resume finds the plan done


def test_the_report_of_a_multiplied_log_tabulates_every_episode_of_it(tmp_path, capsys):
    """--report-only plans from the run's recorded config: the benchmark's report had tabulated the seed
    sweep's 2 episodes a cell, whatever the log held."""
    from pipelines.cli import main

    seed = tmp_path / "seed"
    argv = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "2"]
    assert main([*argv, "--backend", "inline", "--no-progress", "--jit", "off", "--out", str(seed)]) == 0
    out = tmp_path / "big"
    sweep_log_scale.multiply(seed, out, 7)
    assert main(["sweep", "--experiment", "baselines", "--out", str(out), "--report-only"]) == 0
    rows = (out / "episodes.csv").read_text().splitlines()[1:]
    assert len(rows) == 7 * len(get_experiment("baselines").cells((3,)))


def test_a_small_run_prints_and_writes_its_figures(tmp_path, capsys):
    out = tmp_path / "scale.json"
    argv = ["--experiment", "baselines", "--humans", "3", "--episodes", "4", "--json", str(out)]
    assert sweep_log_scale.main(argv) == 0
    (row,) = json.loads(out.read_text())["rows"]
    assert row["episodes"] == 4 and row["report_peak_mb"] > 0 and row["resume_peak_mb"] > 0
    assert row["compare_peak_mb"] > 0 and row["compare_s"] > 0
    assert "compare MB" in capsys.readouterr().out


def test_more_episodes_a_cell_than_a_sweep_takes_are_refused_before_any_run(capsys):
    """sweep.json's plan would be refused by --report-only itself; seen as a bare exit status 1 before."""
    import pytest

    with pytest.raises(SystemExit) as stop:
        sweep_log_scale.main(["--episodes", "1000000"])  # table2 at 5 humans: 2 cells
    assert stop.value.code == 2
    assert "500000 a cell over 2 cells" in capsys.readouterr().err
