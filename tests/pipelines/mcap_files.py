"""MCAP files rewritten from a recording's records, for tests that imitate older or other programs' files."""

from pathlib import Path

from mcap.writer import Writer


def write_mcap(
    out: Path, metadata: dict[str, dict[str, str]], messages: list, *, library: str = "", shift_ns: int = 0
) -> Path:
    """An MCAP file of these metadata records and ``messages`` (as make_reader's iter_messages gives them),
    its header naming ``library``, every log and publish time less ``shift_ns``."""
    with out.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library=library)
        for name, values in metadata.items():
            writer.add_metadata(name, values)
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in messages:
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                schema_id = schemas[schema.id] if schema is not None else 0
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_id
                )
            writer.add_message(
                channels[channel.id],
                log_time=message.log_time - shift_ns,
                data=message.data,
                publish_time=message.publish_time - shift_ns,
            )
        writer.finish()
    return out
