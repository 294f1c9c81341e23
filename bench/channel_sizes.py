"""What each channel of an MCAP log costs: its messages' bytes as written, and as zstd (level
1, 1 MiB chunks of that channel alone, as railfuse's writer compresses) would store them.
Usage: channel_sizes.py LOG.mcap; prints a table, largest first, and the file's size."""
import os
import sys

import zstandard
from mcap.reader import make_reader

CHUNK = 1 << 20


def main(path):
    raw, packed, pending, count, encoding = {}, {}, {}, {}, {}
    z = zstandard.ZstdCompressor(level=1)
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            t = channel.topic
            encoding[t] = channel.message_encoding
            count[t] = count.get(t, 0) + 1
            raw[t] = raw.get(t, 0) + len(message.data)
            buf = pending.setdefault(t, bytearray())
            buf += message.data
            if len(buf) >= CHUNK:
                packed[t] = packed.get(t, 0) + len(z.compress(bytes(buf)))
                buf.clear()
    for t, buf in pending.items():
        if buf:
            packed[t] = packed.get(t, 0) + len(z.compress(bytes(buf)))
    mib = lambda n: n / (1 << 20)
    print(f"{'topic':32} {'encoding':9} {'messages':>9} {'raw MiB':>9} {'zstd MiB':>9}")
    for t in sorted(raw, key=lambda t: -packed.get(t, 0)):
        print(f"{t:32} {encoding[t]:9} {count[t]:9} {mib(raw[t]):9.1f} {mib(packed.get(t, 0)):9.1f}")
    rest = sum(packed.get(t, 0) for t in raw if t != "/eddy_current/block")
    print(f"all but /eddy_current/block: {mib(rest):.1f} MiB zstd; file {mib(os.path.getsize(path)):.1f} MiB")


if __name__ == "__main__":
    main(sys.argv[1])
