"""One log rewritten in every valid MCAP layout by the official Python writer.

    mcap_layouts.py IN.mcap OUT_DIR

writes OUT_DIR/<layout>.mcap for each layout below and prints their names as JSON. Each holds
every message of IN.mcap (log and publish times kept); the layouts differ in what the
specification leaves to the writer: chunks or none, which records the summary repeats,
indexes, statistics, compression, metadata and attachments anywhere, log times out of order,
and a schemaless channel (schema id 0).
"""

import json
import random
import sys
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

LAYOUTS = {
    "default": {},
    "no_repeated_schemas": {"repeat_schemas": False},
    "no_repeated_channels_or_schemas": {"repeat_channels": False, "repeat_schemas": False},
    "unchunked": {"use_chunking": False},
    "no_summary": {
        "index_types": IndexType.NONE,
        "repeat_channels": False,
        "repeat_schemas": False,
        "use_statistics": False,
        "use_summary_offsets": False,
    },
    "no_message_index": {"index_types": IndexType.CHUNK},
    "no_statistics": {"use_statistics": False},
    "no_summary_offsets": {"use_summary_offsets": False},
    "uncompressed_small_chunks": {"compression": CompressionType.NONE, "chunk_size": 4096},
    "lz4": {"compression": CompressionType.LZ4},
    "metadata_and_attachments_anywhere": {},
    "log_times_out_of_order": {},
    "schemaless_channel": {},
}


def read(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = dict(summary.schemas)
        channels = dict(summary.channels)
        messages = [(m.channel_id, m.log_time, m.publish_time, m.data) for _, _, m in reader.iter_messages(log_time_order=False)]
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    return schemas, channels, messages, metadata


def write(path, layout, schemas, channels, messages, metadata):
    options = LAYOUTS[layout]
    with open(path, "wb") as f:
        w = Writer(f, **options)
        w.start(profile="", library="mcap python (railfuse layout test)")
        extra = layout == "metadata_and_attachments_anywhere"
        if extra:
            w.add_attachment(create_time=0, log_time=0, name="before.txt", media_type="text/plain", data=b"first")
            w.add_metadata("railfuse.layout", {"where": "before the schemas"})
        ids = {}
        for sid, s in schemas.items():
            ids[sid] = w.register_schema(name=s.name, encoding=s.encoding, data=s.data)
        chans = {}
        for cid, c in channels.items():
            chans[cid] = w.register_channel(topic=c.topic, message_encoding=c.message_encoding, schema_id=ids.get(c.schema_id, 0), metadata=dict(c.metadata))
        if layout == "schemaless_channel":
            bare = w.register_channel(topic="/notes/bare", message_encoding="json", schema_id=0)
        order = list(messages)
        if layout == "log_times_out_of_order":
            # Shuffled within windows of 200 messages: log times run backwards at times.
            rng = random.Random(27)
            for i in range(0, len(order), 200):
                window = order[i : i + 200]
                rng.shuffle(window)
                order[i : i + 200] = window
        for k, (cid, log, pub, data) in enumerate(order):
            w.add_message(channel_id=chans[cid], log_time=log, publish_time=pub, data=data, sequence=k)
            if extra and k == len(order) // 2:
                w.add_attachment(create_time=log, log_time=log, name="middle.txt", media_type="text/plain", data=b"middle")
                w.add_metadata("railfuse.layout", {"where": "in the middle"})
            if layout == "schemaless_channel" and k % 100 == 0:
                w.add_message(channel_id=bare, log_time=log, publish_time=log, data=b'{"note": "schemaless"}', sequence=k)
        for name, m in metadata:
            w.add_metadata(name, m)
        if extra:
            w.add_attachment(create_time=0, log_time=0, name="after.txt", media_type="text/plain", data=b"last")
        w.finish()


def main():
    source, out = Path(sys.argv[1]), Path(sys.argv[2])
    schemas, channels, messages, metadata = read(source)
    for layout in LAYOUTS:
        write(out / f"{layout}.mcap", layout, schemas, channels, messages, metadata)
    print(json.dumps({"layouts": list(LAYOUTS), "messages": len(messages)}))


if __name__ == "__main__":
    main()
