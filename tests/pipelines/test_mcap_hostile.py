"""Hostile MCAP input: whatever a file holds, ``crowdmpc review`` reports it in a line and never crashes; a
recording killed at any moment leaves every finished episode complete.

Every bad file is generated here from a real recorded episode (tests/pipelines/mcap_episode.py) or with the
mcap writer: cuts at many offsets, flipped bytes inside chunks, payloads that are not JSON or not of the
shape the review reads, bad metadata, empty files, a folder named x.mcap, unfinished .part files.
"""

from __future__ import annotations

import json
import math
import os
import random
import shutil
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import DataEnd, Statistics
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer
from PIL import Image

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.logs.mcap_file import statistics_problem
from pipelines.logs.reader import read_recording
from pipelines.logs.recorder import McapRecorder
from pipelines.logs.recording import episode_filename
from pipelines.logs.review import count
from pipelines.logs.schemas import EPISODE_METRICS, HUMANS, ROBOTS, SOLVER
from tests.pipelines.mcap_episode import record_episode

REPO = Path(__file__).resolve().parents[2]
HEADER_END = 33  # magic (8) + crowdmpc's Header record (9 + 4 + 4 + len("crowdmpc"))
S = 1_000_000_000  # ns


def robot(step: int, n: int = 1) -> dict:
    return {
        "time": 0.4 * step,
        "step": step,
        "positions": [[0.1 * step, 0.0]] * n,
        "velocities": [[0.0, 0.0]] * n,
        "goals": [[1.0, 1.0]] * n,
        "actions": None,
        "commanded": None,
        "reached": [False] * n,
    }


def review(capsys, *args: object) -> tuple[int, str, str]:
    rc = main(["review", *map(str, args)])
    out, err = capsys.readouterr()
    return rc, out, err


def lines_naming(text: str, path: Path) -> list[str]:
    return [line for line in text.splitlines() if str(path) in line]


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    """A finished episode long enough for several chunks."""
    return record_episode(tmp_path_factory.mktemp("episode"), steps=75, n_humans=7)


def test_cut_at_many_offsets_reads_a_prefix_or_is_reported(episode, tmp_path, capsys):
    data = episode.path.read_bytes()
    complete = read_recording(episode.path)
    # the shortest readable cut keeps the first metadata record after the header: one that reads nothing
    # past the header is nothing to review
    first_read = HEADER_END + 9 + int.from_bytes(data[HEADER_END + 1 : HEADER_END + 9], "little")
    rng = random.Random(0)
    cuts = sorted(
        {
            *range(0, HEADER_END + 2, 3),
            HEADER_END,
            first_read - 1,
            first_read,
            *rng.sample(range(40, len(data)), 40),
            len(data) - 1,
        }
    )
    folder = tmp_path / "cuts"
    folder.mkdir()
    shutil.copy(episode.path, folder / "full.mcap")
    unreadable, truncated = [], []
    for cut in cuts:
        path = folder / f"cut{cut:07d}.mcap"
        path.write_bytes(data[:cut])
        try:
            rec = read_recording(path)
        except PipelineError as exc:
            assert str(path) in str(exc) and "\n" not in str(exc)
            unreadable.append(path)
            continue
        truncated.append(path)
        assert rec.truncated and not rec.problems and not rec.message_problems(), cut
        for topic, messages in rec.messages.items():  # what was read is what was written
            assert [m.data for m in messages] == [m.data for m in complete.messages[topic][: len(messages)]]
    assert [p.name for p in unreadable] == [f"cut{c:07d}.mcap" for c in cuts if c < first_read]

    rc, out, err = review(capsys, folder)
    assert rc == 0
    for path in unreadable:
        (line,) = lines_naming(err, path)
        assert line.startswith("crowdmpc review: unreadable: ")
    for path in truncated:
        assert any("is truncated" in line for line in lines_naming(err, path))
    # a cut that kept the episode's metadata repeats the complete file's episode (no row, counted once);
    # one cut before it is a set-up of its own, with a row
    rows = [path for path in truncated if path.name in out]
    assert "full.mcap" in out and len(rows) < len(truncated)
    assert f"holds {len(truncated) - len(rows)} repeats of episodes of " in err
    assert all(not read_recording(path).data("/episode/metrics") for path in rows)
    rc, out, _ = review(capsys, folder, "--check")
    assert rc == 1  # the unreadable cuts fail the check, and so do the truncated ones (a lost footer)
    assert out.count(" each valid; fails: truncated\n") == len(truncated)  # every message each holds is valid
    assert out.count(" ok\n") == 1  # the whole file alone
    assert out.count(" messages read, truncated: ") == len(truncated)


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.ZSTD])
def test_a_flipped_byte_in_a_chunk_loses_that_chunk_only(tmp_path, capsys, compression):
    path = tmp_path / "a.mcap"
    with McapRecorder(path, compression=compression, chunk_size=2048) as rec:
        for k in range(60):
            rec.write("/robots", robot(k), k * S // 2, schema=ROBOTS)
    data = path.read_bytes()
    with open(path, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    assert len(chunks) >= 4
    rng = random.Random(1)
    for i, chunk in enumerate(
        [chunks[0], chunks[len(chunks) // 2], chunks[-1]]
    ):  # the first holds the channel
        # opcode, length, start and end time, uncompressed size and CRC, compression string, data length
        start = chunk.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4 + 4 + len(chunk.compression) + 8
        bad = bytearray(data)
        bad[rng.randrange(start, start + chunk.compressed_size)] ^= 1 << rng.randrange(8)
        flipped = tmp_path / f"flip{i}.mcap"
        flipped.write_bytes(bytes(bad))

        rec = read_recording(flipped)
        (problem,) = rec.problems
        assert problem.startswith(f"bad chunk at byte {chunk.chunk_start_offset} ") and "left out" in problem
        lost = [k for k in range(60) if chunk.message_start_time <= k * S // 2 <= chunk.message_end_time]
        assert 0 < len(lost) < 60
        assert [r["step"] for r in rec.data("/robots")] == [k for k in range(60) if k not in lost]

        rc, _, err = review(capsys, flipped)
        assert rc == 0
        (line,) = lines_naming(err, flipped)
        assert "bad chunk" in line
        rc, out, _ = review(capsys, flipped, "--check")
        assert rc == 1
        assert f"check {flipped}: the file itself: 1 problem\n  bad chunk at byte" in out
        assert f"check {flipped}: {60 - len(lost)} messages, each valid; fails: its own problems\n" in out


def test_the_data_section_crc_is_checked_where_the_file_has_one(tmp_path, capsys):
    path = tmp_path / "a.mcap"
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.NONE, enable_data_crcs=True)
        writer.start()
        writer.add_metadata("episode", {"scenario": "circle"})
        channel = writer.register_channel("/robots", "json", writer.register_schema(*_schema(ROBOTS)))
        writer.add_message(channel, log_time=0, data=ROBOTS_JSON, publish_time=0)
        writer.finish()
    data = bytearray(path.read_bytes())
    assert read_recording(path).problems == []
    data[data.index(b"circle")] ^= 0x20  # "Circle": outside every chunk, only the data section CRC sees it
    path.write_bytes(bytes(data))
    rec = read_recording(path)
    (problem,) = rec.problems
    assert problem.startswith("data section CRC mismatch")
    assert rec.episode()["scenario"] == "Circle" and len(rec.data("/robots")) == 1  # the rest still reads
    rc, out, _ = review(capsys, path, "--check")
    assert rc == 1 and "data section CRC mismatch" in out


def test_a_recording_carries_its_data_section_crc(episode, tmp_path, capsys):
    """The recorder wrote no data section CRC (mcap's default): a flipped bit in the "episode" metadata,
    outside every chunk, made seed 7 read as seed 6 (another episode) and --check said "ok"."""
    data = episode.path.read_bytes()
    at = data.index(b"\x04\x00\x00\x00seed\x01\x00\x00\x007") + 4 + 4 + 4  # the key, the value's length
    bad = bytearray(data)
    bad[at] ^= 1  # "7" -> "6"
    path = tmp_path / "seed.mcap"
    path.write_bytes(bytes(bad))
    rec = read_recording(path)
    assert rec.episode()["seed"] == "6"
    (problem,) = rec.problems
    assert problem.startswith("data section CRC mismatch")
    rc, out, _ = review(capsys, path, "--check")
    assert rc == 1 and f"check {path}: the file itself: 1 problem\n  data section CRC mismatch" in out


def _recorded(path: Path, monkeypatch, *, data_crc: bool, **writer) -> Path:
    """60 robot states in 6 chunks as McapRecorder writes them, or as it did before it wrote the data
    section's CRC (``data_crc=False``: DataEnd's CRC is 0, "not computed"); ``writer``: more Writer kwargs."""
    with monkeypatch.context() as m:
        m.setattr(
            "pipelines.logs.recorder.Writer",
            lambda *a, enable_data_crcs, **k: Writer(*a, **k, **writer, enable_data_crcs=data_crc),
        )
        with McapRecorder(path, chunk_size=2048) as rec:
            for k in range(60):
                rec.write("/robots", robot(k), k * S // 2, schema=ROBOTS)
    with open(path, "rb") as f:
        (end,) = [r for r in StreamReader(f).records if isinstance(r, DataEnd)]
    assert (end.data_section_crc != 0) == data_crc
    return path


def test_a_chunk_skipped_as_an_unknown_record_is_counted_missing(tmp_path, capsys, monkeypatch):
    """A recording made before the data section CRC was written: a chunk whose opcode byte flipped is a
    record mcap's reader does not know and skips, so its messages vanished and --check said "ok"."""
    path = _recorded(tmp_path / "old.mcap", monkeypatch, data_crc=False)
    assert read_recording(path).problems == []
    rc, out, _ = review(capsys, path, "--check")
    assert rc == 0 and out.endswith(f"check {path}: 60 messages, ok\n")
    with open(path, "rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[2]
    lost = [k for k in range(60) if chunk.message_start_time <= k * S // 2 <= chunk.message_end_time]
    assert 0 < len(lost) < 60
    bad = bytearray(path.read_bytes())
    assert bad[chunk.chunk_start_offset] == Opcode.CHUNK
    bad[chunk.chunk_start_offset] ^= 0x80  # 0x86: no record MCAP defines
    flipped = tmp_path / "flipped.mcap"
    flipped.write_bytes(bytes(bad))

    rec = read_recording(flipped)
    assert [r["step"] for r in rec.data("/robots")] == [k for k in range(60) if k not in lost]
    n = 60 - len(lost)
    (problem,) = rec.problems
    assert problem.startswith(f"{n} messages read, the statistics record counts 60 (/robots {n} of 60): ")
    rc, out, _ = review(capsys, flipped, "--check")
    assert rc == 1
    assert f"check {flipped}: the file itself: 1 problem\n  {n} messages read, the statistics" in out
    assert out.endswith(f"check {flipped}: {n} messages, each valid; fails: its own problems\n")

    # where the file has a data section CRC, its mismatch is the one line: the count is not a second
    new = _recorded(tmp_path / "new.mcap", monkeypatch, data_crc=True)
    bad = bytearray(new.read_bytes())
    assert bad[chunk.chunk_start_offset] == Opcode.CHUNK  # the same chunks: only DataEnd's CRC differs
    bad[chunk.chunk_start_offset] ^= 0x80
    new.write_bytes(bytes(bad))
    (problem,) = read_recording(new).problems
    assert problem.startswith("data section CRC mismatch")


def test_without_counts_per_channel_the_total_is_compared():
    """A writer may leave the Statistics record's counts per channel out: its total is still a count."""
    stats = Statistics(
        attachment_count=0, channel_count=2, channel_message_counts={}, chunk_count=1, message_count=5,
        message_end_time=0, message_start_time=0, metadata_count=0, schema_count=1,
    )  # fmt: skip
    assert statistics_problem(stats, {1: 3, 2: 2}, {1: "/robots"}) is None
    problem = statistics_problem(stats, {1: 3, 2: 1}, {1: "/robots"})
    assert problem is not None and problem.startswith("4 messages read, the statistics record counts 5: ")
    stats.channel_message_counts = {1: 3, 2: 2}
    problem = statistics_problem(stats, {1: 3, 2: 1}, {1: "/robots"})
    assert problem is not None and problem.startswith("4 messages read, the statistics record counts 5 "
                                                      "(channel id 2 1 of 2): ")  # fmt: skip


def test_a_summary_without_statistics_is_no_problem(tmp_path, capsys, monkeypatch):
    """MCAP leaves the Statistics record optional: a file without one has nothing to count against."""
    path = _recorded(tmp_path / "bare.mcap", monkeypatch, data_crc=False, use_statistics=False)
    with open(path, "rb") as f:
        assert make_reader(f).get_summary().statistics is None
    assert read_recording(path).problems == []
    rc, out, _ = review(capsys, path, "--check")
    assert rc == 0 and out.endswith(f"check {path}: 60 messages, ok\n")


def test_the_summary_section_crc_is_checked(episode, tmp_path, capsys):
    """No mcap reader checks the footer's summary CRC: a changed chunk index made mcap's indexed reader (as
    Foxglove reads a file) fail, while every message still read front to back and --check said "ok"."""
    data = episode.path.read_bytes()
    footer = len(data) - 8 - 29  # the footer: opcode, length, summary start, summary offset start, CRC
    offsets_start = struct.unpack_from("<Q", data, footer + 17)[0]
    groups = {}  # each summary offset record: opcode, length, group opcode, group start, group length
    for at in range(offsets_start, footer, 1 + 8 + 17):
        group_opcode, group_start, _ = struct.unpack_from("<BQQ", data, at + 9)
        groups[group_opcode] = group_start
    bad = bytearray(data)
    bad[groups[Opcode.CHUNK_INDEX] + 1 + 8 + 8 + 8] ^= 1  # the first chunk index's chunk start offset
    path = tmp_path / "index.mcap"
    path.write_bytes(bytes(bad))
    with open(path, "rb") as f, pytest.raises(Exception):  # noqa: B017 (mcap raises what the bytes make)
        list(make_reader(f, validate_crcs=True).iter_messages())
    rec = read_recording(path)
    (problem,) = rec.problems
    assert problem.startswith("summary section CRC mismatch (recorded ")
    assert {t: len(m) for t, m in rec.messages.items()} == {
        t: len(m) for t, m in read_recording(episode.path).messages.items()
    }
    rc, out, _ = review(capsys, path, "--check")
    assert rc == 1
    assert f"check {path}: the file itself: 1 problem\n  summary section CRC mismatch" in out
    assert out.endswith("each valid; fails: its own problems\n")
    assert read_recording(episode.path).problems == []  # the file as written matches its CRC


def test_a_record_that_does_not_parse_loses_itself_only(episode, tmp_path, capsys):
    """A flipped byte in a metadata record's text (the bytes before the first chunk) ended the walk there:
    the review read no message of the episode, where mcap's own reader read them all."""
    data = episode.path.read_bytes()
    # the "crowdmpc" metadata record (the header's library is the first "crowdmpc"): its name, then its
    # map's byte length and its first key's length, then that key's first character
    start = data.index(b"\x08\x00\x00\x00crowdmpc", HEADER_END) - 9  # its opcode and record length
    bad = bytearray(data)
    bad[start + 9 + 4 + 8 + 4 + 4] = 0xFF  # no UTF-8
    path = tmp_path / "meta.mcap"
    path.write_bytes(bytes(bad))
    with open(path, "rb") as f:
        assert sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages()) > 0
    rec, whole = read_recording(path), read_recording(episode.path)
    (problem,) = rec.problems
    assert problem.startswith(f"corrupt record at byte {start} (UnicodeDecodeError") and "left out" in problem
    assert {t: [m.data for m in ms] for t, ms in rec.messages.items()} == {
        t: [m.data for m in ms] for t, ms in whole.messages.items()
    }
    assert "crowdmpc" not in rec.metadata and rec.episode() == whole.episode()
    rc, out, _ = review(capsys, path, "--check")
    assert rc == 1
    assert f"check {path}: the file itself: 1 problem\n  corrupt record at byte {start} " in out
    n = sum(len(m) for m in whole.messages.values())
    assert out.endswith(f"check {path}: {n} messages, each valid; fails: its own problems\n")


ROBOTS_JSON = b'{"time":0.0,"step":0,"positions":[[0,0]],"velocities":[[0,0]],"goals":[[1,1]],"actions":null,\
"commanded":null,"reached":[false]}'


def _schema(schema) -> tuple[str, str, bytes]:
    return schema.name, "jsonschema", schema.data


def _hostile_file(path: Path) -> None:
    """Everything but the framing is wrong: payloads, shapes, metadata values, a schema that is no schema."""
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start()
        writer.add_metadata("episode", {"seed": "abc", "n_robots": "two", "dt": "-1", "scenario": "circle"})
        writer.add_metadata("config", {"env": "{not json"})
        channels = {
            topic: writer.register_channel(topic, "json", writer.register_schema(*_schema(schema)))
            for topic, schema in (
                ("/robots", ROBOTS),
                ("/mpc/solver", SOLVER),
                ("/episode/metrics", EPISODE_METRICS),
            )
        }
        channels["/humans"] = writer.register_channel(
            "/humans", "json", writer.register_schema("x.Anything", "jsonschema", b'{"type": "object"}')
        )
        channels["/broken"] = writer.register_channel(
            "/broken",
            "json",
            writer.register_schema("x.Broken", "jsonschema", b'{"type": "object", "required": 5}'),
        )
        for topic, seconds, payload in (
            ("/robots", 0.0, b"\xff\xfe not json"),
            ("/robots", 0.4, b"[1, 2]"),
            ("/robots", 0.8, b'{"time": 0.8, "positions": [[0, 0]], "goals": [[1, 1]]}'),
            ("/robots", 1.2, b"[" * 100_000),
            ("/mpc/solver", 0.0, b'{"time": 0, "step": 0, "status": "ok", "solve_time_s": NaN, '
             b'"iterations": 1, "potential": null, "fallback": null}'),
            ("/episode/metrics", 1.2, b'{"metrics": {"success": true}}'),
            ("/broken", 0.0, b'{"a": 1}'),
            ("/humans", 0.0, b'{"time": 0.0}'),
        ):  # fmt: skip
            t = int(seconds * S)
            writer.add_message(channels[topic], log_time=t, data=payload, publish_time=t)
        writer.finish()


def test_payloads_shapes_and_metadata_review_expects_not_are_reported(episode, tmp_path, capsys):
    path = tmp_path / "hostile.mcap"
    _hostile_file(path)
    rec = read_recording(path)
    assert not rec.truncated and rec.data("/robots") == [] and rec.data("/mpc/solver") == []
    assert rec.episode() == {"scenario": "circle"}  # the values that do not parse are left out, and reported
    assert rec.problems == [
        "metadata 'episode': seed = 'abc' is not an integer; the review ignores seed",
        "metadata 'episode': n_robots = 'two' is not an integer; the review ignores n_robots",
        "metadata 'episode': dt = '-1' is not a positive number; the review ignores dt",
    ]
    assert rec.config() == {"env": "{not json"}
    problems = rec.message_problems()
    assert [p.split(":")[0] for p in problems] == [
        "/robots @ 0.000 s",
        "/robots @ 0.400 s",
        "/robots @ 0.800 s",
        "/robots @ 1.200 s",
        "/mpc/solver @ 0.000 s",
        "/humans @ 0.000 s",
    ]
    assert "not JSON (UnicodeDecodeError" in problems[0] and "a JSON list, expected an object" in problems[1]
    assert "lacks 'step'" in problems[2] and "not JSON (RecursionError" in problems[3]
    assert "'solve_time_s' is nan, expected a finite number" in problems[4]

    rc, out, err = review(capsys, path)
    assert rc == 0 and "problems" in out
    (line,) = err.splitlines()
    assert (
        line == f"crowdmpc review: warning: {path}: {rec.problems[0]} (1 of 9 problems; --check lists them)"
    )

    rc, out, err = review(capsys, path, "--check", "--json", tmp_path / "r.json")
    assert rc == 1 and err == ""
    assert f"check {path}: " in out
    errors = "\n".join(json.loads((tmp_path / "r.json").read_text())["check"][str(path)]["errors"])
    for expected in (
        "/robots @ 0.000 s: not JSON",
        "/robots @ 0.400 s (crowdmpc.Robots): $: expected object, got",
        "/robots @ 0.800 s (crowdmpc.Robots): $: missing required property 'step'",
        "/robots @ 1.200 s: not JSON (RecursionError",
        "/mpc/solver @ 0.000 s (crowdmpc.Solver): $.solve_time_s: expected number, got float nan",
        "/humans @ 0.000 s: lacks 'step'",  # its (permissive) schema lets it pass; the review cannot use it
        "/episode/metrics @ 1.200 s (crowdmpc.EpisodeRecord): $: missing required property",
        "/broken: schema 'x.Broken' is malformed (TypeError(",
    ):
        assert expected in errors, expected

    rc, _, err = review(capsys, path, "--plot", tmp_path / "p.png")
    assert (
        rc == 2
        and err.splitlines()[-1]
        == f"crowdmpc review: error: {path} holds no complete state (/robots and /humans) to draw"
    )

    shutil.copy(episode.path, tmp_path / "good.mcap")
    rc, out, err = review(capsys, tmp_path)
    assert rc == 0
    assert "good.mcap" in out and "hostile.mcap" in out
    assert "2 runs, 1 with metrics of another format (left out of the rates)" in out
    assert "success " in out  # the rates of the good run
    assert len(lines_naming(err, path)) == 1


def test_states_of_changing_sizes_cannot_be_drawn(tmp_path, capsys):
    path = tmp_path / "sizes.mcap"
    human = {
        "time": 0.0,
        "step": 0,
        "positions": [[3.0, 0.0]],
        "velocities": [[0.0, 0.0]],
        "goals": [[0.0, 0.0]],
    }
    with McapRecorder(path) as rec:
        for k, n in enumerate((1, 2)):
            rec.write("/robots", robot(k, n), k * S, schema=ROBOTS)
            rec.write("/humans", {**human, "step": k, "time": 0.4 * k}, k * S, schema=HUMANS)
    rc, _, err = review(capsys, path, "--animate", tmp_path / "a.gif")
    assert rc == 2 and "do not make one episode" in err and str(path) in err


def test_check_names_a_bare_nan_where_the_schema_leaves_the_value_open(tmp_path, capsys):
    """Python's json reads bare NaN, so `review --check` passed `"extra": {"r": [1, NaN]}` (Solver.extra is
    open): no JSON reader takes it, and Foxglove drops the message. The review still reads it."""
    errors = {}
    for name, value in (("nan", b"NaN"), ("big", b"1e999"), ("finite", b"0.5")):
        path = tmp_path / f"{name}.mcap"
        with McapRecorder(path) as rec:
            rec.write("/robots", robot(0, 1), 0, schema=ROBOTS)
            solver = b'{"time": 0.0, "step": 0, "status": "ok", "solve_time_s": 0.001, "iterations": 1, '
            solver += b'"potential": null, "fallback": null, "extra": {"r": [1, ' + value + b"]}}"
            rec.write_json("/mpc/solver", solver, 0, schema=SOLVER)
        review(capsys, path, "--check", "--json", tmp_path / f"{name}.json")
        report = json.loads((tmp_path / f"{name}.json").read_text())
        errors[name] = [e for e in report["check"][str(path)]["errors"] if "/mpc/solver" in e]
        assert len(read_recording(path).data("/mpc/solver")) == 1
    assert errors == {
        "nan": ["/mpc/solver @ 0.000 s: $.extra.r[1] is nan, which JSON cannot hold"],
        "big": ["/mpc/solver @ 0.000 s: $.extra.r[1] is inf, which JSON cannot hold"],
        "finite": [],
    }


@pytest.mark.parametrize(
    ("dt", "duration_ms", "pace"),
    [
        ("700", 655_350, "plays 1.07x faster than asked: a frame is shown at most 655.35 s"),
        ("1e300", 655_350, "plays 1.53e+297x faster than asked"),
        ("1e-300", 20, "plays 2e+298x slower than asked: a frame is shown at least 0.02 s"),
        ("0.005", 20, "plays 4x slower than asked: a frame is shown at least 0.02 s"),  # once a delay of 0
        ("0.123", 120, ""),  # centiseconds, as the GIF holds them: no note
    ],
)
def test_an_animation_of_steps_beyond_what_a_gif_holds_plays_at_its_bound(
    tmp_path, capsys, dt, duration_ms, pace
):
    """A GIF holds a frame for at most 65535 centiseconds: a 700 s step (simulate accepts it) or a hand-edited
    dt of 1e300 ended in Pillow's OverflowError traceback. Frames are held to MIN_GIF_FRAME_S .. MAX_FRAME_S,
    and the output line says how much faster or slower than asked the animation plays: a step under 10 ms was
    a delay of 0, which viewers show for 0.1 s, under a note saying 0.001 s."""
    path, gif = tmp_path / "steps.mcap", tmp_path / "a.gif"
    human = {"positions": [[3.0, 0.0]], "velocities": [[0.0, 0.0]], "goals": [[0.0, 0.0]]}
    with McapRecorder(path, metadata={"episode": {"dt": dt, "scenario": "circle"}}) as rec:
        for k in range(2):
            rec.write("/robots", robot(k), k * S, schema=ROBOTS)
            rec.write("/humans", {**human, "step": k, "time": 0.4 * k}, k * S, schema=HUMANS)
    rc, out, err = review(capsys, path, "--animate", gif)
    shown = f"animation: {gif} (2 frames; {pace}" if pace else f"animation: {gif} (2 frames)\n"
    assert rc == 0 and err == "" and shown in out
    with Image.open(gif) as animation:
        assert animation.n_frames == 2 and animation.info.get("duration", 0) == duration_ms


def test_a_radius_beyond_the_simulators_is_reported_and_ignored(tmp_path, capsys):
    """A hand-edited radius of 1e300 passed as a positive number: `review --plot` drew circles that size for
    over a minute. Past the simulator's bound (10 m) it is a metadata problem, and the plot takes the
    default radius."""
    path = tmp_path / "radius.mcap"
    human = {"positions": [[3.0, 0.0]], "velocities": [[0.0, 0.0]], "goals": [[0.0, 0.0]]}
    with McapRecorder(path, metadata={"episode": {"radius": "1e300", "scenario": "circle"}}) as rec:
        for k in range(2):
            rec.write("/robots", robot(k), k * S, schema=ROBOTS)
            rec.write("/humans", {**human, "step": k, "time": 0.4 * k}, k * S, schema=HUMANS)
    problem = "metadata 'episode': radius = '1e300' is beyond the simulator's 10 m; the review ignores radius"
    assert read_recording(path).problems == [problem]
    rc, out, err = review(capsys, path, "--plot", tmp_path / "p.png")
    assert rc == 0 and f"plot: {tmp_path / 'p.png'}" in out and err.strip().endswith(problem)


@pytest.mark.parametrize(
    ("metrics", "problem"),
    [
        ({"success": "yes"}, "'success' is 'yes', expected true or false"),
        (
            {"success": True, "travel_time": math.nan},
            "'travel_time' is nan, expected a finite number or null",
        ),
        ({"success": True, "travel_time": None}, "a success without its travel time"),
    ],
)
def test_metrics_the_review_cannot_add_up_are_left_out_and_checked(
    episode, tmp_path, capsys, metrics, problem
):
    """A hand-made "success": "yes" counted as a success (and passed --check), a NaN travel time made a
    folder's mean travel time unknown for every run: compare refused both files, review took them."""
    whole = read_recording(episode.path).data("/episode/metrics")[0]
    path = tmp_path / "edited.mcap"
    with open(path, "wb") as f:  # by hand: the recorder writes no NaN
        writer = Writer(f)
        writer.start()
        writer.add_metadata("episode", {"scenario": "circle", "n_robots": "1000000000"})
        channel = writer.register_channel(
            "/episode/metrics", "json", writer.register_schema(*_schema(EPISODE_METRICS))
        )
        data = json.dumps({**whole, "metrics": {**whole["metrics"], **metrics}}).encode()
        writer.add_message(channel, log_time=S, data=data, publish_time=S)
        writer.finish()
    read = read_recording(path)
    assert read.data("/episode/metrics") == []
    assert read.message_problems() == [f"/episode/metrics @ 1.000 s: 'metrics' {problem}; left out"]
    assert read.problems == [
        "metadata 'episode': n_robots = 1000000000 is outside the simulator's 0..12; the review ignores "
        "n_robots"
    ]
    rc, out, _ = review(capsys, path, "--check")
    assert rc == 1 and "/episode/metrics @ 1.000 s" in out  # the review's words, or the schema's for NaN


def test_a_folder_reviews_its_readable_files_and_lists_the_rest(episode, tmp_path, capsys):
    good = tmp_path / "good.mcap"
    shutil.copy(episode.path, good)
    data = episode.path.read_bytes()
    unreadable = {
        "empty.mcap": b"",
        "garbage.mcap": b"hello, not an mcap file" * 5,
        "header_cut.mcap": data[:20],
        "magic_only.mcap": data[:8],
    }
    for name, content in unreadable.items():
        (tmp_path / name).write_bytes(content)
    (tmp_path / "x.mcap").mkdir()
    (tmp_path / "killed_early.mcap.part").write_bytes(b"")
    (tmp_path / "killed_late.mcap.part").write_bytes(data[: len(data) // 2])

    rc, out, err = review(capsys, tmp_path)
    assert rc == 0
    assert "good.mcap" in out and "\n1 run\n" in out  # "1 run" (was "1 runs")
    for name in [*unreadable, "x.mcap"]:
        (line,) = lines_naming(err, tmp_path / name)
        assert line.startswith("crowdmpc review: unreadable: "), line
    assert (
        "is empty (0 bytes)" in err and "is not an MCAP file" in err and "is a folder, not a recording" in err
    )
    for name in ("killed_early.mcap.part", "killed_late.mcap.part"):
        (line,) = lines_naming(err, tmp_path / name)
        assert line.startswith(f"crowdmpc review: warning: skipping {tmp_path / name}: unfinished")
    assert len(err.splitlines()) == len(unreadable) + 1 + 2

    rc, out, _ = review(capsys, tmp_path, "--check")
    assert rc == 1 and out.count(" ok\n") == 1  # unreadable files fail the check

    rc, _, err = review(capsys, tmp_path / "killed_late.mcap.part")  # by name, a .part reads
    assert rc == 0 and "is truncated" in err

    good.unlink()
    rc, _, err = review(capsys, tmp_path)
    assert rc == 2  # nothing readable
    assert err.splitlines()[-1].startswith(f"crowdmpc review: error: no readable recording in {tmp_path}")


# ------------------------------------------------------------------------------------------------------------
# a recording killed at random moments
# ------------------------------------------------------------------------------------------------------------

CHILD = """
import sys
from pathlib import Path
from tests.pipelines.mcap_episode import record_episode

print("ready", flush=True)
for seed in range(1000):
    episode = record_episode(Path(sys.argv[1]), seed=seed, steps=12, n_humans=5)
    # One write a line: under PYTHONUNBUFFERED, print(a, b) makes a write per piece, and a kill between them
    # would leave half a line.
    sys.stdout.write(f"{seed} {len(episode.observations)}\\n")
    sys.stdout.flush()
"""


@pytest.mark.slow
def test_a_recording_killed_at_random_moments_loses_no_finished_episode(tmp_path, capsys):
    rng = random.Random(2024)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    moments = [0.0, 0.002, *(rng.uniform(0.0, 0.25) for _ in range(8))]
    for i, delay in enumerate(moments):
        folder = tmp_path / f"run{i}"
        child = subprocess.Popen(
            [sys.executable, "-c", CHILD, str(folder)], cwd=REPO, env=env, stdout=subprocess.PIPE, text=True
        )
        assert child.stdout is not None and child.stdout.readline() == "ready\n"
        time.sleep(delay)
        child.send_signal(signal.SIGKILL)
        out, _ = child.communicate()
        lines = [line for line in out.splitlines(keepends=True) if line.endswith("\n")]  # whole lines only
        finished = {int(seed): int(states) for seed, states in (line.split() for line in lines)}

        files = {p.name for p in folder.glob("*.mcap")}
        names = {seed: episode_filename("circle", seed) for seed in range(len(finished) + 1)}
        assert {names[s] for s in finished} <= files <= set(names.values())  # the next may be renamed
        parts = list(folder.glob("*.part"))
        assert len(parts) <= 1 and all(p.name == names[len(finished)] + ".part" for p in parts)
        for seed, states in finished.items():
            rec = read_recording(folder / names[seed])
            assert not rec.truncated and not rec.problems and not rec.message_problems()
            assert len(rec.data("/robots")) == states and len(rec.data("/episode/metrics")) == 1
        # read by name: truncated, no recording yet, or whole (killed between its data's sync and its rename,
        # a window of the fsync's milliseconds since outputs are replaced durably); never another exception
        for part in parts:
            try:
                rec = read_recording(part)
                assert rec.truncated or not (rec.problems or rec.message_problems())
            except PipelineError as exc:
                assert str(part) in str(exc)

        rc, out, err = review(capsys, folder)
        if files:
            # "1 run" when one finished (the review's plural): which count a kill leaves depends on the load
            assert rc == 0 and f"\n{count(len(files), 'run')}\n" in out, (delay, out, err)
        else:  # killed before the first episode ended: nothing to review, said in one line
            assert rc == 2 and err.splitlines()[-1].startswith("crowdmpc review: error: ")
        assert "truncated" not in err and "Traceback" not in err
        assert all(len(lines_naming(err, part)) == 1 for part in parts)


def test_messages_written_before_their_channel_keep_their_place(tmp_path):
    """A writer may put a message before its channel record (the summary repeats the channels): such
    messages join their topic ahead of the ones after the channel, in file order, and a message whose
    channel never comes is named, not lost silently."""
    path = tmp_path / "early.mcap"
    with path.open("wb") as f:
        writer = Writer(f, compression=CompressionType.NONE)
        writer.start(profile="", library="test")
        schema = writer.register_schema(*_schema(ROBOTS))
        # mcap's writer numbers channels from 1: the first registered below is 1
        writer.add_message(1, log_time=0, data=json.dumps(robot(0)).encode(), publish_time=0)
        for t in (S, 3 * S // 2):  # two on a channel no record describes
            writer.add_message(7, log_time=t, data=json.dumps(robot(1)).encode(), publish_time=t)
        assert writer.register_channel("/robots", "json", schema) == 1
        writer.add_message(1, log_time=2 * S, data=json.dumps(robot(2)).encode(), publish_time=2 * S)
        writer.finish()
    got = read_recording(path)
    assert [m["step"] for m in got.data("/robots")] == [0, 2]
    assert got.problems == [
        "2 message(s) on channel id 7 (times 1.000 s to 1.500 s), which no channel record describes: left out"
    ]


def test_the_check_walks_nesting_deeper_than_the_recursion_limit():
    """A recursive walk raised RecursionError at 600 levels of `extra` that json.loads reads, reported as
    the topic's schema being malformed, and the NaN in the next message went unnamed."""
    from pipelines.logs.schema_check import _non_finite

    deep: list = [float("nan")]
    for _ in range(5000):
        deep = [deep]
    found = _non_finite({"extra": deep, "ok": [1.0, float("inf")]}, "$")
    assert found[0][0] == "$.extra" + "[0]" * 5001 and found[1][0] == "$.ok[1]"
