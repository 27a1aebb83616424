"""McapRecorder: JSON messages round-trip; a topic keeps its type; the file is always finished."""

from __future__ import annotations

import json

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType

from pipelines.errors import PipelineError
from pipelines.logs.mcap_file import MAGIC
from pipelines.logs.reader import read_recording
from pipelines.logs.recorder import DEFAULT_COMPRESSION, McapRecorder
from pipelines.logs.schemas import HUMANS, PREDICTION, ROBOTS, MessageSchema
from pipelines.logs.view import episode_view
from tests.read_only import file_size_limit

ROBOT_MESSAGE = {
    "time": 0.4,
    "step": 1,
    "positions": [[1.0, 2.0], [-0.5, 0.25]],
    "velocities": [[0.1, 0.0], [0.0, -0.1]],
    "goals": [[5.0, 5.0], [-5.0, 5.0]],
    "actions": [[2.0, -2.0], [0.0, 0.5]],
    "commanded": [[3.0, -2.0], [0.0, 0.5]],
    "reached": [False, True],
}
HUMAN_MESSAGE = {
    "time": 0.4,
    "step": 1,
    "positions": [[0.0, 0.0]],
    "velocities": [[1.0, 0.0]],
    "goals": [[4, 0]],
}


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.LZ4, CompressionType.ZSTD])
def test_messages_metadata_and_schemas_round_trip(tmp_path, compression):
    path = tmp_path / "a.mcap"
    with McapRecorder(path, compression=compression, metadata={"episode": {"seed": "3"}}) as rec:
        rec.write("/robots", ROBOT_MESSAGE, 400_000_000, schema=ROBOTS)
        rec.write("/humans", HUMAN_MESSAGE, 400_000_000, schema=HUMANS)
        rec.write("/robots", {**ROBOT_MESSAGE, "step": 2, "time": 0.8}, 800_000_000, schema=ROBOTS)
        rec.add_metadata("late", {"note": "written after messages"})
    got = read_recording(path)
    assert not got.truncated and got.warning is None
    assert [m.data for m in got.messages["/robots"]] == [
        ROBOT_MESSAGE,
        {**ROBOT_MESSAGE, "step": 2, "time": 0.8},
    ]
    assert [m.log_time_ns for m in got.messages["/robots"]] == [400_000_000, 800_000_000]
    assert got.data("/humans") == [HUMAN_MESSAGE]
    assert got.metadata == {"episode": {"seed": "3"}, "late": {"note": "written after messages"}}
    robots = got.channels["/robots"]
    assert (robots.message_encoding, robots.schema_name, robots.schema_encoding) == (
        "json",
        "crowdmpc.Robots",
        "jsonschema",
    )
    assert json.loads(robots.schema_data) == ROBOTS.schema


def test_two_topics_of_one_type_share_one_schema_record(tmp_path):
    path = tmp_path / "a.mcap"
    with McapRecorder(path) as rec:
        rec.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
        rec.write("/robots_again", ROBOT_MESSAGE, 0, schema=ROBOTS)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert len(summary.schemas) == 1 and len(summary.channels) == 2


def test_type_change_on_a_topic_is_refused(tmp_path):
    with McapRecorder(tmp_path / "a.mcap") as rec:
        rec.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
        with pytest.raises(PipelineError, match="'/robots' carries 'crowdmpc.Robots'.*'crowdmpc.Humans'"):
            rec.write("/robots", HUMAN_MESSAGE, 1, schema=HUMANS)
        changed = MessageSchema("crowdmpc.Robots", {**ROBOTS.schema, "required": ["time"]})
        with pytest.raises(PipelineError, match="schema 'crowdmpc.Robots' changed"):
            rec.write("/robots", ROBOT_MESSAGE, 1, schema=changed)
        # an equal schema built anew is the same type
        rec.write("/robots", ROBOT_MESSAGE, 2, schema=MessageSchema("crowdmpc.Robots", ROBOTS.schema))
    assert len(read_recording(tmp_path / "a.mcap").data("/robots")) == 2


def test_file_is_finished_when_the_block_raises(tmp_path):
    path = tmp_path / "a.mcap"
    with pytest.raises(RuntimeError, match="boom"), McapRecorder(path) as rec:
        rec.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
        raise RuntimeError("boom")
    assert rec.closed
    assert path.read_bytes().endswith(MAGIC)
    assert read_recording(path).data("/robots") == [ROBOT_MESSAGE]
    rec.close()  # idempotent
    with pytest.raises(PipelineError, match="already finished"):
        rec.write("/robots", ROBOT_MESSAGE, 1, schema=ROBOTS)


def test_small_chunks_make_several_chunks(tmp_path):
    path = tmp_path / "a.mcap"
    with McapRecorder(path, chunk_size=1024) as rec:
        for k in range(100):
            rec.write("/robots", {**ROBOT_MESSAGE, "step": k}, k, schema=ROBOTS)
    with open(path, "rb") as f:
        stats = make_reader(f).get_summary().statistics
    assert stats.message_count == 100 and stats.chunk_count > 10


def test_bad_input_is_refused_with_a_clear_message(tmp_path):
    with pytest.raises(PipelineError, match="folder .* does not exist"):
        McapRecorder(tmp_path / "missing" / "a.mcap")
    with pytest.raises(PipelineError, match="chunk_size must be a positive"):
        McapRecorder(tmp_path / "a.mcap", chunk_size=0)
    with pytest.raises(PipelineError, match="CompressionType"):
        McapRecorder(tmp_path / "a.mcap", compression="zstd")
    with McapRecorder(tmp_path / "a.mcap") as rec:
        with pytest.raises(PipelineError, match="not plain JSON.*Out of range float"):
            rec.write("/robots", {**ROBOT_MESSAGE, "time": float("nan")}, 0, schema=ROBOTS)
        with pytest.raises(PipelineError, match="needs str keys and values"):
            rec.add_metadata("episode", {"seed": 3})
        with pytest.raises(PipelineError, match="non-negative int of ns"):
            rec.write("/robots", ROBOT_MESSAGE, 0.4, schema=ROBOTS)


def test_default_compression_is_the_best_installed():
    assert DEFAULT_COMPRESSION is CompressionType.ZSTD  # mcap depends on zstandard and lz4


def test_a_symbolic_link_in_place_of_the_unfinished_file_is_refused(tmp_path):
    """A link planted at NAME.mcap.part would make the recording land wherever it points (it overwrote a
    file outside the folder the user named)."""
    outside = tmp_path / "victim.txt"
    outside.write_text("precious")
    folder = tmp_path / "recs"
    folder.mkdir()
    (folder / "run.mcap.part").symlink_to(outside)
    with pytest.raises(PipelineError, match=r"run\.mcap\.part: it is a symbolic link; remove it"):
        McapRecorder(folder / "run.mcap")
    assert outside.read_text() == "precious"
    (folder / "run.mcap.part").unlink()
    (folder / "run.mcap.part").mkdir()  # and whatever else cannot be opened is named, not an OSError
    with pytest.raises(PipelineError, match=r"cannot record to .*run\.mcap\.part: Is a directory"):
        McapRecorder(folder / "run.mcap")


def test_a_repeated_metadata_name_reads_as_its_last_record(tmp_path):
    path = tmp_path / "a.mcap"
    with McapRecorder(path, metadata={"episode": {"seed": "3"}}) as rec:
        rec.add_metadata("episode", {"seed": "4"})
    assert read_recording(path).metadata == {"episode": {"seed": "4"}}


def test_log_times_from_a_start_beyond_int64_are_simulation_times(tmp_path):
    """An MCAP log time is a uint64: a start of 2^63 ns is valid, and every place names a message by its
    simulation time (log time - start), here 0.4 s."""
    start = 1 << 63
    path = tmp_path / "a.mcap"
    with McapRecorder(path, metadata={"episode": {"start_time_ns": str(start)}}) as rec:
        rec.write_json("/robots", b"not json", start + 400_000_000, schema=ROBOTS)
    got = read_recording(path)
    assert got.problems == [] and got.start_time_ns == start
    assert got.sim_seconds(start + 400_000_000) == pytest.approx(0.4)
    [line] = got.message_problems()
    assert line.startswith("/robots @ 0.400 s: not JSON")


def test_episode_view_pairs_states_by_step_and_reads_predictions_as_h_n_2(tmp_path):
    humans = {**HUMAN_MESSAGE, "positions": [[0.0, 0.0], [1.0, 0.0]], "goals": [[4, 0], [5, 0]]}
    # H = 3 steps ahead of N = 2 humans: prediction[h][i] = (h, 10 i) so that any reordering shows
    prediction = [[[float(h), 10.0 * i] for i in range(2)] for h in range(3)]
    path = tmp_path / "a.mcap"
    with McapRecorder(path) as rec:  # no "episode" record: dt comes from the recorded times
        for step in range(3):
            time = 0.25 * step
            stamp = {"time": time, "step": step}
            rec.write("/robots", {**ROBOT_MESSAGE, **stamp}, int(time * 1e9), schema=ROBOTS)
            if step < 2:  # the run was cut between the last /robots and its /humans
                rec.write("/humans", {**humans, **stamp}, int(time * 1e9), schema=HUMANS)
        rec.write(
            "/mpc/prediction",
            {"time": 0.0, "step": 0, "positions": prediction, "iterations": []},
            0,
            schema=PREDICTION,
        )
    view = episode_view(read_recording(path))
    assert view.steps.tolist() == [0, 1] and view.robot_positions.shape == (2, 2, 2)
    assert view.human_positions.shape == (2, 2, 2)
    assert view.dt == pytest.approx(0.25)  # the median step of the times 0, 0.25 (0.4 is the world's default)
    assert view.predictions[0].shape == (3, 2, 2)
    assert view.predictions[0].tolist() == prediction  # [h][i], as written


def test_publish_time_is_the_log_time_and_both_writers_count(tmp_path):
    """Foxglove can order by publish time: it is the log time, for write and write_json alike."""
    path = tmp_path / "a.mcap"
    with McapRecorder(path) as rec:
        rec.write("/robots", ROBOT_MESSAGE, 400_000_000, schema=ROBOTS)
        rec.write_json("/humans", json.dumps(HUMAN_MESSAGE).encode(), 800_000_000, schema=HUMANS)
        assert rec.message_count == 2
    with open(path, "rb") as f:
        times = [(m.log_time, m.publish_time) for _, _, m in make_reader(f).iter_messages()]
    assert times == [(400_000_000, 400_000_000), (800_000_000, 800_000_000)]


def test_a_negative_log_time_or_a_key_that_is_not_text_is_refused(tmp_path):
    with McapRecorder(tmp_path / "a.mcap") as rec:
        with pytest.raises(PipelineError, match="non-negative int of ns, got -1"):
            rec.write("/robots", ROBOT_MESSAGE, -1, schema=ROBOTS)
        with pytest.raises(PipelineError, match="needs str keys and values"):
            rec.add_metadata("episode", {3: "seed"})


def test_metadata_refused_at_the_start_leaves_no_file_behind(tmp_path):
    """``McapRecorder(path, metadata=...)`` with a value that is no str was refused after the header was
    written: the ``.part`` stayed in the folder, open and locked until collected, an unfinished recording of
    nothing (a killed run's ``.part`` there emptied). Metadata is checked before the file is opened now."""
    with pytest.raises(PipelineError, match="needs str keys and values"):
        McapRecorder(tmp_path / "a.mcap", metadata={"episode": {"seed": 3}})
    assert list(tmp_path.iterdir()) == []
    with McapRecorder(tmp_path / "a.mcap", metadata={"episode": {"seed": "3"}}):
        pass
    assert [p.name for p in tmp_path.iterdir()] == ["a.mcap"]


def test_a_longer_left_over_part_file_is_overwritten_not_kept_behind(tmp_path):
    """A killed run's NAME.mcap.part, longer than the new recording: its tail must not stay after the new
    file's end (the finished file would then not end with MCAP's magic and read as truncated)."""
    path = tmp_path / "a.mcap"
    (tmp_path / "a.mcap.part").write_bytes(b"\0" * 200_000)
    with McapRecorder(path) as rec:
        rec.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
    assert path.read_bytes().endswith(MAGIC)
    got = read_recording(path)
    assert not got.truncated and got.problems == [] and got.data("/robots") == [ROBOT_MESSAGE]


def test_a_new_recording_never_takes_a_name_held_by_a_dangling_link(tmp_path):
    """new=True takes a name only when nothing has it: a symbolic link to nowhere is something (replacing
    it would lose whatever the user keeps the link for)."""
    path = tmp_path / "a.mcap"
    path.symlink_to(tmp_path / "nowhere")
    with pytest.raises(FileExistsError):
        McapRecorder(path, new=True)
    assert path.is_symlink() and not (tmp_path / "a.mcap.part").exists()


def test_a_folder_whose_file_system_does_not_lock_is_one_line(tmp_path, monkeypatch):
    """On an NFS mount without its lock daemon flock fails with ENOLCK ("No locks available"): ``simulate
    --record`` there ended in that OSError's traceback; the .part it opened is closed, not left open."""
    import errno
    import fcntl
    import os

    def no_locks(fd, operation):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(fcntl, "flock", no_locks)
    with pytest.raises(PipelineError) as refused:
        McapRecorder(tmp_path / "a.mcap")
    assert str(refused.value) == (
        f"cannot record to {tmp_path / 'a.mcap.part'}: No locks available (its file system does not lock "
        "files; an NFS mount without its lock daemon?); record into a folder on one that does"
    )


def test_two_recorders_of_one_episode_at_once_never_write_one_file(tmp_path):
    """Two runs recording the same seed into one folder at the same time wrote one .part (one run's episode
    silently replaced by a mix of both, or by the other's): the second is refused while the first records;
    once it has finished, a rerun replaces its file as before."""
    path = tmp_path / "a.mcap"
    first = McapRecorder(path)
    first.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
    with pytest.raises(PipelineError, match="another run is recording that episode into this folder now"):
        McapRecorder(path)
    first.close()
    assert read_recording(path).data("/robots") == [ROBOT_MESSAGE]
    with McapRecorder(path) as again:
        again.write("/robots", ROBOT_MESSAGE, 5, schema=ROBOTS)
    assert not (tmp_path / "a.mcap.part").exists() and len(read_recording(path).data("/robots")) == 1


def test_a_refusal_before_the_rename_keeps_the_recording_unfinished(tmp_path):
    """``may_replace`` runs when the file is finished (another run may have finished a file under the
    name since this one began): when it refuses, nothing is replaced and the recording stays as .part."""
    path = tmp_path / "a.mcap"
    path.write_bytes(b"another run's file")

    def refuse(name):
        if name == path:
            raise PipelineError(f"cannot record to {name}: it holds another run's episode")

    rec = McapRecorder(path, may_replace=refuse)
    rec.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
    with pytest.raises(PipelineError, match="another run's episode"):
        rec.close()
    assert path.read_bytes() == b"another run's file"
    assert read_recording(tmp_path / "a.mcap.part").data("/robots") == [ROBOT_MESSAGE]


def test_a_refusal_of_the_unfinished_file_keeps_it(tmp_path):
    """A killed run's ``.part`` is emptied only once ``may_replace`` lets it, with the file locked (another
    run's unfinished recording was truncated unchecked)."""
    part = tmp_path / "a.mcap.part"
    part.write_bytes(b"a killed run's chunks")
    seen = []

    def refuse(name):
        seen.append(name)
        raise PipelineError(f"cannot record to {name}: it holds another run's episode")

    with pytest.raises(PipelineError, match="a.mcap.part: it holds another run's episode"):
        McapRecorder(tmp_path / "a.mcap", may_replace=refuse)
    assert seen == [part] and part.read_bytes() == b"a killed run's chunks"
    with McapRecorder(tmp_path / "a.mcap", may_replace=lambda name: None) as again:  # lock released
        again.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
    assert not part.exists() and read_recording(tmp_path / "a.mcap").data("/robots") == [ROBOT_MESSAGE]


def test_a_recorder_this_program_left_open_is_named_in_the_refusal(tmp_path):
    """A notebook cell whose episode raised keeps its recorder (and the .part's lock) alive in the traceback;
    running the cell again was refused as another run recording, which sent the user looking for another
    program. The refusal says when the holder is a recorder of this program, and not for a lock held by
    anything else (a raw flock here stands in for another program's run)."""
    import fcntl
    import os

    path = tmp_path / "a.mcap"
    left_open = McapRecorder(path)
    with pytest.raises(PipelineError) as refused:
        McapRecorder(path)
    assert "(here: a recorder this program opened and has not closed" in str(refused.value)
    left_open.close()

    fd = os.open(tmp_path / "a.mcap.part", os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(PipelineError) as other:
            McapRecorder(path)
    finally:
        os.close(fd)
    assert str(other.value) == (
        f"cannot record to {tmp_path / 'a.mcap.part'}: another run is recording that episode into this "
        "folder now; record into another folder"
    )


def test_a_write_the_disk_refuses_names_the_unfinished_recording(tmp_path):
    """A chunk (or the footer) met by a full disk, a quota or `ulimit -f` ended `simulate --record` in
    mcap's OSError traceback: one line now naming the ``.part`` it was writing, which keeps what was
    written, and no file under the final name."""
    path = tmp_path / "a.mcap"
    part = tmp_path / "a.mcap.part"
    expected = f"^cannot record to {part}: File too large \\(the recording is unfinished\\); free space"
    rec = McapRecorder(path, chunk_size=1024, compression=CompressionType.NONE)
    with file_size_limit(4096), pytest.raises(PipelineError, match=expected):
        for k in range(100):
            rec.write("/robots", {**ROBOT_MESSAGE, "step": k}, k, schema=ROBOTS)
    with file_size_limit(part.stat().st_size), pytest.raises(PipelineError, match=expected):
        rec.close()  # the summary and footer no longer fit
    assert rec.closed and not path.exists() and part.stat().st_size > 0


@pytest.mark.parametrize("where", ["start", "metadata"])
def test_an_interrupt_as_a_recording_begins_leaves_no_part(tmp_path, monkeypatch, where):
    """A Ctrl-C (or a `kill`, which the CLI takes as one) while the recorder wrote its header or metadata,
    before the constructor returned, left a ``.part`` of a header that nobody held to finish or remove:
    `simulate --record` killed as an episode began kept one beside its finished files (seen under load)."""
    import mcap.writer

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    if where == "start":
        monkeypatch.setattr(mcap.writer.Writer, "start", interrupt)
    else:
        monkeypatch.setattr(McapRecorder, "add_metadata", interrupt)
    with pytest.raises(KeyboardInterrupt):
        McapRecorder(tmp_path / "a.mcap", metadata={"episode": {"seed": "1"}})
    assert list(tmp_path.iterdir()) == []
    monkeypatch.undo()
    with McapRecorder(tmp_path / "a.mcap") as again:  # the name is free, its lock gone with the file
        again.write("/robots", ROBOT_MESSAGE, 0, schema=ROBOTS)
    assert [p.name for p in tmp_path.iterdir()] == ["a.mcap"]
