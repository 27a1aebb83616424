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
    # a resume by other code (its run line as another commit would have written it, plugins and all)
    meta = json.loads((out / "sweep.json").read_text())
    plugins = {"m:Net": "ab" * 32}
    other = dict(
        meta["runs"][-1], code={**code, "commit": "0123456789abcdef", "dirty": False, "plugins": plugins}
    )
    meta["runs"].append(other)
    (out / "sweep.json").write_text(json.dumps(meta))
    capsys.readouterr()
    assert main([*ARGV, "--episodes-per-cell", "1", "--out", str(out), "--report-only"]) == 0
    line = (out / "table.md").read_text(encoding="utf-8").rstrip().splitlines()[-1]
    assert line.startswith("Code: 2 versions, in the order the sweep's runs used them: commit ")
    assert "; commit 0123456789ab, crowdmpc " in line and line.endswith(", plugin m:Net abababababab.")
