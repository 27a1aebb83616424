"""`crowdmpc sweep --reuse DIR`: Table III's F cells are Table II's CMPC cells (the same settings, the same
crowds), and a paper-scale Table III ran those 5000 episodes again, or was seeded by hand with Table II's
lines, whose code its table.md then called "unknown". The episodes taken are those a run of their own gives,
under this experiment's labels, with their runs' code; what the seeded folder does next (resume, report,
config show, review) reads the sweep's own runs."""

from __future__ import annotations

import json
import os
import shutil

import pytest

from pipelines.cli import main
from pipelines.experiments import reuse
from tests.cli_calls import one_line, run_cli

SMALL = ["--humans", "5", "--episodes-per-cell", "2", "--backend", "inline", "--no-progress"]


@pytest.fixture(scope="module")
def table2(tmp_path_factory):
    out = tmp_path_factory.mktemp("t2") / "sweep"
    assert main(["sweep", "--experiment", "table2", *SMALL, "--out", str(out)]) == 0
    return out


def _records(out) -> list[dict]:
    return [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]


def _runs(out) -> list[dict]:
    return json.loads((out / "sweep.json").read_text())["runs"]


def _table3(capsys, out, *extra: str) -> tuple[int, str, str]:
    return run_cli(capsys, "sweep", "--experiment", "table3", *SMALL, "--out", str(out), *extra)


def test_table_iii_takes_table_iis_cmpc_episodes_and_runs_the_rest(table2, tmp_path, capsys):
    reused, fresh = tmp_path / "reused", tmp_path / "fresh"
    code, _, err = _table3(capsys, reused, "--reuse", str(table2))
    assert code == 0 and f"reused 2 episode(s) of 1 cell(s) from {table2} (1 of its runs)" in err
    assert main(["sweep", "--experiment", "table3", *SMALL, "--out", str(fresh)]) == 0
    capsys.readouterr()
    # the same episodes as a run of its own, metric for metric, under Table III's labels
    assert main(["compare", f"reused={reused}", f"fresh={fresh}", "--expect-identical", "--no-progress"]) == 0
    assert "identical: 4 episodes, every metric equal" in capsys.readouterr().out
    taken = [r for r in _records(reused) if r["run"] == 1]
    cmpc = {r["key"]: r for r in _records(table2) if r["method"] == "CMPC"}
    assert {r["key"] for r in taken} == set(cmpc) and {r["method"] for r in taken} == {"F"}
    assert all({**r, "method": "CMPC", "experiment": "table2"} == cmpc[r["key"]] for r in taken)
    runs, source = _runs(reused), _runs(table2)[0]
    assert runs[0] == {**source, "reused_from": str(table2.resolve()), "run_there": 1}  # its code with it
    assert len(runs) == 2 and "reused_from" not in runs[1]
    # its table names the code of both runs' episodes, one commit here
    assert "Code: commit" in (reused / "table.md").read_text()


def test_the_same_command_again_resumes_and_takes_nothing_twice(table2, tmp_path, capsys):
    out = tmp_path / "t3"
    assert _table3(capsys, out, "--reuse", str(table2))[0] == 0
    code, _, err = _table3(capsys, out, "--reuse", str(table2))
    assert code == 0 and "none of its episodes is one of this plan's left to run" in err
    assert len(_records(out)) == 4 and [("reused_from" in r) for r in _runs(out)] == [True, False, False]


def test_a_stop_between_the_run_lines_and_the_records_is_taken_up_again(
    table2, tmp_path, capsys, monkeypatch
):
    out = tmp_path / "t3"

    def stopped(*args):
        raise KeyboardInterrupt  # after sweep.json, before a record

    monkeypatch.setattr(reuse, "_append", stopped)
    code, _, err = _table3(capsys, out, "--reuse", str(table2))
    assert code == 130 and "interrupted" in err
    assert len(_runs(out)) == 1 and not (out / "episodes.jsonl").exists()  # the provenance first
    monkeypatch.undo()
    code, _, err = _table3(capsys, out, "--reuse", str(table2))
    assert code == 0 and "reused 2 episode(s)" in err
    assert [("reused_from" in r) for r in _runs(out)] == [True, False]  # its line once, its number kept
    assert sorted(r["run"] for r in _records(out)) == [1, 1, 2, 2]


def test_a_run_sweep_json_lost_is_named_with_the_run_that_found_it(table2, tmp_path, capsys):
    out = tmp_path / "t3"
    one_a_cell = [*SMALL[:2], "--episodes-per-cell", "1", *SMALL[4:]]
    assert main(["sweep", "--experiment", "table3", *one_a_cell, "--out", str(out)]) == 0
    meta = json.loads((out / "sweep.json").read_text())
    (out / "sweep.json").write_text(json.dumps({**meta, "runs": []}))  # its one line lost
    code, _, err = _table3(capsys, out, "--reuse", str(table2))
    assert code == 0 and "reused 1 episode(s)" in err
    runs = _runs(out)  # the lost run 1, the line taken (2), then the run that found the loss (3)
    assert runs[0] == {"lost": "not listed in sweep.json when run 3 began"}
    assert "reused_from" in runs[1] and len(runs) == 3 and "reused_from" not in runs[2]
    assert sorted(r["run"] for r in _records(out)) == [1, 1, 2, 3]


def test_a_dry_run_counts_them_and_writes_nothing(table2, tmp_path, capsys):
    out = tmp_path / "t3"
    code, stdout, _ = _table3(capsys, out, "--reuse", str(table2), "--dry-run")
    assert code == 0 and stdout.splitlines()[-1] == f"--reuse: 2 of them to take from {table2}"
    assert not out.exists()


def test_records_of_other_weights_are_refused_before_anything_is_written(table2, tmp_path, capsys):
    source, out = tmp_path / "t2", tmp_path / "t3"
    shutil.copytree(table2, source)
    lines = (source / "episodes.jsonl").read_text().splitlines()
    edited = [json.loads(line) for line in lines]
    for r in edited:
        r["predictor_sha256"] = "0" * 64 if r["method"] == "CMPC" else r["predictor_sha256"]
    (source / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in edited))
    code, _, err = _table3(capsys, out, "--reuse", str(source))
    line = one_line(err)
    assert code == 2 and str(source / "episodes.jsonl") in line and "sha256 " + "0" * 64 in line
    assert line.endswith("they are not episodes of this plan now: run the sweep without --reuse")
    assert not out.exists()  # nor the folder made for it


def test_what_cannot_be_reused_is_one_line(table2, tmp_path, capsys):
    def refused(out, *extra: str) -> str:
        code, _, err = _table3(capsys, out, *extra)
        assert code == 2
        return one_line(err)

    assert f"not a sweep folder ({tmp_path / 'sweep.json'} does not exist)" in refused(
        tmp_path / "a", "--reuse", str(tmp_path)
    )
    code, _, err = run_cli(capsys, "sweep", "--experiment", "table2", *SMALL, "--out", str(table2), "--reuse",
                           str(table2))  # fmt: skip
    assert code == 2 and "that is --out itself" in one_line(err)
    assert "--report-only runs nothing" in refused(tmp_path / "b", "--reuse", str(table2), "--report-only")
    # a source of damaged or linked files is named as --reuse's, and no --out is made for it
    bad = tmp_path / "bad"
    shutil.copytree(table2, bad)
    for damaged in ("{", "[]"):
        (bad / "sweep.json").write_text(damaged)
        line = refused(tmp_path / "c", "--reuse", str(bad))
        assert line.startswith(
            f"crowdmpc sweep: error: --reuse {bad}: {bad / 'sweep.json'}: not a sweep file"
        )
        assert not (tmp_path / "c").exists()
    (bad / "sweep.json").unlink()
    (bad / "sweep.json").symlink_to(table2 / "sweep.json")
    assert refused(tmp_path / "c", "--reuse", str(bad)).endswith(
        f"--reuse {bad}: {bad / 'sweep.json'} is a symbolic link; --reuse reads a sweep's own files"
    )
    assert not (tmp_path / "c").exists()
    # a log or a sweep file that is there but is no file (a pipe: read, it waits for good) is named so
    for name in ("sweep.json", "episodes.jsonl"):
        piped = tmp_path / f"piped_{name}"
        shutil.copytree(table2, piped)
        (piped / name).unlink()
        os.mkfifo(piped / name)
        assert refused(tmp_path / "c", "--reuse", str(piped)).endswith(
            f"--reuse {piped}: not a sweep folder ({piped / name} is not a regular file)"
        )
        assert not (tmp_path / "c").exists()
    # a damaged line in its log, named as the source's
    (bad / "sweep.json").unlink()
    shutil.copy(table2 / "sweep.json", bad / "sweep.json")
    lines = (bad / "episodes.jsonl").read_text().splitlines(keepends=True)
    (bad / "episodes.jsonl").write_text("".join([lines[0], "not json\n", *lines[1:]]))
    line = refused(tmp_path / "d", "--reuse", str(bad))
    assert line.startswith(
        f"crowdmpc sweep: error: --reuse {bad}: {bad / 'episodes.jsonl'}:2: not a JSON record"
    )
    assert line.endswith("; that sweep's own rerun refuses it too") and not (tmp_path / "d").exists()


def test_outs_own_records_are_checked_before_anything_is_taken(table2, tmp_path, capsys):
    out = tmp_path / "t3"
    assert main(["sweep", "--experiment", "table3", *SMALL[:2], "--episodes-per-cell", "1", *SMALL[4:],
                 "--out", str(out)]) == 0  # fmt: skip
    records = _records(out)
    for r in records:
        r["predictor_sha256"] = "0" * 64
    (out / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    before = {name: (out / name).read_bytes() for name in ("episodes.jsonl", "sweep.json")}
    code, _, err = _table3(capsys, out, "--reuse", str(table2))
    assert code == 2 and one_line(err).endswith(
        f"use another --out for the new weights, or `crowdmpc sweep --report-only --out {out}` to report the "
        "episodes it holds"
    )
    assert {name: (out / name).read_bytes() for name in before} == before  # nothing taken


def test_a_sweep_of_other_cells_gives_nothing_and_the_sweep_runs_all_of_its_own(table2, tmp_path, capsys):
    code, _, err = run_cli(
        capsys, "sweep", "--experiment", "table3", "--humans", "6", *SMALL[2:],
        "--reuse", str(table2), "--out", str(tmp_path / "c"),
    )  # fmt: skip
    assert code == 0 and "none of its episodes is one of this plan's left to run" in err
    assert len(_runs(tmp_path / "c")) == 1


def test_config_show_and_report_only_read_the_sweeps_own_runs(table2, tmp_path, capsys):
    out = tmp_path / "t3"
    assert _table3(capsys, out, "--reuse", str(table2))[0] == 0
    code, stdout, _ = run_cli(capsys, "config", "show", "--from-sweep", str(out))
    assert code == 0 and "run 2 of 2" in stdout and 'experiment = "table3"' in stdout
    code, _, err = run_cli(capsys, "config", "show", "--from-sweep", str(out), "--run", "1")
    assert code == 2 and f"is run 1 of {table2.resolve()}, whose episodes this sweep took" in one_line(err)
    assert f"--from-sweep {table2.resolve()} --run 1" in err
    # a report asked with no --experiment reads table3's last run, not Table II's copied line
    code, _, _ = run_cli(capsys, "sweep", "--report-only", "--out", str(out), "--no-progress")
    assert code == 0 and "| F |" in (out / "table.md").read_text().replace("  ", " ")


def test_records_without_a_run_take_the_sources_only_run_else_an_unknown_one(table2, tmp_path, capsys):
    for extra_run in (False, True):
        source, out = tmp_path / f"s{extra_run}", tmp_path / f"o{extra_run}"
        shutil.copytree(table2, source)
        records = _records(source)
        for r in records:
            del r["run"]
        (source / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
        if extra_run:
            meta = json.loads((source / "sweep.json").read_text())
            meta["runs"].append(meta["runs"][0])
            (source / "sweep.json").write_text(json.dumps(meta))
        code, _, err = _table3(capsys, out, "--reuse", str(source))
        assert code == 0
        first = _runs(out)[0]
        if extra_run:  # which of two runs made them is unknown: its code too, said as the source's gap
            assert "(1 reused run(s) their sweep's sweep.json lacked, code unknown)" in err
            assert first == {"lost": first["lost"], "reused_from": str(source.resolve()), "run_there": None}
            assert (
                f"unknown (no line of {source / 'sweep.json'} names the run of its episodes)"
                in (out / "table.md").read_text()
            )
        else:
            assert first["run_there"] == 1 and first["code"] == _runs(table2)[0]["code"]


def test_review_reads_the_recording_policy_of_the_sweeps_own_runs(tmp_path, recwarn):
    from pipelines.commands.review_notes import _sweep_kept_failures

    failures = {"config": {"sweep": {"record": "failures"}}}
    (tmp_path / "sweep.json").write_text(
        json.dumps({"runs": [{**failures, "reused_from": "/x", "run_there": 1}]})
    )
    assert not _sweep_kept_failures(tmp_path) and not recwarn.list
    (tmp_path / "sweep.json").write_text(json.dumps({"runs": [failures]}))
    assert _sweep_kept_failures(tmp_path)


def test_the_recordings_taken_are_counted_where_they_stay_and_a_chain_names_its_origin(tmp_path, capsys):
    source = tmp_path / "t2"
    argv = ["sweep", "--experiment", "table2", *SMALL, "--record", "all", "--out", str(source)]
    assert main(argv) == 0
    t3 = tmp_path / "t3"
    code, _, err = _table3(capsys, t3, "--reuse", str(source), "--record", "all")
    assert code == 0 and f"(1 of its runs); 2 of their recordings stay in {source / 'mcap'}" in err
    # a chain: what t3 took from source points at source, where their code and recordings are, in one step
    code, _, err = _table3(capsys, tmp_path / "again", "--reuse", str(t3))
    own = len(_records(t3)) - 2
    assert code == 0 and f"reused {own + 2} episode(s) of 2 cell(s) from {t3} (2 of its runs)" in err
    assert f"; 2 of their recordings stay in {source.resolve() / 'mcap'}, {own} in {t3 / 'mcap'}" in err
    runs = _runs(tmp_path / "again")
    assert runs[0] == {**_runs(source)[0], "reused_from": str(source.resolve()), "run_there": 1}
    assert runs[1] == {**_runs(t3)[1], "reused_from": str(t3.resolve()), "run_there": 2}
    code, _, err = run_cli(capsys, "config", "show", "--from-sweep", str(tmp_path / "again"), "--run", "1")
    assert code == 2 and f"--from-sweep {source.resolve()} --run 1" in err
