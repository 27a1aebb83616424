"""What a sweep's resume and its records rest on, checked against hand-computed values: the episode log made
durable line by line, the record types it refuses, the solver figures a record states, the cells' seeds and
order, and what a rerun says it found done."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import pytest

from pipelines.errors import DroppedLineWarning, PipelineError
from pipelines.experiments.cells import Experiment, get_experiment
from pipelines.experiments.log import EPISODES_FILE, EpisodeLog, episode_log
from pipelines.experiments.sweep import run_sweep
from pipelines.experiments.sweep_config import SweepConfig
from pipelines.experiments.tasks import Cell
from pipelines.experiments.worker import EpisodeOutcome, EpisodeWorker
from pipelines.loop.controllers import ControllerSpec
from pipelines.loop.record import SolverStats, step_time_stats
from pipelines.loop.spec import UnknownController

# ----------------------------------------------------------------------------------------------------------
# The episode log: each line durable before the next episode is taken
# ----------------------------------------------------------------------------------------------------------


def test_each_appended_line_is_on_disk_before_append_returns(tmp_path, monkeypatch):
    """A kill right after ``append`` must not lose the line (the resume would skip nothing and the episode
    would silently run again, or worse, the file would end torn in the middle): append fsyncs the file, and
    does so once the whole line has been written. The folder is synced once, after the first line: the
    file's name must reach the disk too, and later lines add no name (no folder sync per episode)."""
    log = EpisodeLog(tmp_path / "log.jsonl")
    synced: list[tuple[str, bytes]] = []
    real_fsync = os.fsync

    def fsync(fd):
        what = "folder" if stat.S_ISDIR(os.fstat(fd).st_mode) else "file"
        synced.append((what, (tmp_path / "log.jsonl").read_bytes()))  # the file when it is made durable
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    log.append({"key": "a", "x": 1})
    log.append({"key": "b", "x": 2})
    first, both = b'{"key":"a","x":1}\n', b'{"key":"a","x":1}\n{"key":"b","x":2}\n'
    assert synced == [("file", first), ("folder", first), ("file", both)]


def test_the_repair_of_a_torn_tail_is_made_durable(tmp_path, monkeypatch):
    """The cut-off tail must stay cut off after a crash, or the next append would glue onto the torn bytes."""
    path = tmp_path / "log.jsonl"
    path.write_bytes(b'{"key":"a"}\n{"key":"b", "x"')
    synced: list[bytes] = []
    monkeypatch.setattr(os, "fsync", lambda fd: synced.append(path.read_bytes()))
    assert list(EpisodeLog(path).load()) == ["a"]
    assert synced == [b'{"key":"a"}\n']


def test_a_blank_line_is_skipped_and_a_key_must_be_text(tmp_path):
    """A blank line (an editor's) holds no episode and is no damage; a key that is no string is."""
    path = tmp_path / "log.jsonl"
    path.write_bytes(b'{"key":"a"}\n\n{"key":"b"}\n')
    assert list(EpisodeLog(path).load()) == ["a", "b"]
    assert path.read_bytes() == b'{"key":"a"}\n\n{"key":"b"}\n'  # nothing cut
    path.write_bytes(b'{"key":5}\n{"key":"b"}\n')
    with pytest.raises(PipelineError, match=":1: record has no 'key'; the file is damaged"):
        EpisodeLog(path).load()


def test_a_line_that_is_not_utf8_is_torn_at_the_end_and_damage_elsewhere(tmp_path):
    """Bytes that are no UTF-8 are one line's error like any other garbage, never a traceback."""
    path = tmp_path / "log.jsonl"
    path.write_bytes(b'{"key":"a"}\n{"key":"\xc3("}\n')
    with pytest.warns(DroppedLineWarning, match=":2: the last line is no JSON record"):
        assert list(EpisodeLog(path).load()) == ["a"]
    assert path.read_bytes() == b'{"key":"a"}\n'
    path.write_bytes(b'{"key":"\xc3("}\n{"key":"a"}\n')
    with pytest.raises(PipelineError, match=":1: not a JSON record .*the file is damaged"):
        EpisodeLog(path).load()


# Every typed field of a record, written out by hand (not from record_checks.METRIC_KINDS, so that a field
# dropped from the check is noticed): the string "1", which the record's own reading would take for 1 (or
# True), where each expects a number, count or boolean is refused.
TYPED_FIELDS = [
    *(("metrics", name) for name in ("success", "collision", "contact", "discomfort", "timeout")),
    *(("metrics", name) for name in ("travel_time", "min_distance", "min_distance_robots")),
    *(("metrics", name) for name in ("min_distance_humans", "path_length", "reach_times")),
    *(("metrics", name) for name in ("discomfort_steps", "n_steps", "collision_steps", "contact_steps")),
    ("metrics", "min_distance_between_steps"),
    ("metrics", "collision_between_steps"),
    ("metrics", "contact_between_steps"),
    ("metrics", "robot_contact"),
    ("metrics", "robot_contact_steps"),
    ("metrics", "min_distance_robots_between_steps"),
    ("metrics", "robot_contact_between_steps"),
    *(("solver", name) for name in ("steps", "fallback_steps", "total_ms", "median_ms", "p95_ms")),
    *(("solver", name) for name in ("max_ms", "mean_iterations", "max_iterations")),
    ("", "wall_s"),
    ("", "cpu_s"),
]


@pytest.fixture(scope="module")
def one_record(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("one")
    run_sweep(SweepConfig(get_experiment("baselines"), out, 1, humans=(3,), backend="inline", progress=False))
    return json.loads((out / EPISODES_FILE).read_text().splitlines()[0])


@pytest.mark.parametrize(("part", "name"), TYPED_FIELDS, ids=[f"{p or 'rec'}-{n}" for p, n in TYPED_FIELDS])
def test_every_typed_field_of_a_record_is_checked(one_record, tmp_path, part, name):
    record = json.loads(json.dumps(one_record))
    (record[part] if part else record)[name] = "1"
    (tmp_path / EPISODES_FILE).write_text(json.dumps(record) + "\n")
    with pytest.raises(PipelineError, match=rf":1: record's {part + ' ' if part else ''}'{name}' is not"):
        episode_log(tmp_path).load()


@pytest.mark.parametrize(("name", "value"), [("seed", -1), ("seed", 7), ("scenario", "perpendicular")])
def test_a_record_whose_key_is_not_its_cell_scenario_and_seed_is_refused(one_record, tmp_path, name, value):
    """A seed edited to -1 kept its key: the sweep counted the episode as recorded, and compare paired it
    with another crowd's episode."""
    record = {**json.loads(json.dumps(one_record)), name: value}
    (tmp_path / EPISODES_FILE).write_text(json.dumps(record) + "\n")
    with pytest.raises(PipelineError, match=":1: record's key .* is not its cell, scenario and seed"):
        episode_log(tmp_path).load()


# ----------------------------------------------------------------------------------------------------------
# Solver figures of a record
# ----------------------------------------------------------------------------------------------------------


def test_step_time_stats_hand_values():
    # 1..20 ms: median (10 + 11) / 2 = 10.5; p95 by linear interpolation at rank 0.95 * 19 = 18.05, between
    # 19 and 20 ms: 19 + 0.05 = 19.05; max 20. (A mean would be 10.5 too, so the skewed set below tells
    # median from mean: 1, 1, 1, 1, 16 ms -> median 1, mean 4.)
    stats = step_time_stats([i / 1000 for i in range(1, 21)])
    assert stats == pytest.approx({"median_ms": 10.5, "p95_ms": 19.05, "max_ms": 20.0})
    assert step_time_stats([0.001, 0.001, 0.001, 0.001, 0.016])["median_ms"] == pytest.approx(1.0)
    assert step_time_stats([]) == {"median_ms": None, "p95_ms": None, "max_ms": None}


def test_solver_stats_of_steps_hand_values():
    stats = SolverStats.of_steps(
        [0.002, 0.004, 0.012], [3, 1, 2], ["ok", "ok", "fail"], [None, "straight", None]
    )
    assert (stats.steps, stats.total_ms) == (3, pytest.approx(18.0))  # 2 + 4 + 12 ms
    assert (stats.mean_iterations, stats.max_iterations) == (pytest.approx(2.0), 3)  # (3+1+2)/3; max 3
    assert (stats.median_ms, stats.max_ms) == (pytest.approx(4.0), pytest.approx(12.0))
    assert stats.p95_ms == pytest.approx(11.2)  # rank 0.95 * 2 = 1.9: 4 + 0.9 * (12 - 4)
    assert (stats.fallback_steps, dict(stats.statuses), dict(stats.fallbacks)) == (
        1,
        {"ok": 2, "fail": 1},
        {"straight": 1},
    )


def test_solver_stats_of_no_steps_say_none_not_zero():
    """No control step: no time and no iteration count to state (0 would read as "solved in 0 iterations")."""
    stats = SolverStats.of_steps([], [], [], [])
    assert (stats.steps, stats.total_ms, stats.mean_iterations, stats.max_iterations) == (0, 0.0, None, None)
    assert (stats.median_ms, stats.fallback_steps) == (None, 0)


def test_a_record_with_solver_figures_added_later_is_still_read(one_record):
    """A record written by a later version with one more solver figure still loads (the figures it knows)."""
    from pipelines.loop.record import EpisodeRecord

    record = json.loads(json.dumps(one_record))
    record["solver"]["energy_j"] = 1.5
    assert EpisodeRecord.from_dict(record).solver.steps == one_record["solver"]["steps"]


# ----------------------------------------------------------------------------------------------------------
# Cells: the seeds and order of a sweep's episodes, refusals of a bad plan
# ----------------------------------------------------------------------------------------------------------


def test_tasks_go_episode_index_by_episode_index_across_cells():
    """A sweep stopped early holds (about) the same crowds in every cell: the cells alternate within each
    episode index, never one cell's episodes all first."""
    tasks = get_experiment("baselines").tasks(2, humans=(3,), seed=5)
    straight, orca = (c.key for c in get_experiment("baselines").cells((3,)))
    assert [(t.cell.key, t.index, t.scenario, t.seed) for t in tasks] == [
        (straight, 0, "circle", 5),
        (orca, 0, "circle", 5),
        (straight, 1, "perpendicular", 5),
        (orca, 1, "perpendicular", 5),
    ]


def test_a_negative_base_seed_and_empty_cells_are_refused():
    from pipelines.experiments.tasks import scenario_schedule

    assert scenario_schedule(1, seed=0) == [("circle", 0)]  # seed 0 is the default, so it is allowed
    with pytest.raises(PipelineError, match="base seed must be non-negative, got -1"):
        scenario_schedule(1, seed=-1)
    spec = ControllerSpec(controller="orca")
    assert Cell("ORCA", spec, n_humans=1, n_robots=1).key.endswith("-h1-r1")  # one of each is a cell
    with pytest.raises(PipelineError, match="at least one human, got n_humans=0"):
        Cell("ORCA", spec, n_humans=0)
    with pytest.raises(PipelineError, match="at least one robot, got n_robots=0"):
        Cell("ORCA", spec, n_humans=3, n_robots=0)


def test_an_experiment_with_a_repeated_method_label_is_refused():
    """Two columns of one label would share a cell key, so their records would mix."""
    spec = ControllerSpec(controller="orca")
    with pytest.raises(PipelineError, match=r"needs distinct method labels, got \['A', 'A'\]"):
        Experiment("x", "X", (("A", spec), ("A", spec)), (3,))


def test_with_controllers_refuses_an_unregistered_name_up_front():
    with pytest.raises(UnknownController):
        get_experiment("controllers").with_controllers(["orca", "no_such_controller"])


# ----------------------------------------------------------------------------------------------------------
# A rerun: what it found done, plans it refuses, errors after successes
# ----------------------------------------------------------------------------------------------------------


def _config(out: Path, episodes: int, **kw) -> SweepConfig:
    kw = {"humans": (3,), "backend": "inline", "progress": False} | kw
    return SweepConfig(get_experiment("baselines"), out, episodes, **kw)


def test_already_done_counts_only_this_plans_episodes(tmp_path):
    """A rerun asking for fewer episodes than the directory holds found 2 of its 2 done (not the 4 held)."""
    run_sweep(_config(tmp_path, 2))  # 2 cells x 2 episodes
    again = run_sweep(_config(tmp_path, 1))
    assert (again.planned, again.already_done, again.ran) == (2, 2, 0)


def test_each_run_states_its_base_seed_in_sweep_json(tmp_path):
    run_sweep(_config(tmp_path, 1, seed=7))
    meta = json.loads((tmp_path / "sweep.json").read_text())
    assert meta["runs"][-1]["seed"] == 7
    assert {r["seed"] for r in episode_log(tmp_path).load().values()} == {7}


def test_a_plan_with_an_episode_twice_is_refused(tmp_path):
    with pytest.raises(PipelineError, match="plans the same episode twice"):
        run_sweep(_config(tmp_path, 1, humans=(3, 3)))
    assert not (tmp_path / EPISODES_FILE).exists()


def test_errors_after_a_recorded_episode_do_not_stop_the_sweep(tmp_path):
    """The early stop is for a broken setup (the first episodes all raise); once one episode was recorded,
    later errors go to errors.jsonl and the sweep goes on."""

    class FirstOnly:
        name = "fake"

        def run(self, tasks):
            for i, task in enumerate(tasks):
                yield EpisodeWorker().run(task) if i == 0 else EpisodeOutcome(task.key, error="boom")

        def close(self):
            pass

    outcome = run_sweep(_config(tmp_path, 4), backend_factory=lambda config, scratch: FirstOnly())
    assert (outcome.ran, len(outcome.errors)) == (1, 7)  # 2 cells x 4 episodes: 1 recorded, 7 raised
    assert len((tmp_path / "errors.jsonl").read_text().splitlines()) == 7


def test_a_backend_answering_for_an_episode_it_was_not_given_is_one_line(tmp_path):
    class Stray:  # a backend of one's own (run_sweep's backend_factory) with a bug: it was a bare KeyError
        name = "stray"

        def run(self, tasks):
            yield EpisodeOutcome("not-planned", error="boom")

        def close(self):
            pass

    with pytest.raises(
        PipelineError, match="^stray backend returned episode 'not-planned', which it was not"
    ):
        run_sweep(_config(tmp_path, 1), backend_factory=lambda config, scratch: Stray())


class _NoEpisodes:
    """A backend that runs nothing: what sweep.json states is written before any episode."""

    name = "none"

    def run(self, tasks):
        return iter(())

    def close(self):
        pass


def test_a_run_line_states_its_plan(tmp_path):
    """Without --humans the run line names the experiment's crowd sizes (not an empty list), with the
    number of episodes per cell and of planned episodes: what a reader of sweep.json reruns from."""
    experiment = get_experiment("baselines")
    config = SweepConfig(experiment, tmp_path, 3, backend="inline", progress=False)
    run_sweep(config, backend_factory=lambda config, scratch: _NoEpisodes())
    run = json.loads((tmp_path / "sweep.json").read_text())["runs"][-1]
    planned = 3 * len(experiment.methods) * len(experiment.humans)
    assert (run["humans"], run["episodes_per_cell"], run["planned"]) == (list(experiment.humans), 3, planned)


def _rewrite(out: Path, edit) -> None:
    records = [json.loads(line) for line in (out / EPISODES_FILE).read_text().splitlines()]
    for record in records:
        edit(record)
    (out / EPISODES_FILE).write_text("".join(json.dumps(r) + "\n" for r in records))


def test_records_of_the_zoos_current_weights_extend_their_cell(tmp_path):
    """The refusal of changed weights compares with the zoo's sha256 now: records that carry it resume."""
    from predictors.registry import checkpoint_sha256

    sha256 = checkpoint_sha256("social_lstm_eth")
    assert sha256 is not None
    run_sweep(_config(tmp_path, 1))
    _rewrite(tmp_path, lambda r: r.update(predictor="social_lstm_eth", predictor_sha256=sha256))
    again = run_sweep(_config(tmp_path, 1))
    assert (again.already_done, again.ran) == (2, 0)


def test_records_whose_margins_state_no_values_say_nothing_about_them(tmp_path):
    """A controller that plans with no margins may describe them without "margins_m" (a plugin's): such
    records are no evidence of changed margins, and the resume goes on."""
    run_sweep(_config(tmp_path, 1))
    _rewrite(tmp_path, lambda r: r.setdefault("config", {}).update(margins={"mode": "none"}))
    again = run_sweep(_config(tmp_path, 1))
    assert (again.already_done, again.ran) == (2, 0)


def test_uncommitted_changes_alone_are_no_other_code(tmp_path, capsys):
    """The "dirty" flag cannot be compared (two dirty trees may differ or not): alone it is no other code."""
    from pipelines.plugins import code_with_plugins

    run_sweep(_config(tmp_path, 1))
    meta = json.loads((tmp_path / "sweep.json").read_text())
    meta["runs"][-1]["code"] = {**code_with_plugins(), "dirty": not code_with_plugins()["dirty"]}
    (tmp_path / "sweep.json").write_text(json.dumps(meta))
    capsys.readouterr()
    run_sweep(_config(tmp_path, 1))
    assert "note:" not in capsys.readouterr().err
