"""Reading episode recordings back: every message and metadata record, and the episode as arrays.

Files are read with ``NonSeekingReader(...).iter_messages(log_time_order=False)``, the one way mcap 1.6 reads
a file whose writer was killed: it walks the records front to back and stops where the bytes stop, so a
truncated file yields everything up to its last complete chunk. The seeking reader needs the footer, and
log-time ordering sorts (so reads everything) before yielding anything. A file is truncated when it does not
end with MCAP's magic.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.reader import NonSeekingReader
from mcap.records import Metadata
from mcap.stream_reader import StreamReader

from pipelines.errors import PipelineError

MAGIC: Final[bytes] = b"\x89MCAP0\r\n"


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
    data: Any  # the decoded JSON (None when it did not decode; see Recording.decode_errors)


@dataclass(frozen=True)
class Recording:
    """Everything read from one file."""

    path: Path
    metadata: dict[str, dict[str, str]]  # name -> record (the last one when a name repeats)
    channels: dict[str, Channel]  # topic -> channel
    messages: dict[str, list[LoggedMessage]]  # topic -> messages in file order
    truncated: bool  # the file does not end with MCAP's closing magic
    stopped_at: str | None = None  # what ended reading early (truncated files)
    decode_errors: list[str] = field(default_factory=list)

    @property
    def warning(self) -> str | None:
        if not self.truncated:
            return None
        n = sum(len(v) for v in self.messages.values())
        last = max((m[-1].log_time_ns for m in self.messages.values() if m), default=0) / 1e9
        return (
            f"{self.path} is truncated (the run was killed or is still writing): read {n} messages up to "
            f"t = {last:.1f} s, the last complete chunk; the rest is lost ({self.stopped_at or 'no footer'})"
        )

    def episode(self) -> dict[str, str]:
        return self.metadata.get("episode", {})

    def config(self) -> dict[str, Any]:
        return _decoded(self.metadata.get("config", {}))

    def run_meta(self) -> dict[str, Any]:
        return _decoded(self.metadata.get("run", {}))

    def data(self, topic: str) -> list[Any]:
        return [m.data for m in self.messages.get(topic, ()) if m.data is not None]

    @property
    def label(self) -> str:
        ep = self.episode()
        parts = [ep.get("controller"), ep.get("predictor"), ep.get("scenario"), f"seed {ep.get('seed', '?')}"]
        return " / ".join(p for p in parts if p)


def _decoded(record: dict[str, str]) -> dict[str, Any]:
    """Metadata values are JSON text (pipelines.logs.recording); a value that is not stays a string."""
    out: dict[str, Any] = {}
    for key, text in record.items():
        try:
            out[key] = json.loads(text)
        except ValueError:
            out[key] = text
    return out


# ------------------------------------------------------------------------------------------------------------
# reading
# ------------------------------------------------------------------------------------------------------------


def _ends_with_magic(path: Path) -> bool:
    size = path.stat().st_size
    if size < 2 * len(MAGIC):
        return False
    with open(path, "rb") as f:
        f.seek(size - len(MAGIC))
        return f.read() == MAGIC


def _check_header(path: Path) -> None:
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
    if head != MAGIC:
        raise PipelineError(f"{path} is not an MCAP file (it does not start with MCAP's magic bytes)")


def _stop_reason(exc: BaseException) -> str:
    if isinstance(exc, EndOfFile | struct.error):
        return "the file ends inside a record"
    return f"{type(exc).__name__}: {exc}".rstrip(": ")


def read_recording(path: str | Path) -> Recording:
    """Read every message and metadata record of ``path``; a truncated file reads up to its last chunk."""
    path = Path(path)
    if not path.is_file():
        raise PipelineError(f"{path}: no such recording")
    _check_header(path)
    complete = _ends_with_magic(path)
    stopped_at = None

    metadata: dict[str, dict[str, str]] = {}
    with open(path, "rb") as f:
        # emit_chunks: walk over chunks without decompressing them; metadata records sit between chunks.
        try:
            for record in StreamReader(f, emit_chunks=True).records:
                if isinstance(record, Metadata):
                    metadata[record.name] = dict(record.metadata)
        except Exception as exc:  # noqa: BLE001 (any parse error past a cut; a finished file re-raises)
            if complete:
                raise PipelineError(f"{path} is corrupt: {_stop_reason(exc)}") from exc
            stopped_at = _stop_reason(exc)

    channels: dict[str, Channel] = {}
    messages: dict[str, list[LoggedMessage]] = {}
    decode_errors: list[str] = []
    with open(path, "rb") as f:
        try:
            for schema, channel, message in NonSeekingReader(f).iter_messages(log_time_order=False):
                topic = channel.topic
                if topic not in channels:
                    channels[topic] = Channel(
                        topic,
                        channel.message_encoding,
                        schema.name if schema else "",
                        schema.encoding if schema else "",
                        schema.data if schema else b"",
                    )
                    messages[topic] = []
                try:
                    data = json.loads(message.data)
                except ValueError as exc:
                    data = None
                    decode_errors.append(f"{topic} @ {message.log_time / 1e9:.3f} s: not JSON ({exc})")
                messages[topic].append(LoggedMessage(message.log_time, data))
        except Exception as exc:  # noqa: BLE001 (see above)
            if complete:
                raise PipelineError(f"{path} is corrupt: {_stop_reason(exc)}") from exc
            stopped_at = _stop_reason(exc)
    return Recording(path, metadata, channels, messages, not complete, stopped_at, decode_errors)


def find_recordings(directory: str | Path) -> list[Path]:
    directory = Path(directory)
    paths = sorted(directory.glob("*.mcap"))
    if not paths:
        raise PipelineError(f"no .mcap files in {directory}")
    return paths


# ------------------------------------------------------------------------------------------------------------
# the episode as arrays
# ------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EpisodeView:
    """The recorded states and plans as arrays (state rows are the steps that made it into the file)."""

    times: np.ndarray  # (T,) s
    steps: np.ndarray  # (T,) int
    robot_positions: np.ndarray  # (T, M, 2) m
    human_positions: np.ndarray  # (T, N, 2) m
    robot_goals: np.ndarray  # (M, 2) m
    human_goals: np.ndarray  # (N, 2) m
    plans: dict[int, np.ndarray]  # step -> (M, H, 2) m
    predictions: dict[int, np.ndarray]  # step -> (H, N, 2) m
    dt: float  # s
    radius: float  # m

    def row_at(self, t: float) -> int:
        """Index of the recorded state nearest to time ``t`` (s)."""
        return int(np.argmin(np.abs(self.times - t)))


def _points(rows: list[Any], n: int) -> np.ndarray:
    return np.asarray(rows, dtype=float).reshape(n, 2)


def episode_view(rec: Recording) -> EpisodeView:
    humans = rec.data("/humans")
    by_step = {h["step"]: h for h in humans}
    robots = [r for r in rec.data("/robots") if r["step"] in by_step]  # a cut can fall between the two
    if not robots:
        raise PipelineError(f"{rec.path} holds no complete state (/robots and /humans) to draw")
    steps = [r["step"] for r in robots]
    m, n = len(robots[0]["positions"]), len(humans[0]["positions"])
    ep = rec.episode()
    times = np.array([r["time"] for r in robots], dtype=float)
    dt = float(ep["dt"]) if "dt" in ep else float(np.median(np.diff(times))) if len(times) > 1 else 0.4
    return EpisodeView(
        times=times,
        steps=np.array(steps, dtype=int),
        robot_positions=np.array([_points(r["positions"], m) for r in robots]),
        human_positions=np.array([_points(by_step[s]["positions"], n) for s in steps]).reshape(
            len(steps), n, 2
        ),
        robot_goals=_points(robots[0]["goals"], m),
        human_goals=_points(humans[0]["goals"], n),
        plans={p["step"]: np.asarray(p["positions"], dtype=float) for p in rec.data("/mpc/plan")},
        predictions={
            p["step"]: np.asarray(p["positions"], dtype=float).reshape(-1, n, 2)
            for p in rec.data("/mpc/prediction")
        },
        dt=dt,
        radius=float(ep.get("radius", 0.3)),
    )
