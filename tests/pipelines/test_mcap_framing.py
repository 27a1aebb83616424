"""The records that frame a recording, damaged one byte at a time: its Data End record, its header and its
closing magic. Each is one line of the file's problems under ``review --check``, never an "ok", and never
costs the messages that still read."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import DataEnd
from mcap.stream_reader import StreamReader

from pipelines.cli import main
from pipelines.errors import PipelineError
from pipelines.logs.reader import read_recording
from pipelines.logs.recorder import McapRecorder
from tests.pipelines.mcap_episode import record_episode


@pytest.fixture(scope="module")
def episode(tmp_path_factory) -> Path:
    return record_episode(tmp_path_factory.mktemp("episode"), steps=20, n_humans=5).path


def review_check(capsys, path: Path) -> tuple[int, str]:
    rc = main(["review", str(path), "--check"])
    out, _ = capsys.readouterr()
    return rc, out


def test_a_lost_data_end_record_fails_the_check(episode, tmp_path, capsys):
    """A changed opcode byte of the Data End record made mcap's reader skip it as a record it does not know,
    and with it the data section's CRC: --check said "ok" of a file changed outside its chunks."""
    data = episode.read_bytes()
    at = _footer_summary_start(data) - (1 + 8 + 4)  # Data End (opcode, length, CRC) is right before it
    assert data[at] == Opcode.DATA_END
    bad = bytearray(data)
    bad[at] ^= 0x80
    path = tmp_path / "data_end.mcap"
    path.write_bytes(bytes(bad))
    with open(path, "rb") as f:  # mcap reads it front to back without a word
        assert not any(isinstance(r, DataEnd) for r in StreamReader(f, validate_crcs=True).records)

    rec = read_recording(path)
    (problem,) = rec.problems
    assert problem.startswith(
        "no Data End record closes the data section; "
        f"a record of unknown opcode 0x8f at byte {at} was skipped"
    )
    whole = read_recording(episode)
    assert {t: len(m) for t, m in rec.messages.items()} == {t: len(m) for t, m in whole.messages.items()}
    rc, out = review_check(capsys, path)
    assert rc == 1
    assert f"check {path}: the file itself: 1 problem\n  no Data End record closes the data section" in out
    assert read_recording(episode).problems == []  # the file as written has one


def _footer_summary_start(data: bytes) -> int:
    footer = len(data) - 8 - (1 + 8 + 8 + 8 + 4)  # before the closing magic: opcode, length, 2 offsets, CRC
    assert data[footer] == Opcode.FOOTER
    return int.from_bytes(data[footer + 9 : footer + 17], "little")


def test_a_header_that_does_not_parse_loses_itself_only(episode, tmp_path, capsys):
    """A changed byte in the header's library name ("crowdmpc", no longer UTF-8) refused the recording whole
    as one with "no complete MCAP header", where mcap's reader read every message of it."""
    data = episode.read_bytes()
    library = data.index(b"crowdmpc")  # the header's: magic, opcode, length, profile "", library's length
    assert library == 8 + 1 + 8 + 4 + 4
    bad = bytearray(data)
    bad[library + 1] = 0xFF
    path = tmp_path / "header.mcap"
    path.write_bytes(bytes(bad))
    with open(path, "rb") as f:
        assert sum(1 for _ in make_reader(f, validate_crcs=True).iter_messages()) > 0

    rec, whole = read_recording(path), read_recording(episode)
    (problem,) = rec.problems
    assert problem.startswith("corrupt header record at byte 8 (UnicodeDecodeError") and "left out" in problem
    assert {t: [m.data for m in ms] for t, ms in rec.messages.items()} == {
        t: [m.data for m in ms] for t, ms in whole.messages.items()
    }
    assert rec.metadata == whole.metadata and not rec.truncated
    rc, out = review_check(capsys, path)
    assert rc == 1
    assert f"check {path}: the file itself: 1 problem\n  corrupt header record at byte 8 " in out
    n = sum(len(m) for m in whole.messages.values())
    assert out.endswith(f"check {path}: {n} messages, each valid; fails: its own problems\n")

    # a header cut short is still no recording: its length runs past the file's end
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bytes(bad[: library + 4]))
    with pytest.raises(PipelineError, match=r"has no complete MCAP header \(29 bytes; "):
        read_recording(cut)


@pytest.mark.parametrize("opcode", [0x7F, Opcode.SCHEMA, Opcode.DATA_END])
def test_a_header_whose_opcode_changed_loses_itself_only(episode, tmp_path, capsys, opcode):
    """A changed opcode byte of the header record refused the recording whole, "does not start with an MCAP
    header record: not a recording", where mcap's reader read every message of it: the file starts with
    MCAP's magic, and its header's place is damaged as its content was in the test above. An opcode MCAP
    does not define (mcap skips the record), one whose record does not parse (a schema) and one that does
    (a Data End of CRC 0) alike."""
    data = episode.read_bytes()
    assert data[8] == Opcode.HEADER
    bad = bytearray(data)
    bad[8] = opcode
    path = tmp_path / "header_opcode.mcap"
    path.write_bytes(bytes(bad))
    with open(path, "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) > 0

    rec, whole = read_recording(path), read_recording(episode)
    problem = (
        f"the record at byte 8, where MCAP's header stands, has opcode {opcode:#04x}, not a header's 0x01: "
        "readers that check it refuse the file; left out"
    )
    assert rec.problems == [problem]
    assert {t: [m.data for m in ms] for t, ms in rec.messages.items()} == {
        t: [m.data for m in ms] for t, ms in whole.messages.items()
    }
    assert rec.metadata == whole.metadata and not rec.truncated
    rc, out = review_check(capsys, path)
    assert rc == 1 and f"check {path}: the file itself: 1 problem\n  {problem}\n" in out

    # cut inside that record, it is still no recording
    path.write_bytes(bytes(bad[:20]))
    with pytest.raises(PipelineError, match=r"has no complete MCAP header \(20 bytes; "):
        read_recording(path)


def test_a_changed_closing_magic_is_no_cut(episode, tmp_path, capsys):
    """A changed byte of the closing magic was read as a killed run's file: "truncated (the run was killed
    or is still writing) ... the rest is lost", of a file that had lost nothing."""
    bad = bytearray(episode.read_bytes())
    bad[-3] ^= 0x80
    path = tmp_path / "magic.mcap"
    path.write_bytes(bytes(bad))
    rec, whole = read_recording(path), read_recording(episode)
    assert not rec.truncated and rec.warning is None
    (problem,) = rec.problems
    assert problem.startswith("closing magic bytes changed after writing (89 4d 43 41 50 b0 0d 0a, where ")
    assert {t: len(m) for t, m in rec.messages.items()} == {t: len(m) for t, m in whole.messages.items()}
    rc, out = review_check(capsys, path)
    assert rc == 1 and re.search(r"^truncated +no$", out, re.MULTILINE) and "truncated:" not in out
    assert f"check {path}: the file itself: 1 problem\n  closing magic bytes changed after writing" in out
    n = sum(len(m) for m in whole.messages.values())
    assert out.endswith(f"check {path}: {n} messages, each valid; fails: its own problems\n")

    # the same bytes cut anywhere before them are a killed run's file, as before
    for cut in (len(bad) - 1, len(bad) - 8, len(bad) - 9):
        path.write_bytes(bytes(bad[:cut]))
        rec = read_recording(path)
        assert rec.truncated and rec.problems == [], cut


def test_a_cut_is_named_alike_wherever_it_falls(episode, tmp_path):
    """A file cut inside a record longer than the bytes it kept was said to have lost the rest to
    "RecordLengthLimitExceeded: METADATA record has length 243 that exceeds limit 50" (the limit: the file's
    size), where a cut inside a shorter record said "the file ends inside a record"."""
    data = episode.read_bytes()
    first = 8 + 9 + int.from_bytes(data[9:17], "little")  # the record after the header: the metadata
    # the one after it: a file that reads nothing past its header is nothing to review (test below)
    second = first + 9 + int.from_bytes(data[first + 1 : first + 9], "little")
    length = int.from_bytes(data[second + 1 : second + 9], "little")
    for cut in (second + 9 + 1, second + 9 + length - 1):  # its length runs past the file's end, or not
        path = tmp_path / f"cut{cut}.mcap"
        path.write_bytes(data[:cut])
        rec = read_recording(path)
        assert rec.truncated and rec.stopped_at == "the file ends inside a record", cut
        assert rec.warning is not None and rec.warning.endswith("(the file ends inside a record)")


def test_a_cut_before_the_first_chunk_names_no_time(episode, tmp_path):
    """A file cut before its first chunk ended was said to have been "read 0 messages up to t = 0.0 s, the
    last complete chunk": a time and a chunk it never held."""
    data = episode.read_bytes()
    with open(episode, "rb") as f:
        first_chunk = min(c.chunk_start_offset for c in make_reader(f).get_summary().chunk_indexes)
    path = tmp_path / "early.mcap"
    path.write_bytes(data[: first_chunk + 20])
    rec = read_recording(path)
    assert rec.warning == (
        f"{path} is truncated (the run was killed or is still writing): read no message, no chunk was "
        "complete; the rest is lost (the file ends inside a record)"
    )


def test_a_record_length_past_the_file_is_named_in_words(episode, tmp_path, capsys):
    """A complete file whose record's length field ran past its end had a corrupt record in mcap's words,
    "(RecordLengthLimitExceeded: METADATA record has length ... that exceeds limit ...)", where the length
    exceeded the file's size, and else one "at byte" the file's size, "(the file ends inside a record)": the
    place of no record, and a cut in a file that had none."""
    data = episode.read_bytes()
    first = 8 + 9 + int.from_bytes(data[9:17], "little")  # the record after the header: the metadata
    at = first + 9 + int.from_bytes(data[first + 1 : first + 9], "little")  # the next: the first one reads
    room = len(data) - 8 - at - 9  # the bytes from its content's start to the closing magic
    for length in (10**12, room + 12, room + 3):  # past the file's size, into or past the closing magic
        bad = bytearray(data)
        bad[at + 1 : at + 9] = length.to_bytes(8, "little")
        path = tmp_path / f"length{length}.mcap"
        path.write_bytes(bytes(bad))
        rec = read_recording(path)
        problem = (
            f"corrupt record at byte {at} (its length field says {length} bytes, where {room} remain "
            "before the closing magic); the rest of the file is not read"
        )
        assert rec.problems == [problem] and not rec.truncated, length
        rc, out = review_check(capsys, path)
        assert rc == 1 and f"check {path}: the file itself: 1 problem\n  {problem}\n" in out


def test_a_file_that_reads_nothing_past_its_header_is_nothing_to_review(episode, tmp_path, capsys):
    """A file cut to its header (40 bytes of a recording) was reviewed as a table of dashes with exit 0
    without --check, where review's help promises 2 when nothing could be read: a script running `crowdmpc
    review FILE` took it for a recording that had passed. So was a finished file of a header alone."""
    data = episode.read_bytes()
    header_end = 8 + 9 + int.from_bytes(data[9:17], "little")
    first_read = header_end + 9 + int.from_bytes(data[header_end + 1 : header_end + 9], "little")
    for cut in (header_end, 40, first_read - 1):
        path = tmp_path / f"cut{cut}.mcap"
        path.write_bytes(data[:cut])
        for check in ([], ["--check"]):
            assert main(["review", str(path), *check]) == 2, (cut, check)
            out, err = capsys.readouterr()
            assert out == "" and err == (
                f"crowdmpc review: error: {path} holds no metadata record and no message, nothing to review: "
                "it is cut short (the file ends inside a record; its run was killed or is still writing)\n"
            )
    header_alone = tmp_path / "header_alone.mcap"
    McapRecorder(header_alone).close()
    with pytest.raises(
        PipelineError, match=r"header_alone.mcap holds no metadata record and no message, nothing"
    ):
        read_recording(header_alone)

    # a cut that keeps its first metadata record reads it: a killed run's file, reviewed as before
    path = tmp_path / "first.mcap"
    path.write_bytes(data[:first_read])
    assert read_recording(path).truncated
    assert main(["review", str(path)]) == 0
    assert main(["review", str(path), "--check"]) == 1
