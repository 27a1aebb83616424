"""Telling a crowdmpc recording from another program's MCAP file.

A recording is told by what only crowdmpc writes: its header's library (every recorder's since the first),
else, for a header that did not read, the "crowdmpc" metadata record or a ``crowdmpc.*`` schema. Topic names
are not: another program's file with a ``/scene`` of its own (Foxglove's usual topic) read as a recording
with no episode in it, and so did one with a metadata record named "episode" or "config".
"""

from __future__ import annotations

from collections.abc import Iterable

from pipelines.logs.schemas import LIBRARY, SCHEMA_PREFIX


def not_a_recording(
    library: str | None, schemas: Iterable[str], topics: Iterable[str], metadata: Iterable[str]
) -> str | None:
    """Why a file whose header names ``library`` (None: it did not read) and that holds these schema names,
    topics and metadata records is no crowdmpc recording; None for a recording, and for a file that holds
    nothing to tell (a header cut short: the reader says so)."""
    metadata, topics = sorted(metadata), sorted(topics)
    if library == LIBRARY or "crowdmpc" in metadata or any(n.startswith(SCHEMA_PREFIX) for n in schemas):
        return None
    if library is None and not topics and not metadata:
        return None
    held = [
        f"{what}{'s' * (len(names) != 1)} {', '.join(map(repr, names[:3]))}"
        + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        for what, names in (("topic", topics), ("metadata record", metadata))
        if names
    ]
    by = f"its header names library {library!r}" if library is not None else "its header did not read"
    what = f"it holds {'; '.join(held)}" if held else "it holds nothing"
    return (
        f"is an MCAP file but not a crowdmpc recording: {by}, where a recording's names {LIBRARY!r}, and "
        f"{what}, but no 'crowdmpc' metadata record nor a {SCHEMA_PREFIX}* schema"
    )
