"""The schema check of an episode recording (``crowdmpc review --check``): every message validated against
the schema stored in the file, not the one this version of crowdmpc would write.

Apart from pipelines.logs.review, which turns recordings into text (one run's summary, a table over runs, an
A/B comparison): the check reads the channels' schemas and encodings, which nothing of the review reads.
"""

from __future__ import annotations

import json
import math

from pipelines.logs.jsonschema import unsupported_keywords, validate
from pipelines.logs.reader import Channel, LoggedMessage, Recording
from pipelines.logs.schemas import MESSAGE_ENCODING, SCHEMA_ENCODING


def check_recording(rec: Recording) -> tuple[int, list[str]]:
    """Validate every message against its channel's schema as stored in the file: (checked, errors).

    The errors begin with what reading found (bad chunks, bad metadata, corrupt records); then, per message,
    its schema violations, or why the review left it out when the schema lets it pass (not JSON, or lacking
    what the review reads under a schema that does not require it).
    """
    errors = list(rec.problems)
    checked = 0
    for topic, channel in rec.channels.items():
        messages = rec.messages[topic]
        try:
            n, topic_errors = _check_topic(topic, channel, messages, rec.start_time_ns)
        except (ValueError, TypeError, AttributeError, KeyError, IndexError, RecursionError) as exc:
            # the file's schema is JSON but no schema (e.g. "required": 5): nothing on the topic is checked
            n, topic_errors = 0, [f"{topic}: schema {channel.schema_name!r} is malformed ({exc!r})"]
            topic_errors += [
                f"{m.where(topic, rec.start_time_ns)}: {m.problem}" for m in messages if m.problem
            ]
        checked += n
        errors += topic_errors
    return checked, errors


def _check_topic(
    topic: str, channel: Channel, messages: list[LoggedMessage], start_time_ns: int
) -> tuple[int, list[str]]:
    """Checked messages and errors of one topic; messages named by their simulation time (``start_time_ns``:
    the file's log time of the episode start)."""
    unusable = [f"{m.where(topic, start_time_ns)}: {m.problem}" for m in messages if m.problem]
    if channel.message_encoding != MESSAGE_ENCODING or channel.schema_encoding != SCHEMA_ENCODING:
        return 0, [
            f"{topic}: encoding {channel.message_encoding!r} / schema {channel.schema_encoding!r}, "
            f"expected {MESSAGE_ENCODING!r} / {SCHEMA_ENCODING!r}",
            *unusable,
        ]
    try:
        schema = json.loads(channel.schema_data)
    except (ValueError, RecursionError) as exc:
        return 0, [f"{topic}: schema {channel.schema_name!r} is not JSON ({exc})", *unusable]
    if not isinstance(schema, dict):
        return 0, [f"{topic}: schema {channel.schema_name!r} is not a JSON object", *unusable]
    unchecked = unsupported_keywords(schema)
    if unchecked:
        return 0, [
            f"{topic}: schema {channel.schema_name!r} uses keywords not checked here: {unchecked}",
            *unusable,
        ]
    checked, errors = 0, []
    for message in messages:
        if message.data is None:  # not JSON
            errors.append(f"{message.where(topic, start_time_ns)}: {message.problem}")
            continue
        checked += 1
        violations = [
            f"{message.where(topic, start_time_ns)} ({channel.schema_name}): {problem}"
            for problem in validate(message.data, schema)
        ]
        if not violations:  # where its schema lets it pass: bare NaN and Infinity are no JSON (outputs.md)
            violations = [
                f"{message.where(topic, start_time_ns)}: {where} is {value}, which JSON cannot hold"
                for where, value in _non_finite(message.data, "$")
            ]
        if not violations and message.problem:
            violations.append(f"{message.where(topic, start_time_ns)}: {message.problem}")
        errors += violations
    return checked, errors


def _non_finite(value: object, where: str) -> list[tuple[str, float]]:
    """Every NaN or infinite number in decoded JSON, by its path: Python's json reads bare NaN, Infinity and
    1e999, and a schema says nothing of them where it leaves a value open (``Solver.extra``); Foxglove's
    parser drops the whole message. A walk with its own stack: json.loads reads nesting deeper than
    Python's recursion limit allows a recursive walk (it was reported as the schema's fault)."""
    try:  # C's speed for the common message, which holds none (a /scene message holds hundreds of numbers)
        json.dumps(value, allow_nan=False)
        return []
    except (ValueError, RecursionError):
        pass
    found, stack = [], [(value, where)]
    while stack:
        item, path = stack.pop()
        if isinstance(item, float) and not math.isfinite(item):
            found.append((path, item))
        elif isinstance(item, dict):
            stack.extend((v, f"{path}.{k}") for k, v in reversed(item.items()))
        elif isinstance(item, list):
            stack.extend((v, f"{path}[{i}]") for i, v in reversed(list(enumerate(item))))
    return found
