"""An MCAP file's records front to back, its damage noted: how ``pipelines.logs.reader`` walks a recording.

The file is read whole and parsed by mcap's ``StreamReader`` (``emit_chunks``: each chunk is handed on whole,
its CRC checked by the reader, one chunk at a time). The data section's CRC is checked as the walk meets it
(``validate_crcs``; 0, i.e. absent, in recordings made before crowdmpc wrote it), and the summary section's
(the footer's ``summary_crc``), which no mcap reader verifies, at the footer: a changed byte among the chunk
indexes made mcap's indexed reader, as Foxglove reads a file, fail on a file whose messages all read here.
A record that does not parse is stepped over by its length where that lies within the file, and so is the
first record where it is not a header (its opcode byte changed). The messages read are counted against the
summary's Statistics record (``statistics_problem``): where a file has no data section CRC, a chunk whose
opcode byte changed is skipped by mcap's reader as a record it does not know. A footer reached without a
DataEnd record before it is a problem too: that record holds the data section's CRC.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Final

from mcap.exceptions import EndOfFile, RecordLengthLimitExceeded
from mcap.opcode import Opcode
from mcap.records import DataEnd, Footer, Header, McapRecord, Statistics
from mcap.stream_reader import CRCValidationError, StreamReader

from pipelines.errors import PipelineError

MAGIC: Final[bytes] = b"\x89MCAP0\r\n"
# the footer's bytes that its summary CRC covers: opcode, record length, summary start, summary offset start
_FOOTER_CRC_SPAN: Final[int] = 1 + 8 + 8 + 8
_OPCODES: Final[frozenset[int]] = frozenset(Opcode)


CUT: Final[str] = "the file ends inside a record"


def reason(exc: BaseException) -> str:
    if isinstance(exc, EndOfFile | struct.error):
        return CUT
    return f"{type(exc).__name__}: {exc}".rstrip(": ")


def _records(buffer: io.BytesIO, size: int, *, first: bool) -> Iterator[McapRecord]:
    # record_size_limit: no record is longer than the file, whatever a corrupt length field says
    reader = StreamReader(
        buffer, skip_magic=not first, emit_chunks=True, validate_crcs=True, record_size_limit=size
    )
    return iter(reader.records)


def _record_end(data: bytes, offset: int, limit: int) -> int | None:
    """Where the record at ``offset`` ends by its length field, when that lies within ``data[:limit]``: a
    record whose content does not parse (a flipped byte in a metadata string) is stepped over there, where
    it lost every message after it, though its neighbours' bytes are intact."""
    if offset + 9 > limit:
        return None
    end = offset + 9 + struct.unpack_from("<Q", data, offset + 1)[0]
    return end if end <= limit else None


def _overrun(data: bytes, offset: int, limit: int) -> str | None:
    """How the record at ``offset`` of a complete file runs past ``limit``, its last record's end, by its
    length field, in words; None where it does not (its content is what is bad) or the field is cut."""
    if offset + 9 > limit:
        return None
    length, room = struct.unpack_from("<Q", data, offset + 1)[0], limit - offset - 9
    if length <= room:
        return None
    return f"its length field says {length} bytes, where {room} remain before the closing magic"


def summary_crc_problem(data: bytes, footer_offset: int, footer: Footer) -> str | None:
    """Why the summary section of ``data`` does not match its footer's CRC (MCAP: the CRC-32 of every byte
    from the summary's start through the footer's summary offset start; 0: none recorded), or None."""
    if footer.summary_crc == 0:
        return None
    start = footer.summary_start or footer_offset  # no summary: the CRC covers the footer's fields alone
    crc = zlib.crc32(data[start : footer_offset + _FOOTER_CRC_SPAN])
    if crc == footer.summary_crc:
        return None
    return (
        f"summary section CRC mismatch (recorded {footer.summary_crc:#010x}, computed {crc:#010x}): its "
        "index records changed after writing, which readers that seek by them (Foxglove, mcap's) may fail on"
    )


def statistics_problem(
    statistics: Statistics, read: Mapping[int, int], topics: Mapping[int, str]
) -> str | None:
    """Why the messages read (channel id -> how many) do not match what ``statistics`` counts: per channel
    where it has counts per channel, and in all; None when they match. ``topics``: channel id -> topic."""
    counted = statistics.channel_message_counts  # {} where its writer left them out: the total alone
    n, m = sum(read.values()), statistics.message_count
    channels = sorted(counted.keys() | read.keys()) if counted else []
    differ = [c for c in channels if read.get(c, 0) != counted.get(c, 0)]
    if n == m and not differ:
        return None
    each = ", ".join(
        f"{topics.get(c, f'channel id {c}')} {read.get(c, 0)} of {counted.get(c, 0)}" for c in differ
    )
    return (
        f"{n} messages read, the statistics record counts {m}{f' ({each})' if each else ''}: a record "
        "mcap's reader does not know was skipped (a chunk whose opcode byte changed), or the counts changed "
        "after writing"
    )


def _data_end_problem(unknown: list[tuple[int, int]]) -> str:
    """Why a file whose footer was read but no DataEnd record before it is damaged; ``unknown``: the records
    of an opcode MCAP does not define, (offset, opcode), which mcap's reader skipped."""
    instead = "".join(
        f"; a record of unknown opcode {opcode:#04x} at byte {at} was skipped" for at, opcode in unknown
    )
    return (
        f"no Data End record closes the data section{instead}: its CRC went unchecked, so bytes outside the "
        "chunks may have changed unseen"
    )


def _file_bytes(path: Path) -> bytes:
    """The bytes of ``path``, an MCAP file by its opening magic; PipelineError for anything else."""
    if path.is_dir():
        raise PipelineError(f"{path} is a folder, not a recording")
    if not path.is_file():  # /dev/zero or a pipe exists: "no such recording" sent the user looking for it
        why = "is not a regular file (a device or a pipe)" if path.exists() else "no such recording"
        raise PipelineError(f"{path}: {why}")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise PipelineError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    if not data:
        raise PipelineError(f"{path} is empty (0 bytes): its run was killed before writing anything")
    if not data.startswith(MAGIC):
        raise PipelineError(f"{path} is not an MCAP file (it does not start with MCAP's magic bytes)")
    return data


def _after_header(
    path: Path, data: bytes, buffer: io.BytesIO, limit: int, problems: list[str]
) -> tuple[Header | None, Iterator[McapRecord]]:
    """The header of ``data`` (None where it did not read) and the records after it (read through
    ``buffer``), the last ending by ``limit``. A
    header record whose content does not parse, or whose opcode byte changed, but whose length lies within
    the file is stepped over, a problem: one changed byte of it lost the file whole, where mcap's reader
    read every message. PipelineError where no record after the magic ends within the file."""
    records = _records(buffer, len(data), first=True)
    start = len(MAGIC)
    opcode = data[start] if len(data) > start else None
    try:
        header = next(records)
    except Exception as exc:  # noqa: BLE001 (whatever the bytes after the magic are)
        why = reason(exc)
    else:
        # an opcode MCAP does not define is skipped by mcap's reader: what it returned is the next record
        if opcode == Opcode.HEADER and isinstance(header, Header):
            return header, records
        why = ""
    end = _record_end(data, start, limit)
    if end is None:
        why = why or "its first record runs past the file's end"
        raise PipelineError(f"{path} has no complete MCAP header ({len(data)} bytes; {why}): not a recording")
    if opcode == Opcode.HEADER:
        problems.append(f"corrupt header record at byte {start} ({why}); left out")
    else:  # MCAP: "the first record after the leading magic bytes is the Header record"
        problems.append(
            f"the record at byte {start}, where MCAP's header stands, has opcode {opcode:#04x}, not a "
            f"header's {Opcode.HEADER:#04x}: readers that check it refuse the file; left out"
        )
    buffer.seek(end)
    return None, _records(buffer, len(data), first=False)


def walk_file(
    path: Path, take: Callable[[McapRecord, int], None], problems: list[str]
) -> tuple[bool, str | None]:
    """Hand every record of ``path`` to ``take`` (with its offset), its header first where it reads, and the
    damage found to ``problems``; whether the file is complete (it ends with the closing magic, or with its
    footer and 8 bytes a change kept from being it: a problem) and what stopped reading early, if anything
    did. PipelineError when ``path`` is no recording at all."""
    data = _file_bytes(path)
    complete = len(data) >= 2 * len(MAGIC) and data.endswith(MAGIC)
    limit = len(data) - len(MAGIC) if complete else len(data)  # where the last record must end
    buffer = io.BytesIO(data)
    header, records = _after_header(path, data, buffer, limit, problems)
    if header is not None:
        take(header, len(MAGIC))

    stopped_at = None
    # every MCAP file ends its data section with a DataEnd record; a changed opcode byte made mcap's reader
    # skip it as a record it does not know, and with it the data section's CRC
    data_ended, unknown = False, []
    while True:
        offset = buffer.tell()
        if offset < len(data) and data[offset] not in _OPCODES:
            unknown.append((offset, data[offset]))
        try:
            record = next(records)
        except StopIteration:
            break
        except Exception as exc:  # noqa: BLE001 (any parse error: a cut, or corrupt bytes)
            if isinstance(exc, CRCValidationError) and isinstance(exc.record, DataEnd):
                data_ended = True
                if not problems:  # else a bad chunk or record found before it is what changed: no 2nd line
                    problems.append(
                        f"data section CRC mismatch ({exc}): bytes outside the chunks changed after writing"
                    )
                records = _records(buffer, len(data), first=False)  # the summary section still reads
                continue
            end = _record_end(data, offset, limit)
            if end is not None:  # its content is bad, not its length: the records after it still read
                problems.append(f"corrupt record at byte {offset} ({reason(exc)}); left out")
                buffer.seek(end)
                records = _records(buffer, len(data), first=False)
                continue
            if complete:
                why = _overrun(data, offset, limit) or reason(exc)  # not mcap's RecordLengthLimitExceeded
                problems.append(f"corrupt record at byte {offset} ({why}); the rest of the file is not read")
            else:  # a record longer than the whole file, in a file cut short: the cut, as any other
                stopped_at = CUT if isinstance(exc, RecordLengthLimitExceeded) else reason(exc)
            break
        if complete and buffer.tell() > limit:
            # mcap read the bytes its length field claims past the record's content as padding, the closing
            # magic among them: the next read failed at the file's end, named as the corrupt record's place
            problems.append(
                f"corrupt record at byte {offset} ({_overrun(data, offset, limit)}); the rest of the file is "
                "not read"
            )
            take(record, offset)
            break
        data_ended = data_ended or isinstance(record, DataEnd)
        if isinstance(record, Footer):
            if problem := summary_crc_problem(data, offset, record):
                problems.append(problem)
            if not data_ended:
                problems.append(_data_end_problem(unknown))
        take(record, offset)
        if isinstance(record, Footer) and not complete and len(data) - buffer.tell() == len(MAGIC):
            # the file ends where its footer does, but for the magic: a byte changed, nothing was cut off
            problems.append(
                f"closing magic bytes changed after writing ({data[-len(MAGIC) :].hex(' ')}, where MCAP's "
                f"are {MAGIC.hex(' ')}): readers that check them refuse the file"
            )
            complete = True
            break
    return complete, stopped_at
