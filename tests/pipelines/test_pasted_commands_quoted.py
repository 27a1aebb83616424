"""A command line a message gives to paste names its folder as a shell needs it: `crowdmpc sweep --report-only
--out my runs` (a resume refusal's remedy, unquoted) reported nothing of a folder named "my runs" (argparse:
"unrecognized arguments: runs"). Names a shell takes as they are print as before."""

import shlex
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.config.entries import ConfigError
from pipelines.experiments.resume_checks import ResumeChecks


def _pasted(text: str) -> list[str]:
    """The words a shell gives the command between the first pair of backticks of ``text``."""
    return shlex.split(text.split("`")[1])


@pytest.fixture
def sweep(tmp_path, capsys):
    """A sweep of the baselines in a folder whose name has a space (2 episodes, a few seconds)."""
    out = tmp_path / "my sweep"
    options = ["--experiment", "baselines", "--humans", "3", "--robots", "2", "--episodes-per-cell", "1"]
    assert main(["sweep", *options, "--backend", "inline", "--no-progress", "--out", str(out)]) == 0
    capsys.readouterr()
    return out, options


def test_a_resume_refusals_remedy_and_note_quote_the_folder():
    out = Path("/tmp/my runs")
    checks = ResumeChecks(out, [])
    assert _pasted(checks._remedy("the new weights")) == [
        "crowdmpc",
        "sweep",
        "--report-only",
        "--out",
        str(out),
    ]
    checks.add({"key": "another-plan"})  # an episode this run does not plan: the note names config show
    assert _pasted(checks.outside_note() or "") == [
        "crowdmpc", "config", "show", "--from-sweep", str(out), "--run", "N"
    ]  # fmt: skip
    plain = ResumeChecks(Path("runs/mine"), [])._remedy("the new weights")
    assert "`crowdmpc sweep --report-only --out runs/mine`" in plain  # as before


def test_config_show_of_a_reused_run_quotes_the_folder_it_names():
    from pipelines.config.recorded import recorded_entries

    with pytest.raises(ConfigError) as exc:
        recorded_entries(Path("sweep.json"), {"reused_from": "/tmp/my table2", "run_there": 1}, 2)
    assert _pasted(str(exc.value)) == [
        "crowdmpc",
        "config",
        "show",
        "--from-sweep",
        "/tmp/my table2",
        "--run",
        "1",
    ]


def test_a_refusal_beyond_a_bound_and_a_report_of_other_cells_quote_the_folder(sweep, capsys):
    from pipelines.config.recorded import ran_beyond_bound

    out, options = sweep
    ran = ran_beyond_bound(out, "mpc", "w_goal", 10.0)  # the value the folder recorded
    assert _pasted(ran) == ["crowdmpc", "sweep", "--report-only", "--out", str(out)]
    other = [*options[:2], "--humans", "4", *options[4:]]
    assert main(["sweep", *other, "--report-only", "--out", str(out)]) == 2
    assert _pasted(capsys.readouterr().err) == ["crowdmpc", "config", "show", "--from-sweep", str(out)]


def test_review_quotes_the_unfinished_recording_it_names(tmp_path, capsys):
    folder = tmp_path / "my runs"
    folder.mkdir()
    part = folder / "killed.mcap.part"
    part.write_bytes(b"")
    assert main(["review", str(folder)]) == 2
    (warning,) = [line for line in capsys.readouterr().err.splitlines() if "skipping" in line]
    assert _pasted(warning) == ["crowdmpc", "review", str(part)]
