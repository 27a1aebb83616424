"""The report's safety side: per-step frequencies by hand, old records, the histogram's counts, the plots."""

from __future__ import annotations

import csv
import math

import pytest

from pipelines.experiments.cells import Experiment, get_experiment
from pipelines.experiments.report import CELLS_CSV, EPISODES_CSV, write_report
from pipelines.experiments.safety_report import (
    HIST_EDGES,
    MIN_DISTANCE_HIST_CSV,
    MIN_DISTANCE_HIST_PNG,
    SAFETY_TRADEOFF_PNG,
    added_flag_count,
    min_distance_counts,
    step_frequency,
    world_note,
)
from pipelines.experiments.summary import summarize
from pipelines.experiments.tables import markdown_table
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.margins import MarginSpec

NEW_KEYS = ("collision_steps", "contact_steps")


def _record(cell, i, min_distance, n_steps, steps=(0, 0, 0), *, success=True, collision=None, old=False):
    """An episodes.jsonl line; ``steps`` = (collision, contact, discomfort) step counts. ``old``: as written
    before the step counts and the margins / profile / visibility fields existed."""
    collision_steps, contact_steps, discomfort_steps = steps
    metrics = {
        "success": success,
        "travel_time": 15.0 + i if success else None,
        "collision": collision_steps > 0 if collision is None else collision,
        "contact": contact_steps > 0,
        "discomfort": discomfort_steps > 0,
        "timeout": not success,
        "min_distance": min_distance,
        "discomfort_steps": discomfort_steps,
        "collision_steps": collision_steps,
        "contact_steps": contact_steps,
        "n_steps": n_steps,
    }
    record = {
        "key": f"{cell.key}/{i}",
        "cell": cell.key,
        "method": cell.method,
        "n_humans": cell.n_humans,
        "scenario": ("circle", "perpendicular")[i % 2],
        "seed": i // 2,
        "margins": cell.spec.margins.label,
        "profile": cell.world.profile,
        "visibility": cell.world.visibility,
        "metrics": metrics,
        "solver": {
            "steps": n_steps,
            "total_ms": 10.0 * n_steps,
            "median_ms": 10.0,
            "p95_ms": 20.0,
            "max_ms": 30.0,
            "mean_iterations": 2.0,
            "max_iterations": 3,
            "fallback_steps": 0,
            "statuses": {"ok": n_steps},
        },
        "wall_s": 1.0,
    }
    if old:
        for key in (*NEW_KEYS, "discomfort_steps"):
            del metrics[key]
        for key in ("margins", "profile", "visibility"):
            del record[key]
    return record


def _safety_records(old: bool = False):
    """The safety experiment's first two cells: "none" with hand-chosen counts, "alpha=0.5" without
    collisions. "none": states 10 + 20 + 30 = 60; collision steps 3 + 0 + 3 = 6 (10 %), contact 1 + 0 + 2 = 3
    (5 %), discomfort 6 + 0 + 6 = 12 (20 %); minima 0.5, 1.2, 0.7 -> median 0.7."""
    safety = get_experiment("safety")
    none, half = safety.cells()[:2]
    records = [
        _record(none, 0, 0.5, 9, (3, 1, 6), success=False, old=old),
        _record(none, 1, 1.2, 19, old=old),
        _record(none, 2, 0.7, 29, (3, 2, 6), old=old),
    ]
    records += [_record(half, i, 1.0 + 0.5 * i, 20, old=old) for i in range(4)]
    return safety, [none, half], records


def test_step_frequencies_by_hand():
    safety, cells, records = _safety_records()
    none, half = summarize(safety, cells, records)
    assert none.collision_step_freq == pytest.approx(10.0)
    assert none.contact_step_freq == pytest.approx(5.0)
    assert none.discomfort_step_freq == pytest.approx(20.0)
    assert none.min_distance_median == pytest.approx(0.7)
    assert (half.collision_step_freq, half.min_distance_median) == (0.0, pytest.approx(1.75))

    table = markdown_table(safety, [none, half]).splitlines()
    assert "| Collision per step (%) | 10.00 | 0.00 |" in table
    assert "| Min robot-human distance, median (m) | 0.70 | 1.75 |" in table
    # The methods differ in their margins only: shared conventions in the notes, margins in a row.
    assert "Margins: per column; profile paper, robots visible to the humans" in "\n".join(table)
    assert "| Margins / profile / visibility | none / paper / visible | cp0.5 / paper / visible |" in table


def test_step_frequency_needs_every_count():
    rows = [{"collision_steps": 2, "n_steps": 4}, {"collision_steps": 0, "n_steps": 14}]
    assert step_frequency(rows, "collision") == pytest.approx(100.0 * 2 / 20)
    assert math.isnan(step_frequency([*rows, {"n_steps": 9}], "collision"))  # one old record: no rate
    assert math.isnan(step_frequency([*rows, {"collision_steps": 1}], "collision"))  # nor without n_steps
    assert math.isnan(step_frequency([], "collision"))


def test_cells_and_episodes_csv_carry_the_new_columns(tmp_path):
    safety, cells, records = _safety_records()
    write_report(tmp_path, safety, cells, records)
    with open(tmp_path / CELLS_CSV, encoding="utf-8") as f:
        first = next(csv.DictReader(f))
    assert (first["margins"], first["profile"], first["visibility"]) == ("none", "paper", "visible")
    assert float(first["collision_step_freq"]) == pytest.approx(10.0)
    assert float(first["contact_step_freq"]) == pytest.approx(5.0)
    assert float(first["discomfort_step_freq"]) == pytest.approx(20.0)
    assert float(first["min_distance_median"]) == pytest.approx(0.7)
    with open(tmp_path / EPISODES_CSV, encoding="utf-8") as f:
        episodes = list(csv.DictReader(f))
    assert [(e["collision_steps"], e["contact_steps"]) for e in episodes[:3]] == [
        ("3", "1"),
        ("0", "0"),
        ("3", "2"),
    ]
    assert episodes[3]["margins"] == "cp0.5"


def test_episodes_csv_has_the_team_and_the_discomfort_steps_that_cells_csv_counts(tmp_path):
    """episodes.csv had neither `n_robots` (a --robots sweep's rows did not say their team) nor
    `discomfort_steps`, whose sum over a cell's states is cells.csv's `discomfort_step_freq` (20 % for "none":
    6 + 0 + 6 of 60 states). A record without them (hand-made, or older) leaves its cells empty."""
    safety, cells, records = _safety_records()
    for r in records[:3]:
        r["n_robots"] = 3
    write_report(tmp_path, safety, cells, records)
    with open(tmp_path / EPISODES_CSV, encoding="utf-8") as f:
        episodes = list(csv.DictReader(f))
    assert [(e["n_robots"], e["discomfort_steps"]) for e in episodes[:4]] == [
        ("3", "6"),
        ("3", "0"),
        ("3", "6"),
        ("", "0"),
    ]
    states = sum(int(e["n_steps"]) + 1 for e in episodes[:3])
    with open(tmp_path / CELLS_CSV, encoding="utf-8") as f:
        first = next(csv.DictReader(f))
    assert float(first["discomfort_step_freq"]) == pytest.approx(100 * 12 / states)
    old = _safety_records(old=True)
    (tmp_path / "old").mkdir()
    write_report(tmp_path / "old", *old)
    with open(tmp_path / "old" / EPISODES_CSV, encoding="utf-8") as f:
        assert {(e["n_robots"], e["discomfort_steps"]) for e in csv.DictReader(f)} == {("", "")}


def test_old_records_without_the_new_keys_still_report(tmp_path):
    safety, cells, records = _safety_records(old=True)
    report = write_report(tmp_path, safety, cells, records)
    none, _ = summarize(safety, cells, records)
    assert math.isnan(none.collision_step_freq) and math.isnan(none.discomfort_step_freq)
    assert none.min_distance_median == pytest.approx(0.7)  # min_distance has always been recorded
    assert "| Collision per step (%) | — | — |" in report.markdown.splitlines()
    with open(tmp_path / CELLS_CSV, encoding="utf-8") as f:
        assert next(csv.DictReader(f))["collision_step_freq"] == ""
    with open(tmp_path / EPISODES_CSV, encoding="utf-8") as f:
        first = next(csv.DictReader(f))
    assert (first["collision_steps"], first["margins"], first["visibility"]) == ("", "", "")

    # A cell mixing old and new records gives no per-step rate rather than one over part of the cell.
    _, _, new = _safety_records()
    mixed = summarize(safety, cells, records[:1] + new[1:])
    assert math.isnan(mixed[0].collision_step_freq)
    assert mixed[1].collision_step_freq == 0.0


def test_histogram_counts_every_episode_once(tmp_path):
    safety, cells, records = _safety_records()
    records.append(_record(cells[1], 4, None, 20))  # null minimum (no human): the overflow bin
    write_report(tmp_path, safety, cells, records)
    with open(tmp_path / MIN_DISTANCE_HIST_CSV, encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    per_cell: dict[str, int] = {}
    for row in rows:
        per_cell[row["cell"]] = per_cell.get(row["cell"], 0) + int(row["episodes"])
    assert per_cell == {cells[0].key: 3, cells[1].key: 5}
    assert len(rows) == 2 * len(HIST_EDGES)  # 60 bins of 0.05 m up to 3 m, then the overflow
    none = [r for r in rows if r["cell"] == cells[0].key]
    assert {(r["bin_lo_m"], r["bin_hi_m"]) for r in none if r["episodes"] != "0"} == {
        ("0.5", "0.55"),
        ("0.7", "0.75"),
        ("1.2", "1.25"),
    }
    # Bins are [lo, hi): 1.0 m in bin 20, 2.99 m in the last 0.05 m bin; 3 m and no human in the overflow.
    assert list(min_distance_counts([1.0, 2.99, 3.0, math.inf])[[20, 59, 60]]) == [1, 1, 2]
    assert (none[-1]["bin_lo_m"], none[-1]["bin_hi_m"]) == ("3.0", "inf")


def test_write_report_writes_both_plots(tmp_path):
    safety, cells, records = _safety_records()
    report = write_report(tmp_path, safety, cells, records)
    names = {p.name for p in report.files}
    assert {MIN_DISTANCE_HIST_PNG, SAFETY_TRADEOFF_PNG, MIN_DISTANCE_HIST_CSV} <= names
    assert {"cells.csv", "table.md", "success_by_method.png", "collision_by_method.png"} <= names
    for name in (MIN_DISTANCE_HIST_PNG, SAFETY_TRADEOFF_PNG):
        data = (tmp_path / name).read_bytes()
        assert data.startswith(b"\x89PNG") and len(data) > 1000


def _tiny(methods: int) -> Experiment:
    """Two crowd sizes, ``methods`` methods, every one with the same conventions."""
    labels = ("A", "B", "C")[:methods]
    return Experiment(
        name="tiny",
        title="Tiny",
        methods=tuple((label, ControllerSpec("cmpc", margins=MarginSpec())) for label in labels),
        humans=(5, 6),
    )


def test_several_crowd_sizes_and_a_single_method(tmp_path):
    for methods in (2, 1):
        experiment = _tiny(methods)
        cells = experiment.cells()
        records = [_record(c, i, 0.4 + 0.3 * i, 20, (i, 0, 0)) for c in cells for i in range(3)]
        out = tmp_path / str(methods)
        out.mkdir()
        report = write_report(out, experiment, cells, records)
        names = {p.name for p in report.files}
        assert MIN_DISTANCE_HIST_PNG in names and (out / MIN_DISTANCE_HIST_PNG).stat().st_size > 0
        # Nothing to trade off with one method per crowd size.
        assert (SAFETY_TRADEOFF_PNG in names) == (methods == 2) == (out / SAFETY_TRADEOFF_PNG).exists()
        assert "Margins: none; profile paper, robots visible to the humans." in report.markdown
        assert "| Margins / profile / visibility |" not in report.markdown


def test_world_note_of_the_conventions_experiment():
    cells = get_experiment("conventions").cells()
    line, worlds = world_note(cells)
    assert line == (
        "Margins: per column; profile per column, robot visibility per column "
        "(row 'Margins / profile / visibility')."
    )
    assert worlds is not None and worlds[:2] == ["none / v1 / visible", "cp0.1 / v1 / visible"]


def test_world_note_names_the_mpc_settings_every_column_shares():
    """A safe-crossing sweep's table said only "Margins: cps0.05", like a sweep with the margins alone; the
    settings every column shares beside Table I's are named, those of one column only are not."""
    import dataclasses

    def with_settings(cell, *settings):
        spec = dataclasses.replace(cell.spec, mpc_overrides=(*cell.spec.mpc_overrides, *settings))
        return dataclasses.replace(cell, spec=spec)

    cells = get_experiment("table2").cells()
    assert world_note(cells)[0] == "Margins: none; profile paper, robots visible to the humans."
    shared = (("guidance", "standing"), ("stall_release_s", 4.0))
    cells = [with_settings(c, *shared, *((("j_max", 5),) if i == 0 else ())) for i, c in enumerate(cells)]
    line, worlds = world_note(cells)
    assert line == (
        "Margins: none; profile paper, robots visible to the humans. "
        "MPC settings: guidance=standing, stall_release_s=4.0."
    )
    assert worlds is None


def test_episodes_csv_is_in_the_plans_order_whatever_order_the_workers_finished_in(tmp_path):
    safety, cells, records = _safety_records()
    for name, order in (("a", records), ("b", records[::-1])):
        (tmp_path / name).mkdir()
        write_report(tmp_path / name, safety, cells, order)
    first = (tmp_path / "a" / EPISODES_CSV).read_text()
    assert first == (tmp_path / "b" / EPISODES_CSV).read_text()
    assert [line.split(",")[0] for line in first.splitlines()[1:4]] == [r["key"] for r in records[:3]]


def test_cells_csv_gives_the_collision_rate_between_steps(tmp_path):
    """ "none": its two step-sampled collisions (0.5 and 0.7 m) are collisions between steps too, 2 of 3.
    "alpha=0.5": its first episode, 0.82 m apart at the steps, comes within 0.78 m between two: 1 of 4 =
    25 % where the step-sampled rate is 0. The Markdown table changes in its between-step row only."""
    safety, cells, records = _safety_records()
    records[3]["metrics"]["min_distance"] = 0.82
    between = {0: 0.5, 2: 0.7, 3: 0.78}  # record -> closest approach between steps (m)
    for i, r in enumerate(records):
        r["metrics"]["min_distance_between_steps"] = between.get(i, r["metrics"]["min_distance"])
        r["metrics"]["collision_between_steps"] = r["metrics"]["min_distance_between_steps"] < 0.8
        r["metrics"]["contact_between_steps"] = r["metrics"]["min_distance_between_steps"] < 0.6
    (tmp_path / "before").mkdir()
    before = [{**r, "metrics": dict(r["metrics"])} for r in records]
    for r in before:
        for name in ("min_distance_between_steps", "collision_between_steps", "contact_between_steps"):
            del r["metrics"][name]
    old = write_report(tmp_path / "before", safety, cells, before)
    report = write_report(tmp_path, safety, cells, records)
    row = "| Collision between steps (%) (not in the paper) |"
    (now_row,) = [line for line in report.markdown.splitlines() if line.startswith(row)]
    assert now_row.split(" | ")[1].startswith("66.7 [") and now_row.split(" | ")[2].startswith("25.0 [")
    assert [line for line in report.markdown.splitlines() if not line.startswith(row)] == [
        line for line in old.markdown.splitlines() if not line.startswith(row)
    ]
    with open(tmp_path / CELLS_CSV, encoding="utf-8") as f:
        none, half = list(csv.DictReader(f))
    with open(tmp_path / "before" / CELLS_CSV, encoding="utf-8") as f:
        none_before, half_before = list(csv.DictReader(f))
    assert none_before["collision_between_steps_rate"] == ""  # records without the field
    for now, then in ((none, none_before), (half, half_before)):  # every other column unchanged
        assert {k: v for k, v in now.items() if "between" not in k} == {
            k: v for k, v in then.items() if "between" not in k
        }
    assert (none["collision_count"], none["collision_between_steps_count"]) == ("2", "2")
    assert float(none["collision_between_steps_rate"]) == pytest.approx(200.0 / 3)
    assert (half["collision_count"], half["collision_between_steps_count"]) == ("0", "1")
    assert float(half["collision_between_steps_rate"]) == 25.0
    lo, hi = float(half["collision_between_steps_ci_lo"]), float(half["collision_between_steps_ci_hi"])
    assert lo < 25.0 < hi  # the Wilson interval, as the other rates'
    with open(tmp_path / EPISODES_CSV, encoding="utf-8") as f:
        episodes = list(csv.DictReader(f))
    assert [e["collision_between_steps"] for e in episodes[:4]] == ["True", "False", "True", "True"]
    assert [e["contact_between_steps"] for e in episodes[:4]] == ["True", "False", "False", "False"]
    # contact (< 0.6 m) between steps: only the first record's 0.5 m
    assert (none["contact_between_steps_count"], half["contact_between_steps_count"]) == ("1", "0")
    assert (episodes[3]["min_distance"], episodes[3]["min_distance_between_steps"]) == ("0.82", "0.78")


def test_added_flag_count_needs_every_record():
    name = "collision_between_steps"
    assert added_flag_count([{name: True}, {name: False}], name) == 1
    assert added_flag_count([{name: True}, {}], name) is None  # one older record
    assert added_flag_count([], name) is None


def test_the_plots_panels_follow_the_crowd_sizes_and_each_the_methods_order():
    """Panels by number of humans, ascending, whichever method ran which sizes: DMPC at 5 humans and CMPC at
    6 only still give the 5-human panel first; within a panel the experiment's order (CMPC before DMPC)."""
    from types import SimpleNamespace

    from pipelines.experiments.safety_plots import _by_humans

    def column(method, n):
        return SimpleNamespace(cell=SimpleNamespace(method=method, n_humans=n))

    table2 = get_experiment("table2")
    groups = _by_humans(table2, [column("DMPC", 6), column("CMPC", 6), column("DMPC", 5)])
    assert [(n, [s.cell.method for s in cells]) for n, cells in groups.items()] == [
        (5, ["DMPC"]),
        (6, ["CMPC", "DMPC"]),
    ]


def _drawn(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig).draw()
    return fig.canvas.get_renderer()


def test_the_safety_experiments_sixteen_methods_fit_their_plots():
    """`sweep --experiment safety --episodes-per-cell 2`: the histogram's legend of 16 methods, inside the
    panel, ran over its top and the figure's title; the trade-off wrote 16 labels around the two points the
    methods shared, one over the other. The legends stand beside the panels now, inside the figure, and
    the trade-off names the methods there instead (a panel of few methods keeps its labels)."""
    from pipelines.experiments.safety_plots import min_distance_hist_figure, safety_tradeoff_figure

    safety = get_experiment("safety")
    cells = safety.cells()
    records = [_record(c, i, 1.0 + 0.1 * i, 20, (i, 0, 0)) for c in cells for i in range(2)]
    summaries = summarize(safety, cells, records)
    for fig in (min_distance_hist_figure(safety, summaries), safety_tradeoff_figure(safety, summaries)):
        renderer = _drawn(fig)
        (ax,) = fig.axes
        legend = ax.get_legend()
        assert len(legend.get_texts()) >= len(cells)
        box, page = legend.get_window_extent(renderer), fig.bbox
        assert not box.overlaps(ax.get_window_extent(renderer))
        assert not box.overlaps(fig._suptitle.get_window_extent(renderer))
        assert page.x0 <= box.x0 and box.x1 <= page.x1 and page.y0 <= box.y0 and box.y1 <= page.y1
    assert not ax.texts  # no label beside a point
    few = [s for s in summaries if s.cell.method in ("none", "alpha=0.5")]
    (ax,) = safety_tradeoff_figure(safety, few).axes
    (shared,) = ax.texts  # the two at one point share a label, a line each
    assert sorted(shared.get_text().split("\n")) == ["alpha=0.5, 15.5 s", "none, 15.5 s"]


def test_each_of_the_safety_experiments_methods_has_its_own_look():
    """With matplotlib's ten colours, "motion alpha=0.01" was drawn as "none" (both C0), and five more pairs
    alike, in the histogram and the trade-off: lines and points that no legend could tell apart."""
    from matplotlib.colors import to_hex

    from pipelines.experiments.safety_plots import min_distance_hist_figure, safety_tradeoff_figure

    safety = get_experiment("safety")
    cells = safety.cells()
    summaries = summarize(safety, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    (ax,) = min_distance_hist_figure(safety, summaries).axes
    steps = [p for p in ax.patches if p.get_label().split(" (")[0] in safety.method_labels]
    assert len({(to_hex(p.get_edgecolor()), p.get_linestyle()) for p in steps}) == len(cells)
    (ax,) = safety_tradeoff_figure(safety, summaries).axes
    points = [c.lines[0] for c in ax.containers]
    assert len({(to_hex(p.get_color()), p.get_marker()) for p in points}) == len(cells)


def test_the_histogram_counts_episodes_in_whole_ticks():
    """Two episodes a cell: the y axis ("episodes") was ticked 0, 0.25, 0.5, ..., 2."""
    from pipelines.experiments.safety_plots import min_distance_hist_figure

    table2 = get_experiment("table2")
    cells = table2.cells((5, 6))
    summaries = summarize(table2, cells, [_record(c, i, 1.0, 20) for c in cells for i in range(2)])
    fig = min_distance_hist_figure(table2, summaries)
    _drawn(fig)
    for ax in fig.axes:
        ticks = ax.get_yticks()
        assert len(ticks) >= 2 and all(t == int(t) for t in ticks)


ROBOT_ROW = "| Robot-robot contact rate (%) (< 0.6 m; not in the paper) |"


def test_robot_robot_contact_in_cells_csv_episodes_csv_and_the_table(tmp_path):
    """Robots touching each other (not a metric of the paper). "none": robot-robot contact steps 2, 0, 1 of
    10, 20, 30 states -> 2 of 3 episodes, 3 of 60 states = 5 %; "alpha=0.5": none, 0 of 4. Records from before
    the field read empty / "—"; every other column and row stays as it was."""
    from pipelines.experiments.summary import wilson_interval

    safety, cells, records = _safety_records()
    before = [{**r, "metrics": dict(r["metrics"])} for r in records]
    for r, steps in zip(records, (2, 0, 1, 0, 0, 0, 0), strict=True):
        r["metrics"] |= {"robot_contact": steps > 0, "robot_contact_steps": steps}
    (tmp_path / "before").mkdir()
    old = write_report(tmp_path / "before", safety, cells, before)
    report = write_report(tmp_path, safety, cells, records)
    with open(tmp_path / CELLS_CSV, encoding="utf-8") as f:
        none, half = list(csv.DictReader(f))
    with open(tmp_path / "before" / CELLS_CSV, encoding="utf-8") as f:
        none_before, half_before = list(csv.DictReader(f))
    assert (none["robot_contact_count"], half["robot_contact_count"]) == ("2", "0")
    assert (
        float(none["robot_contact_rate"]) == pytest.approx(200.0 / 3)
        and float(half["robot_contact_rate"]) == 0
    )
    assert (
        float(none["robot_contact_step_freq"]) == pytest.approx(5.0)
        and half["robot_contact_step_freq"] == "0.0"
    )
    lo, hi = (100.0 * x for x in wilson_interval(2, 3))
    assert (
        float(none["robot_contact_ci_lo"]) == pytest.approx(lo) and float(none["robot_contact_ci_hi"]) == hi
    )
    robot = ("robot_contact_count", "robot_contact_rate", "robot_contact_ci_lo", "robot_contact_ci_hi")
    assert [none_before[k] for k in (*robot, "robot_contact_step_freq")] == [""] * 5
    for now, then in ((none, none_before), (half, half_before)):  # every other column unchanged
        assert {k: v for k, v in now.items() if "robot_contact" not in k} == {
            k: v for k, v in then.items() if "robot_contact" not in k
        }
    with open(tmp_path / EPISODES_CSV, encoding="utf-8") as f:
        episodes = list(csv.DictReader(f))
    assert [(e["robot_contact"], e["robot_contact_steps"]) for e in episodes[:3]] == [
        ("True", "2"),
        ("False", "0"),
        ("True", "1"),
    ]
    (row,) = [line for line in report.markdown.splitlines() if line.startswith(ROBOT_ROW)]
    assert row.split(" | ")[1:] == [
        f"66.7 [{lo:.1f}, {hi:.1f}]",
        f"0.0 [0.0, {100 * wilson_interval(0, 4)[1]:.1f}] |",
    ]
    (row_before,) = [line for line in old.markdown.splitlines() if line.startswith(ROBOT_ROW)]
    assert row_before == f"{ROBOT_ROW} — | — |"
    others = [line for line in report.markdown.splitlines() if not line.startswith(ROBOT_ROW)]
    assert others == [line for line in old.markdown.splitlines() if not line.startswith(ROBOT_ROW)]


def test_between_step_rows_of_the_table():
    """Collisions and robot contact between steps (straight motion within each step) by hand: "none" 1 of 3
    episodes collide between steps and 2 of 3 robot pairs touch; "alpha=0.5" none of 4. Records from before
    the fields read "—"."""
    from pipelines.experiments.summary import wilson_interval

    safety, cells, records = _safety_records()
    old = markdown_table(safety, summarize(safety, cells, records)).splitlines()
    for r, (collides, touches) in zip(
        records, [(True, True), (False, True), (False, False)] + [(False,) * 2] * 4, strict=True
    ):
        r["metrics"] |= {"collision_between_steps": collides, "robot_contact_between_steps": touches}
    table = markdown_table(safety, summarize(safety, cells, records)).splitlines()

    def cell(k: int, n: int) -> str:
        lo, hi = (100.0 * x for x in wilson_interval(k, n))
        return f"{100.0 * k / n:.1f} [{lo:.1f}, {hi:.1f}]"

    none_half = {"collision": (cell(1, 3), cell(0, 4)), "robot": (cell(2, 3), cell(0, 4))}
    assert (
        f"| Collision between steps (%) (not in the paper) | {' | '.join(none_half['collision'])} |" in table
    )
    assert f"| Robot-robot contact between steps (%) | {' | '.join(none_half['robot'])} |" in table
    assert "| Collision between steps (%) (not in the paper) | — | — |" in old
    assert "| Robot-robot contact between steps (%) | — | — |" in old


def test_world_note_names_the_settings_every_column_of_one_controller_shares():
    """safe_crossing.toml's DMPC update and stop rules are DMPC's alone: the table said nothing of them, and
    its DMPC column read as the paper's Jacobi."""
    import dataclasses

    def with_settings(cell, *settings):
        spec = dataclasses.replace(cell.spec, mpc_overrides=(*cell.spec.mpc_overrides, *settings))
        return dataclasses.replace(cell, spec=spec)

    shared = (("guidance", "standing"),)
    dmpc = (("dmpc_stop", "no_improvement"), ("dmpc_update", "gauss_seidel"))
    cells = [
        with_settings(c, *shared, *(dmpc if c.spec.controller == "dmpc" else ()))
        for c in get_experiment("table2").cells()
    ]
    assert world_note(cells)[0] == (
        "Margins: none; profile paper, robots visible to the humans. MPC settings: guidance=standing. "
        "DMPC's: dmpc_stop=no_improvement, dmpc_update=gauss_seidel."
    )
    # one DMPC column without them (a --vary column's value is in its label): not every DMPC column's
    cells[1] = dataclasses.replace(cells[1], spec=get_experiment("table2").cells()[1].spec)
    assert cells[1].spec.controller == "dmpc" and "DMPC's" not in world_note(cells)[0]
