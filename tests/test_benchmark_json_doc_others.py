"""docs/outputs.md's tables of "The other benchmarks' `--json FILE`" against what each script writes at its
least size, run through its own main() in this process. Where a run cannot be that small, the part that is
not is stood in for: sweep_floor's Table II sweep (its summary is run_all's, tested there), sweep_log_scale's
timed children (review_memory's ``peak``, run for real below), partial_history's protocol files (five small
scenes, not the prepared ETH data) and two of compile_cache's three sweeps (the same function with another
--jit)."""

from __future__ import annotations

import json
import os
import shutil
import sys

from tests.benchmark_modules import load_benchmark
from tests.pipelines.test_outputs_doc_files import check_documented, doc_table
from tests.predictors.samples import write_crowds

CV = "constant_velocity"
RUN_ALL = "`benchmarks/run_all.py --json FILE`"
RUN_ALL_ROBOTS_ROW, RUN_ALL_FLOOR, RUN_ALL_UPDATE_CELL, RUN_ALL_UPDATE_ROW = 11, 9, 12, 13


def table(script: str, index: int = 0) -> dict[str, dict[str, str]]:
    return doc_table(f"`benchmarks/{script}.py`", index)


def without(rows: dict[str, dict[str, str]], *names: str) -> dict[str, dict[str, str]]:
    return {name: row for name, row in rows.items() if name not in names}


def run_json(script: str, argv: list[str], tmp_path, monkeypatch, module=None) -> dict:
    """``benchmarks/<script>.py ARGV --json FILE``'s object, its main() (``module``'s, a part patched, else
    the script's) run here, given the arguments or through ``sys.argv`` for those that read them there."""
    module = module or load_benchmark(script)
    out = tmp_path / f"{script}.json"
    argv = [*argv, "--json", str(out)]
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *argv])
    takes_argv = module.main.__code__.co_argcount > 0
    assert (module.main(argv) if takes_argv else module.main()) in (0, None)
    return json.loads(out.read_text(encoding="utf-8"))


def test_batchings_json_is_as_documented(tmp_path, monkeypatch):
    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    argv = ["--model", "vanilla_lstm", "--batch-size", "2", "--epochs", "1", "--train", data]
    report = run_json("batching", argv, tmp_path, monkeypatch)
    check_documented(table("batching"), [report])
    check_documented(table("batching", 1), report["rows"])
    assert [row["batching"] for row in report["rows"]] == ["shuffled", "by_size"]


def test_compile_caches_json_is_as_documented(tmp_path):
    compile_cache = load_benchmark("compile_cache")
    env = os.environ | {"CROWDMPC_CACHE": str(tmp_path / "cache")}
    sweep = compile_cache.run_sweep(tmp_path / "off", "off", 1, CV, env)
    assert set(table("compile_cache")) == {"cold", "warm", "off"}
    # main() writes each sweep without its episodes' metrics, which it only compares
    from bench_cli import json_text  # on the path once a benchmark is loaded

    written = json.loads(json_text(without(sweep, "metrics")))
    check_documented(table("compile_cache", 1), [written])


def test_cost_scales_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--cost-scale", "1", "--robots", "1", "--humans", "1", "--episodes", "1"]
    report = run_json("cost_scale", argv, tmp_path, monkeypatch)
    check_documented(table("cost_scale"), [report])
    check_documented(table("cost_scale", 1), report["rows"])


def test_dmpc_scalings_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--robots", "2", "--humans", "1", "--episodes", "1", "--rules", "jacobi:regret"]
    report = run_json("dmpc_scaling", [*argv, "--replay", "--replay-reps", "1"], tmp_path, monkeypatch)
    check_documented(table("dmpc_scaling"), [report])
    cells = report["cells"].values()
    cell = without(doc_table(RUN_ALL, RUN_ALL_UPDATE_CELL), "speedup_median") | table("dmpc_scaling", 1)
    check_documented(cell, cells)
    check_documented(doc_table(RUN_ALL, RUN_ALL_UPDATE_ROW), [r for c in cells for r in c["rows"].values()])
    check_documented(table("dmpc_scaling", 2), [c["replay"] for c in cells])


def test_exact_couplings_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--predictor", CV, "--humans", "1", "--episodes", "1", "--max-iter", "1"]
    check_documented(table("exact_coupling"), [run_json("exact_coupling", argv, tmp_path, monkeypatch)])


def test_first_steps_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--predictor", CV, "--episodes", "1", "--humans", "1"]
    report = run_json("first_step", argv, tmp_path, monkeypatch)
    check_documented(table("first_step"), [report])
    # what its header line names: a saved file said neither crowd, scenario, seeds nor conventions
    assert {"humans": 1, "scenario": "circle", "seed": 0, "profile": "paper"}.items() <= report.items()
    assert list(report["modes"]) == ["default", "ipopt_alone", "fatrop_alone"]
    check_documented(table("first_step", 1), report["modes"].values())


def test_partial_historys_json_is_as_documented(tmp_path, monkeypatch):
    from predictors.data import locate

    # the protocol's val files made ready from the raw data take a minute: five small scenes instead
    val = write_crowds(tmp_path / "crowds.ndjson")
    monkeypatch.setattr(locate, "protocol_files", lambda *args, **kwargs: {"val": [val]})
    argv = ["--predictor", CV, "--horizon", "1", "--tracked", "1", "--splits", "val"]
    report = run_json("partial_history", argv, tmp_path, monkeypatch)
    check_documented(table("partial_history"), [report])
    assert report["scenes"] > 0 and list(report["ade_fde_m"]) == ["all", "1"]
    check_documented(table("partial_history", 1), report["ade_fde_m"].values())


def test_poolings_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--agents", "1", "--batch", "1", "--repeats", "1", "--phase", "eval"]
    report = run_json("pooling", argv, tmp_path, monkeypatch)
    check_documented(table("pooling"), [report])
    check_documented(table("pooling", 1), report["rows"])
    measurements = [row[mode] for row in report["rows"] for mode in ("dense", "sparse")]
    check_documented(table("pooling", 2), measurements)


def test_replay_coverages_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--predictor", CV, "--crowds", "orca", "--episodes", "1", "--humans", "1"]
    report = run_json("replay_coverage", argv, tmp_path, monkeypatch)
    check_documented(table("replay_coverage"), [report])
    check_documented(table("replay_coverage", 1), report["crowds"].values())
    assert all(
        isinstance(share, float | None) for crowd in report["crowds"].values()
        for shares in crowd["coverage"].values() for share in shares
    )  # fmt: skip


def test_review_memorys_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--files", "1", "--episodes", "1", "--humans", "1"]
    report = run_json("review_memory", argv, tmp_path, monkeypatch)
    check_documented(table("review_memory"), [report])
    check_documented(table("review_memory", 1), report["rows"])


def test_robot_scalings_json_is_as_documented(tmp_path, monkeypatch):
    # one robot as well: no robot-robot distance (null)
    argv = ["--robots", "1", "2", "--controllers", "cmpc", "--humans", "1", "--episodes", "1"]
    report = run_json("robot_scaling", [*argv, "--scenarios", "circle"], tmp_path, monkeypatch)
    check_documented(table("robot_scaling"), [report])
    row = without(doc_table(RUN_ALL, RUN_ALL_ROBOTS_ROW), "method", "mpc_overrides")
    check_documented(row, report["rows"])


def test_robot_swaps_json_is_as_documented(tmp_path, monkeypatch):
    argv = ["--robots", "2", "--controllers", "cmpc", "--episodes", "1"]
    report = run_json("robot_swaps", argv, tmp_path, monkeypatch)
    check_documented(table("robot_swaps"), [report])
    check_documented(table("robot_swaps", 1), report["rows"])


def test_sensor_ranges_json_is_as_documented(tmp_path, monkeypatch):
    reports = [  # no human as well: no robot-human distance (null)
        run_json("sensor_range", ["--predictor", CV, "--radii", "4", "--humans", n, "--episodes", "1"],
                 tmp_path, monkeypatch)
        for n in ("0", "1")
    ]  # fmt: skip
    check_documented(table("sensor_range"), reports)
    check_documented(table("sensor_range", 1), [row for report in reports for row in report["rows"]])


def test_solvers_json_is_as_documented(tmp_path, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)  # no gcc: no jit variants, which compile (s each)
    report = run_json("solvers", ["--humans", "1", "--episodes", "1"], tmp_path, monkeypatch)
    check_documented(table("solvers"), [report])
    assert sorted(report["results"]) == ["joint/fatrop", "joint/ipopt", "local/fatrop", "local/ipopt"]
    check_documented(table("solvers", 1), report["results"].values())


def test_sweep_floors_json_is_as_documented(tmp_path, monkeypatch):
    sweep_floor = load_benchmark("sweep_floor")
    # the Table II sweep it times (minutes) replaced by two of its episodes' rows
    rows = [{"cell": "c", "wall_s": 1.0, "fatrop joint": 0.5}, {"cell": "d", "wall_s": 2.0, "encoder": 0.2}]
    monkeypatch.setattr(sweep_floor, "measure", lambda episodes_per_cell: rows)
    report = run_json("sweep_floor", ["--episodes-per-cell", "2"], tmp_path, monkeypatch, sweep_floor)
    check_documented(doc_table(RUN_ALL, RUN_ALL_FLOOR) | table("sweep_floor"), [report])


def test_sweep_log_scales_json_is_as_documented(tmp_path, monkeypatch):
    sweep_log_scale = load_benchmark("sweep_log_scale")
    # each child's peak and time as review_memory.peak gives them (its test runs it): 3 processes of seconds
    monkeypatch.setattr(sweep_log_scale, "measured", lambda code, *args: (100.5, 1.5, "VmHWM"))
    argv = ["--experiment", "baselines", "--episodes", "1"]
    report = run_json("sweep_log_scale", argv, tmp_path, monkeypatch, sweep_log_scale)
    check_documented(table("sweep_log_scale"), [report])
    check_documented(table("sweep_log_scale", 1), report["rows"])
