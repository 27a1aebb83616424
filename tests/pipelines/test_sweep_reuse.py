"""`crowdmpc sweep --reuse DIR`: Table III's F cells are Table II's CMPC cells (the same settings, the same
crowds), and a paper-scale Table III ran those 5000 episodes again, or was seeded by hand with Table II's
lines, whose code its table.md then called "unknown". The records taken are the episodes a fresh run gives,
under this experiment's labels, with their run's code."""

from __future__ import annotations

import json

import pytest

from pipelines.cli import main
from tests.cli_calls import run_cli

SMALL = ["--humans", "5", "--episodes-per-cell", "2", "--backend", "inline", "--no-progress"]


@pytest.fixture(scope="module")
def table2(tmp_path_factory):
    out = tmp_path_factory.mktemp("t2") / "sweep"
    assert main(["sweep", "--experiment", "table2", *SMALL, "--out", str(out)]) == 0
    return out


def _records(out) -> list[dict]:
    return [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]


def test_table_iii_takes_table_iis_cmpc_episodes_and_runs_the_rest(table2, tmp_path, capsys):
    reused, fresh = tmp_path / "reused", tmp_path / "fresh"
    code, _, err = run_cli(
        capsys, "sweep", "--experiment", "table3", *SMALL, "--reuse", str(table2), "--out", str(reused)
    )
    assert code == 0 and f"reused 2 episodes of 1 cell(s) from {table2} (1 of its runs)" in err
    assert main(["sweep", "--experiment", "table3", *SMALL, "--out", str(fresh)]) == 0
    capsys.readouterr()
    # the same episodes as a run of its own, metric for metric, under Table III's labels
    assert main(["compare", f"reused={reused}", f"fresh={fresh}", "--expect-identical", "--no-progress"]) == 0
    assert "identical: 4 episodes, every metric equal" in capsys.readouterr().out
    taken = [r for r in _records(reused) if r["run"] == 1]
    cmpc = {r["key"]: r for r in _records(table2) if r["method"] == "CMPC"}
    assert {r["key"] for r in taken} == set(cmpc) and {r["method"] for r in taken} == {"F"}
    assert all({**r, "method": "CMPC", "experiment": "table2"} == cmpc[r["key"]] for r in taken)
    runs = json.loads((reused / "sweep.json").read_text())["runs"]
    source = json.loads((table2 / "sweep.json").read_text())["runs"][0]
    assert runs[0] == {**source, "reused_from": str(table2.resolve()), "run_there": 1}  # its code with it
    assert len(runs) == 2 and "reused_from" not in runs[1]


def test_a_dry_run_counts_them_and_writes_nothing(table2, tmp_path, capsys):
    out = tmp_path / "t3"
    argv = ["sweep", "--experiment", "table3", *SMALL, "--reuse", str(table2), "--out", str(out), "--dry-run"]
    code, stdout, _ = run_cli(capsys, *argv)
    assert (
        code == 0
        and stdout.splitlines()[-1] == f"--reuse: 2 of them recorded in {table2}"
        and not out.exists()
    )


def test_what_cannot_be_reused_is_one_line(table2, tmp_path, capsys):
    def refused(*extra: str) -> str:
        code, _, err = run_cli(capsys, "sweep", "--experiment", "table3", *SMALL, *extra)
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        return err

    assert "not a sweep folder (it holds no episodes.jsonl and sweep.json)" in refused(
        "--reuse", str(tmp_path), "--out", str(tmp_path / "a")
    )
    assert "that is --out itself" in refused("--reuse", str(table2), "--out", str(table2))
    assert main(["sweep", "--experiment", "table3", *SMALL, "--out", str(tmp_path / "b")]) == 0
    assert "holds a sweep already; --reuse seeds a new folder" in refused(
        "--reuse", str(table2), "--out", str(tmp_path / "b")
    )
    assert "--report-only runs nothing" in refused(
        "--reuse", str(table2), "--out", str(tmp_path / "b"), "--report-only"
    )
    # a sweep of other cells: nothing in common, said, and the sweep runs all of its own
    code, _, err = run_cli(capsys, "sweep", "--experiment", "table3", *SMALL[:1], "6", *SMALL[2:],
                           "--reuse", str(table2), "--out", str(tmp_path / "c"))  # fmt: skip
    assert code == 0 and "none of its episodes is one of this plan's" in err
