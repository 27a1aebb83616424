"""Reading episode recordings back: every message and metadata record (the episode as arrays: view.py).

A file is read whole into memory and walked front to back, record by record (mcap's ``StreamReader`` with
``emit_chunks``), so that a truncated file (its writer was killed) yields everything up to its last complete
chunk; a file is truncated when it stops short of MCAP's closing magic. CRCs are verified where the file
carries them: each chunk's (``breakup_chunk(validate_crc=True)``, one chunk at a time, so that a bad chunk
loses only its own messages), the data section's and the summary section's (``pipelines.logs.mcap_file``,
the walk); the messages read are counted against the file's Statistics record, where it has one.

Log times are wall clock since the Unix epoch: the episode's start (metadata "episode" ``start_time_ns``) +
its simulation time (``pipelines.logs.recording``); files recorded before that, without ``start_time_ns``,
count log time from 0. Either way ``Recording.sim_seconds`` gives the simulation time of a log time, and
every place (warnings, problems) names a message by it.

Nothing in a file raises past ``read_recording`` except a file that is not a recording at all (missing, a
folder, empty, not MCAP, no complete header, another program's MCAP file (``pipelines.logs.foreign``), no
metadata record and no message read): a bad chunk, a message that is not JSON or lacks what the review reads
(``pipelines.logs.shapes``), a bad metadata value or a corrupt record becomes a line of ``Recording.problems``
or of ``LoggedMessage.problem``, and the messages it held are left out.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from mcap.records import Channel as McapChannel
from mcap.records import Chunk, Header, McapRecord, Message, Metadata, Schema, Statistics
from mcap.stream_reader import breakup_chunk

from pipelines.errors import PipelineError
from pipelines.logs.foreign import not_a_recording
from pipelines.logs.mcap_file import reason, statistics_problem, walk_file
from pipelines.logs.recorder import UNFINISHED_SUFFIX
from pipelines.logs.schemas import EPISODE_FORMAT
from pipelines.logs.shapes import episode_metadata_problems, message_problem
from predictors.errors import short_repr

START_TIME_KEY: Final[str] = "start_time_ns"  # in the "episode" metadata record (pipelines.logs.recording)


@dataclass(frozen=True)
class Channel:
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes


@dataclass(frozen=True)
class LoggedMessage:
    log_time_ns: int
    data: Any  # the decoded JSON (None when it did not decode)
    problem: str | None = None  # why the review leaves it out: not JSON, or lacks what the review reads

    def where(self, topic: str, start_time_ns: int = 0) -> str:
        """``topic @ T s``, T the simulation time (``start_time_ns``: the log time of the episode's start)."""
        return f"{topic} @ {_seconds(self.log_time_ns - start_time_ns)}"


@dataclass(frozen=True)
class Recording:
    """Everything read from one file."""

    path: Path
    metadata: dict[str, dict[str, str]]  # name -> record (the last one when a name repeats)
    channels: dict[str, Channel]  # topic -> channel
    messages: dict[str, list[LoggedMessage]]  # topic -> messages in file order
    truncated: bool  # the file stops short of MCAP's closing magic (a changed one is a problem)
    stopped_at: str | None = None  # what ended reading early (truncated files)
    problems: list[str] = field(default_factory=list)  # bad chunks, bad metadata, corruption (not messages)

    def __repr__(self) -> str:
        # Not the dataclass's: it printed every message, hundreds of kB for one episode, where a notebook
        # shows the value of a cell's last line.
        messages = sum(len(m) for m in self.messages.values())
        problems = len(self.problems) + len(self.message_problems())
        state = "truncated" if self.truncated else "complete"
        topics = len(self.messages)
        return (
            f"Recording({str(self.path)!r}, {self.label!r}, {messages} messages on {topics} topics, {state}, "
            f"{problems} problems)"
        )

    @property
    def warning(self) -> str | None:
        if not self.truncated:
            return None
        n = sum(len(v) for v in self.messages.values())
        ends = [m[-1].log_time_ns for m in self.messages.values() if m]
        # no message read has no time to name: "up to t = 0.0 s, the last complete chunk" told of a chunk
        read = (
            f"read {n} messages up to t = {self.sim_seconds(max(ends)):.1f} s, the last complete chunk"
            if ends
            else "read no message, no chunk was complete"
        )
        return (
            f"{self.path} is truncated (the run was killed or is still writing): {read}; the rest is lost "
            f"({self.stopped_at or 'no footer'})"
        )

    @property
    def start_time_ns(self) -> int:
        """The log time of the episode's start: its wall-clock start in ns since the Unix epoch, or 0 for a
        file recorded before log times were wall clock (or whose value is bad: a ``problems`` line)."""
        return start_time_ns(self.metadata)

    def sim_seconds(self, log_time_ns: int) -> float:
        """The simulation time (s) of a log time of this file."""
        return (log_time_ns - self.start_time_ns) / 1e9

    def message_problems(self) -> list[str]:
        """A line per message the review leaves out (``LoggedMessage.problem``), naming topic and time."""
        return [
            f"{m.where(topic, self.start_time_ns)}: {m.problem}; left out"
            for topic, messages in self.messages.items()
            for m in messages
            if m.problem
        ]

    @property
    def problems_warning(self) -> str | None:
        """One line naming the file, its first problem and how many there are (file's, then messages')."""
        problems = self.problems + self.message_problems()
        if not problems:
            return None
        n = len(problems)
        return f"{self.path}: {problems[0]}" + (f" (1 of {n} problems; --check lists them)" if n > 1 else "")

    def episode(self) -> dict[str, str]:
        """The "episode" metadata record without the values that do not parse (they are in ``problems``)."""
        record = self.metadata.get("episode", {})
        bad = episode_metadata_problems(record)
        return {k: v for k, v in record.items() if k not in bad}

    def config(self) -> dict[str, Any]:
        return decode_metadata(self.metadata.get("config", {}))

    def run_meta(self) -> dict[str, Any]:
        return decode_metadata(self.metadata.get("run", {}))

    def data(self, topic: str) -> list[Any]:
        """The messages of ``topic`` that the review can use (see ``LoggedMessage.problem``)."""
        return [m.data for m in self.messages.get(topic, ()) if m.problem is None]

    @property
    def label(self) -> str:
        ep = self.episode()
        env = self.config().get("env")
        crowd = env.get("crowd") if isinstance(env, dict) else None
        # a replayed crowd's people are not the scenario's: the figures of an eth_test run read as ORCA's
        replayed = f"crowd {crowd}" if isinstance(crowd, str) and crowd != "orca" else None
        parts = [ep.get("controller"), ep.get("predictor"), ep.get("scenario"), replayed]
        return " / ".join(p for p in [*parts, f"seed {ep.get('seed', '?')}"] if p)


def _start_time_problem(metadata: dict[str, dict[str, str]]) -> str | None:
    text = metadata.get("episode", {}).get(START_TIME_KEY)
    if text is None:
        return None
    try:
        value = int(text)
    except ValueError:
        value = -1
    if 0 <= value < 1 << 64:  # an MCAP log time is a uint64
        return None
    return f"{START_TIME_KEY} = {text!r} is not a log time (an integer of ns in 0 .. 2^64 - 1)"


def start_time_ns(metadata: dict[str, dict[str, str]]) -> int:
    """The log time of the episode's start from the metadata records; 0 when absent (older files) or bad."""
    if _start_time_problem(metadata) is not None:
        return 0
    return int(metadata.get("episode", {}).get(START_TIME_KEY, "0"))


def decode_metadata(record: Mapping[str, str]) -> dict[str, Any]:
    """Metadata values are JSON text (pipelines.logs.recording); a value that is not stays a string."""
    out: dict[str, Any] = {}
    for key, text in record.items():
        try:
            out[key] = json.loads(text)
        except (ValueError, RecursionError):
            out[key] = text
    return out


# ------------------------------------------------------------------------------------------------------------
# reading
# ------------------------------------------------------------------------------------------------------------


def _seconds(ns: int) -> str:
    return f"{ns / 1e9:.3f} s"


class _Walk:
    """The records of one file in order, into channels, messages, metadata and problems; ``metadata_only``:
    into its metadata alone, its chunks left compressed; ``topics``: only these topics' messages decoded."""

    def __init__(self, path: Path, *, metadata_only: bool = False, topics: frozenset[str] | None = None):
        self.path = path
        self.metadata_only = metadata_only
        self.topics = topics
        self.metadata: dict[str, dict[str, str]] = {}
        self.channels: dict[str, Channel] = {}
        self.messages: dict[str, list[LoggedMessage]] = {}
        self.problems: list[str] = []
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, McapChannel] = {}
        self._orphans: dict[int, list[Message]] = {}  # channel id -> messages read before its channel
        self._read: Counter[int] = Counter()  # channel id -> messages read, whatever their topic
        self._statistics: Statistics | None = None
        self._library: str | None = None  # the header's; None where it did not read

    def take(self, record: McapRecord, offset: int) -> None:
        if self.metadata_only and not isinstance(record, Metadata):
            return
        if isinstance(record, Chunk):
            try:
                inner = breakup_chunk(record, validate_crc=True)
            except Exception as exc:  # noqa: BLE001 (CRC, codec or parse error: the chunk's bytes are bad)
                start = start_time_ns(self.metadata)  # metadata precede the chunks
                self.problems.append(
                    f"bad chunk at byte {offset} (times {_seconds(record.message_start_time - start)} to "
                    f"{_seconds(record.message_end_time - start)}): {reason(exc)}; its messages are left out"
                )
                return
            for r in inner:
                self.take(r, offset)
        elif isinstance(record, Schema):
            self._schemas.setdefault(record.id, record)
        elif isinstance(record, McapChannel):
            self._channels.setdefault(record.id, record)
        elif isinstance(record, Message):
            self._read[record.channel_id] += 1
            channel = self._channels.get(record.channel_id)
            if channel is None:
                self._orphans.setdefault(record.channel_id, []).append(record)
            elif self.topics is None or channel.topic in self.topics:
                self._messages_of(channel).append(self._decoded(channel.topic, record))
        elif isinstance(record, Metadata):
            self.metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Statistics) and self._statistics is None:
            self._statistics = record
        elif isinstance(record, Header):
            self._library = record.library

    @property
    def messages_read(self) -> int:
        """The messages read, whatever their topic (``topics`` leaves some undecoded) or channel."""
        return sum(self._read.values())

    def foreign(self) -> str | None:
        """Why the file is another program's MCAP file (``pipelines.logs.foreign``); None for a recording."""
        schemas = {
            self._schemas[c.schema_id].name for c in self._channels.values() if c.schema_id in self._schemas
        }
        topics = {channel.topic for channel in self._channels.values()}
        return not_a_recording(self._library, schemas, topics, self.metadata.keys())

    def finish(self) -> None:
        """The messages read against the Statistics record's counts; messages whose channel came later (the
        summary repeats the channels) join their topic first."""
        if self._statistics is not None and not self.problems:  # else a bad chunk or record lost them: 1 line
            topics = {i: c.topic for i, c in self._channels.items()}
            if problem := statistics_problem(self._statistics, self._read, topics):
                self.problems.append(problem)
        start = start_time_ns(self.metadata)
        for channel_id, orphans in self._orphans.items():
            channel = self._channels.get(channel_id)
            if channel is None:
                self.problems.append(
                    f"{len(orphans)} message(s) on channel id {channel_id} (times "
                    f"{_seconds(orphans[0].log_time - start)} to {_seconds(orphans[-1].log_time - start)}), "
                    "which no channel record describes: left out"
                )
                continue
            if self.topics is not None and channel.topic not in self.topics:
                continue
            topic_messages = self._messages_of(channel)
            topic_messages[:0] = [self._decoded(channel.topic, m) for m in orphans]
        for key, problem in episode_metadata_problems(self.metadata.get("episode", {})).items():
            self.problems.append(f"metadata 'episode': {problem}; the review ignores {key}")
        recorded = self.metadata.get("crowdmpc", {}).get("format")
        if recorded is not None and recorded != EPISODE_FORMAT:  # absent: not a crowdmpc recorder's file
            self.problems.append(
                f"recorded in format {recorded!r}; this crowdmpc reads {EPISODE_FORMAT!r}: its channels may "
                "mean other things, review it with the crowdmpc version that recorded it"
            )
        bad_start = _start_time_problem(self.metadata)
        if bad_start is not None:
            self.problems.append(f"metadata 'episode': {bad_start}; times are log times from 0")

    def _messages_of(self, channel: McapChannel) -> list[LoggedMessage]:
        topic = channel.topic
        if topic not in self.channels:
            schema = self._schemas.get(channel.schema_id)
            self.channels[topic] = Channel(
                topic,
                channel.message_encoding,
                schema.name if schema else "",
                schema.encoding if schema else "",
                schema.data if schema else b"",
            )
            self.messages[topic] = []
        return self.messages[topic]

    @staticmethod
    def _decoded(topic: str, message: Message) -> LoggedMessage:
        try:
            data = json.loads(message.data)
        except (ValueError, RecursionError) as exc:  # UnicodeDecodeError is a ValueError
            return LoggedMessage(message.log_time, None, f"not JSON ({type(exc).__name__}: {exc})")
        return LoggedMessage(message.log_time, data, message_problem(topic, data))


def _why_none(walk: _Walk, complete: bool, stopped_at: str | None) -> str:
    """Why a file read nothing past its header, said after "holds no metadata record and no message"."""
    if not complete:
        cut = stopped_at or "no footer"
        return f", nothing to review: it is cut short ({cut}; its run was killed or is still writing)"
    if walk.problems:
        return f" that reads, nothing to review: {walk.problems[0]}"
    return ", nothing to review"


def read_recording(path: str | Path, topics: Iterable[str] | None = None) -> Recording:
    """Read every message and metadata record of ``path``; a truncated file reads up to its last chunk.
    ``topics``: only the messages of these (``crowdmpc compare`` reads "/episode/metrics" alone), the other
    topics absent from ``messages`` and ``channels``: every chunk is still decompressed and checked, but
    the hundreds of state messages are not parsed.

    Raises PipelineError only when ``path`` is no recording at all: missing, a folder, empty, not MCAP, cut
    inside its header, another program's MCAP file, or one with no metadata record and no message.
    """
    if not isinstance(path, str | os.PathLike):
        raise PipelineError(f"read_recording takes a path to an MCAP file, got {short_repr(path)}")
    if isinstance(topics, str | bytes):  # iterated, "/episode/metrics" was its characters: nothing read
        raise PipelineError(f"topics must be a list of topics, e.g. [{topics!r:.60}], got the string itself")
    path = Path(path)
    walk = _Walk(path, topics=None if topics is None else frozenset(topics))
    complete, stopped_at = walk_file(path, walk.take, walk.problems)
    if (foreign := walk.foreign()) is not None:  # a table of dashes, and "ok" under --check, said nothing
        raise PipelineError(f"{path} {foreign}")
    walk.finish()
    if not walk.metadata and not walk.messages_read:
        # it was a table of dashes, exit 0 without --check, where review's help promises 2 when nothing reads
        raise PipelineError(
            f"{path} holds no metadata record and no message{_why_none(walk, complete, stopped_at)}"
        )
    return Recording(
        path, walk.metadata, walk.channels, walk.messages, not complete, stopped_at, walk.problems
    )


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The metadata records of ``path`` as ``read_recording`` reads them (a truncated file's too), without
    decompressing its chunks; the same PipelineError for a file that is no recording at all."""
    walk = _Walk(Path(path), metadata_only=True)
    walk_file(walk.path, walk.take, walk.problems)
    return walk.metadata


# Where a folder's recordings are looked for: in it, else one and two levels below it (find_recordings).
FOLDER_LEVELS: Final[tuple[tuple[str, ...], ...]] = (("*.mcap",), ("*/*.mcap", "*/*/*.mcap"))


def find_recordings(directory: str | Path) -> tuple[list[Path], list[Path]]:
    """The ``*.mcap`` entries of ``directory`` (whatever they are) and its unfinished ``*.mcap.part``; when it
    holds neither, those one and two levels below it (runs/ over runs/cmpc/ and runs/dmpc/, a sweep's DIR
    over DIR/mcap/CELL/), not the whole tree: a folder of recordings is reviewed as it is, never mixed with
    its subfolders'."""
    directory = Path(directory)
    for patterns in FOLDER_LEVELS:
        paths = sorted(p for pattern in patterns for p in directory.glob(pattern))
        unfinished = sorted(p for pattern in patterns for p in directory.glob(pattern + UNFINISHED_SUFFIX))
        if paths or unfinished:
            return paths, unfinished
    raise PipelineError(f"no .mcap files in {directory}, nor in the two levels of folders below it")
