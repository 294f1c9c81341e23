"""Copies an MCAP log without one topic, with the official `mcap` reader and writer (a log
railfuse did not write): `drop_topic.py SRC DST TOPIC`. Prints what it copied as JSON."""

import json
import sys

from mcap.reader import make_reader
from mcap.writer import Writer


def main(src: str, dst: str, topic: str) -> None:
    copied = dropped = 0
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        header = reader.get_header()
        writer = Writer(out)
        writer.start(profile=header.profile, library="drop_topic.py")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.topic == topic:
                dropped += 1
                continue
            if channel.id not in channels:
                sid = 0
                if schema is not None:
                    if schema.id not in schemas:
                        schemas[schema.id] = writer.register_schema(
                            schema.name, schema.encoding, schema.data
                        )
                    sid = schemas[schema.id]
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, sid, dict(channel.metadata)
                )
            writer.add_message(
                channels[channel.id],
                message.log_time,
                message.data,
                message.publish_time,
                message.sequence,
            )
            copied += 1
        for m in reader.iter_metadata():
            writer.add_metadata(m.name, dict(m.metadata))
        writer.finish()
    print(json.dumps({"copied": copied, "dropped": dropped}))


if __name__ == "__main__":
    main(*sys.argv[1:4])
