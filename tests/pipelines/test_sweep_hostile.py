"""A sweep directory that was damaged or edited by hand stops the sweep with one line naming the file (and
the line), never a traceback, and nothing of it is overwritten."""

import dataclasses
import errno
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.experiments.cells import get_experiment
from pipelines.experiments.log import (
    EPISODES_FILE,
    ERRORS_FILE,
    LOCK_FILE,
    MCAP_DIR,
    SWEEP_FILE,
    EpisodeLog,
    episode_log,
)
from pipelines.experiments.report import CELLS_CSV, TABLE_MD
from pipelines.experiments.sweep import run_sweep
from pipelines.experiments.sweep_config import SweepConfig
from predictors.calibration_store import save_calibration
from predictors.zoo import checkpoints_dir, user_zoo_dir
from predictors.zoo_edit import add_to_zoo
from tests.calibration_blocks import constant_velocity_block
from tests.read_only import file_size_limit
from tests.waits import within

ARGV = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "1", "--backend",
        "inline", "--no-progress", "--jit", "off"]  # fmt: skip


def _config(out: Path) -> SweepConfig:
    return SweepConfig(get_experiment("baselines"), out, 1, humans=(3,), backend="inline", progress=False)


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("good")
    run_sweep(_config(out))
    return out


@pytest.mark.parametrize(
    "content",
    [b"{not json", b"\xff\xfe", b"[1, 2]", b'{"runs": 3}', b"[" * 100_000 + b"]" * 100_000],
    ids=["broken", "not-utf8", "a-list", "runs-not-a-list", "deep"],
)
def test_a_garbage_sweep_file_is_named_and_left_alone(tmp_path, capsys, content):
    (tmp_path / SWEEP_FILE).write_bytes(content)
    assert main([*ARGV, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{tmp_path / SWEEP_FILE}: not a sweep file" in err[0]
    assert (tmp_path / SWEEP_FILE).read_bytes() == content


@pytest.mark.parametrize("argv", [[*ARGV, "--out", "{out}"], ["config", "show", "--from-sweep", "{out}"]])
def test_an_oversized_sweep_file_is_refused_before_it_is_read(tmp_path, capsys, monkeypatch, argv):
    """sweep.json was read whole, whatever its size, where a config, a manifest or a metrics file is
    refused past its cap: a sweep file of gigabytes took the memory. The cap (64 MiB) is lowered here."""
    from predictors import checkpoint

    monkeypatch.setattr(checkpoint, "MAX_DOCUMENT_BYTES", 1 << 16)
    document = '{"experiment": "baselines", "runs": [], "pad": ""}'
    content = document.replace('""', '"' + "x" * ((1 << 16) + 1 - len(document)) + '"').encode()
    assert len(content) == (1 << 16) + 1
    out = tmp_path / "sweep"
    out.mkdir()
    (out / SWEEP_FILE).write_bytes(content)
    code = main([a.format(out=out) for a in argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert (
        f"{out / SWEEP_FILE}: {len(content)} bytes, more than the {1 << 16} a sweep file may have" in err[0]
    )
    assert (out / SWEEP_FILE).read_bytes() == content


@pytest.mark.parametrize("name", [SWEEP_FILE, EPISODES_FILE, CELLS_CSV, f"{SWEEP_FILE}.part"])
def test_a_sweep_file_that_is_a_folder_is_named(tmp_path, name):
    """Named before anything is read or run (the OS's "Is a directory" named no option, and for cells.csv
    came after the episodes)."""
    if name != SWEEP_FILE:  # a sweep directory, so that it is not refused as a folder of other files
        (tmp_path / SWEEP_FILE).write_text('{"experiment": "baselines", "runs": []}')
    (tmp_path / name).mkdir()
    with pytest.raises(PipelineError, match=f"{tmp_path / name} is a directory where the sweep keeps a file"):
        run_sweep(_config(tmp_path))


@pytest.mark.parametrize("name", [SWEEP_FILE, EPISODES_FILE, f"{SWEEP_FILE}.part"])
def test_a_sweep_file_that_is_a_pipe_is_named_not_waited_on(tmp_path, name):
    """A sweep with a pipe for sweep.json waited for good on its read; its folder check now names it."""
    if name != SWEEP_FILE:
        (tmp_path / SWEEP_FILE).write_text('{"experiment": "baselines", "runs": []}')
    os.mkfifo(tmp_path / name)
    with (
        within(20, "a sweep waited on the pipe"),
        pytest.raises(PipelineError, match=f"{tmp_path / name} is not a regular file .a dev"),
    ):
        run_sweep(_config(tmp_path))


def test_a_pipe_for_sweep_json_is_read_by_no_reader(tmp_path, capsys):
    """read_sweep_file, which compare and --reuse read it with, names it rather than wait (compare goes on
    without the code the episodes ran, as for a damaged one)."""
    out = tmp_path / "sweep"
    out.mkdir()
    os.mkfifo(out / SWEEP_FILE)
    (out / EPISODES_FILE).write_text("")
    with within(20, "compare waited on the pipe"):
        main(["compare", f"a={out}", f"b={out}"])
    assert "sweep.json: not a sweep file (not a regular file" in capsys.readouterr().err


def _damage(good: Path, tmp_path: Path, edit) -> Path:
    lines = (good / EPISODES_FILE).read_text().splitlines()
    records = [json.loads(line) for line in lines]
    edit(records[0])
    (tmp_path / EPISODES_FILE).write_text("".join(json.dumps(r) + "\n" for r in records))
    return tmp_path / EPISODES_FILE


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (lambda r: r.pop("metrics"), "not an episode record"),
        (lambda r: r.update(metrics="fine"), "not an episode record"),
        (lambda r: r["solver"].pop("steps"), "not an episode record"),
        (lambda r: r.update(seed="seven"), "not an episode record"),
        (lambda r: r.update(index=True), "'index' is not an integer"),
        (lambda r: r.update(cell=None), "'cell' is not a string"),
    ],
    ids=["no-metrics", "metrics-string", "solver-incomplete", "seed-string", "index-bool", "cell-null"],
)
def test_a_damaged_record_is_named_by_file_and_line(good, tmp_path, edit, reason):
    path = _damage(good, tmp_path, edit)
    before = path.read_bytes()
    with pytest.raises(PipelineError, match=rf"{path}:1: .*{reason}.*the file is damaged"):
        episode_log(tmp_path).load()
    assert path.read_bytes() == before  # not repaired away: a damaged line is the user's to look at


def test_the_records_a_sweep_writes_pass_the_check(good):
    assert len(episode_log(good).load()) == 2


# ----------------------------------------------------------------------------------------------------------
# Record fields of the wrong type: counted wrongly ("yes" a success) or a traceback in the report
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (lambda r: r["metrics"].update(travel_time="abc"), "'travel_time' is not a finite number or null"),
        (lambda r: r["metrics"].update(success="yes"), "metrics 'success' is not a boolean"),
        (lambda r: r["metrics"].update(collision=1), "metrics 'collision' is not a boolean"),
        (lambda r: r["metrics"].update(min_distance=True), "not a finite number or null"),
        (lambda r: r["metrics"].update(min_distance=math.nan), "'min_distance' is not a finite number"),
        (lambda r: r["metrics"].update(travel_time=math.inf), "'travel_time' is not a finite number or null"),
        (lambda r: r["metrics"].update(path_length=["x"]), "'path_length' is not a list of finite numbers"),
        (lambda r: r["metrics"].update(n_steps=2.5), "metrics 'n_steps' is not a non-negative integer"),
        (lambda r: r["metrics"].update(contact_steps="3"), "'contact_steps' is not a non-negative"),
        (lambda r: r["metrics"].update(collision_between_steps="yes"), "_between_steps' is not a boolean"),
        (lambda r: r["metrics"].update(min_distance_between_steps="0.5"), "_steps' is not a finite number"),
        (lambda r: r["metrics"].update(robot_contact="yes"), "'robot_contact' is not a boolean"),
        (lambda r: r["metrics"].update(robot_contact_steps=-1), "'robot_contact_steps' is not a non-neg"),
        (lambda r: r["solver"].update(median_ms="abc"), "solver 'median_ms' is not a finite number or null"),
        (lambda r: r.update(solver="fast"), "not an episode record"),
        (lambda r: r.pop("wall_s"), "record's 'wall_s' is not a finite number"),
        (lambda r: r.update(seed=None), "record's 'seed' is not an integer"),
        (lambda r: r.update(seed="0"), "record's 'seed' is not an integer"),
        (lambda r: r.update(seed=0.5), "record's 'seed' is not an integer"),
        (lambda r: r.update(scenario=["circle"]), "record's 'scenario' is not a string"),
        (lambda r: r.update(scenario=None), "record's 'scenario' is not a string"),
    ],
    ids=["time-string", "success-string", "collision-int", "distance-bool", "distance-nan", "time-inf",
         "path-strings", "steps-float", "count-string", "between-string", "between-distance-string",
         "robot-contact-string", "robot-contact-steps-negative",
         "solver-string-time", "solver-string", "no-wall-time", "seed-null", "seed-string", "seed-float",
         "scenario-list", "scenario-null"],
)  # fmt: skip
def test_a_record_field_of_the_wrong_type_is_named_by_file_and_line(good, tmp_path, edit, reason):
    path = _damage(good, tmp_path, edit)
    with pytest.raises(PipelineError, match=rf"{path}:1: .*{reason}.*the file is damaged"):
        episode_log(tmp_path).load()


def test_the_report_refuses_a_tampered_metric_in_one_line(good, tmp_path, capsys):
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    _damage(good, out, lambda r: r["metrics"].update(success="yes"))
    assert main([*ARGV, "--report-only", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"crowdmpc sweep: error: {out / EPISODES_FILE}:1: record's metrics 'success' is not a boolean (got "
        "'yes'); the file is damaged: edit out that line (a copy kept) and its episode runs again"
    ]
    assert not (out / TABLE_MD).exists() or (out / TABLE_MD).read_bytes() == (good / TABLE_MD).read_bytes()


def test_missing_counts_and_null_times_as_the_writer_writes_them_pass(good, tmp_path):
    def older(record):
        added = ("min_distance_between_steps", "collision_between_steps", "contact_between_steps")
        added += ("robot_contact", "robot_contact_steps", "min_distance_robots_between_steps")
        for name in ("collision_steps", "contact_steps", *added, "robot_contact_between_steps"):
            record["metrics"].pop(name)  # records from before the counts, between-step figures, robot contact
        record["metrics"].update(travel_time=None, min_distance_robots=None, reach_times=[None])

    _damage(good, tmp_path, older)
    assert len(episode_log(tmp_path).load()) == 2


DEEP = b"[" * 100_000 + b"]" * 100_000 + b"\n"  # json's parser recurses: a RecursionError, no JSONDecodeError


def test_a_deeply_nested_record_is_named_by_file_and_line(good, tmp_path, capsys):
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    first, second = (good / EPISODES_FILE).read_bytes().splitlines(keepends=True)
    (out / EPISODES_FILE).write_bytes(first + DEEP + second)
    assert main([*ARGV, "--report-only", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{out / EPISODES_FILE}:2: not a JSON record (" in err[0]
    assert err[0].endswith("the file is damaged: edit out that line (a copy kept) and its episode runs again")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--backend", "ray"], "the Ray backend needs the cluster extra"),
        (["--ray-address", "x:1"], "the Ray backend needs the cluster extra"),
        (["--backend", "process", "--ray-address", "x:1"], "--ray-address needs the Ray backend, not"),
    ],
    ids=["ray", "auto-address", "process-address"],
)
def test_a_backend_that_cannot_start_leaves_no_run_line(
    good, tmp_path, capsys, monkeypatch, options, message
):
    """The run's line was written before the backend was made: the refused run became the sweep's last, which
    --report-only and `config show --from-sweep` then took for the sweep's plan."""
    monkeypatch.setattr("pipelines.experiments.backends.ray_available", lambda: False)
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    before = (out / SWEEP_FILE).read_bytes()
    argv = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "2",
            "--no-progress", "--jit", "off", *options]  # fmt: skip
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert (out / SWEEP_FILE).read_bytes() == before
    assert main([*argv, "--out", str(tmp_path / "new")]) == 2
    assert not (tmp_path / "new").exists()


def test_a_compile_cache_that_cannot_be_used_is_refused_before_any_worker(tmp_path, capsys, monkeypatch):
    """--jit with $CROWDMPC_CACHE a file (or read-only, or a path gcc cannot take) started the workers, and
    every episode raised the cache's error into errors.jsonl: "0/2 episodes recorded", exit 1. One line now,
    naming the option and the variable, before the sweep folder is made."""
    monkeypatch.setattr("pipelines.experiments.worker.jit_available", lambda: True)  # gcc or not
    (tmp_path / "file").write_text("x")
    monkeypatch.setenv("CROWDMPC_CACHE", str(tmp_path / "file"))
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "table2", "--humans", "5", "--episodes-per-cell", "1", "--backend",
            "inline", "--no-progress", "--jit", "on", "--out", str(out)]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"crowdmpc sweep: error: --jit on: $CROWDMPC_CACHE={tmp_path / 'file'}: {tmp_path / 'file'} is not a "
        "directory; set $CROWDMPC_CACHE to a writable directory; or use --jit off"
    ]
    assert not out.exists()
    assert main([*argv, "--dry-run"]) == 0  # nothing compiles: nothing to refuse


def test_a_record_the_disk_refuses_names_the_log_and_a_resume_keeps_the_earlier_ones(tmp_path):
    """An episode's record met by a full disk (here `ulimit -f`) ended the sweep in an OSError traceback,
    twice over (the failed flush raised again as the file closed): one line now naming the log, the
    record and that a rerun resumes; the rerun's read cuts the torn line and keeps the earlier records."""
    log = EpisodeLog(tmp_path / EPISODES_FILE)
    log.append({"key": "a", "x": 1})
    size = log.path.stat().st_size
    with file_size_limit(size + 20), pytest.raises(PipelineError) as caught:
        log.append({"key": "b", "x": list(range(100))})
    assert str(caught.value) == (
        f"{log.path}: could not append the record of 'b' (File too large); the episodes recorded before it "
        "are kept: free space and run the same sweep again to resume"
    )
    assert log.path.stat().st_size == size + 20  # the torn line
    assert log.load() == {"a": {"key": "a", "x": 1}} and log.path.stat().st_size == size
    log.append({"key": "b", "x": 2})
    assert set(log.load()) == {"a", "b"}


def test_a_recording_the_disk_refuses_names_it_and_leaves_no_part(tmp_path):
    """`sweep --record` on a full disk ended in "could not write (No space left on device)" at best, naming
    no file (a write's OSError has none): one line naming the episode's recording now, no .part left, an
    earlier recording of that name as it was."""
    from pipelines.experiments.outcome_write import write_atomic as _write_atomic

    path = tmp_path / MCAP_DIR / "a.mcap"
    _write_atomic(path, b"old")
    with file_size_limit(100), pytest.raises(PipelineError) as caught:
        _write_atomic(path, bytes(1000))
    assert str(caught.value) == (
        f"{path}: could not write the episode's recording (File too large); the episodes recorded before it "
        "are kept: free space and run the same sweep again to resume"
    )
    assert path.read_bytes() == b"old" and [p.name for p in path.parent.iterdir()] == ["a.mcap"]


def test_a_new_sweep_whose_few_episodes_all_raised_says_so_without_a_missing_log(
    tmp_path, capsys, monkeypatch
):
    """Fewer episodes than stop a sweep early, all raising (a compile cache on a full disk: each compile's
    ENOSPC): its report then opened episodes.jsonl, which no episode had made, and the sweep ended in
    "error: [Errno 2] No such file or directory: .../episodes.jsonl" after pointing at errors.jsonl. The
    errors' line stands alone now, with exit code 1 and a report of no episodes."""

    def broken(spec, env_config=None, *, jit=False, read=None):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr("pipelines.experiments.worker.make_controller", broken)
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "controllers", "--controllers", "cmpc", "--predictor",
            "constant_velocity", "--humans", "3", "--episodes-per-cell", "2", "--backend", "inline",
            "--no-progress", "--out", str(out)]  # fmt: skip
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert f"2 episodes raised; see {out / ERRORS_FILE}" in err
    assert "error:" not in err and not (out / EPISODES_FILE).exists()
    assert (out / TABLE_MD).is_file()
    # a report of it afterwards said "episodes.jsonl does not exist", as of a folder that never held a sweep
    assert main(["sweep", "--report-only", "--out", str(out)]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc sweep: error: {out} holds no recorded episode, only episodes that raised (see "
        f"{out / ERRORS_FILE}): nothing to report; rerun the sweep without --report-only to retry them\n"
    )


@pytest.mark.parametrize("made", [False, True])
def test_a_report_of_a_folder_without_a_sweep_names_the_folder_not_the_experiment(tmp_path, capsys, made):
    """--report-only reads the experiment from --out's sweep.json; of a folder without one (missing, empty)
    it asked for --experiment, and given one, said episodes.jsonl does not exist."""
    out = tmp_path / "sweep"
    if made:
        out.mkdir()
    assert main(["sweep", "--report-only", "--out", str(out)]) == 2
    assert (
        capsys.readouterr().err
        == f"crowdmpc sweep: error: {out} holds no sweep (sweep.json): nothing to report\n"
    )


@pytest.mark.parametrize(
    "mode",
    [["--report-only"], ["--report-only", *ARGV[1:3]], ARGV[1:3] + ["--dry-run"]],
    ids=["report", "report-of-experiment", "dry-run"],
)
def test_a_sweeps_file_given_for_its_folder_is_named_as_config_show_names_it(good, capsys, mode):
    """--report-only --out DIR/sweep.json said the file "holds no sweep (sweep.json)", and a dry run listed
    the plan as of a new folder, where `config show --from-sweep` says to give its folder."""
    assert main(["sweep", *mode, "--out", str(good / SWEEP_FILE)]) == 2
    assert capsys.readouterr().err == (
        f"crowdmpc sweep: error: --out {good / SWEEP_FILE}: that is a sweep's file; give its folder, {good}\n"
    )


def test_report_only_needs_no_gcc_whatever_jit_says(tmp_path, capsys, monkeypatch):
    """--report-only runs nothing, yet --jit on (as a sweep's recorded config states it) was refused without
    gcc: "--jit on needs gcc on the PATH", on the machine the report was to be written on."""
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "table2", "--predictor", "constant_velocity", "--humans", "1", "--out",
            str(out), "--episodes-per-cell", "1", "--backend", "inline", "--no-progress"]  # fmt: skip
    assert main([*argv, "--jit", "off"]) == 0
    capsys.readouterr()
    monkeypatch.setattr("pipelines.experiments.worker.jit_available", lambda: False)  # no gcc here
    assert main([*argv, "--jit", "on", "--report-only"]) == 0
    assert "Table II" in (out / TABLE_MD).read_text()


def test_a_run_line_is_added_once_the_backend_has_started(good, tmp_path):
    """A backend refused only as it starts (a Ray cluster that cannot be joined) leaves no line either."""
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    before = (out / SWEEP_FILE).read_bytes()
    config = dataclasses.replace(_config(out), episodes_per_cell=2)

    def unreachable(config, scratch):
        raise PipelineError("cannot join a Ray cluster at --ray-address 'x:1'")

    with pytest.raises(PipelineError, match="cannot join"):
        run_sweep(config, backend_factory=unreachable)
    assert (out / SWEEP_FILE).read_bytes() == before
    assert run_sweep(config).ran == 2
    assert len(json.loads((out / SWEEP_FILE).read_text())["runs"]) == 2


def test_a_sweep_interrupted_before_its_backend_started_resumes(tmp_path, capsys, monkeypatch):
    """Ctrl-C while the workers started: the run line was not written yet, the report was, and the rerun the
    sweep advised was refused as a folder "holding files but no sweep"."""
    out = tmp_path / "sweep"

    def interrupted(config, scratch):
        raise KeyboardInterrupt

    with monkeypatch.context() as patched:
        patched.setattr("pipelines.experiments.sweep._default_backend", interrupted)
        assert main([*ARGV, "--out", str(out)]) == 130
    said = "interrupted: rerun the same command to start it (stopped while its workers started: no episode "
    assert said in capsys.readouterr().err  # it had said "to resume" of a sweep that never started
    assert main([*ARGV, "--out", str(out)]) == 0
    assert len(json.loads((out / SWEEP_FILE).read_text())["runs"]) == 1
    with monkeypatch.context() as patched:  # the same stop over recorded episodes: a resume, said so
        patched.setattr("pipelines.experiments.sweep._default_backend", interrupted)
        assert main([*ARGV, "--out", str(out), "--episodes-per-cell", "2"]) == 130
    said = "interrupted: rerun the same command to resume (stopped while its workers started: no episode "
    assert said in capsys.readouterr().err


# ----------------------------------------------------------------------------------------------------------
# The sweep directory: only its own files, never through a link, never a folder of the user's
# ----------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name",
    [EPISODES_FILE, ERRORS_FILE, SWEEP_FILE, LOCK_FILE, TABLE_MD, CELLS_CSV, "success_by_method.png",
     "sweep.json.part", MCAP_DIR, f"{MCAP_DIR}/some-cell"],
)  # fmt: skip
@pytest.mark.parametrize("report_only", [False, True], ids=["run", "report-only"])
def test_a_sweep_file_that_is_a_link_is_refused_before_anything_is_read(
    good, tmp_path, capsys, name, report_only
):
    out = tmp_path / "sweep"
    shutil.copytree(good, out)
    victim = tmp_path / "victim.txt"
    victim.write_bytes(b"the victim's line\n{torn")
    link = out / name
    if link.exists():
        link.unlink()
    link.parent.mkdir(exist_ok=True)
    link.symlink_to(victim if "mcap" not in name else tmp_path)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.is_symlink()}
    argv = [*ARGV, "--episodes-per-cell", "2", "--out", str(out)] + (["--report-only"] if report_only else [])
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"crowdmpc sweep: error: {link} is a symbolic link; a sweep writes only its own files: remove the "
        "link or choose another --out"
    ]
    assert victim.read_bytes() == b"the victim's line\n{torn"
    assert before == {p.name: p.read_bytes() for p in out.iterdir() if p.is_file() and not p.is_symlink()}


def test_a_folder_of_other_files_is_not_a_sweep_directory(tmp_path, capsys):
    mine = {TABLE_MD: b"my table\n", CELLS_CSV: b"a,b\n1,2\n"}
    for name, data in mine.items():
        (tmp_path / name).write_bytes(data)
    assert main([*ARGV, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"crowdmpc sweep: error: --out {tmp_path} holds files but no sweep (sweep.json, episodes.jsonl); a "
        "sweep would overwrite them: choose an empty or new folder"
    ]
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == mine
    with pytest.raises(PipelineError, match="holds files but no sweep"):
        run_sweep(_config(tmp_path))


def test_a_sweep_stopped_while_writing_its_first_sweep_file_resumes(tmp_path, monkeypatch, capsys):
    out = tmp_path / "stopped"
    real_replace = os.replace

    def stopped(src, dst):
        if Path(dst).name == SWEEP_FILE:
            raise KeyboardInterrupt
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", stopped)
    outcome = run_sweep(_config(out))  # written once the backend has started: an interrupt of the run
    assert outcome.interrupted and outcome.ran == 0
    monkeypatch.undo()
    assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]  # the writer took its temporary file away
    # a SIGKILL leaves it behind: the same command still resumes
    (out / (SWEEP_FILE + ".part")).write_text('{"runs": [{"start')
    assert main([*ARGV, "--out", str(out)]) == 0
    assert len(episode_log(out).load()) == 2
    assert not (out / (SWEEP_FILE + ".part")).exists()


def test_an_empty_or_new_folder_and_a_sweep_directory_are_fine(good, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main([*ARGV, "--out", str(tmp_path / "empty")]) == 0
    assert main([*ARGV, "--out", str(tmp_path / "new" / "sweep")]) == 0
    out = tmp_path / "resumed"
    shutil.copytree(good, out)
    assert main([*ARGV, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    assert len(episode_log(out).load()) == 4
    assert "4/4 episodes recorded (2 this run" in capsys.readouterr().err


def test_report_only_tabulates_the_sweep_that_is_there_or_refuses(tmp_path, capsys):
    """--report-only read the plan from its own options: another --experiment relabelled the records as its
    methods, and without the run's --humans, --robots and --seed it wrote empty tables over the report;
    without its --episodes-per-cell it projected the CPU time of the default 1000 episodes per cell."""
    out = tmp_path / "sweep"
    run_sweep(SweepConfig(get_experiment("baselines"), out, 1, humans=(3,), seed=7, n_robots=2,
                          backend="inline", progress=False))  # fmt: skip
    report = ["sweep", "--report-only", "--no-progress", "--out", str(out)]
    capsys.readouterr()
    assert main([*report, "--experiment", "baselines"]) == 0  # humans, robots, seed, episodes: the run's
    table = (out / TABLE_MD).read_text()
    assert "| Numbers of pedestrians | 3 | 3 |" in table and "| Episodes | 1 | 1 |" in table
    assert "Robots: 2 per episode" in table
    assert "; the 2 planned episodes take " in capsys.readouterr().err  # 2 cells x 1 episode
    shown = tmp_path / "run.toml"  # `config show` writes every default, which asks for none of them
    assert main(["config", "show"]) == 0
    shown.write_text(capsys.readouterr().out)
    assert main(["--config", str(shown), *report, "--experiment", "baselines"]) == 0
    assert "; the 2 planned episodes take " in capsys.readouterr().err
    assert (out / TABLE_MD).read_text() == table
    for options, message in (
        (["--experiment", "table2"], f"{out} holds a sweep of experiment 'baselines', not 'table2'"),
        (["--experiment", "baselines", "--humans", "4"], "holds 2 records, none of them of the cells"),
    ):
        assert main([*report, *options]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0], err
        assert (out / TABLE_MD).read_text() == table  # left as it was


def test_report_only_of_an_experiment_swept_from_python_names_no_experiment_option(tmp_path, capsys):
    """A folder of docs/examples/own_experiment.py: --report-only advised '--experiment sensed_margins', which
    argparse then refused (no such choice); it now says how such a sweep's report is written."""
    from pipelines.experiments.cells import Experiment
    from pipelines.loop.controllers import ControllerSpec

    mine = Experiment(
        name="mine", title="ORCA alone", methods=(("ORCA", ControllerSpec("orca")),), humans=(1,)
    )
    out = tmp_path / "sweep"
    run_sweep(SweepConfig(mine, out, 1, n_robots=1, backend="inline", progress=False))
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--no-progress", "--experiment", "table2", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{out} holds a sweep of experiment 'mine', not 'table2'" in err[0], err
    assert "--experiment mine" not in err[0] and "'mine' is no --experiment" in err[0]
    assert "pipelines.experiments.report.write_report" in err[0]


# ----------------------------------------------------------------------------------------------------------
# A broken zoo entry: refused by the driver in simulate's line, before any worker starts (and in --dry-run)
# ----------------------------------------------------------------------------------------------------------


def test_a_zoo_entry_whose_weights_changed_is_refused_up_front_as_simulate_does(tmp_path, capsys):
    add_to_zoo(checkpoints_dir() / "vanilla_lstm_eth.pt", name="my_v", protocol="test", training_data={},
               metrics={})  # fmt: skip
    weights = user_zoo_dir() / "my_v.pt"
    data = bytearray(weights.read_bytes())
    data[len(data) // 2] ^= 0xFF
    weights.write_bytes(bytes(data))
    small = ["--humans", "1", "--robots", "1"]
    assert main(["simulate", "--controller", "cmpc", "--predictor", "my_v", *small, "--episodes", "1"]) == 2
    simulate = capsys.readouterr().err.strip().splitlines()
    assert len(simulate) == 1 and "but the manifest expects" in simulate[0]
    sweep = ["sweep", "--experiment", "controllers", "--controllers", "cmpc", "--predictor", "my_v", *small,
             "--episodes-per-cell", "4", "--backend", "inline", "--no-progress", "--jit", "off"]  # fmt: skip
    for extra in (["--dry-run"], []):
        assert main([*sweep, *extra, "--out", str(tmp_path / "sweep")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [simulate[0].replace("crowdmpc simulate:", "crowdmpc sweep:")]
    assert not (tmp_path / "sweep").exists()


def test_a_sweep_of_controllers_that_plan_without_a_predictor_does_not_check_one(tmp_path, capsys):
    """--predictor names the predictor of the methods that plan with one; orca and straight load none, so a
    name that is not available refused a sweep of them alone."""
    sweep = ["sweep", "--experiment", "controllers", "--controllers", "orca,straight", "--predictor", "nope",
             "--humans", "1", "--robots", "1", "--episodes-per-cell", "1", "--dry-run"]  # fmt: skip
    assert main([*sweep, "--out", str(tmp_path / "sweep")]) == 0
    with_cmpc = [*sweep[:4], "orca,cmpc", *sweep[5:]]
    assert main([*with_cmpc, "--out", str(tmp_path / "sweep2")]) == 2
    assert "needs predictors ['nope'] that are not available" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--set", "controller.coupling=nlp", "sweep", "--experiment", "table2", "--predictor",
          "constant_velocity"], "method 'DMPC' of experiment 'table2': coupling 'nlp' puts the predictor"),
        (["sweep", "--experiment", "coupling", "--predictor", "orca_oracle"],
         "method 'NLP exact' of experiment 'coupling': the orca_oracle predictor works with coupling 'ibr'"),
    ],
    ids=["dmpc-nlp", "oracle-nlp"],
)  # fmt: skip
def test_a_coupling_no_controller_builds_is_refused_before_the_sweep_starts(argv, message, tmp_path, capsys):
    """The controller refused it as each episode began: workers started and every episode of the method
    raised into errors.jsonl; the dry run passed it."""
    out = tmp_path / "sweep"
    small = ["--humans", "5", "--episodes-per-cell", "1", "--backend", "inline", "--jit", "off"]
    for extra in (["--dry-run"], []):
        assert main([*argv, *small, *extra, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0]
    assert not out.exists()


def test_a_d_min_below_the_contact_distance_is_refused_before_the_sweep_starts(tmp_path, capsys):
    """`--set mpc.d_min=0.5` (below 2 x radius = 0.6 m: the MPC accepts contact) ran every episode of a sweep
    (CMPC, 9 humans: within 0.8 m of a human in 6 of 6 episodes). d_min at the contact distance is allowed."""
    out = tmp_path / "sweep"
    sweep = ["sweep", "--experiment", "controllers", "--humans", "1", "--robots", "1", "--episodes-per-cell",
             "1", "--backend", "inline", "--jit", "off",
             "--set", "mpc.d_min=0.5", "--no-progress"]  # fmt: skip
    for extra in (["--dry-run"], []):
        assert main([*sweep, "--controllers", "orca,cmpc", *extra, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1
        assert "method 'cmpc' of experiment 'controllers': the MPC's d_min 0.5 m is below" in err[0]
        assert err[0].endswith("(--set mpc.d_min=0.6)")  # not "a smaller [world] radius": a sweep refuses it
    assert not out.exists()
    at_contact = [*sweep[:-2], "mpc.d_min=0.6", "--no-progress"]
    assert main([*at_contact, "--controllers", "orca,cmpc", "--dry-run", "--out", str(out)]) == 0


# ----------------------------------------------------------------------------------------------------------
# A recalibration keeps the cell key: its records and new episodes must not mix two margin sets
# ----------------------------------------------------------------------------------------------------------

MARGINS_ARGV = ["sweep", "--experiment", "controllers", "--controllers", "cmpc", "--predictor",
                "constant_velocity", "--margins", "conformal", "--humans", "1", "--robots", "1", "--backend",
                "inline", "--no-progress", "--jit", "off"]  # fmt: skip


def _calibrate(scale: float, created: str = "2026-01-01T00:00:00+00:00") -> None:
    """constant_velocity's closed-loop block at alpha 0.1: margins 0.18 k * scale at step k, made at
    ``created`` (a refusal names it)."""
    block = constant_velocity_block(np.outer(np.arange(1, 20) / 100.0 * scale, [1.0, 2.0, 3.0, 4.0]))
    save_calibration(dataclasses.replace(block, created=created))


def test_a_cell_is_not_extended_after_a_recalibration(tmp_path, capsys):
    out = tmp_path / "sweep"
    _calibrate(1.0)
    assert main([*MARGINS_ARGV, "--episodes-per-cell", "2", "--out", str(out)]) == 0
    records = (out / EPISODES_FILE).read_bytes()
    _calibrate(2.0, "2026-01-02T00:00:00+00:00")  # the same predictor, source and alpha: the same cell key
    capsys.readouterr()
    assert main([*MARGINS_ARGV, "--episodes-per-cell", "4", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    cell = "cmpc-constant_velocity-F-ibr-m=cp0.1-paper-visible-h1-r1"
    assert err == [
        f"crowdmpc sweep: error: {out / EPISODES_FILE} holds episodes of {cell} planned with margins "
        "[0.18, 0.36, 0.54, 0.72] m, but the cell's margins are now [0.36, 0.72, 1.08, 1.44] m: "
        "constant_velocity's closed-loop calibration at alpha 0.1 was made again after the records "
        "(records: your calibration of 2026-01-01 00:00 UTC, now: your calibration of 2026-01-02 00:00 UTC); "
        f"use another --out for the new margins, or `crowdmpc sweep --report-only --out {out}` to report the "
        "episodes it holds"
    ]
    assert (out / EPISODES_FILE).read_bytes() == records
    assert len(json.loads((out / SWEEP_FILE).read_text())["runs"]) == 1  # a refused run leaves no line
    _calibrate(1.0)  # the records' margins again: the cell extends as before
    assert main([*MARGINS_ARGV, "--episodes-per-cell", "4", "--out", str(out)]) == 0
    margins = {tuple(r["config"]["margins"]["margins_m"]) for r in episode_log(out).load().values()}
    assert margins == {(0.18, 0.36, 0.54, 0.72)}


def test_changed_margins_per_motion_class_are_refused_too(good, tmp_path):
    classes = {"names": ["new", "standing", "slow", "walking"], "quantiles": [[0.1]] * 4}
    _damage(good, tmp_path, lambda r: r["config"].update(margins={"margins_m": [], "classes": classes}))
    (tmp_path / SWEEP_FILE).write_bytes((good / SWEEP_FILE).read_bytes())
    with pytest.raises(
        PipelineError,
        match=r"planned with margins per motion class, where the cell now plans with none: they",
    ):
        run_sweep(_config(tmp_path))


@pytest.mark.parametrize("mode", ["conformal", "conformal-motion", "conformal-shortfall"])
def test_margins_without_a_calibration_are_refused_before_the_sweep_starts(mode, tmp_path, capsys):
    """The per-human modes resolve their class margins in the controller only: the check before the workers
    passed them, and the sweep made its folder, started workers and stopped on its first 4 episodes. The dry
    run, which did not check margins, passed them too."""
    out = tmp_path / "sweep"
    argv = ["sweep", "--experiment", "table2", "--humans", "5", "--episodes-per-cell", "1", "--margins",
            f"{mode}:0.3", "--backend", "inline"]  # fmt: skip
    for extra in (["--dry-run"], []):
        assert main([*argv, *extra, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "no closed-loop calibration at alpha=0.3" in err[0]
    assert not out.exists()


def test_a_run_line_the_disk_refuses_names_sweep_json_and_keeps_it(tmp_path, capsys):
    """A rerun whose new line of sweep.json met a full disk (here `ulimit -f`) said "could not write (File too
    large)", naming no file: now sweep.json, which stays as it was."""
    out = tmp_path / "sw"
    argv = ["sweep", "--experiment", "baselines", "--humans", "3", "--episodes-per-cell", "2"]
    argv += ["--backend", "inline", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    before = (out / SWEEP_FILE).read_text()
    capsys.readouterr()
    with file_size_limit(len(before) + 10):  # a second run's line does not fit
        assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith(f"crowdmpc sweep: error: could not write {out / SWEEP_FILE} (File too large)")
    assert (out / SWEEP_FILE).read_text() == before


def test_report_only_takes_the_sweeps_recorded_config_for_what_is_not_typed(tmp_path, capsys):
    """A sweep run with --predictor, --margins, --humans and --robots: `--report-only --out DIR` alone
    tabulated none of its records (refused: "none of them of the cells planned here") until every option
    was typed again. Its last run's recorded config now stands beneath what is typed; a --config file
    replaces it, as it replaces any recorded setting."""
    out = tmp_path / "sw"
    run = ["sweep", "--experiment", "table2", "--predictor", "constant_velocity", "--humans", "2"]
    run += ["--robots", "2", "--margins", "fixed:0.1,0.1,0.1,0.1", "--seed", "3", "--episodes-per-cell", "1"]
    assert main([*run, "--backend", "inline", "--no-progress", "--out", str(out)]) == 0
    table = (out / TABLE_MD).read_text()
    (out / TABLE_MD).unlink()
    capsys.readouterr()
    assert main(["sweep", "--report-only", "--no-progress", "--out", str(out)]) == 0
    assert (out / TABLE_MD).read_text() == table
    assert main(["sweep", "--report-only", "--no-progress", "--out", str(out), "--humans", "3"]) == 2
    assert "none of them of the cells planned here" in capsys.readouterr().err  # typed: the command's
    shown = tmp_path / "run.toml"
    assert main(["config", "show"]) == 0
    shown.write_text(capsys.readouterr().out)
    report = ["--config", str(shown), "sweep", "--experiment", "table2", "--report-only", "--out", str(out)]
    assert main(report) == 2
    assert "none of them of the cells planned here" in capsys.readouterr().err


def test_report_only_of_a_sweep_file_with_no_run_yet_says_what_is_missing(tmp_path, capsys):
    """A sweep.json of no run line (one stopped before its first) was read as a recorded config and refused
    in `config show --from-sweep`'s words; the report goes on from what is typed, and says what is missing."""
    out = tmp_path / "sw"
    out.mkdir()
    (out / SWEEP_FILE).write_text('{"runs": []}\n')
    assert main(["sweep", "--experiment", "table2", "--report-only", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "episodes.jsonl does not exist: nothing to report" in err and "--from-sweep" not in err
