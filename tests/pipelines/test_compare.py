"""``crowdmpc compare``: sweeps paired on the crowds they share, against numbers worked by hand."""

import json
import math
import os
import re
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.commands.compare import labelled
from pipelines.errors import PipelineError
from pipelines.experiments.paired import Outcome, mcnemar_exact, paired_interval, versus

ENV = {"crowd": "orca", "crossing": "paper", "spawn_separation": 0.5, "formation": "auto", "time_limit": 40.0}


def _record(i: int, success: bool, collision: bool, travel: float, *, method="CMPC", humans=7, **changes):
    """Episode ``i`` of a cell (circle when even, seed i // 2) with the outcomes given; ``changes`` replace
    parts of it: ``env``, ``mpc`` (the config's), ``contact``, ``discomfort``, ``min_distance``."""
    metrics = {
        "success": success,
        "travel_time": travel if success else None,
        "collision": collision,
        "contact": changes.get("contact", False),
        "discomfort": changes.get("discomfort", False),
        "timeout": not success,
        "min_distance": changes.get("min_distance", 1.0),
        "min_distance_robots": 1.0,
        "min_distance_humans": 1.0,
        "path_length": [10.0, 10.0, 10.0],
        "reach_times": [travel] * 3,
        "discomfort_steps": 0,
        "n_steps": 50,
    }
    cell = f"{method.lower()}-constant_velocity-F-ibr-m=none-paper-visible-h{humans}-r3"
    scenario = ("circle", "perpendicular")[i % 2]
    return {
        "seed": i // 2,
        "scenario": scenario,
        "n_humans": humans,
        "n_robots": 3,
        "controller": method.lower(),
        "predictor": "constant_velocity",
        "metrics": metrics,
        "solver": {
            "steps": 50,
            "total_ms": 100.0,
            "median_ms": 2.0,
            "p95_ms": 3.0,
            "max_ms": 4.0,
            "mean_iterations": 2.0,
            "max_iterations": 2,
            "fallback_steps": 0,
        },
        "key": f"{cell}/{scenario}/{i // 2}",
        "cell": cell,
        "method": method,
        "index": i,
        "wall_s": 1.0,
        "profile": "paper",
        "config": {"env": changes.get("env", ENV), "mpc": changes.get("mpc", {"w_coll": 1e7})},
    }


def _sweep(path: Path, records: list[dict], commit: str | None = "0123456789abcdef") -> Path:
    path.mkdir(parents=True)
    (path / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    if commit:
        code = {"commit": commit, "dirty": False}
        (path / "sweep.json").write_text(json.dumps({"experiment": "table2", "runs": [{"code": code}]}))
    return path


# base and new on four crowds: success 1,0,1,1 vs 1,1,0,1; collision 0,1,1,0 vs 0,0,0,0; travel on the two
# both completed (episodes 0 and 3): 10 -> 11 and 9 -> 12
BASE = [(True, False, 10.0), (False, True, 0.0), (True, True, 12.0), (True, False, 9.0)]
NEW = [(True, False, 11.0), (True, False, 13.0), (False, False, 0.0), (True, False, 12.0)]


def test_two_runs_by_hand(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(NEW)])
    assert main(["compare", f"base={a}", f"new={b}", "--json", str(tmp_path / "c.json")]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| CMPC")]
    # base: 3 of 4 succeed, 2 of 4 collide, travel (10 + 12 + 9) / 3 = 10.33
    assert rows[0] == "| CMPC | 7 | 3 | base | 4 | 75.0 | 50.0 | 0.0 | 0.0 | 10.3 |  |  |  |  |  |  |"
    # new: 3 of 4, 0 of 4, (11 + 13 + 12) / 3 = 12; success +1 (episode 1) / -1 (episode 2), McNemar p = 1;
    # collision +0 / -2, p = 2 / 4 = 0.5; travel differences 1 and 3: mean 2, sd sqrt(2), half t95(1) = 12.71
    assert rows[1] == (
        "| CMPC | 7 | 3 | new | 4 | 75.0 | 0.0 | 0.0 | 0.0 | 12.0 | +1 / −1 (p = 1) | +0 / −2 (p = 0.5) "
        "| +0 / −0 (p = 1) | +0 / −0 (p = 1) | +2.00 ± 12.71 (2) | 0 of 4 |"
    )
    report = json.loads((tmp_path / "c.json").read_text())
    against = report["groups"][0]["versus_first"]["new"]
    assert {k: against["collision"][k] for k in ("gained", "lost", "p", "difference_pp")} == {
        "gained": 0,
        "lost": 2,
        "p": 0.5,
        "difference_pp": -50.0,
    }
    assert against["travel_difference"] == {"mean": 2.0, "half_width_95": pytest.approx(12.7062), "n": 2}
    assert report["runs"][0]["code"] == ["0123456789ab"] and report["shared_episodes"] == 4


def test_discomfort_is_paired_as_the_papers_rate_of_episodes(tmp_path, capsys):
    """Discomfort, one of the paper's four metrics (% of episodes in which a robot's projected path crossed a
    human's), was not compared at all: neither rates, nor the paired counts, nor --json. It pairs as the
    other flags do. Base 1,1,0,0 against new 0,1,1,1: 50 % and 75 %, +2 (episodes 2, 3) / −1 (episode 0),
    McNemar p = 2 (C(3,0) + C(3,1)) / 2^3 = 1; one pair with it in both, none in neither."""
    base = [_record(i, *o, discomfort=i < 2) for i, o in enumerate(BASE)]
    new = [_record(i, *o, discomfort=i > 0) for i, o in enumerate(NEW)]
    a, b = _sweep(tmp_path / "a", base), _sweep(tmp_path / "b", new)
    assert main(["compare", f"base={a}", f"new={b}", "--json", str(tmp_path / "c.json")]) == 0
    out = capsys.readouterr().out
    header = next(line for line in out.splitlines() if line.startswith("| method"))
    assert header.split(" | ")[5:10] == ["success %", "collision %", "contact %", "discomfort %", "travel s"]
    rows = [line.split(" | ") for line in out.splitlines() if line.startswith("| CMPC")]
    assert (rows[0][8], rows[1][8]) == ("50.0", "75.0")
    assert rows[1][13] == "+2 / −1 (p = 1)"  # after success, collision and contact's paired counts
    report = json.loads((tmp_path / "c.json").read_text())
    group = report["groups"][0]
    assert [group["runs"][run]["rates"]["discomfort"] for run in ("base", "new")] == [50.0, 75.0]
    against = group["versus_first"]["new"]
    low, high = paired_interval(both=1, gained=2, lost=1, neither=0)
    assert against["discomfort"] == {
        "gained": 2,
        "lost": 1,
        "p": 1.0,
        "difference_pp": 25.0,
        "interval_pp": [100 * low, 100 * high],
    }
    assert against["text"]["discomfort"] == "+2 / −1 (p = 1)"
    # additions only: the keys scripts read before are all still there
    assert {"success", "collision", "contact", "travel_difference", "same_metrics", "text"} <= set(against)


def test_the_code_named_is_that_of_the_runs_the_episodes_name(tmp_path, capsys):
    """A run line no record names (a run stopped before its first episode, a copied `--reuse` line whose
    records a kill cut off) made none of the episodes: its code was listed beside theirs."""
    lines = [{"code": {"commit": commit, "dirty": False}} for commit in ("aaaaaaaaaaaa", "bbbbbbbbbbbb")]
    folders = []
    # records from before they kept their run, or a damaged one's: every line may have made them
    for name, run in (("named", {"run": 2}), ("unnamed", {}), ("damaged", {"run": [2]})):
        path = _sweep(tmp_path / name, [{**_record(i, *o), **run} for i, o in enumerate(BASE)])
        (path / "sweep.json").write_text(json.dumps({"experiment": "table2", "runs": lines}))
        folders.append(path)
    out = tmp_path / "c.json"
    labels = [f"{name}={path}" for name, path in zip("abc", folders, strict=True)]
    assert main(["compare", *labels, "--json", str(out), "--no-progress"]) == 0
    codes = [run["code"] for run in json.loads(out.read_text())["runs"]]
    assert codes == [["bbbbbbbbbbbb"], *[["aaaaaaaaaaaa", "bbbbbbbbbbbb"]] * 2]


def test_mcnemar_and_the_travel_spread_by_hand():
    # 1 vs 3 discordant: 2 (C(4,0) + C(4,1)) / 2^4 = 10 / 16
    assert mcnemar_exact(1, 3) == pytest.approx(0.625)

    def o(success, travel):
        return Outcome(success, False, False, False, travel, "k", b"", b"", frozenset())

    v = versus(
        [o(True, 10.0), o(True, 10.0), o(True, 10.0), o(False, None)], [o(True, 11.0), o(True, 12.0)] * 2
    )
    # differences 1, 2, 1 (base's 4th failed): mean 4/3, sd sqrt(1/3), half t95(2) sqrt(1/3) / sqrt(3)
    assert v.travel_difference == pytest.approx(4 / 3)
    assert v.travel_half_width == pytest.approx(4.302653 / 3)
    assert v.flags["success"].gained == 1 and v.flags["success"].lost == 0


def test_a_method_pairs_whatever_its_case_and_only_on_the_same_crowd(tmp_path, capsys):
    """Table II writes "CMPC", the controllers experiment "cmpc": the same episodes. Another formation (or
    crowd, or profile) places other humans from the same seed: those pair with nothing."""
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [_record(i, *o, method="cmpc") for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(b), "--expect-identical"]) == 0
    assert "identical: 4 episodes, every metric equal" in capsys.readouterr().out
    wedge = {**ENV, "formation": "wedge"}
    c = _sweep(tmp_path / "c", [_record(i, *o, env=wedge) for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(c)]) == 2
    assert "the runs share no episode" in capsys.readouterr().err
    # the same crowds under another label (a --vary column's): said so, where it blamed the crowds
    d = _sweep(tmp_path / "d", [_record(i, *o, method="CMPC w_goal=10") for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(d)]) == 2
    assert one_line_err(capsys).endswith(
        "the runs share no method on the same crowds (episodes pair by their method's label, humans and "
        "robots; a --vary column's label names its value, and --by-cell pairs sweeps by cell): a: CMPC; d: "
        "CMPC w_goal=10\n"
    )


def test_by_cell_pairs_sweeps_columns_of_one_cell_whatever_their_labels(tmp_path, capsys):
    """A --vary column of Table I's value is the plain sweep's cell ("CMPC orca.time_horizon=5.0" and
    "CMPC"): by label the two shared nothing, so the README's claim could not be checked with
    --expect-identical. By cell they pair, shown under the first run's label; another cell pairs with none."""
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    varied = [{**_record(i, *o), "method": "CMPC orca.time_horizon=5.0"} for i, o in enumerate(BASE)]
    b = _sweep(tmp_path / "b", varied)
    assert main(["compare", str(a), str(b), "--by-cell", "--expect-identical"]) == 0
    out = capsys.readouterr().out
    assert "identical: 4 episodes, every metric equal" in out and "| CMPC | 7 | 3 | b | 4 |" in out
    other = [
        {
            **r,
            "cell": f"{r['cell']}-orca.time_horizon=2.0",
            "key": r["key"].replace(r["cell"], f"{r['cell']}-orca.time_horizon=2.0"),
        }
        for r in varied
    ]
    c = _sweep(tmp_path / "c", other)
    assert main(["compare", str(a), str(c), "--by-cell"]) == 2
    assert "the runs share no" in one_line_err(capsys)
    sim = _simulate_json(tmp_path / "run.json", [_record(i, *o) for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(sim), "--by-cell"]) == 2
    assert one_line_err(capsys).endswith(
        f"run: {sim} is no sweep folder: --by-cell pairs sweeps' episodes by cell\n"
    )


def test_by_cell_says_which_cells_the_runs_hold_where_they_share_none(tmp_path, capsys):
    """Table II with the paper's predictor and with constant velocity, --by-cell: "the runs share no method
    on the same crowds (...): a: CMPC; b: CMPC", as if the two shared their one method. The cells, each
    run's as it spells them, the first two named and the rest counted."""
    a = _sweep(tmp_path / "a", [_record(i, *o, humans=h) for h in (5, 6, 7) for i, o in enumerate(BASE)])
    lstm = [_record(i, *o, humans=7) for i, o in enumerate(BASE)]
    b = _sweep(
        tmp_path / "b",
        [
            {**r, **{k: r[k].replace("constant_velocity", "social_lstm_eth") for k in ("cell", "key")}}
            for r in lstm
        ],
    )
    assert main(["compare", str(a), str(b), "--by-cell"]) == 2
    cell = "cmpc-{}-F-ibr-m=none-paper-visible-h{}-r3"
    assert one_line_err(capsys).endswith(
        "the runs share no cell on the same crowds (--by-cell pairs sweeps' episodes by their cell's key, "
        "which names its predictor, margins and settings; without it they pair by method): "
        f"a: {cell.format('constant_velocity', 5)}, {cell.format('constant_velocity', 6)} and 1 more cell; "
        f"b: {cell.format('social_lstm_eth', 7)}\n"
    )


@pytest.mark.parametrize("by_cell", [[], ["--by-cell"]])
def test_a_sweeps_methods_are_listed_in_its_plans_order(tmp_path, capsys, by_cell):
    """`--vary mpc.d_min=0.6,0.65,0.7` run by parallel workers logs 0.65's episodes first: the table and the
    plot listed the methods as their episodes came. A sweep lists them as sweep.json plans its cells; a
    sweep.json without them (older sweeps) keeps the order the episodes came in."""
    values = ["0.6", "0.65", "0.7"]
    records = []
    for i, o in enumerate(BASE):
        for value in ("0.65", "0.7", "0.6"):  # as the workers finished them
            record = _record(i, *o, method=f"CMPC mpc.d_min={value}")
            cell = f"{record['cell']}-mpc.d_min={value}"
            records.append({**record, "cell": cell, "key": record["key"].replace(record["cell"], cell)})
    cells = {r["cell"]: {"key": r["cell"], "method": r["method"], "n_humans": 7} for r in records}
    planned = sorted(cells.values(), key=lambda c: values.index(c["method"].rsplit("=")[-1]))
    code = {"commit": "0123456789abcdef", "dirty": False}
    for name, line in (("planned", {"code": code, "cells": planned}), ("unplanned", {"code": code})):
        path = _sweep(tmp_path / name, records)
        (path / "sweep.json").write_text(json.dumps({"experiment": "table2", "runs": [line]}))
        out = tmp_path / f"{name}.json"
        assert main(["compare", f"a={path}", f"b={path}", "--json", str(out), *by_cell]) == 0
        methods = [g["method"].rsplit("=")[-1] for g in json.loads(out.read_text())["groups"]]
        assert methods == (values if name == "planned" else ["0.65", "0.7", "0.6"])
        rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| CMPC")]
        assert [row.split(" | ")[0].rsplit("=")[-1] for row in rows[::2]] == methods


def test_expect_identical_names_what_differs(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    changed = [_record(i, *o, min_distance=0.9 if i == 2 else 1.0) for i, o in enumerate(BASE)]
    b = _sweep(tmp_path / "b", [*changed, _record(4, True, False, 8.0)])  # one more crowd, one metric moved
    assert main(["compare", str(a), str(b), "--expect-identical"]) == 1
    out, err = capsys.readouterr()
    assert "| 3 of 4 |" in out  # success, collision, contact and travel all equal: the minimum distance moved
    assert "not identical: b holds 1 episode not in every run (e.g. cmpc-" in err
    assert "1 of 4 episodes of b differ from the first run's" in err


def test_the_settings_that_differ_are_listed(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    changed = {"w_coll": 1e6, "a_detail": {"made": "today"}}  # a detail sorts after the setting it is under
    b = _sweep(tmp_path / "b", [_record(i, *o, mpc=changed) for i, o in enumerate(BASE)], commit=None)
    assert main(["compare", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert (
        "Settings b's episodes ran with where they differ from a's:\n  mpc.w_coll: 10000000.0 -> 1000000.0\n"
        '  mpc.a_detail.made: (not recorded) -> "today"'
    ) in out
    assert "b: " + str(b) + ", 4 episodes, code not recorded" in out


def test_json_on_standard_output_is_the_document_alone(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(NEW)])
    assert main(["compare", str(a), str(b), "--json", "-", "--no-progress"]) == 0
    out, err = capsys.readouterr()
    success = json.loads(out)["groups"][0]["versus_first"]["b"]["success"]
    assert (success["gained"], success["lost"], success["p"], success["difference_pp"]) == (1, 1, 1.0, 0.0)
    low, high = success["interval_pp"]  # 3 of 4 both: an interval symmetric about no change
    assert low == pytest.approx(-high) and 0 < high < 100
    assert "| CMPC | 7 | 3 | a |" in err


@pytest.mark.parametrize(
    ("items", "message"),
    [
        (["a"], "give at least two runs to compare"),
        (["x=a", "x=b"], "label 'x' is given twice"),
        (["=a", "b"], "expected [LABEL=]RUN"),
        (["", "b"], "expected [LABEL=]RUN"),
        # a newline or "|" broke the table's rows (a folder so named needs a label of its own)
        (["a\nb=a", "b"], "label 'a\\nb' must be printable text without '|'"),
        (["a|b=a", "b"], "label 'a|b' must be printable text without '|'"),
        (["a|b", "b"], "label 'a|b' must be printable text without '|' (it names the run in the table's"),
    ],
)
def test_labels_are_checked(items, message, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(PipelineError, match=re.escape(message)):
        labelled(items)


def test_a_folder_whose_name_holds_an_equals_sign_is_taken_whole(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "w=1e6").mkdir()
    assert labelled(["w=1e6", "base=b"]) == [("w=1e6", Path("w=1e6")), ("base", Path("b"))]


def test_bad_runs_are_one_line_errors(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    (tmp_path / "empty").mkdir()
    damaged = _sweep(tmp_path / "damaged", [_record(0, *BASE[0])])
    with (damaged / "episodes.jsonl").open("a") as f:
        f.write('{"key": "x", "metrics": []}\n')
    first = _record(0, *BASE[0])  # and the same crowd in another cell of one label
    second = {
        **first,
        "cell": f"{first['cell']}-x",
        "key": first["key"].replace(first["cell"], f"{first['cell']}-x"),
    }
    twice = _sweep(tmp_path / "twice", [first, second])
    piped = tmp_path / "piped"  # its log a pipe: read, it waits for good
    piped.mkdir()
    os.mkfifo(piped / "episodes.jsonl")
    for other, message in [
        (piped, f"{piped / 'episodes.jsonl'} is not a regular file (a folder or a pipe)"),
        (tmp_path / "missing", "does not exist (a sweep folder, a simulate --json file, or recordings"),
        (tmp_path / "empty", "holds no episodes.jsonl"),
        (damaged, "damaged/episodes.jsonl:2: not an episode record"),
        (twice, "holds two episodes of method 'CMPC' on one crowd"),  # and names the way out, by cell
        (twice, "its cells are not told apart by method (use --by-cell)"),
    ]:
        assert main(["compare", str(a), str(other)]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_the_json_output_may_not_replace_a_runs_file(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(NEW)])
    before = (a / "episodes.jsonl").read_bytes()
    assert main(["compare", str(a), str(b), "--json", str(a / "episodes.jsonl")]) == 2
    assert "--json" in capsys.readouterr().err
    assert (a / "episodes.jsonl").read_bytes() == before


def test_a_record_older_than_the_recorded_config_pairs_by_its_profile(tmp_path, capsys):
    """Sweeps recorded no config at first: such an episode ran its profile's placement, the ORCA crowd and
    the automatic formation, and pairs with a new record of those; a v1 record pairs with neither."""

    def old(i, outcome, profile):
        record = _record(i, *outcome)
        del record["config"]
        return record | {"profile": profile}

    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [old(i, o, "paper") for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(b), "--expect-identical"]) == 0
    capsys.readouterr()
    v1 = _sweep(tmp_path / "v1", [old(i, o, "v1") for i, o in enumerate(BASE)])
    for first in (a, b):
        assert main(["compare", str(first), str(v1)]) == 2
        assert "share no episode" in capsys.readouterr().err


def test_an_mpc_option_a_record_predates_reads_as_the_value_it_ran_with(tmp_path, capsys):
    """mpc.flock_distance came after: a record without it ran the one d_flock ("uniform"), so compare named
    "mpc.flock_distance: (not recorded) -> "uniform"" as a difference between two identical runs."""
    old = _sweep(tmp_path / "old", [_record(i, *o, mpc={"w_floc": 10.0}) for i, o in enumerate(BASE)])
    mpc = {"w_floc": 10.0, "flock_distance": "uniform"}
    new = _sweep(tmp_path / "new", [_record(i, *o, mpc=mpc) for i, o in enumerate(BASE)])
    assert main(["compare", str(old), str(new), "--expect-identical"]) == 0
    assert "flock_distance" not in capsys.readouterr().out
    goals = {**mpc, "flock_distance": "goals"}
    other = _sweep(tmp_path / "goals", [_record(i, *o, mpc=goals) for i, o in enumerate(BASE)])
    assert main(["compare", str(old), str(other)]) == 0
    assert 'mpc.flock_distance: "uniform" -> "goals"' in capsys.readouterr().out


def test_a_record_older_than_a_metric_is_compared_on_the_metrics_it_has(tmp_path, capsys):
    """robot_contact came after the first sweeps: a record without it equals one with it where every metric
    both have is equal, and not where one of those differs."""

    def newer(i, outcome, **changes):
        record = _record(i, *outcome, **changes)
        record["metrics"] |= {"robot_contact": False, "robot_contact_steps": 0}
        return record

    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [newer(i, o) for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(b), "--expect-identical"]) == 0
    c = _sweep(tmp_path / "c", [newer(i, o, min_distance=0.7 if i else 1.0) for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(c), "--expect-identical"]) == 1
    assert "| 1 of 4 |" in capsys.readouterr().out


def test_a_damaged_sweep_file_is_noted_and_its_episodes_still_compared(tmp_path, capsys):
    """`sweep --report-only` refuses a sweep.json that does not read; compare passed it by unsaid, showing
    "code not recorded" as of a run from before code was kept."""
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(BASE)], commit=None)
    capsys.readouterr()
    assert main(["compare", str(a), str(b), "--expect-identical"]) == 0
    assert "note:" not in capsys.readouterr().err  # a run without the file: nothing to say
    (b / "sweep.json").write_text("{bad")
    assert main(["compare", str(a), str(b), "--expect-identical"]) == 0
    assert capsys.readouterr().err.startswith(
        f"note: {b / 'sweep.json'}: not a sweep file (JSONDecodeError: Expecting property name enclosed in "
        "double quotes: line 1 column 2 (char 1)); its episodes are compared without the code they ran\n"
    )


def test_the_paired_interval_matches_a_published_example():
    """Cavo et al. (2012) as Fagerland, Lydersen and Laake's "Statistical Analysis of Contingency Tables"
    (2017, chapter 8) gives it: 59 pairs with the outcome in both, 6 in the first alone, 16 in the second
    alone, 80 in neither; Newcombe's square-and-add: -0.0621 (95 % CI -0.1186 to -0.0046)."""
    low, high = paired_interval(both=59, gained=6, lost=16, neither=80)
    assert (round(low, 4), round(high, 4)) == (-0.1186, -0.0046)
    # 0 of n in both runs: an interval of width, not the normal approximation's single point
    low, high = paired_interval(0, 0, 0, 50)
    assert low < 0 < high and high == pytest.approx(-low) and high < 0.08
    assert all(math.isnan(x) for x in paired_interval(0, 0, 0, 0))  # no pair


def test_the_plot_is_drawn_and_its_path_checked_first(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(NEW)])
    assert main(["compare", str(a), str(b), "--plot", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").read_bytes().startswith(b"\x89PNG")
    assert main(["compare", str(a), str(b), "--plot", str(tmp_path / "p.xyz")]) == 2
    assert "--plot" in one_line_err(capsys)
    both = str(tmp_path / "same.png")
    assert main(["compare", str(a), str(b), "--plot", both, "--json", both]) == 2
    assert "name the same file" in one_line_err(capsys)


def one_line_err(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


def _simulate_json(path: Path, records: list[dict], commit: str = "fedcba9876543210") -> Path:
    """A `crowdmpc simulate --json` document of ``records`` (their closed-loop fields, not the sweep's)."""
    sweep_only = ("key", "cell", "method", "index", "wall_s", "profile")
    episodes = [{k: v for k, v in r.items() if k not in sweep_only} for r in records]
    document = {"run": {}, "code": {"commit": commit, "dirty": True}, "summary": {}, "episodes": episodes}
    path.write_text(json.dumps(document), encoding="utf-8")
    return path


def test_a_simulate_json_pairs_with_a_sweep_by_its_controller(tmp_path, capsys):
    """simulate's episodes are its controller's ("cmpc"), a sweep's column "CMPC": the same crowds pair."""
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    sim = _simulate_json(tmp_path / "run.json", [_record(i, *o) for i, o in enumerate(BASE)])
    assert main(["compare", str(a), str(sim), "--expect-identical"]) == 0
    out = capsys.readouterr().out
    assert f"run: {sim}, 4 episodes, code fedcba987654+dirty" in out
    assert "| CMPC | 7 | 3 | run | 4 | 75.0 | 50.0 |" in out


def test_a_simulate_json_that_cannot_pair_is_one_line(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    unseeded = _simulate_json(tmp_path / "unseeded.json", [{**_record(0, *BASE[0]), "seed": None}])
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"groups": []}))
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    for path, message in [
        (unseeded, "episode 0 has no seed: an unseeded run's crowds pair with none"),
        (other, "not a `crowdmpc simulate --json` file (no summary and episodes)"),
        (broken, "not a simulate --json file (JSONDecodeError"),
    ]:
        assert main(["compare", str(a), str(path)]) == 2
        assert message in one_line_err(capsys)


def test_a_setting_a_record_predates_is_no_difference_at_the_value_it_ran_with(tmp_path, capsys):
    """A sweep recorded before `env.robot_spacing` existed ran with none (the formation's own): against a new
    record of none the settings agree; against one spaced 1.3 m, the crowds differ and nothing pairs."""
    old = {k: v for k, v in ENV.items() if k != "robot_spacing"}
    a = _sweep(tmp_path / "a", [_record(i, *o, env=old) for i, o in enumerate(BASE)])
    b = _sweep(
        tmp_path / "b", [_record(i, *o, env={**ENV, "robot_spacing": None}) for i, o in enumerate(BASE)]
    )
    assert main(["compare", str(a), str(b), "--no-progress"]) == 0
    assert "b ran with the settings of a." in capsys.readouterr().out
    c = _sweep(
        tmp_path / "c", [_record(i, *o, env={**ENV, "robot_spacing": 1.3}) for i, o in enumerate(BASE)]
    )
    assert main(["compare", str(a), str(c), "--no-progress"]) == 2
    assert "share no episode" in capsys.readouterr().err


def test_a_sweeps_log_named_for_its_folder_is_its_folder(tmp_path, capsys):
    a = _sweep(tmp_path / "a", [_record(i, *o) for i, o in enumerate(BASE)])
    b = _sweep(tmp_path / "b", [_record(i, *o) for i, o in enumerate(BASE)])
    assert (
        main(["compare", f"a={a}", f"b={b / 'episodes.jsonl'}", "--expect-identical", "--no-progress"]) == 0
    )
    assert f"b: {b}, 4 episodes" in capsys.readouterr().out
    assert labelled([str(b / "episodes.jsonl"), str(a)])[0][0] == "b"  # unlabelled: its folder's name


def test_a_replay_pairs_with_its_reactive_replay_and_no_other_crowd():
    """A replay and its reactive replay draw the same people from a seed (they differ in whether those
    yield): docs/replayed_crowds.md pairs them, and compare refused ("the runs share no episode"); another
    recording, or ORCA's crowd, draws other people."""
    from pipelines.experiments.compare import crowd_identity

    def identity(crowd: str):
        return crowd_identity(_record(0, True, False, 15.0, env={**ENV, "crowd": crowd}))

    assert identity("eth_test") == identity("eth_test_reactive") != identity("hotel_test")
    assert identity("hotel_test_reactive") == identity("hotel_test") != identity("orca")


def test_episodes_of_one_cell_share_their_identitys_strings():
    """A run holds every episode's identity (a million at 1000x Table II): its strings are one object per
    value, not a copy per record as each line's JSON decodes them (908 -> 530 bytes a record)."""
    from pipelines.experiments.compare import crowd_identity

    first, second = (json.loads(json.dumps(_record(i, True, False, 15.0))) for i in (0, 2))  # fresh strings
    one, two = crowd_identity(first), crowd_identity(second)
    assert one[4] != two[4]  # the seeds
    shared = [i for i, part in enumerate(one) if isinstance(part, str)]
    assert len(shared) >= 7 and all(one[i] is two[i] for i in shared)
    assert not hasattr(Outcome(True, False, False, False, 1.0, "k", b"", b"", frozenset()), "__dict__")


def test_a_simulate_json_of_a_sweeps_set_up_reads_as_run_with_its_settings(tmp_path, capsys):
    """simulate's JSON names its sensor in the config alone, and not the replayed file: against a sweep's
    episodes of the same set-up it read as run with no sensor, and the file as null (none)."""
    env = {**ENV, "crowd": "eth_test"}
    records = []
    for i, o in enumerate(BASE):
        record = {**_record(i, *o, env=env), "sensor_range": 3.0, "sensor_tracks": True}
        record["config"]["sensing"] = {"radius_m": 3.0, "report_tracks": True}
        records.append({**record, "crowd_sha256": "ab" * 32})
    a = _sweep(tmp_path / "a", records)
    sweep_only = ("sensor_range", "sensor_tracks", "crowd_sha256")
    sim = _simulate_json(
        tmp_path / "run.json", [{k: v for k, v in r.items() if k not in sweep_only} for r in records]
    )
    assert main(["compare", f"a={a}", f"b={sim}", "--expect-identical", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "sensor_range" not in out and "sensor_tracks" not in out, out
    assert re.search(r"crowd_sha256: \S+ -> \(not recorded\)", out), out
