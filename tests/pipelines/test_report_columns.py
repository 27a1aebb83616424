"""A sweep's report read from its log a record at a time (pipelines.experiments.cell_columns,
pipelines.commands.sweep_log_read.read_log): the same files as the report of the records held whole, in memory
that does not grow by a record's size per episode; and a resume's checks (pipelines.experiments.resume_checks)
read the same way."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import math
import random
import tracemalloc
from array import array
from pathlib import Path

import pytest

from pipelines.commands.sweep_log_read import read_log
from pipelines.commands.sweep_report import report
from pipelines.commands.sweep_table_notes import code_note
from pipelines.errors import PipelineError
from pipelines.experiments import log as log_module
from pipelines.experiments.cell_columns import COUNTS, FLAGS, FLOATS, Column
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.log import EPISODES_FILE, SWEEP_FILE, EpisodeLog
from pipelines.experiments.report import write_report
from pipelines.experiments.sweep import run_sweep
from pipelines.experiments.sweep_config import SweepConfig
from pipelines.experiments.tasks import scenario_schedule

REPORT_FILES = ("cells.csv", "episodes.csv", "table.md", "min_distance_hist.csv")


@pytest.mark.parametrize(
    ("kind", "values"),
    [
        (FLOATS, [1.5, None, 0.0, -2.25, math.inf]),
        (FLOATS, [1.5, None, 3, 2.0]),  # an integer where floats were: read back an integer
        (FLOATS, [1.5, math.nan, None]),  # a NaN is no null
        (COUNTS, [0, None, 7, 2**63 - 1]),
        (COUNTS, [0, 2**70, None]),  # past 64 bits
        (COUNTS, [1, 2.5, True]),
        (FLAGS, [True, None, False]),
        (FLAGS, [True, 1, None]),  # an integer is no boolean
    ],
)
def test_a_column_reads_back_every_value_as_it_was_given(kind, values):
    column = Column(kind)
    for value in values:
        column.append(value)
    back = [column[i] for i in range(len(column))]
    assert [(type(v), v) for v in back if not (isinstance(v, float) and math.isnan(v))] == [
        (type(v), v) for v in values if not (isinstance(v, float) and math.isnan(v))
    ]
    assert [isinstance(v, float) and math.isnan(v) for v in back] == [
        isinstance(v, float) and math.isnan(v) for v in values
    ]


def test_a_column_of_its_own_kind_is_a_machine_array():
    """8 bytes a value (1 a flag), not a Python object each: the point of the columns."""
    for kind, values in ((FLOATS, [1.0, None]), (COUNTS, [3, None]), (FLAGS, [False, None])):
        column = Column(kind)
        for value in values:
            column.append(value)
        assert isinstance(column.values, array)


def _lines(records):
    return "".join(json.dumps(r, separators=(",", ":")) + "\n" for r in records)


def test_keys_of_one_hash_are_two_records_and_a_repeated_key_is_refused_at_its_line(tmp_path, monkeypatch):
    """The log remembers each key's hash, not the key: equal hashes are told apart by the keys themselves."""
    monkeypatch.setattr(log_module, "hash", lambda key: 0, raising=False)  # every key one hash
    path = tmp_path / EPISODES_FILE
    path.write_text(_lines([{"key": "a"}, {"key": "b"}, {"key": "c"}]))
    assert list(EpisodeLog(path).load()) == ["a", "b", "c"]
    path.write_text(_lines([{"key": "a"}, {"key": "b"}, {"key": "a"}]))
    with pytest.raises(PipelineError, match=r":3: a second record for 'a'"):
        EpisodeLog(path).load()


def test_scan_gives_each_records_line_and_offset(tmp_path):
    path = tmp_path / EPISODES_FILE
    path.write_text(_lines([{"key": "a"}, {"key": "b"}]) + "\n" + _lines([{"key": "c"}]))
    data = path.read_bytes()
    for offset, line, record in EpisodeLog(path).scan():
        assert data[offset : offset + len(line)] == line and json.loads(line) == record


def _sweep(out: Path, per_cell: int = 2) -> SweepConfig:
    config = SweepConfig(
        get_experiment("baselines"), out, per_cell, humans=(3,), backend="inline", progress=False
    )
    run_sweep(config)
    return config


def _multiplied(seed: SweepConfig, out: Path, per_cell: int, shuffle: bool = False) -> SweepConfig:
    """``out``: a sweep of ``per_cell`` episodes a cell, each a copy of one of ``seed``'s records under the
    plan's key (benchmarks/sweep_log_scale.py's), in a shuffled order with ``shuffle``."""
    out.mkdir()
    records = list(EpisodeLog(seed.out / EPISODES_FILE).load().values())
    by_cell: dict[str, list[dict]] = {}
    for record in sorted(records, key=lambda r: r["index"]):
        by_cell.setdefault(record["cell"], []).append(record)
    copies = []
    for i, (scenario, seed_number) in enumerate(scenario_schedule(per_cell, seed.seed)):
        for cell, kept in by_cell.items():
            copy = kept[i % len(kept)] | {"index": i, "seed": seed_number, "scenario": scenario}
            copy["key"] = f"{cell}/{scenario}/{seed_number}"
            copy["metrics"] = copy["metrics"] | {"min_distance": 0.5 + (i % 97) / 31}  # distinct figures
            copy["solver"] = copy["solver"] | {"total_ms": 1.0 + i / 7}
            copies.append(copy)
    if shuffle:
        random.Random(0).shuffle(copies)
    (out / EPISODES_FILE).write_text(_lines(copies))
    meta = json.loads((seed.out / SWEEP_FILE).read_text())
    (out / SWEEP_FILE).write_text(json.dumps(meta))
    return SweepConfig(seed.experiment, out, per_cell, humans=(3,), backend="inline", progress=False)


def _report(config: SweepConfig) -> str:
    cells = config.experiment.cells(config.humans, config.n_robots)
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        report(config, cells, config.tasks())
    return printed.getvalue()


@pytest.mark.parametrize("shuffle", [False, True])
def test_the_report_of_a_log_is_that_of_its_records_held_whole(tmp_path, shuffle):
    """Every file byte for byte, the plots' data too (the PNGs): the columns hold each value as read."""
    config = _multiplied(_sweep(tmp_path / "seed"), tmp_path / "log", 40, shuffle=shuffle)
    printed = _report(config)
    cells = config.experiment.cells(config.humans, config.n_robots)
    whole = tmp_path / "whole"
    whole.mkdir()
    records = list(EpisodeLog(config.out / EPISODES_FILE).load().values())
    held = write_report(whole, config.experiment, cells, records)
    # the sweep's report ends with its code, from sweep.json, which a report of records alone has not
    code = code_note(config.out)
    assert code.startswith("Code: commit ")
    assert printed.strip() == (held.markdown + f"\n{code}\n").strip()
    names = [p.name for p in held.files]
    assert set(REPORT_FILES) <= set(names) and any(n.endswith(".png") for n in names)
    for name in names:
        expected = (whole / name).read_bytes() + (f"\n{code}\n".encode() if name == "table.md" else b"")
        assert (config.out / name).read_bytes() == expected, name


def test_a_log_replaced_while_the_report_reads_it_is_refused(tmp_path):
    config = _multiplied(_sweep(tmp_path / "seed"), tmp_path / "log", 3)
    cells = config.experiment.cells(config.humans, config.n_robots)
    log = read_log(config, cells, config.tasks())
    from pipelines.commands.sweep_log_read import episode_rows

    path = config.out / EPISODES_FILE
    path.write_bytes(path.read_bytes().replace(b'"success":true', b'"success":fals', 1))
    with pytest.raises(PipelineError, match="changed while the report read it"):
        list(episode_rows(path, cells, log))


def _peak_kb(config: SweepConfig) -> float:
    tracemalloc.start()
    try:
        _report(config)
        return tracemalloc.get_traced_memory()[1] / 1024
    finally:
        tracemalloc.stop()


def test_the_reports_memory_does_not_grow_by_a_record_per_episode(tmp_path):
    """A record (its config left out) held 3.7 KB of Python objects; 4.1 GB at a million episodes. The
    report's peak grows by far less than a record an episode: measured between two logs, so that what the
    report holds at any size (its plots) cancels out."""
    seed = _sweep(tmp_path / "seed")
    small = _multiplied(seed, tmp_path / "small", 100)
    large = _multiplied(seed, tmp_path / "large", 1100)
    _peak_kb(small)  # the first report imports matplotlib's fonts
    extra_episodes = 2 * (1100 - 100)
    per_episode = (_peak_kb(large) - _peak_kb(small)) / extra_episodes
    assert per_episode < 1.5, f"{per_episode:.2f} KB more an episode"


def _resume_peak_kb(config: SweepConfig) -> float:
    tracemalloc.start()
    try:
        outcome = run_sweep(config)
        assert outcome.ran == 0 and outcome.already_done == outcome.planned
        return tracemalloc.get_traced_memory()[1] / 1024
    finally:
        tracemalloc.stop()


def test_a_resumes_memory_does_not_grow_by_a_record_per_episode(tmp_path):
    """A resume held each record's key, predictor and margins while it planned the rest: its peak grew 1.31
    KB an extra episode here (tracemalloc), 0.73 KB reading them a record at a time, the plan itself (its
    tasks, their index by key) most of it."""
    seed = _sweep(tmp_path / "seed")
    small = _multiplied(seed, tmp_path / "small", 100)
    large = _multiplied(seed, tmp_path / "large", 1100)
    for config in (small, large):  # a planning method's records state their margins in their config
        path = config.out / EPISODES_FILE
        records = [json.loads(line) for line in path.read_text().splitlines()]
        for r in records:
            r["config"] = {"margins": {"margins_m": [], "classes": None}, "mpc": {"horizon": 4}}
        path.write_text(_lines(records))
    _resume_peak_kb(small)  # imports
    per_episode = (_resume_peak_kb(large) - _resume_peak_kb(small)) / (2 * (1100 - 100))
    assert per_episode < 1.0, f"{per_episode:.2f} KB more an episode"


def test_a_resume_names_the_first_planned_episode_whose_margins_changed_whatever_the_logs_order(tmp_path):
    """The checks see each distinct margin set once, with the first planned episode that states it: the
    error names that one, as a check over the plan's episodes in order does, in any order of the log."""
    config = _multiplied(_sweep(tmp_path / "seed"), tmp_path / "log", 6, shuffle=True)
    path = config.out / EPISODES_FILE
    records = [json.loads(line) for line in path.read_text().splitlines()]
    first_cell = config.experiment.cells(config.humans, config.n_robots)[0].key
    for r in records:
        margins = [0.3] if r["index"] < 2 else [0.2]
        if r["cell"] == first_cell:
            r["config"] = {"margins": {"margins_m": margins, "classes": None}}
    path.write_text(_lines(records))
    with pytest.raises(PipelineError, match=rf"episodes of {first_cell} planned with margins \[0.3\] m"):
        run_sweep(config)


def test_episodes_csv_of_a_log_lists_a_cell_named_twice_once_as_of_records_held_whole(tmp_path):
    """report.episode_rows sorts by a cell's place (its last) and labels it with its last label."""
    from pipelines.commands.sweep_log_read import episode_rows
    from pipelines.experiments.report import episode_rows as held_rows

    config = _multiplied(_sweep(tmp_path / "seed"), tmp_path / "log", 3, shuffle=True)
    first, second = config.experiment.cells(config.humans, config.n_robots)
    cells = (first, second, dataclasses.replace(first, method="again"))
    log = read_log(config, cells, config.tasks())
    rows = list(episode_rows(config.out / EPISODES_FILE, cells, log))
    records = EpisodeLog(config.out / EPISODES_FILE).load().values()
    assert rows == list(held_rows(records, cells)) and len(rows) == 6
    assert [r["method"] for r in rows] == [second.method] * 3 + ["again"] * 3
