"""benchmarks/paired_runs.py: sweeps compared on the episodes they share, against numbers worked by hand."""

import csv
from pathlib import Path

import pytest

from tests.benchmark_modules import load_benchmark

paired_runs = load_benchmark("paired_runs")
FIELDS = ["method", "n_humans", "scenario", "seed", "success", "collision", "travel_time"]


def _run(path: Path, outcomes: list[tuple[bool, bool, float]], method: str = "CMPC") -> Path:
    path.mkdir()
    with (path / "episodes.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(FIELDS)
        for seed, (success, collision, travel) in enumerate(outcomes):
            writer.writerow([method, 7, "circle", seed, success, collision, travel])
    return path


def test_two_runs_on_their_shared_episodes(tmp_path, capsys):
    a = _run(
        tmp_path / "a", [(True, False, 10.0), (False, True, 0.0), (True, True, 12.0), (True, False, 9.0)]
    )
    b = _run(tmp_path / "b", [(True, False, 11.0), (True, False, 13.0), (False, False, 0.0)])  # 3 shared
    assert paired_runs.main([f"base={a}", f"new={b}"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1]
    # base: 2 of 3 succeed, 2 of 3 collide, travel (10 + 12) / 2; new: 2 of 3, 0, (11 + 13) / 2; +1 / -1.
    assert row == "| CMPC | 7 (3) | 66.7 / 66.7 / 11.0 | 66.7 / 0.0 / 12.0 | +1 / −1 (p = 1) |"
    with pytest.raises(paired_runs.PipelineError, match="no such file"):
        paired_runs.main([f"base={a}", f"new={tmp_path}"])


def test_a_method_is_the_same_whatever_its_case(tmp_path, capsys):
    """Table II writes "CMPC", the controllers experiment "cmpc": the same episodes, named as run one."""
    a = _run(tmp_path / "a", [(True, False, 10.0), (False, False, 0.0)])
    b = _run(tmp_path / "b", [(True, False, 12.0), (True, False, 14.0)], method="cmpc")
    assert paired_runs.main([f"table2={a}", f"controllers={b}"]) == 0
    row = capsys.readouterr().out.strip().splitlines()[-1]
    assert row == "| CMPC | 7 (2) | 50.0 / 0.0 / 10.0 | 100.0 / 0.0 / 13.0 | +1 / −0 (p = 1) |"


@pytest.mark.parametrize(
    ("labels", "message"),
    [
        # the second "base" replaced the first: two runs compared, the first given never read
        (["base=c", "new=a", "base=a"], "label 'base' is given twice (c and a)"),
        (["a=a", "a=a"], "label 'a' is given twice"),  # was "give at least two runs"
    ],
)
def test_a_label_given_twice_is_refused(labels, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in ("a", "c"):
        _run(tmp_path / name, [(True, False, 10.0)])
    with pytest.raises(SystemExit) as stop:
        paired_runs.main(labels)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err


def test_a_csv_without_a_column_or_with_a_bad_row_is_a_one_line_error(tmp_path, capsys):
    """A missing column was a KeyError traceback."""
    a = _run(tmp_path / "a", [(True, False, 10.0)])
    short = tmp_path / "short"
    short.mkdir()
    (short / "episodes.csv").write_text("method,n_humans,scenario,seed,success\nCMPC,7,circle,0,True\n")
    assert paired_runs.run_main(lambda: paired_runs.main([f"a={a}", f"b={short}"])) == 2
    err = capsys.readouterr().err
    assert f"error: {short / 'episodes.csv'}: no column collision, travel_time (not a `crowdmpc sweep`" in err
    (short / "episodes.csv").write_text(",".join(FIELDS) + "\nCMPC,seven,circle,0,True,False,1.0\n")
    assert paired_runs.run_main(lambda: paired_runs.main([f"a={a}", f"b={short}"])) == 2
    assert f"{short / 'episodes.csv'}, line 2: not an episode's row" in capsys.readouterr().err


def test_runs_of_another_profile_or_team_share_no_crowd(tmp_path, capsys):
    """The paper profile and v1 draw other humans from a seed, and so do 3 and 6 robots (crowdsim.scenarios):
    a table2 sweep under --profile v1 was paired with one under paper episode by episode ("+1 / −1" at 9
    humans), as if on the same crowds. The profile column and the cell key's robots ("-r3") are part of an
    episode's identity: such runs share none, which is an error naming them; runs of one profile and team
    pair as before."""

    def run(name: str, profile: str, robots: int) -> Path:
        path = tmp_path / name
        path.mkdir()
        with (path / "episodes.csv").open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow([*FIELDS, "profile", "cell"])
            for seed, success in enumerate((True, False)):
                cell = f"cmpc-social_lstm_eth-F-ibr-m=none-{profile}-visible-h7-r{robots}"
                writer.writerow(["CMPC", 7, "circle", seed, success, False, 10.0, profile, cell])
        return path

    paper, v1, six = run("paper", "paper", 3), run("v1", "v1", 3), run("six", "paper", 6)
    for other in (v1, six):
        with pytest.raises(paired_runs.PipelineError, match=r"share no episode .*profile, robots"):
            paired_runs.main([f"a={paper}", f"b={other}"])
    again = run("again", "paper", 3)
    assert paired_runs.main([f"a={paper}", f"b={again}"]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1].endswith("| +0 / −0 (p = 1) |")
