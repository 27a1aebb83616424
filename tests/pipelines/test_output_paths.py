"""Output paths with ``..`` after a folder that does not exist: ``mkdir(parents=True)`` made that folder to
step out of it, and left it behind empty. Each command now writes its named output and makes nothing else;
a ``..`` after something that exists (a symbolic link) is left for the OS to resolve."""

import os
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.commands.output_paths import output_arg, without_missing_parents
from tests.benchmark_modules import load_benchmark
from tests.cli_calls import parser_error, run_cli
from tests.predictors.samples import write_tiny_ewap, write_walk_file

QUICK_SIMULATE = ["simulate", "--controller", "straight", "--humans", "0", "--episodes", "1", "--no-progress"]


def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


@pytest.mark.parametrize(
    ("given", "expected"),
    [
        ("new/x/../run", "new/run"),
        ("new/x/y/../../run", "new/run"),
        ("new/x/../../run", "run"),
        ("new/..", "."),
        ("../run", "../run"),  # nothing before the "..": the cwd's parent, as written
        ("new/run", "new/run"),
        ("have/x/../run", "have/run"),  # have exists, x not
        ("have/../run", "have/../run"),  # have exists: its ".." is the OS's
    ],
)
def test_only_a_missing_folders_dotdot_goes(given, expected, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "have").mkdir()
    assert without_missing_parents(Path(given)) == Path(expected)
    assert output_arg(given) == Path(expected)
    assert list(tmp_path.iterdir()) == [tmp_path / "have"]  # judging made nothing


def test_an_existing_links_dotdot_is_resolved_as_the_os_does(tmp_path, monkeypatch):
    """link -> real/deep: link/../out.json is real/out.json (the target's parent), not out.json beside the
    link, which a lexical normalisation would give."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "real" / "deep").mkdir(parents=True)
    (tmp_path / "link").symlink_to(tmp_path / "real" / "deep")
    assert without_missing_parents(Path("link/x/../../out.json")) == Path("link/../out.json")
    assert main([*QUICK_SIMULATE, "--json", "link/x/../../out.json"]) == 0
    assert (tmp_path / "real" / "out.json").is_file()
    assert _tree(tmp_path) == {"real", "real/deep", "real/out.json", "link"}


def test_simulate_makes_only_its_outputs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    outputs = ["--json", "J/x/../r.json", "--plot", "P/x/y/../../p.png", "--record", "R/x/../rec"]
    assert main([*QUICK_SIMULATE, *outputs]) == 0
    assert _tree(tmp_path) == {
        "J",
        "J/r.json",
        "P",
        "P/p.png",
        "R",
        "R/rec",
        "R/rec/circle_seed000000.mcap",
    }
    assert "wrote J/r.json" in capsys.readouterr().out


def test_review_makes_only_its_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main([*QUICK_SIMULATE, "--record", "rec"]) == 0
    (recording,) = Path("rec").glob("*.mcap")
    outputs = ["--plot", "P/x/../p.png", "--json", "J/x/../r.json"]
    assert main(["review", str(recording), *outputs]) == 0
    assert _tree(tmp_path) - _tree(tmp_path / "rec") - {"rec"} >= {"P/p.png", "J/r.json"}
    assert not Path("P/x").exists() and not Path("J/x").exists()


def test_train_makes_only_its_run_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    data = write_walk_file(tmp_path / "walk.ndjson")
    argv = ["train", "--model", "vanilla_lstm", "--train", str(data), "--val", str(data), "--no-progress"]
    assert main([*argv, "--epochs", "1", "--limit-batches", "1", "--out", "NP/x/../run"]) == 0
    assert sorted(os.listdir("NP")) == ["run"]
    assert Path("NP/run/checkpoints/last.ckpt").is_file()


def test_data_makes_only_its_outputs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    raw = write_tiny_ewap(tmp_path / "data")
    assert main(["data", "prepare", "--raw", str(raw), "--out", "D/x/../prepared", "--no-check"]) == 0
    assert sorted(os.listdir("D")) == [".prepared.prepare.lock", "prepared"]  # its lock, beside it


def test_a_benchmarks_json_makes_only_its_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    bench_cli = load_benchmark("bench_cli")
    path = bench_cli.output_file("B/x/../r.json")
    assert path == Path("B/r.json")
    bench_cli.write_json(path, {"rows": []})
    assert _tree(tmp_path) == {"B", "B/r.json"}


def test_data_synth_and_export_make_only_their_files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    synth = ["data", "synth", "--episodes", "1", "--humans", "7", "--seed", "0", "--out", "S/x/../s.ndjson"]
    assert main(synth) == 0
    assert "x" not in os.listdir("S") and Path("S/s.ndjson").is_file()
    export = ["export", "vanilla_lstm_eth", "--humans", "1", "--robots", "1", "--horizon", "2"]
    assert main([*export, "--out", "E/x/../m.casadi"]) == 0
    assert os.listdir("E") == ["m.casadi"]


@pytest.mark.parametrize(
    "argv",
    [
        ["data", "synth", "--episodes", "1", "--humans", "7", "--seed", "0", "--out"],
        ["data", "prepare", "--raw", ".", "--out"],
        ["export", "constant_velocity", "--out"],
        ["train", "--model", "social_lstm", "--out"],
        ["review", ".", "--plot"],
        ["compare", "a", "b", "--plot"],
    ],
)
def test_an_output_named_dash_is_refused_as_standard_output(argv, tmp_path, monkeypatch, capsys):
    """``data synth --out -`` (and every output option but ``--json``) made a file or folder called "-",
    where "-" is standard output to every tool and to ``--json -``; "./-" names one called "-"."""
    monkeypatch.chdir(tmp_path)
    line = parser_error(capsys, *argv, "-")
    assert line.endswith(
        f"argument {argv[-1]}: got '-' (standard output), but this output is a file or folder; name one "
        f"(./- for one called '-'); see 'crowdmpc {' '.join(argv[: 2 if argv[0] == 'data' else 1])} --help'"
    )
    assert os.listdir(tmp_path) == []


def test_a_synth_into_a_file_called_dash_names_it_so(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    synth = ["data", "synth", "--episodes", "1", "--humans", "7", "--seed", "0", "--out", "./-"]
    code, out, _ = run_cli(capsys, *synth)
    assert code == 0 and Path("-").is_file() and "path: ./-\n" in out


@pytest.mark.parametrize("ending", ["/", "/."])
@pytest.mark.parametrize(
    "argv",
    [
        ["data", "synth", "--episodes", "1", "--humans", "7", "--seed", "0", "--out"],
        ["export", "constant_velocity", "--out"],
        ["review", "x.mcap", "--plot"],
        ["compare", "a", "b", "--json"],
        [*QUICK_SIMULATE, "--json"],
    ],
)
def test_a_file_output_named_as_a_folder_is_refused(argv, ending, tmp_path, monkeypatch, capsys):
    """``data synth --out runs/`` wrote a file called runs (Path drops the slash), as export --out, the
    --json options and simulate's --json did: an output that is a file, named as a folder, is refused."""
    monkeypatch.chdir(tmp_path)
    given = f"runs{ending}"
    if argv[0] == "simulate":  # read as a setting, not by the parser
        code, _, err = run_cli(capsys, *argv, given)
        assert code == 2 and err == (
            f"crowdmpc simulate: error: --json {given}: a folder, but this output is a file; name a file "
            "in it\n"
        )
    else:
        line = parser_error(capsys, *argv, given)
        assert (
            f"argument {argv[-1]}: got {given!r}, a folder, but this output is a file; name a file in it"
            in line
        )
    assert os.listdir(tmp_path) == []
