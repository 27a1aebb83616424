"""The docs examples' command lines: a mistyped or unusable argument is one line naming it, exit 2, and
``-h`` describes them (argparse, as crowdmpc's own commands)."""

import runpy
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
# each example's arguments with OUT in place of its output folder
OUTPUT_ARGUMENTS = {
    "own_layout.py": (["OUT"], "argument OUT_DIR"),
    "gym_velocity_policy.py": (["1", "OUT"], "argument OUT_DIR"),
    "own_experiment.py": (["OUT", "--episodes", "1"], "argument out"),
}


def _run(example: str, argv: list[str], monkeypatch, cwd: Path) -> int:
    monkeypatch.chdir(cwd)  # what an example makes of an argument it takes for a folder lands there
    monkeypatch.setattr("sys.argv", [str(EXAMPLES / example), *argv])
    with pytest.raises(SystemExit) as stopped:
        runpy.run_path(str(EXAMPLES / example), run_name="__main__")
    return stopped.value.code


@pytest.mark.parametrize("example", sorted(OUTPUT_ARGUMENTS))
def test_an_output_folder_that_cannot_be_made_is_one_line_naming_it(example, tmp_path, monkeypatch, capsys):
    """`python docs/examples/own_layout.py /proc/x` (a folder no one can make) ended in a FileNotFoundError
    traceback from the recorder's mkdir, after the controllers were built; a folder inside a file, in a
    NotADirectoryError. Both are refused before any work, naming the argument."""
    a_file = tmp_path / "notes.txt"
    a_file.write_text("mine\n")
    argv, named = OUTPUT_ARGUMENTS[example]
    for out, why in ((a_file / "runs", f"{a_file} is not a directory"), (a_file, "not a directory")):
        code = _run(example, [str(out) if a == "OUT" else a for a in argv], monkeypatch, tmp_path)
        err = capsys.readouterr().err
        assert code == 2 and "Traceback" not in err
        assert err.splitlines()[-1] == f"{example}: error: {named} {out}: {why}"
    assert a_file.read_text() == "mine\n"


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_the_own_layout_examples_folder_under_proc_is_refused_as_the_user_met_it(
    tmp_path, monkeypatch, capsys
):
    assert _run("own_layout.py", ["/proc/x"], monkeypatch, tmp_path) == 2
    err = capsys.readouterr().err
    assert err.splitlines()[-1].startswith(
        "own_layout.py: error: argument OUT_DIR /proc/x: cannot create it in"
    )


def test_the_own_layout_example_describes_its_argument(tmp_path, monkeypatch, capsys):
    assert _run("own_layout.py", ["-h"], monkeypatch, tmp_path) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: own_layout.py [-h] [OUT_DIR]\n") and "(runs/own_layout)" in out
    assert _run("own_layout.py", ["a", "b"], monkeypatch, tmp_path) == 2
    assert capsys.readouterr().err.splitlines()[-1] == "own_layout.py: error: unrecognized arguments: b"
    assert not any(tmp_path.iterdir())  # -h was taken for OUT_DIR: a folder "-h" was recorded into
