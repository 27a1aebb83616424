"""table.md names the code behind its episodes (sweep.json recorded it; the table alone said nothing)."""

from __future__ import annotations

import json

from pipelines.cli import main
from pipelines.version import code_identity

ARGV = ["sweep", "--experiment", "controllers", "--controllers", "straight", "--humans", "1", "--backend"]
ARGV += ["inline", "--no-progress"]


def test_the_table_names_the_code_of_its_runs(tmp_path, capsys):
    out = tmp_path / "s"
    assert main([*ARGV, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    code = code_identity()
    line = (out / "table.md").read_text(encoding="utf-8").rstrip().splitlines()[-1]
    assert line.startswith(f"Code: commit {str(code['commit'])[:12]}") and f"CasADi {code['casadi']}" in line
    # its episodes as another commit would have recorded them (plugins and all), resumed by this code
    meta = json.loads((out / "sweep.json").read_text())
    plugins = {"m:Net": "ab" * 32}
    meta["runs"][0]["code"] = {**code, "commit": "0123456789abcdef", "dirty": False, "plugins": plugins}
    (out / "sweep.json").write_text(json.dumps(meta))
    capsys.readouterr()
    assert main([*ARGV, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    line = (out / "table.md").read_text(encoding="utf-8").rstrip().splitlines()[-1]
    assert line.startswith("Code: 2 versions, in the order the sweep's runs used them: commit 0123456789ab, ")
    assert ", plugin m:Net abababababab; commit " in line


def test_the_table_names_only_the_code_of_the_runs_it_tabulates(tmp_path, capsys):
    """A run that made none of the tabulated episodes (a resume with nothing left to run, or one whose cells
    another --set made new) was named all the same: "2 versions" behind a table of one run's episodes."""
    from pipelines.commands.sweep_table_notes import code_note

    out = tmp_path / "s"
    assert main([*ARGV, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    meta = json.loads((out / "sweep.json").read_text())
    other = {**code_identity(), "commit": "0123456789abcdef", "dirty": False}
    meta["runs"] += [dict(meta["runs"][-1], code=other), {"lost": "not listed in sweep.json"}]
    (out / "sweep.json").write_text(json.dumps(meta))
    capsys.readouterr()
    assert main([*ARGV, "--episodes-per-cell", "1", "--out", str(out), "--report-only"]) == 0
    line = (out / "table.md").read_text(encoding="utf-8").rstrip().splitlines()[-1]
    assert line.startswith("Code: commit ") and "0123456789ab" not in line  # run 2 made no episode
    assert "0123456789ab" in code_note(out, {2}) and "0123456789ab" in code_note(out)  # every run's
    assert code_note(out, {1, None}).startswith("Code: 3 versions")  # a record without its run: all of them
    assert code_note(out, {3}) == "Code: unknown (a run sweep.json no longer listed)."
    assert code_note(out, {1, 9}).endswith("; unknown (a run sweep.json no longer listed).")  # past its lines
    for damaged in (0, -1):  # a record naming no line of the file: run 0 was passed over, -1 counted
        note = code_note(out, {1, damaged})
        assert note.startswith("Code: 2 versions") and "unknown (a run sweep.json no longer listed)" in note


def test_a_run_without_a_commit_is_said_to_have_none(tmp_path, capsys):
    """A sweep by an installed wheel, or by `ray job submit --working-dir` (Ray's upload leaves .git out),
    records no commit: table.md said "Code: commit None, crowdmpc 0.1.0, ..." (met with Ray 2.60)."""
    from pipelines.commands.sweep_table_notes import code_note

    out = tmp_path / "s"
    assert main([*ARGV, "--episodes-per-cell", "1", "--out", str(out)]) == 0
    meta = json.loads((out / "sweep.json").read_text())
    meta["runs"][0]["code"] = {**code_identity(), "commit": None, "dirty": None, "diff_sha256": None}
    (out / "sweep.json").write_text(json.dumps(meta))
    assert code_note(out).startswith("Code: no git commit, crowdmpc ")
    assert "None" not in code_note(out)
