"""The eddy-current blocks of two logs of the same run, one in protobuf (decoded by
mcap-protobuf-support through the file's own descriptors) and one in JSON: every sample the
same, as float32. Usage: eddy_protobuf.py PROTOBUF.mcap JSON.mcap; prints a JSON summary."""
import json
import sys

import numpy as np
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from railfuse_messages import eddy_current_volts

TOPIC = "/eddy_current/block"


def protobuf_blocks(path):
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, _, m in reader.iter_decoded_messages(topics=[TOPIC]):
            assert channel.message_encoding == "protobuf" and schema.name == "railfuse.EddyCurrentBlock"
            assert len(m.sensor_a) == 0 and m.counts_i16, "samples on the grid travel as counts"
            yield (m.stamp_ns, *eddy_current_volts(m))


def json_blocks(path):
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=[TOPIC]):
            assert channel.message_encoding == "json"
            d = json.loads(message.data)
            yield d["stamp_ns"], np.float32(d["sensor_a"]), np.float32(d["sensor_b"])


def main(pb, js):
    blocks = samples = 0
    for (t1, a1, b1), (t2, a2, b2) in zip(protobuf_blocks(pb), json_blocks(js), strict=True):
        assert t1 == t2
        assert np.array_equal(a1, a2) and np.array_equal(b1, b2), f"block at {t1} differs"
        blocks += 1
        samples += len(a1) + len(b1)
    print(json.dumps({"blocks": blocks, "samples": samples}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
