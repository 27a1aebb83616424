"""A thin, typed MCAP writer for JSON messages.

``write(topic, message, log_time_ns, schema=...)`` registers the schema and the channel the first time a topic
is seen and refuses a different schema on a topic already written. The recorder is a context manager that
always finishes the file (chunk flushed, summary and footer written), also when the block raises.

Chunks default to 64 KiB (DESIGN.md): a run killed mid-way loses at most the open chunk, ~30 small messages,
where mcap's 1 MiB default would lose ~1000.

The file is written as ``<name>.part`` and renamed to ``<name>`` when it is finished; see ``McapRecorder``.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import weakref
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Final

from mcap.writer import CompressionType, Writer

from pipelines.errors import PipelineError, RecordingRefused
from pipelines.logs.schemas import LIBRARY, MESSAGE_ENCODING, SCHEMA_ENCODING, MessageSchema

DEFAULT_CHUNK_SIZE: Final[int] = 64 * 1024  # bytes, uncompressed
UNFINISHED_SUFFIX: Final[str] = ".part"  # the file's name until it is finished


def _default_compression() -> CompressionType:
    """zstd when ``zstandard`` imports, else lz4, else none: mcap's writer refuses a codec it cannot load."""
    try:
        import zstandard  # noqa: F401

        return CompressionType.ZSTD
    except ImportError:
        pass
    try:
        import lz4.frame  # noqa: F401

        return CompressionType.LZ4
    except ImportError:
        return CompressionType.NONE


DEFAULT_COMPRESSION: Final[CompressionType] = _default_compression()

# Compact, and strict: NaN/Infinity are not JSON and Foxglove's parser rejects them.
_ENCODER: Final = json.JSONEncoder(separators=(",", ":"), allow_nan=False)


# This process's recorders, so that a refusal can name the case a notebook meets, a recorder left open by a
# cell that raised (its traceback keeps it alive), apart from another program's run. Weak: one collected
# without close() has closed its file, and with it its lock.
_OPEN: weakref.WeakSet[McapRecorder] = weakref.WeakSet()


def _create(path: Path, *, new: bool = False, may_replace: Callable[[Path], None] | None = None) -> IO[bytes]:
    """``path`` opened for writing, never through a symbolic link: one planted at ``<name>.part`` in the
    folder the user named would make the recording land wherever it points. ``new``: only if nothing has
    that name (FileExistsError otherwise), atomically, so two processes never both get it. Otherwise the
    file is locked (``flock``, released when the file is closed or its process dies) before it is emptied:
    two runs recording the same episode into one folder at once wrote one file, and a killed run's ``.part``
    is still taken over, once ``may_replace`` (if given) has let it: what it raises goes up, the file kept."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | (os.O_EXCL if new else 0)
    try:
        fd = os.open(path, flags, 0o666)  # the umask decides, as for the run's other outputs
    except FileExistsError:  # only with new (O_EXCL): the caller chooses another name
        raise
    except OSError as exc:
        if path.is_symlink():
            raise RecordingRefused(f"cannot record to {path}: it is a symbolic link; remove it") from None
        raise RecordingRefused(f"cannot record to {path}: {exc.strerror}") from None
    if not new:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            here = (
                " (here: a recorder this program opened and has not closed, such as one an episode that "
                "raised left open; close() it, or open recorders with `with`)"
                if any(not r.closed and r.part_path.absolute() == path.absolute() for r in _OPEN)
                else ""
            )
            raise RecordingRefused(
                f"cannot record to {path}: another run is recording that episode into this folder now{here}; "
                "record into another folder"
            ) from None
        except OSError as exc:  # ENOLCK (an NFS mount without its lock daemon), EOPNOTSUPP: not a bug of ours
            os.close(fd)
            raise RecordingRefused(
                f"cannot record to {path}: {exc.strerror} (its file system does not lock files; an NFS mount "
                "without its lock daemon?); record into a folder on one that does"
            ) from None
        try:
            if may_replace is not None:
                may_replace(path)
            os.ftruncate(fd, 0)
        except BaseException:
            os.close(fd)
            raise
    return os.fdopen(fd, "wb")


def _check_metadata(name: str, data: Mapping[str, str]) -> None:
    """PipelineError unless ``data`` maps strings to strings, as MCAP metadata holds them."""
    bad = {k: v for k, v in data.items() if not isinstance(k, str) or not isinstance(v, str)}
    if bad:
        raise PipelineError(f"metadata {name!r} needs str keys and values; got {bad!r}")


class McapRecorder:
    """Write JSON messages with JSON schemas to one MCAP file.

    :param path: the file to create (its folder must exist); an existing file is replaced when this one is
        finished. Until then the bytes go to ``<path>.part``.
    :param chunk_size: uncompressed bytes per chunk.
    :param compression: chunk compression; the default is the best codec installed.
    :param metadata: ``{name: {key: value}}`` metadata records written right after the header.
    :param new: take ``path`` only if it is free: neither it nor ``<path>.part`` exists (FileExistsError
        otherwise). The ``.part`` is created atomically and ``path`` checked after it, so that of recorders
        choosing names at the same time in one folder only one gets each (a finished file's ``.part`` is
        gone before its final name appears).
    :param may_replace: a check that a file may be replaced, raising if not: called with ``<path>.part``
        once it is locked, before it is emptied (it may be a killed run's unfinished recording; not with
        ``new``), where what it raises goes up with the file kept; and with ``path`` on closing, just before
        the file is finished and takes that name, while the ``.part`` is still locked (another run may have
        finished a file there since this one started), where a refusal leaves the finished recording its
        ``.part`` name, and ``close`` raises that.
    :param durable: finish with a durable rename (``replace_durably``: the file synced before it, its folder
        after), so that a power loss leaves no recording empty or lost; False for a scratch file whose bytes
        are copied, synced, elsewhere (a sweep's worker), where the syncs would only cost time.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        compression: CompressionType = DEFAULT_COMPRESSION,
        metadata: Mapping[str, Mapping[str, str]] | None = None,
        new: bool = False,
        may_replace: Callable[[Path], None] | None = None,
        durable: bool = True,
    ):
        if chunk_size <= 0:
            raise PipelineError(f"chunk_size must be a positive number of bytes, got {chunk_size}")
        if not isinstance(compression, CompressionType):
            raise PipelineError(f"compression must be an mcap CompressionType, got {compression!r}")
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise RecordingRefused(f"cannot record to {self.path}: folder {self.path.parent} does not exist")
        # Written to <name>.part, renamed to <name> by close(), rather than created at <name> once the first
        # chunk is ready: a file under its final name is then always a finished recording (a folder review, a
        # sweep's resume, Foxglove never meet a half-written one, nor a 0-byte one from a run killed in its
        # first second, when header and metadata still sat in the write buffer), while nothing is lost: a
        # killed run leaves its chunks in the .part, which `crowdmpc review NAME.part` reads. Creating the
        # file late would still leave a truncated .mcap for any kill after the first chunk.
        self.part_path = self.path.with_name(self.path.name + UNFINISHED_SUFFIX)
        self._may_replace = may_replace
        self._durable = durable
        for name, data in (metadata or {}).items():  # before the file: a refusal left a .part of a header
            _check_metadata(name, data)
        self._stream: IO[bytes] = _create(self.part_path, new=new, may_replace=may_replace)
        if new and (self.path.exists() or self.path.is_symlink()):
            self._stream.close()
            self.part_path.unlink()
            raise FileExistsError(f"{self.path} exists")
        try:
            # the data section's CRC too (mcap leaves it out by default): the chunks carry CRCs of their own,
            # but a flipped bit in the metadata records before them (seed 0 read as seed 1) passed --check
            self._writer = Writer(
                self._stream, chunk_size=chunk_size, compression=compression, enable_data_crcs=True
            )
            self._writer.start(profile="", library=LIBRARY)
        except OSError as exc:
            self._stream.close()
            raise self._unwritten(exc) from None
        except BaseException:
            self._discard()
            raise
        self._channels: dict[str, tuple[int, MessageSchema]] = {}
        self._schema_ids: dict[tuple[str, bytes], int] = {}  # one schema record shared by the topics using it
        self._closed = False
        self.message_count = 0
        _OPEN.add(self)
        try:
            for name, data in (metadata or {}).items():
                self.add_metadata(name, data)
        except BaseException:
            _OPEN.discard(self)
            self._closed = True
            self._discard()
            raise

    def _discard(self) -> None:
        """Remove the ``.part`` a constructor that did not return had made: nobody holds the recorder to
        finish it, so a Ctrl-C (or a `kill`, taken as one) in a program's own recording as it began left a
        ``.part`` of a header (the closed loop holds an interrupt while its observers start). Removed while
        its lock is held, then closed."""
        with contextlib.suppress(OSError):
            self.part_path.unlink()
        self._stream.close()

    # -- context manager: the file is finished however the block ends ----------------------------------------
    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Flush the open chunk, write the summary and footer, close the file and give it its name.

        Idempotent. When finishing fails the file keeps its ``.part`` name: it is not a finished recording.
        """
        if self._closed:
            return
        self._closed = True
        try:
            try:
                # the check before the footer: between the footer and the rename a killed run leaves a whole
                # recording named .part, a window kept to a moment (a .part reads as an unfinished recording)
                refusal = self._refusal()
                self._writer.finish()
                self._stream.flush()
                if refusal is not None:
                    raise refusal  # the recording is whole, under its .part name
                if self._durable:
                    from predictors.durable import replace_durably  # not at import: it loads casadi

                    replace_durably(self.part_path, self.path)
                else:
                    os.replace(self.part_path, self.path)
            finally:
                self._stream.close()  # the lock goes with it, after the rename
        except OSError as exc:
            raise self._unwritten(exc) from None

    def _unwritten(self, exc: OSError) -> PipelineError:
        """A write of the file that failed (a full disk, a quota, `ulimit -f`): one line naming it, not
        mcap's OSError traceback; what was written stays in the ``.part``, an unfinished recording."""
        return PipelineError(
            f"cannot record to {self.part_path}: {exc.strerror or exc} (the recording is unfinished); free "
            "space and run it again"
        )

    def _refusal(self) -> Exception | None:
        """What ``may_replace`` raised for ``path``, if it raised."""
        if self._may_replace is None:
            return None
        try:
            self._may_replace(self.path)
        except Exception as exc:
            return exc
        return None

    # -- writing ---------------------------------------------------------------------------------------------
    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A named MCAP metadata record; keys and values must be strings (encode anything else first)."""
        self._check_open()
        _check_metadata(name, data)
        try:
            self._writer.add_metadata(name, dict(data))
        except OSError as exc:
            raise self._unwritten(exc) from None

    def write(
        self, topic: str, message: Mapping[str, Any], log_time_ns: int, *, schema: MessageSchema
    ) -> None:
        """Append ``message`` (plain JSON values) to ``topic`` at ``log_time_ns`` (ns since the Unix epoch, as
        Foxglove reads it; an episode's recording: its wall-clock start + simulation time)."""
        channel_id = self._channel_id(topic, schema, log_time_ns)
        try:
            data = _ENCODER.encode(message).encode()
        except (TypeError, ValueError) as exc:  # a numpy array, a NaN, ...
            raise PipelineError(f"message on {topic!r} at {log_time_ns} ns is not plain JSON: {exc}") from exc
        self._add_message(channel_id, log_time_ns, data)

    def write_json(self, topic: str, data: bytes, log_time_ns: int, *, schema: MessageSchema) -> None:
        """Like ``write`` for a message already encoded as JSON text (hot paths that format it directly).

        The text is not parsed here; ``crowdmpc review --check`` validates it.
        """
        channel_id = self._channel_id(topic, schema, log_time_ns)
        self._add_message(channel_id, log_time_ns, data)

    def _add_message(self, channel_id: int, log_time_ns: int, data: bytes) -> None:
        try:  # a chunk is written out when full: the write that may meet a full disk
            self._writer.add_message(channel_id, log_time=log_time_ns, data=data, publish_time=log_time_ns)
        except OSError as exc:
            raise self._unwritten(exc) from None
        self.message_count += 1

    def _channel_id(self, topic: str, schema: MessageSchema, log_time_ns: int) -> int:
        """The topic's channel, registered on first use; refuses another schema and a bad log time."""
        self._check_open()
        if not isinstance(log_time_ns, int) or log_time_ns < 0:
            raise PipelineError(
                f"log time must be a non-negative int of ns, got {log_time_ns!r} on {topic!r}"
            )
        known = self._channels.get(topic)
        if known is None:
            return self._register(topic, schema)
        channel_id, known_schema = known
        if not known_schema.same_as(schema):
            raise PipelineError(
                f"topic {topic!r} carries {known_schema.name!r} messages; refusing a {schema.name!r} "
                "message (a changed schema needs a new topic)"
                if known_schema.name != schema.name
                else f"topic {topic!r}: schema {schema.name!r} changed since the topic was registered"
            )
        return channel_id

    def _register(self, topic: str, schema: MessageSchema) -> int:
        key = (schema.name, schema.data)
        schema_id = self._schema_ids.get(key)
        if schema_id is None:
            schema_id = self._writer.register_schema(schema.name, SCHEMA_ENCODING, schema.data)
            self._schema_ids[key] = schema_id
        channel_id = self._writer.register_channel(topic, MESSAGE_ENCODING, schema_id)
        self._channels[topic] = (channel_id, schema)
        return channel_id

    def _check_open(self) -> None:
        if self._closed:
            raise PipelineError(f"{self.path} is already finished; open a new recorder")
