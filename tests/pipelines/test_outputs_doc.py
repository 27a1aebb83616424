"""docs/outputs.md, the reference of what the commands write, against what they do write: every field,
column, topic and metadata key of a small sweep, a simulate --json, a recording and a review --json is named
there, and its MCAP example runs as printed."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import re
import shlex
from pathlib import Path

import pytest
from mcap.reader import make_reader

from pipelines.cli import main
from pipelines.logs.schemas import CHANNELS

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "outputs.md"
README = REPO / "README.md"
# cells.csv and the summaries write four columns per rate; the doc names the rate and the four suffixes once
FAMILY = ("_count", "_rate", "_ci_lo", "_ci_hi")


def _documented() -> set[str]:
    return set(re.findall(r"`([^`\s]+)`", DOC.read_text()))


def _undocumented(names, documented: set[str]) -> list[str]:
    def named(name: str) -> bool:
        if name in documented:
            return True
        return any(name.endswith(s) and name[: -len(s)] in documented for s in FAMILY)

    return sorted(n for n in set(names) if not named(n))


def _strict(text: str):
    def refuse(constant: str):
        raise ValueError(f"bare {constant} in JSON")

    return json.loads(text, parse_constant=refuse)


@pytest.fixture(scope="module")
def outputs(tmp_path_factory) -> Path:
    """A recorded baselines sweep, a recorded CMPC simulate with --json, and a review --json of it."""
    root = tmp_path_factory.mktemp("outputs")
    sweep = [
        "sweep",
        "--experiment",
        "baselines",
        "--humans",
        "3",
        "--episodes-per-cell",
        "1",
        "--no-progress",
    ]
    assert main([*sweep, "--backend", "inline", "--record", "all", "--out", str(root / "sw")]) == 0
    # the README's recorded simulate, whose runs/d the MCAP example below reads, with one episode of its 10
    (line,) = [line for line in README.read_text().splitlines() if line.endswith(" --record runs/d")]
    simulate = shlex.split(
        line.replace("--episodes 10", "--episodes 1").replace("runs/d", str(root / "runs/d"))
    )
    outputs = ["--json", str(root / "sim.json"), "--no-progress"]
    assert simulate[0] == "crowdmpc" and main([*simulate[1:], *outputs]) == 0
    assert main(["review", str(root / "runs/d"), "--json", str(root / "review.json")]) == 0
    return root


def test_every_record_field_and_sweep_file_is_documented(outputs):
    doc = _documented()
    record = _strict((outputs / "sw/episodes.jsonl").read_text().splitlines()[0])
    assert _undocumented([*record, *record["metrics"], *record["solver"]], doc) == []
    sweep = _strict((outputs / "sw/sweep.json").read_text())
    assert _undocumented([*sweep, *sweep["runs"][0], *sweep["runs"][0]["code"]], doc) == []
    # ISO 8601's extended form throughout (strftime's %z wrote "+0000", which strict readers refuse)
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d", sweep["runs"][0]["started"])
    assert sweep["runs"][0]["backend"] == "inline"  # the one that ran, as asked here
    files = [p.name for p in (outputs / "sw").iterdir() if not p.name.endswith(".png")]
    assert _undocumented(files, doc) == []


@pytest.mark.parametrize("name", ["cells.csv", "episodes.csv", "min_distance_hist.csv"])
def test_every_csv_column_is_documented(outputs, name):
    with open(outputs / "sw" / name, encoding="utf-8", newline="") as f:
        header = next(csv.reader(f))
    assert _undocumented(header, _documented()) == []


def test_every_simulate_and_review_field_is_documented(outputs):
    doc = _documented()
    sim = _strict((outputs / "sim.json").read_text())
    assert _undocumented([*sim, *sim["run"], *sim["code"], *sim["summary"]], doc) == []
    review = _strict((outputs / "review.json").read_text())
    names = [*review, *review["runs"][0], *review["runs"][0]["solver"], *review["groups"][0]]
    assert _undocumented([*names, *review["totals"], *review["totals"]["ends"]], doc) == []


def test_review_totals_lack_only_the_summary_fields_the_doc_says(outputs):
    """`review --json`'s totals were documented as "the summary's fields above", but hold no iteration counts
    or statuses (those are per run, under its `solver`): a reader looking for `iterations_mean` there found
    none. The doc names the summary fields the totals leave out; they must be exactly the ones left out."""
    pattern = r"`totals` only when .*? the summary's fields above but (.*?), which each run's"
    said = re.search(pattern, " ".join(DOC.read_text().split()))
    assert said is not None, "outputs.md does not say which summary fields review's totals leave out"
    summary = _strict((outputs / "sim.json").read_text())["summary"]
    totals = _strict((outputs / "review.json").read_text())["totals"]
    assert set(re.findall(r"`([^`]+)`", said.group(1))) == set(summary) - set(totals)


def test_review_json_of_several_set_ups_has_totals_per_group_only(tmp_path):
    """outputs.md listed a top-level `totals` in every `review DIR --json`; with two set-ups in the folder
    there is none (each group has its own), as review's --help says: a reader's `review["totals"]` failed."""
    for controller in ("orca", "straight"):
        argv = ["simulate", "--controller", controller, "--humans", "1", "--no-progress"]
        assert main([*argv, "--record", str(tmp_path / "runs" / controller)]) == 0
    assert main(["review", str(tmp_path / "runs"), "--json", str(tmp_path / "review.json")]) == 0
    review = _strict((tmp_path / "review.json").read_text())
    assert "totals" not in review and all("totals" in group for group in review["groups"])
    assert "`totals` only when the folder holds one set-up" in " ".join(DOC.read_text().split())


def test_every_compare_field_is_documented(outputs, tmp_path):
    """`crowdmpc compare --json` of the sweep against a copy with one setting changed in its records."""
    other = tmp_path / "other"
    other.mkdir()
    lines = (outputs / "sw/episodes.jsonl").read_text().splitlines()
    changed = [_strict(line) for line in lines]
    for record in changed:
        record["config"]["env"]["time_limit"] = 1.0
    (other / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in changed))
    assert main(["compare", str(outputs / "sw"), str(other), "--json", str(tmp_path / "c.json")]) == 0
    report = _strict((tmp_path / "c.json").read_text())
    group = report["groups"][0]
    versus = group["versus_first"]["other"]
    names = [*report, *report["runs"][0], *group, *group["runs"]["sw"], *versus, *versus["travel_difference"]]
    names += [*versus["success"], *report["settings_differ"]["other"][0]]
    assert report["settings_differ"]["other"][0]["setting"] == "env.time_limit"
    assert _undocumented(names, _documented()) == []
    # each rate and paired figure named in compare's own section: `discomfort` is a record field above, so a
    # compare that paired it undocumented passed the check over the whole page
    section = DOC.read_text().split("## `crowdmpc compare", 1)[1].split("\n## ", 1)[0]
    named = set(re.findall(r"`([^`\s]+)`", section))
    assert _undocumented([*group["runs"]["sw"]["rates"], *versus, *versus["text"]], named) == []


def test_every_channel_schema_and_metadata_key_of_a_recording_is_documented(outputs):
    doc = _documented()
    with open(outputs / "runs/d/perpendicular_seed000000.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        topics = [c.topic for c in summary.channels.values()]
        schemas = [s.name for s in summary.schemas.values()]
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert sorted(topics) == sorted(CHANNELS)
    fields = [f for s in CHANNELS.values() if s.name.startswith("crowdmpc.") for f in s.schema["properties"]]
    keys = [k for name in ("crowdmpc", "episode") for k in metadata[name]]
    assert _undocumented([*topics, *schemas, *fields, *metadata, *keys], doc) == []


def test_a_single_file_review_json_is_documented(outputs):
    """`review FILE --json` wrote `summary`, `compare` (with --compare) and `check` (with --check), which the
    doc did not name: it described `review DIR --json` alone."""
    recording = next((outputs / "runs/d").glob("*.mcap"))
    argv = ["review", str(recording), "--compare", str(recording), "--check"]
    assert main([*argv, "--json", str(outputs / "review_file.json")]) == 0
    review = _strict((outputs / "review_file.json").read_text())
    names = [*review, *review["summary"], *next(iter(review["check"].values()))]
    assert _undocumented(names, _documented()) == []


def test_the_mcap_example_runs_as_printed(outputs, monkeypatch):
    example = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert example is not None
    monkeypatch.chdir(outputs)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(example.group(1), str(DOC), "exec"), {})
    commit, controller, horizon = printed.getvalue().splitlines()[0].split()
    assert (controller, horizon) == ("dmpc", "4") and commit
    assert re.search(r"^\d+ states; robot 0 starts at \[.*\] m$", printed.getvalue().splitlines()[1])
    assert re.search(r"^success (True|False) min distance \d", printed.getvalue().splitlines()[2])


def test_an_unseen_humans_prediction_is_a_pair_of_nulls_as_documented(tmp_path):
    """outputs.md said `/mpc/prediction`'s `positions` held null for a human the controller did not see, but
    the recording writes `[null, null]` at each step (the schema's point of two numbers or nulls): a reader
    testing `p is None` found every human predicted."""
    argv = ["simulate", "--controller", "cmpc", "--predictor", "constant_velocity", "--humans", "3"]
    argv += ["--robots", "2", "--sensor-range", "1", "--set", "env.time_limit=2", "--no-progress"]
    assert main([*argv, "--record", str(tmp_path)]) == 0
    with open(next(tmp_path.glob("*.mcap")), "rb") as f:
        _, _, message = next(make_reader(f).iter_messages(topics=["/mpc/prediction"]))
    first = _strict(message.data)
    unseen = {tuple(point) for step in first["positions"] for point in step}
    assert unseen == {(None, None)}  # no human within 1 m of a robot at the start
    row = next(line for line in DOC.read_text().splitlines() if line.startswith("| `/mpc/prediction`"))
    assert "`[null, null]` at every step for a human the controller did not see" in row


def test_the_documented_cell_key_is_the_one_a_sweep_makes(tmp_path, capsys):
    """outputs.md's cell key left out the `[mpc]` values a cell sets (`-w_goal=20.0`, after the coupling) and
    did not say that the simulator settings come before the humans and robots: a reader who built a key by it
    (to find a cell's records or its mcap/ folder) built one that no sweep writes."""
    said = re.search(
        r"`--set mpc.w_goal=20 --set env.time_limit=50` makes .*? `([^`]+)`",
        " ".join(DOC.read_text().split()),
    )
    assert said is not None, "outputs.md gives no cell key of a sweep with --set"
    argv = ["sweep", "--experiment", "table2", "--humans", "5", "--episodes-per-cell", "2", "--dry-run"]
    argv += ["--set", "mpc.w_goal=20", "--set", "env.time_limit=50", "--out", str(tmp_path / "sw")]
    assert main(argv) == 0
    printed = capsys.readouterr()
    assert said.group(1) in (printed.out + printed.err).split()
