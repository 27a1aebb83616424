"""docs/outputs.md's tables of the benchmarks' JSON against what they write: run_all.py's smallest run of two
sections through its command line, and each other kind of its rows from its measurement at the least size
(the sweep's excepted: a Table II sweep of process workers); control_step.py's and prepare.py's smallest
runs. Every key a row of its table, of its type."""

from __future__ import annotations

import json
import sys

from pipelines.loop.controllers import ControllerSpec
from tests.benchmark_modules import load_benchmark
from tests.pipelines.test_outputs_doc_files import check_documented, doc_table

run_all = load_benchmark("run_all")  # puts benchmarks/ on the path: its parts and siblings import by name
from run_all_parts import measurements  # noqa: E402
from run_all_parts.sections import SECTION_RUNS  # noqa: E402

HEADING = "`benchmarks/run_all.py --json FILE`"
CV = "constant_velocity"


def test_every_section_is_a_row_of_the_top_table():
    top = doc_table(HEADING, 0)
    assert set(top) == {"machine", "settings", "errors", *(key for key, _ in SECTION_RUNS.values())}


def test_the_smallest_run_is_as_documented(tmp_path):
    out = tmp_path / "run_all.json"
    argv = ["--quick", "--sections", "simulator,dmpc", "--steps", "2", "--json", str(out)]
    assert run_all.main(argv) == 0
    report = json.loads(out.read_text(encoding="utf-8"))
    check_documented({k: v for k, v in doc_table(HEADING, 0).items() if k in report}, [report])
    check_documented(doc_table(HEADING, 1), [report["machine"]])
    check_documented(doc_table(HEADING, 2), [report["settings"]])
    check_documented(doc_table(HEADING, 3), report["simulator_step"].values())
    entries = report["dmpc_parallel"].values()
    check_documented(doc_table(HEADING, 5), entries)
    steps = doc_table(HEADING, 4)
    check_documented(
        {k: v for k, v in steps.items() if k != "floor"},
        [e[m] for e in entries for m in e if m != "speedup_median"],
    )


def test_the_other_rows_are_as_documented():
    import ibr_solves
    import sweep_floor

    steps = [
        measurements.mpc_step(ControllerSpec("cmpc", CV), 1, 1, floor=True),
        measurements.any_step(ControllerSpec("straight"), 2, 1, 2, 1),
    ]
    check_documented(doc_table(HEADING, 4), steps)
    one_process = measurements.episodes_per_minute(ControllerSpec("straight"), 1, 1)
    check_documented(doc_table(HEADING, 7), [one_process])
    rows = [{"cell": "c", "wall_s": 1.0, "fatrop joint": 0.5}, {"cell": "c", "wall_s": 2.0, "encoder": 0.2}]
    check_documented(doc_table(HEADING, 9), [sweep_floor.summary(rows, 2)])
    check_documented(
        doc_table(HEADING, 10), measurements.export_rows("social_lstm_soft_eth", 2, 2, False).values()
    )
    robots = [measurements.robots_row("cmpc", 3, 1, 1, variant) for variant in ("paper", "many")]
    check_documented(doc_table(HEADING, 11), robots)
    cell = measurements.dmpc_update_cell(3, 1, "jacobi:regret", 1)
    cell["speedup_median"] = cell["speedup"]["step_median"]  # as the section adds it
    check_documented(doc_table(HEADING, 12), [cell])
    check_documented(doc_table(HEADING, 13), cell["rows"].values())
    check_documented(doc_table(HEADING, 14), [ibr_solves.measure(CV, 1, 1, False)])


def test_control_steps_json_is_as_documented(tmp_path):
    control_step = load_benchmark("control_step")
    out = tmp_path / "control.json"
    assert control_step.main(["--humans", "2", "--episodes", "1", "--json", str(out)]) == 0
    report = json.loads(out.read_text(encoding="utf-8"))
    heading = "`benchmarks/control_step.py --json FILE`"
    check_documented(doc_table(heading, 0), [report])
    assert sorted(report["rows"]) == ["cmpc      2 humans", "dmpc      2 humans", "floor     2 humans"]
    check_documented(doc_table(heading, 1), report["rows"].values())


def test_prepares_json_is_as_documented(tmp_path, monkeypatch):
    prepare = load_benchmark("prepare")
    out = tmp_path / "prepare.json"
    argv = ["prepare.py", "--predictor", CV, "--humans", "1", "2", "--json", str(out)]
    monkeypatch.setattr(sys, "argv", argv)
    prepare.main()
    report = json.loads(out.read_text(encoding="utf-8"))
    heading = "`benchmarks/prepare.py --json FILE`"
    jit_only = ("cold_cache", "warm_cache")  # --jit compiles every size, twice: minutes
    check_documented({k: v for k, v in doc_table(heading, 0).items() if k not in jit_only}, [report])
    check_documented(doc_table(heading, 1), [report["no_jit"]])
    assert set(report["no_jit"]["seconds"]) == {"1", "2"}
    assert all(isinstance(s, float) for s in report["no_jit"]["seconds"].values())
